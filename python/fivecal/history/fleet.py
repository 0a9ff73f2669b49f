"""``fleet_identify``: identification of many datasets on Dask.

Datasets come from a folder (every ``*.json`` below it), a glob, a list of
paths, or a manifest (Parquet or CSV with a ``path`` column and optionally
``machine_id``, ``time``, ``procedure``). Without a manifest the machine id
is the name of the dataset's folder and the time the ISO date (or date and
time) in the file name, else the file's modification time.

Datasets go to Dask in chunks (one task for up to 32 of them): for each,
the worker reads it, computes its digest, skips it when that digest is
already finished, identifies it and returns a small record (values,
covariance, fit quality) or the error. The client is
the only writer: it records results in the store (and/or partitioned
Parquet) as they complete, so a run stopped half way keeps what it did and a
re-run skips it. A dataset that fails is recorded as a failure, never stops
the run, and is tried again by the next run.

Dask is optional (``pip install 'fivecal[fleet]'``); only this module imports it.
"""
from __future__ import annotations

import datetime
import glob
import logging
import os
import re
import threading
import time as _time
from dataclasses import dataclass, field
from typing import List, Optional, Sequence, Union

import numpy as np

from .. import files
from ..uncertainty import monte_carlo
from .store import (Calibration, Store, arrow_table, calibration_from_result, dataset_digest, require_pyarrow,
                    utc_time)
from .. import _core, plausibility
from ..dataset import Dataset
from ..identification import identify


def require_dask():
    try:
        import dask  # noqa: F401
        import distributed  # noqa: F401
    except ImportError:
        raise ValueError("fleet runs need Dask, which is not installed: pip install 'fivecal[fleet]'") from None


@dataclass
class Job:
    path: str
    machine_id: str
    time: str
    procedure: str = ""


_DATE = re.compile(r"(\d{4}-\d{2}-\d{2})(?:[T_ ](\d{2})[:-]?(\d{2})(?:[:-]?(\d{2}))?)?")


def _time_of(path: str) -> str:
    m = _DATE.search(os.path.basename(path))
    if m:
        d, hh, mm, ss = m.groups()
        text = d + (f"T{hh}:{mm}:{ss or '00'}" if hh else "T00:00:00")
        try:
            return utc_time(text)
        except ValueError:
            pass
    return utc_time(datetime.datetime.fromtimestamp(os.path.getmtime(path), datetime.timezone.utc))


def jobs_from(source: Union[str, Sequence[str]], procedure: str = "", machine_id: Optional[str] = None) -> List[Job]:
    """The datasets of ``source``: a folder, a glob, a list of paths, or a
    manifest (``.parquet`` / ``.csv``) with a ``path`` column."""
    if isinstance(source, (list, tuple)):
        paths = [os.fspath(p) for p in source]
    else:
        source = os.fspath(source)
        low = source.lower()
        if low.endswith((".parquet", ".csv")) and os.path.isfile(source):
            return _manifest(source, procedure, machine_id)
        if os.path.isdir(source):
            paths = sorted(glob.glob(os.path.join(source, "**", "*.json"), recursive=True))
        else:
            paths = sorted(glob.glob(source, recursive=True))
        if not paths:
            raise ValueError(f"{source}: no dataset found (a folder of *.json, a glob or a manifest)")
    return [Job(p, machine_id or os.path.basename(os.path.dirname(os.path.abspath(p))), _time_of(p), procedure)
            for p in paths]


def _manifest(path: str, procedure: str, machine_id: Optional[str]) -> List[Job]:
    if path.lower().endswith(".parquet"):
        require_pyarrow()
        import pyarrow.parquet as pq

        rows = pq.read_table(path).to_pylist()
    else:
        import csv

        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    if rows and "path" not in rows[0]:
        raise ValueError(f"{path}: the manifest has no 'path' column")
    base = os.path.dirname(os.path.abspath(path))
    jobs = []
    for i, r in enumerate(rows):
        p = r["path"]
        if not p:
            raise ValueError(f"{path}: row {i + 1}: empty path")
        p = p if os.path.isabs(p) else os.path.join(base, p)
        jobs.append(Job(p, r.get("machine_id") or machine_id or os.path.basename(os.path.dirname(p)),
                        utc_time(r["time"]) if r.get("time") else _time_of(p), r.get("procedure") or procedure))
    return jobs


