"""``fivecal history add|list|show|compare|export|trend`` and ``fivecal fleet identify``."""
from __future__ import annotations

import argparse
import json
import math
import os
import sys


def _store(args, create=False):
    from .store import Store

    return Store(args.store, create=create)


def _tolerances(items) -> dict:
    out = {}
    for text in items or ():
        for item in [t for t in text.split(",") if t.strip()]:
            if "=" not in item:
                raise ValueError(f"--tolerance: expected NAME=VALUE (mm / rad), got '{item.strip()}'")
            k, v = item.split("=", 1)
            try:
                x = float(v)
            except ValueError:
                raise ValueError(f"--tolerance: {k.strip()}: '{v.strip()}' is not a number") from None
            if not (math.isfinite(x) and x > 0):
                raise ValueError(f"--tolerance: {k.strip()}: expected a positive number, got '{v.strip()}'")
            out[k.strip()] = x
    return out


def _add(args) -> int:
    from .store import dataset_digest

    digest = dataset_digest(args.dataset) if args.dataset else None
    machine = args.machine or args.dataset
    with _store(args, create=True) as s:
        i = s.add(args.result, machine_id=args.machine_id, procedure=args.procedure or "", time=args.time,
                  machine=machine, digest=digest)
        c = s.get(i)
    print(f"{args.store}: calibration #{i} of {c.machine_id} at {c.time} recorded ({len(c.names)} parameters, "
          f"verdict {c.verdict})")
    return 0


def _list(args) -> int:
    with _store(args) as s:
        cals = s.list(args.machine_id, args.procedure)
    if args.json:
        print(json.dumps([{"id": c.id, "machine_id": c.machine_id, "time": c.time, "procedure": c.procedure,
                           "verdict": c.verdict, "digest": c.digest} for c in cals], indent=1))
        return 0
    tw = max([22] + [len(c.time) + 2 for c in cals])     # times with microseconds are longer
    print(f"{'id':>6}  {'machine':<14}{'time':<{tw}}{'procedure':<12}{'verdict':<14}{'rms µm':>8}  digest")
    for c in cals:
        print(f"{c.id:>6}  {c.machine_id:<14}{c.time:<{tw}}{c.procedure:<12}{c.verdict:<14}"
              f"{c.rms * 1e3:>8.3f}  {c.digest[:12]}")
    print(f"{len(cals)} calibrations")
    return 0


def _show(args) -> int:
    from ..units import display_scale

    with _store(args) as s:
        c = s.get(args.id)
    if args.json:
        print(json.dumps(c.to_dict(), indent=1))
        return 0
    print(f"calibration #{c.id}: {c.machine_id} at {c.time}, procedure '{c.procedure}', verdict {c.verdict}, "
          f"rms {c.rms * 1e3:.3f} µm, chi2 {c.chi2:.1f} (dof {c.dof}), fivecal {c.fivecal_version}")
    print(f"  dataset sha256 {c.digest}" + (f" ({c.source})" if c.source else ""))
    for n, v, u in zip(c.names, c.values, c.std):
        f, unit = display_scale(n)
        print(f"  {n:<14}{v * f:>12.3f} ± {u * f:.3f} {unit}" + ("  (undetermined)" if n in c.undetermined else ""))
    return 0


def _resolve(s, ref: str, what: str):
    from .store import calibration_from_result

    if os.path.isfile(ref):
        import datetime

        mtime = datetime.datetime.fromtimestamp(os.path.getmtime(ref), datetime.timezone.utc)
        return calibration_from_result(ref, os.path.basename(ref), time=mtime, source=ref)
    try:
        i = int(ref)
    except ValueError:
        raise ValueError(f"{what}: '{ref}' is neither a calibration id nor a result file") from None
    if s is None:
        raise ValueError(f"{what}: calibration id {ref} needs --store")
    return s.get(i)


def _compare(args) -> int:
    from ..machine import Machine
    from .trend import compare

    s = _store(args) if args.store else None
    try:
        a, b = _resolve(s, args.a, "A"), _resolve(s, args.b, "B")
        machine = Machine.load(args.machine) if args.machine else (s.machine(b.machine_id) if s else None)
    finally:
        if s is not None:
            s.close()
    cmp = compare(a, b, machine=machine, tolerances=_tolerances(args.tolerance), z_limit=args.z)
    print(json.dumps(cmp.to_dict(), indent=1) if args.json else cmp.report())
    return 0


