"""``fivecal history add|list|show|compare|export|trend`` and ``fivecal fleet identify``."""
from __future__ import annotations

import argparse
import json
import os
import sys
import warnings

from ..history.fleet import _time_of, fleet_identify
from ..history.store import AlreadyRecorded, Store, calibration_from_result, dataset_digest, write_parquet
from ..history.trend import ChartDesign, compare, detect, grade, plot_trend, pooled_statistics
from ..identification import resolve_estimate
from ..machine import Machine
from ..report.history import History
from ..tolerances import check_names, parse_tolerances, volumetric_tolerance
from ..units import display_scale
from .common import MAX_TRIALS, MAX_WORKERS, check_size


def _store(args, create=False):
    return Store(args.store, create=create)


def _recording(record):
    """Run ``record()`` (a Store.add); a repeat is said on stderr (exit 0,
    nothing changed). Returns (row id, whether it was a repeat)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", AlreadyRecorded)
        i = record()
    for w in caught:
        if issubclass(w.category, AlreadyRecorded):
            a = w.message
            print(f"history: {a.machine_id}: this dataset is already recorded (calibration #{a.id} at {a.time}); "
                  "nothing changed (--replace replaces it)", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return i, any(issubclass(w.category, AlreadyRecorded) for w in caught)


def _add(args) -> int:
    digest = dataset_digest(args.dataset) if args.dataset else None
    machine = args.machine or args.dataset
    with _store(args, create=True) as s:
        i, repeat = _recording(lambda: s.add(args.result, machine_id=args.machine_id, procedure=args.procedure or "",
                                             time=args.time, machine=machine, digest=digest, replace=args.replace,
                                             rebuilt=args.rebuilt))
        c = s.get(i)
    if not repeat:
        print(f"{args.store}: calibration #{i} of {c.machine_id} at {c.time} recorded ({len(c.names)} parameters, "
              f"verdict {c.verdict})" + (" as the first after a rebuild" if args.rebuilt else ""))
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
    s = _store(args) if args.store else None
    try:
        a, b = _resolve(s, args.a, "A"), _resolve(s, args.b, "B")
        # the machines the store recorded for stored calibrations: a comparison across machines is refused
        ma, mb = ((s.machine(c.machine_id) if s is not None and c.id else None) for c in (a, b))
        machine = Machine.load(args.machine) if args.machine else (mb if s else None)
    finally:
        if s is not None:
            s.close()
    tol = parse_tolerances(args.tolerance, names=[n for n in a.names if n in set(b.names)],
                           what="both calibrations")
    cmp = compare(a, b, machine=machine, tolerances=tol, z_limit=args.z, machines=(ma, mb))
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
        # written while the store is open: the one guard refuses OUT being the store
        write_parquet(cals, args.out, label="OUT")
    print(f"{len(cals)} calibrations written to {args.out}")
    return 0


def _trend(args) -> int:
    vt = volumetric_tolerance(args.volumetric_tolerance)
    with _store(args) as s:
        machine = s.machine(args.machine_id)
        rebuilt = s.rebuilt_at(args.machine_id)
        # a rebuilt machine's trend starts at its rebuild: never pooled across it
        cals = s.list(args.machine_id, args.procedure, since=rebuilt)
        if not cals:
            raise ValueError(f"{args.store}: no calibration of machine '{args.machine_id}'"
                             + (f" since its rebuild at {rebuilt}" if rebuilt else ""))
        tol = parse_tolerances(args.tolerance, names=_names_of(cals[-1]),
                               what=f"machine {args.machine_id}'s latest calibration")
    if rebuilt:
        print(f"machine {args.machine_id} rebuilt at {rebuilt}: the trend starts there")
    charts = detect(cals, false_alarm_rate=args.false_alarm_rate)
    if charts:
        d = next(iter(charts.values()))
        design = ChartDesign.for_rate(args.false_alarm_rate, len(charts))
        print(f"CUSUM (self-starting, k = {d.k:g}, h = {d.h:.3f}: in-control ARL {design.arl0_one_sided:.0f} "
              f"calibrations per one-sided chart, {args.false_alarm_rate:g} false alarms per calibration over "
              f"{len(charts)} parameters)")
        for n, ch in charts.items():
            print(f"  {n:<12}" + (", ".join(ch.times[i] for i in ch.alarms) if ch.alarms else "no alarm"))
    status = 0
    if tol or vt is not None:
        g = grade(cals[-1], tol, vt, machine=machine)
        print(g.report())
        status = 1 if g.verdict == "fail" else 0
    try:
        print(pooled_statistics(cals, by=args.pool).report())
    except ValueError as e:
        print(f"pooled statistics: {e}")
    if args.plot:
        plot_trend(cals, args.plot, tolerances=tol, charts=charts, label="--plot")
        print(f"trend plot: {args.plot}")
    return status


def _names_of(cal) -> list:
    """Names a tolerance may name: the graded calibration's parameters."""
    return list(cal.names) + list(cal.fixed)


