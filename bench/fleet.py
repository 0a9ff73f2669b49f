"""Fleet bench (issue 18): nightly sphere checks of a simulated fleet
identified through Dask, change detection scored, throughput measured.

    python3 bench/fleet.py                      # 1,000 machines x 30 nights (the issue's fleet)
    python3 bench/fleet.py --machines 100       # a smaller run
    python3 bench/fleet.py --quick              # 40 machines x 30 nights, throughput on 400 datasets

Writes bench/fleet_results.json:
- ``detection``: the full fleet identified on a LocalCluster of 2 workers,
  then CUSUM (false-alarm rate 0.05 % per machine-night) per machine: drifts
  found within 5 nights of onset, false alarms per quiet machine-night;
- ``throughput``: datasets per second on 1 and 2 workers (fresh stores, the
  same datasets; cluster start-up excluded);
- ``overhead``: per dataset, serially in this process, the time inside the C++
  core (every ``fivecal._core`` call, by cProfile) against the whole
  fleet task (read and validate the JSON, digest, fit, record).
"""
from __future__ import annotations

import argparse
import cProfile
import json
import logging
import os
import pstats
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def score(store, truth, nights, rate=0.0005, within=5):
    from fivecal import history

    detected = drifts = false = quiet = 0
    delays = []
    with history.Store(store) as s:
        for m in truth:
            charts = history.detect(s.list(m["machine_id"]), false_alarm_rate=rate)
            alarms = sorted({i for c in charts.values() for i in c.alarms})
            onset = m["drift"]["onset"] if m["drift"] else nights
            quiet += onset
            false += sum(1 for i in alarms if i < onset)
            if m["drift"]:
                drifts += 1
                hit = [i for i in alarms if onset <= i < onset + within]
                if hit:
                    detected += 1
                    delays.append(hit[0] - onset)
    return {"drifts": drifts, "detected_within_5_nights": detected, "fraction_detected": detected / max(drifts, 1),
            "mean_delay_nights": sum(delays) / max(len(delays), 1), "false_alarms": false,
            "quiet_machine_nights": quiet, "false_alarm_fraction": false / max(quiet, 1), "design_rate": rate}


def throughput(source, workers, tmp):
    from distributed import Client, LocalCluster

    from fivecal.history.fleet import fleet_identify

    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.CRITICAL) as c, \
            Client(c) as client:
        t = time.perf_counter()
        run = fleet_identify(source, store=os.path.join(tmp, f"tp{workers}.fcdb"), client=client)
        dt = time.perf_counter() - t
    return {"workers": workers, "datasets": run.done, "seconds": dt, "datasets_per_second": run.done / dt}


def overhead(paths):
    from fivecal.history.fleet import identify_one, jobs_from

    jobs = jobs_from(paths)
    identify_one(jobs[0])                       # warm-up: imports, schema cache
    prof = cProfile.Profile()
    t = time.perf_counter()
    prof.enable()
    for j in jobs:
        r = identify_one(j)
        assert r[0] == "ok", r
    prof.disable()
    total = time.perf_counter() - t
    core = 0.0
    for (file, line, name), (cc, nc, tt, ct, callers) in pstats.Stats(prof).stats.items():
        if file == "~" and "fivecal._core" in name:
            core += tt
    n = len(jobs)
    # cProfile slows the Python side; the plain per-dataset time is measured too
    t = time.perf_counter()
    for j in jobs:
        identify_one(j)
    plain = (time.perf_counter() - t) / n
    return {"datasets": n, "per_dataset_s": plain, "core_share_profiled": core / total,
            "core_per_dataset_s_profiled": core / n, "python_per_dataset_s_profiled": (total - core) / n}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--machines", type=int, default=1000)
    p.add_argument("--nights", type=int, default=30)
    p.add_argument("--throughput-datasets", type=int, default=2000)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--out", default=os.path.join(HERE, "fleet_results.json"))
    a = p.parse_args(argv)
    if a.quick:
        a.machines, a.throughput_datasets = 40, 400
    import fivecal
    from fivecal.history import fleetsim
    from fivecal.history.fleet import fleet_identify

    with tempfile.TemporaryDirectory() as tmp:
        data = os.path.join(tmp, "data")
        truth = fleetsim.fleet_truth(a.machines, a.nights, drift_fraction=0.05, seed=2026)
        t = time.perf_counter()
        paths = fleetsim.write_fleet(data, truth, a.nights, seed=2026)
        sim = time.perf_counter() - t
        print(f"simulated {len(paths)} sphere checks in {sim:.0f} s", file=sys.stderr)
        tp_paths = paths[:a.throughput_datasets]
        tps = [throughput(tp_paths, w, tmp) for w in (1, 2)]
        for r in tps:
            print(f"throughput: {r['workers']} worker(s): {r['datasets_per_second']:.1f} datasets/s", file=sys.stderr)
        ov = overhead(paths[:50])
        print(f"per dataset {ov['per_dataset_s'] * 1e3:.1f} ms, core share {ov['core_share_profiled']:.0%}",
              file=sys.stderr)
        store = os.path.join(tmp, "fleet.fcdb")
        t = time.perf_counter()
        run = fleet_identify(data, store=store, procedure="sphere", workers=2, progress=sys.stderr.isatty())
        full = time.perf_counter() - t
        det = score(store, truth, a.nights)
        print(run.summary(), file=sys.stderr)
        print(json.dumps(det), file=sys.stderr)
    doc = {"fivecal": fivecal.__version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"), "cores": os.cpu_count(),
           "loadavg_at_end": os.getloadavg(), "machines": a.machines, "nights": a.nights,
           "datasets": len(paths), "simulation_seconds": sim,
           "full_run": {"workers": 2, "seconds_with_cluster_start": full, "identified": run.done,
                        "failed": run.failed},
           "detection": det, "throughput": tps, "overhead": ov}
    with open(a.out, "w") as f:
        json.dump(doc, f, indent=1)
    print(json.dumps(doc, indent=1))


if __name__ == "__main__":
    main()