def _failures(args) -> int:
    with _store(args) as s:
        rows = s.failures()
    for r in rows:
        print(f"{r['time']}  {r['machine_id']:<14}{r['source']}: {r['error']}")
    print(f"{len(rows)} failed datasets (a fleet re-run tries them again)")
    return 0


def _export(args) -> int:
    with _store(args) as s:
        cals = s.list(args.machine_id)
    from .store import write_parquet

    write_parquet(cals, args.out)
    print(f"{len(cals)} calibrations written to {args.out}")
    return 0


def _trend(args) -> int:
    from .trend import ChartDesign, detect, grade, plot_trend, pooled_statistics

    with _store(args) as s:
        cals = s.list(args.machine_id, args.procedure)
        machine = s.machine(args.machine_id)
    if not cals:
        raise ValueError(f"{args.store}: no calibration of machine '{args.machine_id}'")
    charts = detect(cals, false_alarm_rate=args.false_alarm_rate)
    if charts:
        d = next(iter(charts.values()))
        design = ChartDesign.for_rate(args.false_alarm_rate, len(charts))
        print(f"CUSUM (self-starting, k = {d.k:g}, h = {d.h:.3f}: in-control ARL {design.arl0_one_sided:.0f} "
              f"calibrations per one-sided chart, {args.false_alarm_rate:g} false alarms per calibration over "
              f"{len(charts)} parameters)")
        for n, ch in charts.items():
            print(f"  {n:<12}" + (", ".join(ch.times[i] for i in ch.alarms) if ch.alarms else "no alarm"))
    tol = _tolerances(args.tolerance)
    status = 0
    if tol or args.volumetric_tolerance:
        g = grade(cals[-1], tol, args.volumetric_tolerance, machine=machine)
        print(g.report())
        status = 1 if g.verdict == "fail" else 0
    try:
        print(pooled_statistics(cals, by=args.pool).report())
    except ValueError as e:
        print(f"pooled statistics: {e}")
    if args.plot:
        plot_trend(cals, args.plot, tolerances=tol, charts=charts)
        print(f"trend plot: {args.plot}")
    return status


def _fleet(args) -> int:
    from .fleet import fleet_identify

    if not args.store and not args.parquet:
        raise ValueError("fleet identify: give --store FILE and/or --parquet DIR for the results")
    from ..cli import MAX_TRIALS, MAX_WORKERS, check_size

    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers: expected an integer >= 1, got {args.workers}")
    if args.workers is not None:
        check_size("--workers", args.workers, "worker processes", MAX_WORKERS)
    if args.trials < 0:
        raise ValueError(f"--trials: expected an integer >= 0, got {args.trials}")
    check_size("--trials", args.trials, "trials per dataset", MAX_TRIALS)
    est = args.estimate.split(",") if "," in args.estimate else args.estimate
    run = fleet_identify(args.source, store=args.store, parquet=args.parquet, estimate=est,
                         procedure=args.procedure or "", machine_id=args.machine_id, scheduler=args.scheduler,
                         workers=args.workers, progress=not args.no_progress, trials=args.trials)
    print(run.summary())
    for path, err in run.failures[:20]:
        print(f"  failed: {path}: {err}", file=sys.stderr)
    if len(run.failures) > 20:
        print(f"  ... {len(run.failures) - 20} more" + (f" (fivecal history failures --store {args.store})"
                                                         if args.store else ""), file=sys.stderr)
    return 0


def add_identify_options(p) -> None:
    """``fivecal identify``'s history options: the report shows this machine's
    trend, the comparison with its previous calibration and pass / fail."""
    g = p.add_argument_group("history (`fivecal docs history`)")
    g.add_argument("--history", metavar="STORE", help="calibration store (SQLite file): with --report, the "
                   "report adds this machine's trend, the comparison with its previous calibration and, with "
                   "tolerances, pass / fail. This result is placed in the trend at the date in the dataset's "
                   "file name (YYYY-MM-DD[THH:MM[:SS]]), else at the file's modification time")
    g.add_argument("--machine-id", metavar="ID",
                   help="which machine of the store this dataset is (needed with --history)")
    g.add_argument("--tolerance", action="append", metavar="NAME=VALUE",
                   help="largest acceptable |value|, mm / rad, e.g. EX0C=0.005 (repeatable, comma separated)")
    g.add_argument("--volumetric-tolerance", type=float, metavar="MM",
                   help="largest acceptable predicted tool-point error, mm")
    g.add_argument("--record", action="store_true", help="also record this result in the store (created if "
                   "missing), with the dataset's digest and that time, after the report is written")
    g.add_argument("--procedure", metavar="LABEL", help="procedure label recorded with --record (e.g. sphere, tango)")