def _fleet(args) -> int:
    if not args.store and not args.parquet:
        raise ValueError("fleet identify: give --store FILE and/or --parquet DIR for the results")
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


def _tolerance_help(what: str) -> str:
    return (f"largest acceptable {what}, e.g. EX0C=12um, EA0C=20urad, EXX1=5um/m (repeatable, comma "
            "separated); a bare number is in mm / rad, and a bare number too large for the parameter "
            "(12 for EX0C) is refused as probably µm (`fivecal docs history`)")


def _record_options(g) -> None:
    g.add_argument("--replace", action="store_true", help="replace the calibration of the same dataset "
                   "(digest) of this machine id when it is already recorded (without: a repeat changes nothing)")
    g.add_argument("--rebuilt", action="store_true", help="the machine was rebuilt: accept a result whose "
                   "machine definition differs from the one recorded for this machine id; the store records "
                   "the rebuild and the trend starts again here")


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
    g.add_argument("--tolerance", action="append", metavar="NAME=VALUE", help=_tolerance_help("|value|"))
    g.add_argument("--volumetric-tolerance", metavar="MM",
                   help="largest acceptable predicted tool-point error, mm (or with a unit: 20um)")
    g.add_argument("--record", action="store_true", help="also record this result in the store (created if "
                   "missing), with the dataset's digest and that time, after the report is written")
    g.add_argument("--procedure", metavar="LABEL", help="procedure label recorded with --record (e.g. sphere, tango)")
    _record_options(g)


def identify_history(args):
    """The report's :class:`~fivecal.report.history.History` for ``fivecal
    identify`` (None without --history); checks the options first (the
    tolerance names against the machine: :func:`check_identify_history`)."""
    given = [o for o, v in (("--machine-id", args.machine_id), ("--tolerance", args.tolerance),
                            ("--volumetric-tolerance", args.volumetric_tolerance), ("--record", args.record),
                            ("--procedure", args.procedure), ("--replace", args.replace),
                            ("--rebuilt", args.rebuilt)) if v]
    if not args.history:
        if given:
            raise ValueError(f"{given[0]}: needs --history STORE")
        return None
    if not args.machine_id or not args.machine_id.strip():
        raise ValueError("--history: give --machine-id ID (which machine of the store this dataset is)")
    if not args.report and not args.record:
        raise ValueError("--history: the trend, comparison and pass / fail go in the HTML report: give "
                         "--report DIR (or --record to only record the result)")
    for o, v in (("--replace", args.replace), ("--rebuilt", args.rebuilt)):
        if v and not args.record:
            raise ValueError(f"{o}: only with --record")
    vt = volumetric_tolerance(args.volumetric_tolerance)
    tol = parse_tolerances(args.tolerance)

    # a missing (without --record) or foreign file is said before the fit
    Store(args.history, create=args.record).close()

    return History(args.history, args.machine_id.strip(), tolerances=tol or None,
                   volumetric_tolerance=vt, time=_time_of(args.dataset) if os.path.isfile(args.dataset) else None)


