"""fivecal's own time on every case of bench/run.py, this tree against another
checkout of fivecal, in one run:

    python3 bench/versus.py /path/to/other/checkout [--rounds 5] [--out versus.json]

Why a separate harness: a day's machine speed varies by tens of percent, so
"not slower than before" cannot be read off two results.json files written on
different days. Here both builds run in the same minutes. Each side is a
long-lived worker process with its own tree's `python/` first on the path (two
builds of `fivecal._core` cannot share a process); the controller asks them in
turn for one timed round of a case (the fastest of as many runs as take about
0.3 s), alternating which side goes first, so load and clock drift fall on
both alike. A case's data are built once per worker
(the first run is a warm-up, not counted) by bench/run.py's own set-up code,
which uses only public API both trees have.

Both sides' outputs are compared (fitted values in their sigma, Monte Carlo
spreads and forward-kinematics sums relatively, the design's chosen groups):
the "agree" column says whether the two trees solved the same problem to
rounding (1e-4), so a time is never compared with different work.

The ratio of a case is the median over rounds of this side's time over the
other's in the same round, with a bootstrap 95 % interval. The two runs of a
round are seconds apart and share the machine's state; the ratio of the two
sides' medians does not pair them, and on this VM, whose runs are bimodal
(the same run at 8 or 11 s), it read 1.14 for a case whose paired rounds
read 0.96 (bench/NOTES.md, session 17).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import random
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
CASES = ["forward_kinematics", "tango_S3", "tango_S4", "tango_auto", "tango_auto_vce",
         "ball3d_fit_10000", "ball3d_fit_100000", "ball3d_fit_1000000",
         "monte_carlo_1000_t1", "monte_carlo_1000_t2", "monte_carlo_10000_t1", "monte_carlo_10000_t2",
         "design_search_10000"]


# ---- worker: one tree's fivecal ----------------------------------------------

def _summary(out):
    """What a case's output says about the problem it solved, for the
    controller to check that both trees solved the same one."""
    import numpy as np

    if hasattr(out, "estimated") and hasattr(out, "values"):     # a fit
        return {"kind": "fit", "iterations": int(out.iterations),
                "values": {k: float(v) for k, v in out.values.items()},
                "std": {k: float(v) for k, v in out.std.items()}}
    if hasattr(out, "groups") and hasattr(out, "evaluations"):    # a design
        return {"kind": "design", "groups": sorted(int(g) for g in out.groups)}
    if isinstance(getattr(out, "std", None), dict):               # a Monte Carlo
        return {"kind": "spread", "std": {k: float(v) for k, v in out.std.items()}}
    a = np.asarray(out, dtype=float)                              # forward kinematics
    return {"kind": "points", "shape": list(a.shape), "sum": float(a.sum()), "sum_sq": float((a * a).sum())}


def _difference(a, b):
    """How far two summaries are apart: for fits in the fitted sigma, for
    spreads and point sums relatively; inf when they differ in kind or names."""
    if a["kind"] != b["kind"]:
        return float("inf")
    if a["kind"] == "design":
        return 0.0 if a["groups"] == b["groups"] else float("inf")
    if a["kind"] == "points":
        if a["shape"] != b["shape"]:
            return float("inf")
        return max(abs(a[k] - b[k]) / max(abs(a[k]), abs(b[k]), 1e-300) for k in ("sum", "sum_sq"))
    if set(a["std"]) != set(b["std"]):
        return float("inf")
    if a["kind"] == "fit":
        return max((abs(a["values"][k] - b["values"][k]) / a["std"][k] for k in a["std"] if a["std"][k] > 0),
                   default=0.0)
    return max(abs(a["std"][k] - b["std"][k]) / max(abs(a["std"][k]), abs(b["std"][k]), 1e-300) for k in a["std"])


def _prepare(case):
    """The case's call (no arguments), built as bench/run.py builds it."""
    import numpy as np

    import fivecal
    import run as bench
    from fivecal.procedures import tango

    if case == "forward_kinematics":
        m, errors = tango.hu40t_machine(), tango.thesis_s4_errors()
        rng = np.random.default_rng(0)
        n = 1_000_000
        axes = {"X": rng.uniform(-300, 300, n), "Y": rng.uniform(-300, 300, n), "Z": rng.uniform(-300, 300, n),
                "B": rng.uniform(-90, 90, n), "C": rng.uniform(-360, 360, n), "S": rng.uniform(0, 360, n)}
        q, theta = m.axes_matrix(axes), m.theta(errors)
        return lambda: fivecal._core.tool_poses(m._core, theta, q, None, None, False)[0]
    if case in ("tango_S3", "tango_S4"):
        subset = case[-2:]
        errors = tango.thesis_s4_errors() if subset == "S4" else tango.thesis_s3_errors()
        ds = tango.hu40t_dataset(errors=errors, seed=3)
        return lambda: fivecal.identify(ds, subset, allow_unidentifiable=subset == "S4")
    if case.startswith("tango_auto"):
        ds = tango.hu40t_dataset(errors=tango.thesis_s3_errors(), seed=3)
        vc = case.endswith("_vce")
        return lambda: fivecal.identify(ds, "auto", fix=[], variance_components=vc)
    if case.startswith("ball3d_fit_"):
        _, ds, names, *_ = bench.ball3d_dataset(int(case.rsplit("_", 1)[1]))
        return lambda: fivecal.identify(ds, names, default_setup=False)
    if case.startswith("monte_carlo_"):
        from fivecal import uncertainty

        _, _, trials, threads = case.split("_")
        ds = tango.hu40t_dataset(seed=5)
        return lambda: uncertainty.monte_carlo(ds, "S3", trials=int(trials), threads=int(threads[1:]), seed=1,
                                               progress=False, keep_samples=False)
    if case == "design_search_10000":
        from fivecal import design

        m, art, plan, groups = bench.design_pool(10_000)
        ds = fivecal.simulate(m, plan, artefact=art, tip_radius=tango.TIP_RADIUS)
        return lambda: design.design_plan(ds, 14, "S3", groups=groups, criterion="d", method="exchange")
    raise ValueError(f"unknown case {case!r}")