def identify_history(args):
    """The report's :class:`~fivecal.history.report.History` for ``fivecal
    identify`` (None without --history); checks the options first."""
    from .report import History

    given = [o for o, v in (("--machine-id", args.machine_id), ("--tolerance", args.tolerance),
                            ("--volumetric-tolerance", args.volumetric_tolerance), ("--record", args.record),
                            ("--procedure", args.procedure)) if v]
    if not args.history:
        if given:
            raise ValueError(f"{given[0]}: needs --history STORE")
        return None
    if not args.machine_id or not args.machine_id.strip():
        raise ValueError("--history: give --machine-id ID (which machine of the store this dataset is)")
    if not args.report and not args.record:
        raise ValueError("--history: the trend, comparison and pass / fail go in the HTML report: give "
                         "--report DIR (or --record to only record the result)")
    vt = args.volumetric_tolerance
    if vt is not None and not (math.isfinite(vt) and vt > 0):
        raise ValueError(f"--volumetric-tolerance: expected a positive number of mm, got {vt}")
    from .store import Store

    # a missing (without --record) or foreign file is said before the fit
    Store(args.history, create=args.record).close()
    from .fleet import _time_of

    return History(args.history, args.machine_id.strip(), tolerances=_tolerances(args.tolerance) or None,
                   volumetric_tolerance=vt, time=_time_of(args.dataset) if os.path.isfile(args.dataset) else None)


def grade_identify(result, hist) -> str:
    """``fivecal identify --tolerance``: this result graded as the report
    grades it (printed); returns the verdict (pass, fail, undecided)."""
    from .store import calibration_from_result
    from .trend import grade

    cal = calibration_from_result(result, hist.machine_id, time=hist.time, source="this identification")
    g = grade(cal, hist.tolerances or {}, hist.volumetric_tolerance, machine=result.dataset.machine)
    print()
    print(g.report())
    return g.verdict


def record_identify(args, result, hist) -> None:
    """``fivecal identify --record``: the result into the store."""
    from .store import Store

    with Store(hist.store, create=True) as s:
        i = s.add(result, machine_id=hist.machine_id, procedure=args.procedure or "", time=hist.time,
                  source=args.dataset)
        n = len(s.list(hist.machine_id))
    print(f"history: calibration #{i} of {hist.machine_id} recorded in {hist.store} ({n} in all)")