def check_identify_history(args, hist, dataset) -> None:
    """Before the fit, with the dataset loaded: every tolerance names a
    parameter of its machine, and the machine is the one the store holds for
    --machine-id (unless --rebuilt)."""
    if hist is None:
        return
    m = dataset.machine
    if hist.tolerances:
        check_names(hist.tolerances, m.parameter_names(), f"machine {m.name} ({m.topology})")
        # a tolerance on a parameter the fit will not estimate could only be graded after it, on nothing
        est = resolve_estimate(dataset, args.estimate, args.fix)
        check_names(hist.tolerances, est, f"the fit (--estimate {args.estimate} estimates {len(est)} parameters; "
                    "estimate it or drop its tolerance)")
    if not args.rebuilt and os.path.exists(hist.store):
        with Store(hist.store, create=False) as s:
            s.check_machine(hist.machine_id, m)


def grade_identify(result, hist) -> str:
    """``fivecal identify --tolerance``: this result graded as the report
    grades it (printed); returns the verdict (pass, fail, undecided)."""
    cal = calibration_from_result(result, hist.machine_id, time=hist.time, source="this identification")
    g = grade(cal, hist.tolerances or {}, hist.volumetric_tolerance, machine=result.dataset.machine)
    print()
    print(g.report())
    return g.verdict


def record_identify(args, result, hist) -> None:
    """``fivecal identify --record``: the result into the store; a
    non-finite fit is not recorded (said on stderr; the command then exits 1
    on the fit, keeping its report and result to inspect)."""
    cal = calibration_from_result(result, hist.machine_id, time=hist.time, procedure=args.procedure or "",
                                  source=args.dataset)
    try:
        cal.check()
    except ValueError as e:
        print(f"history: not recorded: {e}", file=sys.stderr)
        return
    with Store(hist.store, create=True) as s:
        i, repeat = _recording(lambda: s.add(cal, machine_id=hist.machine_id, machine=result.dataset.machine,
                                             replace=args.replace, rebuilt=args.rebuilt))
        n = len(s.list(hist.machine_id))
    if not repeat:
        print(f"history: calibration #{i} of {hist.machine_id} recorded in {hist.store} ({n} in all)"
              + (", the first after a rebuild" if args.rebuilt else ""))


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
    a.add_argument("result", help="result document of any fivecal procedure (--out of identify, sphere-check, rtest, dbb, ...)")
    a.add_argument("--machine-id", required=True, help="which machine (free text, e.g. its serial number)")
    a.add_argument("--procedure", help="procedure label (default: the result document's procedure name, e.g. sphere-check, rtest)")
    a.add_argument("--time", help="when it was measured, ISO 8601 (default now; without a zone: UTC)")
    a.add_argument("--machine", help="machine JSON (kept for volumetric comparisons)")
    a.add_argument("--dataset", help="the dataset the result came from: its sha256 digest is recorded "
                   "(and its machine kept)")
    _record_options(a)
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
    c.add_argument("a", metavar="A", help="calibration id in --store, or a result document of any procedure")
    c.add_argument("b", metavar="B", help="calibration id in --store, or a result document of any procedure")
    c.add_argument("--machine", help="machine JSON for the volumetric change (default: the store's)")
    c.add_argument("--tolerance", action="append", metavar="NAME=VALUE", help=_tolerance_help("change |B - A|"))
    c.add_argument("--z", type=float, default=3.0, help="|z| above this is reported as a change (default 3)")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=_compare)

    e = hs.add_parser("export", help="write the calibrations to Parquet (needs fivecal[arrow])")
    common(e)
    e.add_argument("out", metavar="OUT", help="Parquet file to write")
    e.add_argument("--machine-id")
    e.set_defaults(func=_export, file_labels={"out": "OUT"})

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
                   help=_tolerance_help("|value| of the latest calibration"))
    t.add_argument("--volumetric-tolerance", metavar="MM",
                   help="largest acceptable predicted tool-point error, mm (or with a unit: 20um)")
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