def _load(path: str):
    """``fivecal.load_dataset`` without its JSON-schema pass: the C++ loader
    checks every key and value itself (unknown keys, types, ranges, naming the
    observation and field), which ``load_dataset`` already relies on for big
    datasets. The schema pass costs more than the fit of a nightly sphere
    check; a fleet run pays the core's time, not the Python validator's."""

    text = files.read_text(path, "dataset")
    try:
        ds = Dataset(_core.Dataset.from_json(text))
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    plausibility.check_loaded(ds, where=path)
    return ds


def identify_one(job: Job, estimate="location", done: frozenset = frozenset(), options: Optional[dict] = None,
                 trials: int = 0, machine: bool = True):
    """Worker side: ``("skipped", digest, job)``, ``("ok", Calibration, (wall,
    CPU) seconds of this thread in the identification call, machine)`` or
    ``("failed", digest, job, error text)``;
    ``machine``: the machine's definition (dict), None with ``machine=False``.
    ``trials`` > 0: the covariance is that of a JCGM 101 Monte Carlo of
    ``trials`` trials around this dataset (one thread: the cluster is the
    parallelism), recorded as ``uncertainty = "monte_carlo:N"``."""

    digest = ""
    try:
        ds = _load(job.path)
        digest = dataset_digest(ds)
        if digest in done:
            return ("skipped", digest, job)
        t0, c0 = _time.perf_counter(), _time.thread_time()
        r = identify(ds, estimate=estimate, **(options or {}))
        fit = (_time.perf_counter() - t0, _time.thread_time() - c0)
        cal = calibration_from_result(r, job.machine_id, job.time, job.procedure, digest=digest, source=job.path)
        cal.check()         # a non-finite fit is a failure of this dataset, not a record
        if trials:
            mc = monte_carlo(ds, estimate, trials=trials, threads=1, progress=False, keep_samples=False,
                             **{k: v for k, v in (options or {}).items() if k in ("fix", "initial", "robust")})
            idx = [mc.names.index(n) for n in cal.names]
            cal.covariance = np.asarray(mc.covariance, float)[np.ix_(idx, idx)]
            cal.uncertainty = f"monte_carlo:{trials}"
        return ("ok", cal, fit, ds.machine.to_dict() if machine else None)
    except Exception as e:      # a bad dataset is recorded, the run goes on
        return ("failed", digest, job, f"{type(e).__name__}: {e}")


def identify_chunk(jobs: Sequence[Job], estimate="location", done: frozenset = frozenset(),
                   options: Optional[dict] = None, trials: int = 0):
    """Worker side, one Dask task for several datasets: ``(results, seconds,
    cpu_seconds)``, the :func:`identify_one` result of each job (a machine's
    definition only with the first of its results in the chunk), the task's
    wall time and its thread's CPU time (on a loaded machine the wall time
    also counts the waits for a core). One task per dataset cost the scheduler, the transfer and the
    client about as much as a nightly fit (issue 18's bench), so datasets go
    in chunks."""
    t0, c0 = _time.perf_counter(), _time.thread_time()
    out, sent = [], set()
    for j in jobs:
        r = identify_one(j, estimate=estimate, done=done, options=options, trials=trials,
                         machine=j.machine_id not in sent)
        if r[0] == "ok":
            sent.add(j.machine_id)
        out.append(r)
    return out, _time.perf_counter() - t0, _time.thread_time() - c0


