"""Session 14 timer: the Monte Carlo of 10,000 TANGO S3 re-fits (bench/run.py's
case_monte_carlo: hu40t dataset seed 5, seed 1, no samples kept) on 1 and 2
threads, and the ball3d fit (case_ball3d) at the given sizes, for one or two
fivecal builds interleaved round by round. Medians of the rounds and the load.

    PYTHONPATH=python python3 bench/mc_ball3d_timer.py --paths /tmp/main_pkg python --rounds 5
        [--trials 10000] [--threads 1 2] [--sizes 10000 100000 1000000] [--skip-mc] [--skip-ball3d]
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

CHILD = r"""
import json, os, sys, time
sys.path.insert(0, sys.argv[1]); sys.path.insert(0, sys.argv[2])
import numpy as np, fivecal
from fivecal import uncertainty
from fivecal.procedures import tango
from run import ball3d_dataset
what = json.loads(sys.argv[3])
out = {}
if what["mc"]:
    ds = tango.hu40t_dataset(seed=5)
    for th in what["threads"]:
        t, c = time.perf_counter(), time.process_time()
        r = uncertainty.monte_carlo(ds, "S3", trials=what["trials"], threads=th, seed=1, progress=False,
                                    keep_samples=False)
        out[f"mc_t{th}"] = time.perf_counter() - t
        out[f"mc_t{th}_cpu_ms_per_trial"] = 1e3 * (time.process_time() - c) / what["trials"]
        out[f"mc_t{th}_std"] = [float(r.std[k]) for k in r.names]
for n in what["sizes"]:
    _, ds, names, *_ = ball3d_dataset(n)
    fivecal.identify(ds, names, default_setup=False)  # warm
    ts, cs = [], []
    for _ in range(3 if n < 10**6 else 1):
        t, c = time.perf_counter(), time.process_time()
        r = fivecal.identify(ds, names, default_setup=False)
        ts.append(time.perf_counter() - t)
        cs.append(time.process_time() - c)
    out[f"ball3d_{n}"] = min(ts)
    out[f"ball3d_{n}_cpu"] = min(cs)
    out[f"ball3d_{n}_values"] = [r.values[k] for k in names]
    out[f"ball3d_{n}_std"] = [r.std[k] for k in names]
print(json.dumps(out))
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", nargs="+", required=True)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--trials", type=int, default=10000)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10000, 100000, 1000000])
    ap.add_argument("--skip-mc", action="store_true")
    ap.add_argument("--skip-ball3d", action="store_true")
    a = ap.parse_args()
    what = json.dumps({"mc": not a.skip_mc, "threads": a.threads, "trials": a.trials,
                       "sizes": [] if a.skip_ball3d else a.sizes})
    runs = {p: [] for p in a.paths}
    loads = []
    for i in range(a.rounds):
        for p in a.paths:
            loads.append(os.getloadavg()[0])
            res = subprocess.run([sys.executable, "-c", CHILD, os.path.abspath(p), HERE, what],
                                 capture_output=True, text=True)
            if res.returncode:
                sys.exit(res.stderr)
            runs[p].append(json.loads(res.stdout.strip().splitlines()[-1]))
            print(p, i, {k: round(v, 4) for k, v in runs[p][-1].items() if isinstance(v, float)}, flush=True)
    print(f"load average (1 min) over the rounds: {min(loads):.1f}-{max(loads):.1f}")
    for p in a.paths:
        keys = [k for k, v in runs[p][0].items() if isinstance(v, float)]
        print(p, {k: round(statistics.median(r[k] for r in runs[p]), 4) for k in keys})
    if len(a.paths) == 2:
        p0, p1 = a.paths
        for k, v in runs[p0][0].items():
            if isinstance(v, list) and k.endswith("_values"):
                sk = k.replace("_values", "_std")
                d = max(abs(x - y) / s for x, y, s in zip(v, runs[p1][0][k], runs[p0][0][sk]))
                print(f"{k}: max difference {d:.3g} sigma")
            if isinstance(v, list) and k.startswith("mc_") and k.endswith("_std"):
                d = max(abs(x - y) / x for x, y in zip(v, runs[p1][0][k]))
                print(f"{k}: max relative difference of the MC std {d:.3g}")


if __name__ == "__main__":
    main()