def register(sub) -> None:
    p = sub.add_parser("history", help="calibration store: record, list, compare, trend, export",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="A calibration store is one SQLite file holding every recorded "
                       "identification of a fleet of machines (`fivecal docs history`).",
                       epilog="examples:\n"
                       "  fivecal history add --store shop.fcdb result.json --machine-id HU40-17 --procedure sphere\n"
                       "  fivecal history list --store shop.fcdb --machine-id HU40-17\n"
                       "  fivecal history compare --store shop.fcdb 12 31 --tolerance EX0C=0.005\n"
                       "  fivecal history compare old_result.json new_result.json --machine machine.json\n"
                       "  fivecal history trend --store shop.fcdb --machine-id HU40-17 --plot trend.png\n"
                       "  fivecal history export --store shop.fcdb all.parquet")
    hs = p.add_subparsers(dest="history_command", required=True)

    def common(q, store_required=True):
        q.add_argument("--store", required=store_required, help="calibration store file (SQLite)")

    a = hs.add_parser("add", help="record a result (result.json of fivecal identify --out)")
    common(a)
    a.add_argument("result", help="result JSON")
    a.add_argument("--machine-id", required=True, help="which machine (free text, e.g. its serial number)")
    a.add_argument("--procedure", help="procedure label (e.g. sphere, tango, dbb)")
    a.add_argument("--time", help="when it was measured, ISO 8601 (default now; without a zone: UTC)")
    a.add_argument("--machine", help="machine JSON (kept for volumetric comparisons)")
    a.add_argument("--dataset", help="the dataset the result came from: its sha256 digest is recorded "
                   "(and its machine kept)")
    a.set_defaults(func=_add)

    lst = hs.add_parser("list", help="list recorded calibrations")
    common(lst)
    lst.add_argument("--machine-id")
    lst.add_argument("--procedure")
    lst.add_argument("--json", action="store_true")
    lst.set_defaults(func=_list)

    sh = hs.add_parser("show", help="one calibration's values and uncertainties")
    common(sh)
    sh.add_argument("id", type=int)
    sh.add_argument("--json", action="store_true")
    sh.set_defaults(func=_show)

    c = hs.add_parser("compare", help="two calibrations parameter by parameter (z-scores, volumetric change)")
    common(c, store_required=False)
    c.add_argument("a", metavar="A", help="calibration id in --store, or a result JSON")
    c.add_argument("b", metavar="B", help="calibration id in --store, or a result JSON")
    c.add_argument("--machine", help="machine JSON for the volumetric change (default: the store's)")
    c.add_argument("--tolerance", action="append", metavar="NAME=VALUE",
                   help="largest acceptable change, mm / rad, e.g. EX0C=0.005 (repeatable, comma separated)")
    c.add_argument("--z", type=float, default=3.0, help="|z| above this is reported as a change (default 3)")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=_compare)

    e = hs.add_parser("export", help="write the calibrations to Parquet (needs fivecal[arrow])")
    common(e)
    e.add_argument("out", help="Parquet file to write")
    e.add_argument("--machine-id")
    e.set_defaults(func=_export)

    fl = hs.add_parser("failures", help="datasets a fleet run could not identify, with the reason")
    common(fl)
    fl.set_defaults(func=_failures)

    t = hs.add_parser("trend", help="CUSUM change detection, grade against tolerances, pooled statistics, plot")
    common(t)
    t.add_argument("--machine-id", required=True)
    t.add_argument("--procedure")
    t.add_argument("--false-alarm-rate", type=float, default=0.001,
                   help="in-control probability that a calibration raises an alarm (default 0.001)")
    t.add_argument("--tolerance", action="append", metavar="NAME=VALUE",
                   help="largest acceptable |value|, mm / rad (the latest calibration is graded)")
    t.add_argument("--volumetric-tolerance", type=float, help="largest acceptable predicted tool-point error, mm")
    t.add_argument("--pool", choices=["days", "cycles"], default="days", help="pooled statistics by (default days)")
    t.add_argument("--plot", help="write the trend plot (PNG) here")
    t.set_defaults(func=_trend)

    f = sub.add_parser("fleet", help="identify many datasets on Dask (needs fivecal[fleet])",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Identify every dataset of a folder, glob or manifest on a Dask cluster "
                       "(a LocalCluster by default). Failures are recorded, not fatal; a re-run skips datasets "
                       "already identified (same sha256 digest).",
                       epilog="examples:\n"
                       "  fivecal fleet identify nightly/ --store shop.fcdb --procedure sphere\n"
                       "  fivecal fleet identify 'nightly/*/2026-11-*.json' --parquet results/ "
                       "--scheduler tcp://10.0.0.5:8786")
    fs = f.add_subparsers(dest="fleet_command", required=True)
    fi = fs.add_parser("identify", help="identify a folder / glob / manifest of datasets")
    fi.add_argument("source", help="folder (every *.json below it; machine id = the file's folder, time = the "
                    "date in its name), glob, or manifest .parquet/.csv with columns path[, machine_id, time, "
                    "procedure]")
    fi.add_argument("--store", help="calibration store to record the results in")
    fi.add_argument("--parquet", help="folder of Parquet files partitioned by machine_id to write")
    fi.add_argument("--estimate", default="location", help="parameters / presets (default: location)")
    fi.add_argument("--procedure", help="procedure label recorded with each result")
    fi.add_argument("--machine-id", help="one machine id for every dataset")
    fi.add_argument("--scheduler", metavar="ADDRESS", help="an existing Dask scheduler (default: a LocalCluster)")
    fi.add_argument("--workers", type=int, help="LocalCluster worker processes (default: min(2, cores))")
    fi.add_argument("--trials", type=int, default=0, help="also a Monte Carlo (JCGM 101) of this many trials "
                    "per dataset; its covariance is recorded (default 0: the fit's)")
    fi.add_argument("--no-progress", action="store_true", help="no Dask progress bar")
    fi.set_defaults(func=_fleet)
