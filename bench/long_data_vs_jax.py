"""ball3d fits of 10^4, 10^5 and 10^6 R-test samples (bench/run.py's
case_ball3d: the same machine, poses, errors and noise), fivecal against
the strengthened JAX baseline (baseline_jax.ball3d_fit_function), measured
interleaved: each round runs fivecal's identify and then JAX's warm fit, so
that a load shifting on the shared machine moves both sides alike. Medians
of the rounds; JAX's trace and compile apart.

    PYTHONPATH=python python3 bench/long_data_vs_jax.py [--sizes 10000 100000 1000000] [--rounds 5]
        [--fivecal-path DIR]   # import fivecal from DIR (a saved older build: before/after in one run)

JAX is not a dependency of fivecal: `pip install jax` to run this.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0, help="fivecal's threads (0: every core)")
    ap.add_argument("--fivecal-path", help="directory holding the fivecal package to measure")
    ap.add_argument("--no-jax", action="store_true")
    ap.add_argument("--out", help="append the results (JSON lines) to this file")
    a = ap.parse_args(argv)
    sys.path.insert(0, a.fivecal_path or os.path.join(HERE, "..", "python"))
    sys.path.insert(0, HERE)
    import fivecal

    jbase = None if a.no_jax else __import__("baseline_jax")
    m = fivecal.Machine.load(os.path.join(HERE, "..", "examples", "machines", "c600u.json"))
    true = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
    names = list(true)
    tool, table = [0.0, 0.0, 150.0], [50.0, 0.0, 80.0]
    fit = jbase.ball3d_fit_function(m, names) if jbase else None
    for n in a.sizes:
        rng = np.random.default_rng(1)
        rot = {"X": np.zeros(n), "Y": np.zeros(n), "Z": np.zeros(n), "A": rng.uniform(-90, 90, n),
               "C": rng.uniform(0, 360, n)}
        _, tool_axes = m.tool_pose(rot, tip=tool)
        axes = m.inverse(np.tile(table, (n, 1)), tool_axes=tool_axes, start={k: v[0] for k, v in rot.items()})
        meas = m.tool_point(axes, true, tip=tool) - np.array(table) + rng.normal(0, 5e-4, (n, 3))
        ds = fivecal.ball_dataset(m, "ball3d", axes, tool, table, measured=meas, setup="R1")
        kw = {"num_threads": a.threads} if a.threads else {}

        def run_f():
            return fivecal.identify(ds, names, default_setup=False, **kw)

        r = run_f()
        assert r.verdict == "ok", r.verdict
        out = {"case": f"ball3d_fit_{n}", "samples": n, "fit_path": r.fit_path, "iterations": r.iterations,
               "fivecal": a.fivecal_path or "tree", "load_average_before": list(os.getloadavg())}
        tf, tj = [], []
        if fit:
            qj = m.axes_matrix(axes)
            for i, ax in enumerate(m.axis_names):
                if m.is_rotary(ax):
                    qj[:, i] = np.deg2rad(qj[:, i])
            ta, tb = np.asarray(tool, float), np.asarray(table, float)
            t = time.perf_counter()
            x_j, it_j, _, ok_j, *_ = jbase.block(fit(qj, ta, tb, meas))
            out["jax_compile_s"] = time.perf_counter() - t
            assert bool(ok_j)
            out["jax_max_difference_in_sigma"] = max(abs(float(x_j[i]) - r.values[k]) / r.std[k]
                                                     for i, k in enumerate(names))
            out["jax_jacobian_evaluations"] = int(it_j)
        for _ in range(a.rounds):
            t = time.perf_counter()
            run_f()
            tf.append(time.perf_counter() - t)
            if fit:
                t = time.perf_counter()
                jbase.block(fit(qj, ta, tb, meas))
                tj.append(time.perf_counter() - t)
        out.update({"fivecal_s": statistics.median(tf), "runs_fivecal_s": tf,
                    "load_average_after": list(os.getloadavg())})
        if fit:
            out.update({"jax_s": statistics.median(tj), "runs_jax_s": tj,
                        "jax_over_fivecal": statistics.median(tj) / statistics.median(tf)})
        print(json.dumps(out), flush=True)
        if a.out:
            with open(a.out, "a") as f:
                f.write(json.dumps(out) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