@dataclass
class FleetRun:
    """Counts and times of a fleet run. ``fit_seconds``: time in the
    identification calls (the C++ fit and the wrapping of its result),
    ``task_seconds``: time the workers spent in fleet tasks (that and reading,
    validating, digesting the datasets and building the records),
    ``fit_cpu_seconds`` and ``task_cpu_seconds``: the same in CPU time of the
    workers' task threads, ``store_seconds``: the client's time writing
    results; ``seconds``: wall time of the run, cluster start-up included when
    the run started it."""
    done: int = 0
    skipped: int = 0
    failed: int = 0
    seconds: float = 0.0
    fit_seconds: float = 0.0
    task_seconds: float = 0.0
    fit_cpu_seconds: float = 0.0
    task_cpu_seconds: float = 0.0
    store_seconds: float = 0.0
    tasks: int = 0
    failures: List[tuple] = field(default_factory=list)
    calibrations: List[Calibration] = field(default_factory=list)

    def summary(self) -> str:
        rate = self.done / self.seconds if self.seconds > 0 else float("nan")
        return (f"fleet: {self.done} identified, {self.skipped} skipped (already done), {self.failed} failed, "
                f"{self.seconds:.1f} s ({rate:.1f} datasets/s)")


def _chunk_size(n: int, workers: int) -> int:
    # big enough that the scheduler's per-task cost is small against the fits,
    # small enough that every worker gets several tasks (balance, progress)
    return max(1, min(32, -(-n // (4 * max(workers, 1)))))


def fleet_identify(source, store: Optional[Union[str, Store]] = None, parquet: Optional[str] = None,
                   estimate="location", procedure: str = "", machine_id: Optional[str] = None,
                   scheduler: Optional[str] = None, workers: Optional[int] = None, progress: bool = False,
                   options: Optional[dict] = None, batch: int = 200, client=None, trials: int = 0,
                   chunk: Optional[int] = None) -> FleetRun:
    """Identify every dataset of ``source`` on Dask (``scheduler``: address of
    an existing cluster; default a ``LocalCluster`` of ``workers`` processes,
    one thread each). Results go to ``store`` (path or :class:`Store`) and/or
    ``parquet`` (a folder, partitioned by machine_id). ``trials``: also a
    Monte Carlo of that many trials per dataset for the covariance. ``chunk``:
    datasets per Dask task (default: up to 32, at least 4 tasks a worker).
    Returns counts and, when neither output is given, the calibrations."""
    require_dask()
    from distributed import Client, LocalCluster, as_completed

    if chunk is not None and chunk < 1:
        raise ValueError(f"chunk: expected an integer >= 1, got {chunk}")
    jobs = jobs_from(source, procedure, machine_id)
    own_store = isinstance(store, (str, os.PathLike))
    st = Store(store) if own_store else store
    done = set(st.digests()) if st is not None else set()
    if parquet:
        done |= _parquet_digests(parquet)
    run = FleetRun()
    t0 = _time.perf_counter()
    cluster = None
    try:
        if client is None:
            if scheduler:
                client = Client(scheduler)
            else:
                # silence_logs: the workers' heartbeat complaints while the cluster
                # shuts down are not the user's concern
                cluster = LocalCluster(n_workers=workers or min(2, os.cpu_count() or 1), threads_per_worker=1,
                                       processes=True, dashboard_address=None, silence_logs=logging.CRITICAL)
                client = Client(cluster)
            own_client = True
        else:
            own_client = False
        try:
            size = chunk or _chunk_size(len(jobs), sum(client.nthreads().values()))
            chunks = [jobs[i:i + size] for i in range(0, len(jobs), size)]
            # one copy of the finished digests on every worker (a list: scatter
            # would split a set into one future per element)
            done_f = client.scatter([frozenset(done)], broadcast=True)[0] if done else frozenset()
            futures = client.map(identify_chunk, chunks, estimate=estimate, done=done_f, options=options,
                                 trials=trials, pure=False,
                                 key=[f"fivecal-identify-{i}-{os.path.basename(c[0].path)}"
                                      for i, c in enumerate(chunks)])
            jobs_of = {f.key: c for f, c in zip(futures, chunks)}
            writer = threading.Thread(target=_collect, args=(as_completed(futures), st, parquet, run, batch,
                                                             st is None and not parquet, jobs_of))
            writer.start()
            if progress:
                from distributed import progress as dask_progress

                dask_progress(futures)
            writer.join()
            if getattr(run, "_error", None):
                raise run._error
        finally:
            if own_client:
                client.close()
    finally:
        if cluster is not None:
            cluster.close()
        if own_store and st is not None:
            st.close()
    run.seconds = _time.perf_counter() - t0
    return run


def _collect(completed, st, parquet, run: FleetRun, batch: int, keep: bool, jobs_of: dict) -> None:
    pending: List[Calibration] = []
    machines = {}

    def flush():
        if not pending:
            return
        t = _time.perf_counter()
        if st is not None:
            # a dataset of another machine in a machine's folder fails, the run goes on
            for k in dict.fromkeys(c.machine_id for c in pending):
                mine = [c for c in pending if c.machine_id == k]
                try:
                    st.check_machine(k, machines.get(k), [n for c in mine for n in c.names])
                except ValueError as e:
                    for c in mine:
                        pending.remove(c)
                        run.done -= 1
                        run.failed += 1
                        run.failures.append((c.source, str(e)))
                        st.add_failure(c.digest, f"ValueError: {e}", c.source, k)
                    machines.pop(k, None)
            st.add_many(pending, machines=machines)
        if parquet:
            _write_parquet_part(parquet, pending)
        if keep:
            run.calibrations.extend(pending)
        pending.clear()
        machines.clear()
        run.store_seconds += _time.perf_counter() - t

    try:
        for fut in completed:
            try:
                results, seconds, cpu = fut.result()
                run.task_seconds += seconds
                run.task_cpu_seconds += cpu
            except Exception as e:   # the task itself died (a worker killed by it): its datasets are failures
                results = [("failed", "", j, f"{type(e).__name__}: {e}") for j in jobs_of[fut.key]]
            run.tasks += 1
            for r in results:
                if r[0] == "skipped":
                    run.skipped += 1
                elif r[0] == "ok":
                    _, cal, fit, mdef = r
                    run.done += 1
                    run.fit_seconds += fit[0]
                    run.fit_cpu_seconds += fit[1]
                    pending.append(cal)
                    if mdef is not None:
                        machines[cal.machine_id] = mdef
                    if len(pending) >= batch:
                        flush()
                else:
                    _, digest, job, err = r
                    run.failed += 1
                    run.failures.append((job.path, err))
                    if st is not None:
                        t = _time.perf_counter()
                        st.add_failure(digest or "", err, job.path, job.machine_id)
                        run.store_seconds += _time.perf_counter() - t
        flush()
    except BaseException as e:     # re-raised by the caller's thread
        run._error = e


def _parquet_digests(folder: str) -> set:
    if not os.path.isdir(folder):
        return set()

    require_pyarrow()
    import pyarrow.dataset as pds

    files = glob.glob(os.path.join(folder, "**", "*.parquet"), recursive=True)
    if not files:
        return set()
    return set(pds.dataset(folder, format="parquet", partitioning="hive").to_table(columns=["digest"])
               .column("digest").to_pylist())


def _write_parquet_part(folder: str, cals: Sequence[Calibration]) -> None:
    require_pyarrow()
    import uuid

    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.dataset as pds

    files.guard_output(folder, "--parquet")      # a store or a dataset given as the folder
    part = pds.partitioning(pa.schema([("machine_id", pa.string())]), flavor="hive")
    by: dict = {}
    for c in cals:
        by.setdefault(c.machine_id, []).append(c)
    for k, group in by.items():
        sub = os.path.join(folder, part.format(pc.field("machine_id") == k)[0])
        files.make_dirs(sub)
        t = arrow_table(group)
        files.write_parquet_table(os.path.join(sub, f"part-{uuid.uuid4().hex}-0.parquet"),
                                  t.drop_columns(["machine_id"]), label="--parquet")
