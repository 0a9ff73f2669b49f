"""Long-data fits (issue 15, item 3): R-test samples on the c600u, as
bench/run.py's case_ball3d, at 1e6 and 1e7 samples, built from arrays (no
JSON), fitted by identify on the accumulated normal equations.

Each size runs in its own process so that its peak RSS (getrusage) is its
own. The arithmetic floor is a stated count: a nearly linear fit needs at
least two passes with derivatives over the data (one to step, one to see the
step converged, whose J^T J also gives the covariance) and one pass without
(the residuals at the solution). A pass costs at least the evaluation of
every sample's tool point (measured here with Machine.tool_point on the same
arrays, one thread) plus forming J^T J (rows p (p + 1) flops, at the
measured GFLOP/s of numpy's dense product); the derivatives are counted at
the cost of the point itself, which understates the floor.

The machine is shared: the load average is recorded with each result.

With --parquet the samples go through a Parquet file instead (the issue's
case: a long trace on disk): one process writes it in pieces of 10^6
samples (the same poses and noise recipe), and the measuring process starts
from the file: load_s is fivecal.load_dataset, identify_s the fit, and its
peak RSS covers load and fit alone.

    PYTHONPATH=python python3 bench/long_data.py [--sizes 1000000 10000000] [--threads 2] [--parquet]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "python"))

import fivecal  # noqa: E402

NAMES = ["EB0A", "EA0C", "EB0C", "EY0C"]


def peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def dense_gflops():
    """GFLOP/s of a tall-skinny J^T J (the kernel the accumulation runs)."""
    a = np.random.default_rng(0).normal(size=(768, 8))
    reps = 2000
    t = time.perf_counter()
    for _ in range(reps):
        a.T @ a
    dt = time.perf_counter() - t
    return reps * 768 * 8 * 9 / dt / 1e9


MACHINE = os.path.join(HERE, "..", "examples", "machines", "c600u.json")
TRUE = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
TOOL, TABLE = [0.0, 0.0, 150.0], [50.0, 0.0, 80.0]


def samples(m, n, rng):
    """Axis readings and measured displacements of n R-test samples."""
    rot = {"X": np.zeros(n), "Y": np.zeros(n), "Z": np.zeros(n), "A": rng.uniform(-90, 90, n),
           "C": rng.uniform(0, 360, n)}
    _, tool_axes = m.tool_pose(rot, tip=TOOL)
    axes = m.inverse(np.tile(TABLE, (n, 1)), tool_axes=tool_axes, start={k: v[0] for k, v in rot.items()})
    # The inverse follows the shortest move from sample to sample: over 1e7
    # random samples C winds up to 1e5 degrees. The same poses, one turn.
    axes["C"] = np.mod(axes["C"], 360.0)
    meas = m.tool_point(axes, TRUE, tip=TOOL) - np.array(TABLE) + rng.normal(0, 5e-4, (n, 3))
    return axes, meas


def write_parquet(n, path, piece=1_000_000):
    """The samples as a Parquet dataset, written in pieces (never the whole
    trace in memory)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from fivecal.io import columnar

    m = fivecal.Machine.load(MACHINE)
    small = fivecal.ball_dataset(m, "ball3d", {a: [0.0] for a in m.axis_names}, TOOL, TABLE,
                                 measured=[[0.0, 0.0, 0.0]], setup="R1")
    schema = columnar.dataset_columns(small).schema
    rng = np.random.default_rng(1)
    with pq.ParquetWriter(path, schema, compression="zstd") as w:
        for s in range(0, n, piece):
            k = min(piece, n - s)
            axes, meas = samples(m, k, rng)
            cols = {"type": pa.array(np.full(k, "ball3d", dtype=object), pa.string()),
                    "setup": pa.array(np.full(k, "R1", dtype=object), pa.string())}
            cols.update({a: np.asarray(v, dtype=float) for a, v in axes.items()})
            for c, x in zip("xyz", meas.T):
                cols[f"measured_{c}"] = np.ascontiguousarray(x)
            for c, x in zip("xyz", TOOL):
                cols[f"tool_ball_{c}"] = np.full(k, x)
            for c, x in zip("xyz", TABLE):
                cols[f"table_ball_{c}"] = np.full(k, x)
            w.write_table(pa.table({f.name: cols[f.name] for f in schema}, schema=schema))