def worker():
    """Answers one line per request "CASE K" on stdout: {case, seconds,
    summary}. K = 0: build the case and run it once (warm-up: caches, lazily
    built tables, page faults), its time; K > 0: the fastest of K runs."""
    sys.path.insert(0, HERE)
    calls = {}
    for line in sys.stdin:
        if not line.strip():
            continue
        case, k = line.split()
        if case not in calls:
            calls[case] = _prepare(case)
        best, out = float("inf"), None
        for _ in range(max(1, int(k))):
            t = time.perf_counter()
            out = calls[case]()
            best = min(best, time.perf_counter() - t)
        print(json.dumps({"case": case, "seconds": best, "summary": _summary(out)}), flush=True)


# ---- controller ----------------------------------------------------------------

def _git(tree, *args):
    try:
        return subprocess.run(["git", "-C", tree, *args], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "?"


class Side:
    def __init__(self, name, tree):
        self.name, self.tree = name, os.path.abspath(tree)
        pkg = os.path.join(self.tree, "python", "fivecal")
        if not any(f.startswith("_core") and f.endswith(".so") for f in os.listdir(pkg)):
            raise SystemExit(f"{pkg}: no built _core module (run scripts/dev_build.sh in {self.tree})")
        env = {**os.environ, "PYTHONPATH": os.path.join(self.tree, "python")}
        self.proc = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--worker"], env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.commit = _git(self.tree, "rev-parse", "--short", "HEAD")

    def run(self, case, k=1):
        self.proc.stdin.write(f"{case} {k}\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise SystemExit(f"the {self.name} worker ({self.tree}) stopped during {case}")
        return json.loads(line)

    def close(self):
        self.proc.stdin.close()
        self.proc.wait()


def paired_ratio(this_runs, other_runs, resamples=4000, seed=0):
    """The median of the per-round ratios this/other and its bootstrap 95 %
    interval (percentiles of the median over resampled rounds; a fixed seed,
    so one run's document is reproducible from its times)."""
    if len(this_runs) != len(other_runs) or not this_runs:
        raise ValueError("paired_ratio: the two sides need the same, non-zero number of rounds")
    q = [a / b for a, b in zip(this_runs, other_runs)]
    rng = random.Random(seed)
    meds = sorted(statistics.median(rng.choices(q, k=len(q))) for _ in range(resamples))
    return statistics.median(q), [meds[int(0.025 * resamples)], meds[int(0.975 * resamples) - 1]]


def compare(other: str, rounds: int = 5, cases=CASES, log=print) -> dict:
    """fivecal's own time of each case in this tree and in ``other``,
    interleaved; the document bench/run.py --versus keeps in results.json."""
    sides = [Side("this", os.path.join(HERE, "..")), Side("other", other)]
    rows = []
    load_before = os.getloadavg()
    try:
        for case in cases:
            runs = {s.name: [] for s in sides}
            summary = {}
            # A run on this shared machine is now and then slowed by tens of
            # percent (another tenant, a frequency step): each round's figure
            # is the fastest of `best_of` runs, as many as take about 0.3 s
            # on the slower side (the same number for both).
            warm = max(s.run(case, 0)["seconds"] for s in sides)
            best_of = max(1, min(25, math.ceil(0.3 / max(warm, 1e-6))))
            for k in range(rounds):
                for s in (sides if k % 2 == 0 else sides[::-1]):
                    r = s.run(case, best_of)
                    runs[s.name].append(r["seconds"])
                    summary[s.name] = r["summary"]
            med = {n: statistics.median(v) for n, v in runs.items()}
            diff = _difference(summary["this"], summary["other"])
            ratio, ci = paired_ratio(runs["this"], runs["other"])
            row = {"case": case, "this_s": med["this"], "other_s": med["other"],
                   "this_over_other": ratio, "ratio_ci95": ci, "runs_this_s": runs["this"],
                   "runs_other_s": runs["other"], "best_of": best_of, "difference": diff, "agree": diff <= 1e-4,
                   "iterations": {n: summary[n].get("iterations") for n in summary},
                   "load_average": os.getloadavg()[0]}
            rows.append(row)
            log(f"{case:24s} this {med['this'] * 1e3:10.2f} ms   other {med['other'] * 1e3:10.2f} ms   "
                f"this/other {ratio:.3f} [{ci[0]:.3f}, {ci[1]:.3f}]   agree: {row['agree']} ({diff:.1e})")
    finally:
        for s in sides:
            s.close()
    return {"date": time.strftime("%Y-%m-%d %H:%M:%S"), "rounds": rounds,
            "this": {"tree": sides[0].tree, "commit": sides[0].commit},
            "other": {"tree": sides[1].tree, "commit": sides[1].commit},
            "load_average_before": load_before, "load_average_after": os.getloadavg(), "results": rows}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("other", help="the other checkout (its python/fivecal holds its built _core)")
    p.add_argument("--rounds", type=int, default=5, help="timed rounds per side and case (the median of the paired ratios reported)")
    p.add_argument("--cases", default=",".join(CASES), help="comma-separated subset of: " + ", ".join(CASES))
    p.add_argument("--out", default=os.path.join(HERE, "versus.json"))
    a = p.parse_args(argv)
    cases = [c for c in a.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        p.error(f"--cases: unknown {', '.join(unknown)}")
    doc = compare(a.other, a.rounds, cases)
    with open(a.out, "w") as f:
        json.dump(doc, f, indent=1)
    print(f"written {a.out}")
    return 0


if __name__ == "__main__":
    if sys.argv[1:] == ["--worker"]:
        worker()
    else:
        sys.exit(main())
