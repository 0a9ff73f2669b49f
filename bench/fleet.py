"""Fleet bench (issue 18): nightly sphere checks of a simulated fleet
identified through Dask, change detection scored, throughput and the Python
overhead per dataset measured.

    python3 bench/fleet.py                          # 1,000 machines x 30 nights, 1 and 2 workers (the issue's case)
    python3 bench/fleet.py --machines 100 --nights 30 --workers 2
    python3 bench/fleet.py --data /tmp/fleet        # keep the simulated fleet there and reuse it next time

Writes bench/fleet_results.json for the default case (another case: a file
in the temporary folder, or --out):
- ``runs``: for each worker count, the whole fleet identified on a fresh
  LocalCluster (1 thread a worker, processes) into a fresh store: datasets per
  second (cluster start-up excluded) and where each dataset's time went,
  summed over the workers: ``fit`` (the identification call: the C++ fit and
  the wrapping of its result), ``worker_other`` (reading, parsing and
  checking the dataset, its digest, building the record), ``dask_and_client``
  (scheduling, transfer, the client's store writes, idle workers); a worker
  count's ``fit_share`` is fit / (workers x wall time); ``fit_cpu`` and
  ``worker_other_cpu`` are the same in CPU time of the task threads, and
  ``fit_share_of_task_cpu`` the fit's part of it (on a loaded machine wall
  times also count the waits for a core, CPU times do not);
- ``detection``: CUSUM (false-alarm rate 0.05 % per machine-night) over each
  machine's history in the store: drifts found within 5 nights of onset (the
  issue's target: >= 95 %) and false alarms per quiet machine-night (target
  <= 0.2 %);
- ``breakdown``: per dataset, serially in this process, each step of a fleet
  task timed on its own (CPU time of this thread), and the share of the C++ identify call and of all
  C++ calls (parse, canonical JSON for the digest, fit).
Nothing is asserted: the file records what the run saw, with the load average.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
RATE, WITHIN = 0.0005, 5


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def cluster(workers):
    from distributed import Client, LocalCluster

    c = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                     silence_logs=logging.CRITICAL)
    return c, Client(c)


def score(store, truth, nights):
    from fivecal import history

    detected = drifts = false = quiet = 0
    delays = []
    with history.Store(store) as s:
        for m in truth:
            charts = history.detect(s.list(m["machine_id"]), false_alarm_rate=RATE)
            alarms = sorted({i for c in charts.values() for i in c.alarms})
            onset = m["drift"]["onset"] if m["drift"] else nights
            quiet += onset
            false += sum(1 for i in alarms if i < onset)
            if m["drift"]:
                drifts += 1
                hit = [i for i in alarms if onset <= i < onset + WITHIN]
                if hit:
                    detected += 1
                    delays.append(hit[0] - onset)
    return {"drifts": drifts, "detected_within_5_nights": detected, "fraction_detected": detected / max(drifts, 1),
            "mean_delay_nights": sum(delays) / max(len(delays), 1), "false_alarms": false,
            "quiet_machine_nights": quiet, "false_alarm_fraction": false / max(quiet, 1), "design_rate": RATE}


def fleet_run(data, workers, store, chunk=None):
    from fivecal.history.fleet import fleet_identify

    load0 = os.getloadavg()
    c, client = cluster(workers)
    try:
        t = time.perf_counter()
        run = fleet_identify(data, store=store, procedure="sphere", client=client, chunk=chunk)
        wall = time.perf_counter() - t
    finally:
        client.close()
        c.close()
    n = max(run.done, 1)
    spent = workers * wall
    return {"workers": workers, "datasets": run.done, "failed": run.failed,
            # which datasets and why (first few): a failure is recorded, not fatal, but must be explained
            "failures": [{"path": os.path.relpath(str(p), str(data)), "error": e} for p, e in run.failures[:10]],
            "tasks": run.tasks,
            "seconds": wall, "datasets_per_second": run.done / wall,
            "per_dataset_ms": {"fit": 1e3 * run.fit_seconds / n,
                               "worker_other": 1e3 * (run.task_seconds - run.fit_seconds) / n,
                               "fit_cpu": 1e3 * run.fit_cpu_seconds / n,
                               "worker_other_cpu": 1e3 * (run.task_cpu_seconds - run.fit_cpu_seconds) / n,
                               "dask_and_client": 1e3 * (spent - run.task_seconds) / n,
                               "client_store_writes": 1e3 * run.store_seconds / n,
                               "total_worker_time": 1e3 * spent / n},
            "fit_share": run.fit_seconds / spent, "fit_share_of_task_cpu": run.fit_cpu_seconds / run.task_cpu_seconds,
            "loadavg_before": load0, "loadavg_after": os.getloadavg()}


def breakdown(paths):
    """Each step of :func:`fivecal.history.fleet.identify_one`, timed apart."""
    from fivecal import _core, files, plausibility
    from fivecal.dataset import Dataset
    from fivecal.history.fleet import identify_one, jobs_from
    from fivecal.history.store import calibration_from_result, dataset_digest
    from fivecal.identification import Result, identify

    jobs = jobs_from(paths)
    identify_one(jobs[0])                       # warm-up: imports, caches
    steps = dict.fromkeys(["read", "parse (C++)", "plausibility checks", "digest (C++ canonical JSON + sha256)",
                           "identify: C++ call", "identify: wrapping the result", "record"], 0.0)
    clock = time.thread_time         # CPU of this thread: the waits for a core on a loaded machine left out
    for j in jobs:
        t = clock()
        text = files.read_text(j.path, "dataset")
        t1 = clock()
        ds = Dataset(_core.Dataset.from_json(text))
        t2 = clock()
        plausibility.check_loaded(ds, where=j.path)
        t3 = clock()
        digest = dataset_digest(ds)
        t4 = clock()
        r = identify(ds, estimate="location")
        t5 = clock()
        Result(r._core, ds)                     # the wrapping again, alone: identify() = C++ call + this
        t6 = clock()
        calibration_from_result(r, j.machine_id, j.time, j.procedure, digest=digest, source=j.path)
        ds.machine.to_dict()
        t7 = clock()
        for k, dt in zip(steps, (t1 - t, t2 - t1, t3 - t2, t4 - t3, (t5 - t4) - (t6 - t5), t6 - t5, t7 - t6)):
            steps[k] += dt
    t = clock()
    for j in jobs:
        identify_one(j)
    whole = (clock() - t) / len(jobs)
    n = len(jobs)
    per = {k: 1e3 * v / n for k, v in steps.items()}
    total = sum(per.values())
    cpp = per["parse (C++)"] + per["digest (C++ canonical JSON + sha256)"] + per["identify: C++ call"]
    return {"datasets": n, "per_dataset_ms": per, "sum_of_steps_ms": total, "identify_one_ms": 1e3 * whole,
            "share_identify_cpp": per["identify: C++ call"] / total, "share_all_cpp": cpp / total}


def simulate(data, truth, nights, workers):
    from fivecal.history import fleetsim

    expected = [os.path.join(data, m["machine_id"], fleetsim.night_time(k)[:10] + ".json")
                for m in truth for k in range(nights)]
    stamp = os.path.join(data, "fleet-truth.json")
    if os.path.isfile(stamp) and all(os.path.isfile(p) for p in expected):
        with open(stamp) as f:
            if json.load(f) == truth:
                log(f"reusing the simulated fleet in {data}")
                return expected, 0.0
    t = time.perf_counter()
    c, client = cluster(workers)
    try:
        paths = fleetsim.write_fleet(data, truth, nights, seed=2026, client=client)
    finally:
        client.close()
        c.close()
    with open(stamp, "w") as f:
        json.dump(truth, f)
    return paths, time.perf_counter() - t


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--machines", type=int, default=1000)
    p.add_argument("--nights", type=int, default=30)
    p.add_argument("--workers", default="1,2", help="worker counts, comma separated (default 1,2)")
    p.add_argument("--data", help="folder for the simulated fleet, kept and reused (default: a temporary one)")
    p.add_argument("--chunk", type=int, help="datasets per Dask task (default: fivecal's choice, up to 32)")
    p.add_argument("--breakdown", type=int, default=200, help="datasets timed step by step (default 200)")
    p.add_argument("--out", help="results file (default bench/fleet_results.json for the default case, "
                   "else fivecal-fleet-<machines>x<nights>.json in the temporary folder)")
    a = p.parse_args(argv)
    workers = [int(w) for w in a.workers.split(",")]
    full = (a.machines, a.nights, workers, a.chunk) == (1000, 30, [1, 2], None)
    out = a.out or (os.path.join(HERE, "fleet_results.json") if full else
                    os.path.join(tempfile.gettempdir(), f"fivecal-fleet-{a.machines}x{a.nights}.json"))

    import fivecal
    from fivecal.history import fleetsim

    load0 = os.getloadavg()
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        data = a.data or os.path.join(tmp, "data")
        truth = fleetsim.fleet_truth(a.machines, a.nights, drift_fraction=0.05, seed=2026)
        paths, sim = simulate(data, truth, a.nights, max(workers))
        log(f"{len(paths)} sphere checks simulated in {sim:.0f} s")
        runs, stores = [], []
        for w in workers:
            store = os.path.join(tmp, f"fleet-{w}.fcdb")
            r = fleet_run(data, w, store, a.chunk)
            runs.append(r)
            stores.append(store)
            log(f"{w} worker(s): {r['datasets_per_second']:.1f} datasets/s, fit share {r['fit_share']:.0%} "
                f"(of the tasks' CPU {r['fit_share_of_task_cpu']:.0%}), "
                f"per dataset {json.dumps({k: round(v, 2) for k, v in r['per_dataset_ms'].items()})} ms")
        det = score(stores[-1], truth, a.nights)
        log(f"detection: {json.dumps(det)}")
        same = None
        if len(stores) > 1:
            from fivecal import history

            def values(s):
                with history.Store(s) as st:
                    return {c.digest: c.values.tobytes() for c in st.list()}
            first = values(stores[0])
            same = all(values(s) == first for s in stores[1:])
        bd = breakdown(paths[:a.breakdown])
        log(f"breakdown (ms per dataset): {json.dumps({k: round(v, 2) for k, v in bd['per_dataset_ms'].items()})}")
    doc = {"fivecal": fivecal.__version__, "date": time.strftime("%Y-%m-%d %H:%M:%S"), "cores": os.cpu_count(),
           "loadavg_at_start": load0, "loadavg_at_end": os.getloadavg(), "machines": a.machines,
           "nights": a.nights, "chunk": a.chunk, "datasets": len(paths), "simulation_seconds": sim,
           "total_seconds": time.perf_counter() - t_all, "runs": runs,
           "same_values_on_every_worker_count": same, "detection": det, "breakdown": bd}
    with open(out, "w") as f:
        json.dump(doc, f, indent=1)
    print(json.dumps(doc, indent=1))


if __name__ == "__main__":
    main()