def one_size(n, threads, dense, parquet=None):
    m = fivecal.Machine.load(MACHINE)
    true, tool = TRUE, TOOL
    t0 = time.perf_counter()
    if parquet:
        ds = fivecal.load_dataset(parquet)
        t_build = time.perf_counter() - t0
        axes = None
    else:
        axes, meas = samples(m, n, np.random.default_rng(1))
        ds = fivecal.ball_dataset(m, "ball3d", axes, TOOL, TABLE, measured=meas, setup="R1")
        t_build = time.perf_counter() - t0
        del meas
    rss_data = peak_rss_mb()

    if axes is not None:
        # The floor's per-pass evaluation: every sample's tool point, once.
        t = time.perf_counter()
        m.tool_point(axes, true, tip=tool)
        t_point = time.perf_counter() - t

    load = os.getloadavg()
    t = time.perf_counter()
    r = fivecal.identify(ds, NAMES, default_setup=False, num_threads=threads)
    t_fit = time.perf_counter() - t
    assert r.verdict == "ok", r.verdict
    rss = peak_rss_mb()
    if axes is None:
        # From the file, after the fit: the floor's arrays stay out of the
        # load and fit's peak.
        import pyarrow.parquet as pq

        cols = pq.read_table(parquet, columns=list(m.axis_names))
        axes = {a: cols.column(a).to_numpy() for a in m.axis_names}
        del cols
        t = time.perf_counter()
        m.tool_point(axes, true, tip=tool)
        t_point = time.perf_counter() - t
    rows, p = 3 * n, len(NAMES)
    gf = dense_gflops()
    flops_pass = rows * p * (p + 1) + 2 * rows * p
    floor = 3 * t_point + 2 * flops_pass / (gf * 1e9)
    out = {"case": f"ball3d_long_{n}", "samples": n, "rows": rows, "unknowns": p, "threads": threads,
           "fit_path": r.fit_path, "iterations": r.iterations, "identify_s": t_fit,
           "source": "parquet" if parquet else "arrays",
           ("load_s" if parquet else "dataset_build_s"): t_build, "tool_point_pass_s": t_point,
           "normal_equation_flops_per_pass": flops_pass, "dense_gflops": gf,
           "floor_s": floor, "ratio_to_floor": t_fit / floor,
           "peak_rss_before_identify_mb": rss_data, "peak_rss_mb": rss,
           "load_average_before": list(load), "load_average_after": list(os.getloadavg()),
           "values": {k: r.values[k] for k in NAMES}, "std": {k: r.std[k] for k in NAMES}}
    if dense:
        t = time.perf_counter()
        rd = fivecal.identify(ds, NAMES, default_setup=False, num_threads=threads, fit_path="dense")
        out["dense_identify_s"] = time.perf_counter() - t
        out["dense_peak_rss_mb"] = peak_rss_mb()
        out["max_difference_in_sigma"] = max(abs(rd.values[k] - r.values[k]) / rd.std[k] for k in NAMES)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1_000_000, 10_000_000])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--dense-up-to", type=int, default=1_000_000,
                    help="also time the dense path at sizes up to this (memory: rows x p doubles, several copies)")
    ap.add_argument("--out", default=os.path.join(HERE, "long_data.json"))
    ap.add_argument("--parquet", action="store_true",
                    help="load the samples from a Parquet file (written first, in another process)")
    ap.add_argument("--one", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--file", help=argparse.SUPPRESS)
    ap.add_argument("--write", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.write:
        write_parquet(a.one, a.file)
        return 0
    if a.one:
        print(json.dumps(one_size(a.one, a.threads, a.one <= a.dense_up_to, a.file)))
        return 0
    import tempfile

    tmp = tempfile.TemporaryDirectory()
    results = []
    for n in a.sizes:
        extra = []
        if a.parquet:
            path = os.path.join(tmp.name, f"rtest{n}.parquet")
            subprocess.run([sys.executable, __file__, "--write", "--one", str(n), "--file", path], check=True)
            extra = ["--file", path]
        proc = subprocess.run([sys.executable, __file__, "--one", str(n), "--threads", str(a.threads),
                               "--dense-up-to", str(a.dense_up_to)] + extra, capture_output=True, text=True)
        if a.parquet:
            os.remove(path)
        if proc.returncode != 0:
            results.append({"case": f"ball3d_long_{n}", "samples": n, "error": proc.stderr.strip()[-2000:]})
        else:
            results.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        print(json.dumps(results[-1]), flush=True)
    doc = {"cpu_count": os.cpu_count(), "date": time.strftime("%Y-%m-%d %H:%M:%S"),
           "note": "shared machine: see each result's load average", "results": results}
    with open(a.out, "w") as f:
        json.dump(doc, f, indent=1)
    print(f"written {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
