"""``fivecal dbb ...``: double ball bar tests from the command line.

  four-step four-step test of a rotary pair: the general engine's fit, the method beside it
  jiang     Jiang & Cripps four-step test of a rotary pair (and the general engine)
  wang      Wang et al. simultaneous A/C path: Table 1, patterns, identification
  circular  planar circular test: ISO 230-4 values and diagnosis
  volumetric  circular tests of the XY, YZ and ZX planes, by plane and combined
  plot      polar plot of traces (CSV or a dataset setup)

Errors are one line on stderr (the caller, cli.main, prints them).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys

import numpy as np

from ..dataset import load_dataset, save_dataset
from ..files import read_json
from ..guards import FitWarning
from ..identification import identify, write_result
from ..machine import Machine
from ..procedures import dbb
from ..procedures.sphere_check import spindle_equivalent
from ..io import b5r
from ..report.circular import write_circular_report, write_volumetric_report
from ..report.polar import (dbb_groups, plane_name, plot_circular_test, plot_four_step, plot_polar, plot_polar_grid,
                            plot_volumetric, plot_wang_patterns)
from ..simulation import simulate
from ..tolerances import parse_value
from .common import (EXIT_FIT, EXIT_OK, MAX_SAMPLES, POSITIVE, SEED, SIGMA, _FORCE_HELP, _float_type, _values_verdict,
                     check_step, fit_status)

#: Jiang & Cripps Tables 2-3 (positions in mm; orientations read as arc-seconds,
#: see examples/machines/README.md).
_ARCSEC = math.pi / (180 * 3600)
PAPER_JIANG = {"EY0A": 0.0342, "EZ0A": -0.0353, "EB0A": 6.62 * _ARCSEC, "EC0A": 1.89 * _ARCSEC,
               "EX0C": 0.0013, "EY0C": -0.0525, "EA0C": -22.32 * _ARCSEC, "EB0C": -3.75 * _ARCSEC}
#: Wang et al. Section 5.1: 7, -5, 6 um before compensation; the angular value did
#: not survive in the text, 20 urad is assumed.


def paper_jiang(machine) -> dict:
    """The paper's Tables 2-3 by role on any rotary pair: the carrier gets
    A's values, the carried axis C's, in the order of the pair's PIGE names
    (positions along the first and second plane axes, then the tilts about
    them)."""
    names = dbb.four_step_pair(machine)["names"]
    return dict(zip(names, PAPER_JIANG.values()))


PAPER_WANG = {"EX0C": 0.007, "EY0C": -0.005, "EZ0C": 0.006, "EA0C": 20e-6}


def _values(text, what: str, paper=None) -> dict:
    """NAME=VALUE pairs (mm, rad), a JSON file of them, or 'paper'."""
    if text is None:
        return {}
    if text == "paper" and paper is not None:
        return dict(paper)
    if os.path.exists(text):
        d = read_json(text, "errors")
        if not isinstance(d, dict):
            raise ValueError(f"{text}: expected an object name -> value")
        out = {}
        for k, v in d.items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{text}: {k}: expected a finite number (mm or rad), got {json.dumps(v)[:40]}")
            out[k] = float(v)
        return out
    out = {}
    for part in text.replace(";", ",").split(","):
        if not part.strip():
            continue
        if "=" not in part:
            raise ValueError(f"{what}: expected NAME=VALUE pairs, a JSON file or 'paper', got {part!r}")
        k, v = part.split("=", 1)
        try:
            x = float(v)
        except ValueError:
            raise ValueError(f"{what}: {k.strip()}: not a number ({v!r})") from None
        if not math.isfinite(x):
            raise ValueError(f"{what}: {k.strip()}: not a finite number ({v!r})")
        out[k.strip()] = x
    return out


def _vector(text, n: int, what: str):
    if text is None:
        return None
    try:
        v = [float(x) for x in text.replace(" ", "").split(",")]
    except ValueError:
        raise ValueError(f"{what}: expected {n} comma-separated numbers, got {text!r}") from None
    if not all(math.isfinite(x) for x in v):
        raise ValueError(f"{what}: expected {n} finite numbers, got {text!r}")
    if len(v) != n:
        raise ValueError(f"{what}: expected {n} comma-separated numbers, got {len(v)}")
    return v


def _machine(path):
    if path is None:
        raise ValueError("--machine is required here (a machine JSON file)")
    if not os.path.exists(path):
        bundled = os.path.join(os.path.dirname(__file__), "examples", "machines", path)
        if os.path.exists(bundled):
            path = bundled
        elif os.path.exists(bundled + ".json"):
            path = bundled + ".json"
    return Machine.load(path)


# A tiny --step would otherwise ask for billions of poses (cli.MAX_SAMPLES).
def _check_step(step: float, sweep: float) -> None:
    check_step("--step", step, sweep, what="samples", limit=MAX_SAMPLES)


@contextlib.contextmanager
def _quiet_fit_warnings():
    """FitWarnings silenced: the command judges the fit itself, in one line."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        yield


#: The fit part of a result document written without a machine-error fit (CSV
#: circular runs without --machine, the volumetric evaluation): no parameters,
#: marked undetermined, so export, compensate and history refuse it rather than
#: take "no errors" for a measured zero.
_NO_FIT = {"parameters": {}, "converged": True, "verdict": "undetermined", "undetermined": []}


# ---- jiang / four-step ------------------------------------------------------
def _jiang(args) -> int:
    return _four_step(args, "jiang-cripps")


def _four_step_cmd(args) -> int:
    return _four_step(args, "four-step")


def _four_step(args, procedure: str) -> int:
    """``dbb four-step`` and ``dbb jiang``: the same readings, the same fit.
    The machine errors of the result document are the general engine's
    (identify's fit of every reading, judged by identify's verdict); the
    four-step method's own values (eqs. 1-20) go into ``procedure.values``."""
    command = "dbb jiang" if procedure == "jiang-cripps" else "dbb four-step"
    if args.no_engine and args.out:
        raise ValueError("--out: the result's machine errors are the general engine's fit; drop --no-engine")
    setups = None
    if args.setups:
        setups = [s.strip() for s in args.setups.split(",")]
        if len(setups) != 4:
            raise ValueError("--setups: four ids (carrier, carrier extended, carried, carried extended), "
                             "e.g. A1,A2,C1,C2")
    if args.dataset:
        ds = load_dataset(args.dataset)
    else:
        m = _machine(args.machine)
        _check_step(args.step, 359.0)  # a rotary-table step of the default plan sweeps 0..359 deg
        try:
            plan = dbb.four_step_plan(m, step=args.step, setups=setups)
        except ValueError as e:
            if "plan.step" in str(e):
                raise ValueError(f"--step: {e}") from None
            raise
        if args.csv:
            traces = {}
            for part in args.csv.split(","):
                if "=" not in part:
                    raise ValueError("--csv: expected SETUP=FILE pairs, e.g. A1=a1.csv,A2=a2.csv,... "
                                     "(setups: " + ",".join(setups or dbb.four_step_pair(m)["setups"]) + ")")
                sid, path = part.split("=", 1)
                t = dbb.read_trace_csv(path.strip())
                dbb.check_direction(t, path.strip())  # a file named cw/ccw must turn that way
                traces[sid.strip()] = t
            ds = dbb.four_step_dataset(m, traces, plan)
        elif args.simulate is not None:
            errors = _values(args.simulate, "--simulate", paper_jiang(m))
            ds = simulate(m, plan, errors=errors, sigma={"dbb": args.sigma}, seed=args.seed)
        else:
            raise ValueError("give a DATASET, or --machine with --simulate ERRORS or --csv SETUP=FILE,...")
        if args.save_dataset:
            save_dataset(ds, args.save_dataset)
    with _quiet_fit_warnings():  # judged once below, in one line
        res = dbb.jiang_cripps(ds, setups=setups,
                               a_pivot_offset=_vector(args.a_pivot_offset, 2, "--a-pivot-offset") or (0, 0),
                               c_pivot_offset=_vector(args.c_pivot_offset, 2, "--c-pivot-offset") or (0, 0),
                               uniform_angles=args.uniform_angles, refer_positions=not args.no_refer,
                               a_removal=args.a_removal, engine=not args.no_engine, spindle_names=True)
    print(res.report())
    if args.out and res.engine is not None:
        write_result(args.out, res.engine, procedure, res.procedure_values())
        print(f"\nresult written to {args.out}")
    if args.plot:
        plot_four_step(res, args.plot)
        print(f"polar plots written to {args.plot}")

    verdicts = [("four-step values", _values_verdict(res.values, res.std))]
    if res.engine is not None:
        verdicts.append(("general engine", res.engine.assessment()))
    elif not args.no_engine:
        # the engine refused the fit (a confounded set): nothing a consumer may use
        written = [x for x in (args.plot,) if x]
        print(f"fivecal {command}: not usable: the general engine did not fit ({res.engine_error})"
              + (f"; no result written to {args.out}" if args.out else "")
              + (f" ({' and '.join(written)} written, to inspect)" if written else ""), file=sys.stderr)
        return EXIT_FIT
    return fit_status(command, verdicts, args.force, (args.out, args.plot))


# ---- wang ------------------------------------------------------------------
def _wang(args) -> int:
    geometry = {"table_ball": _vector(args.table_ball, 3, "--table-ball") or (0.0, 150.0, 130.0),
                "radius": args.radius, "height": args.height}
    ds = load_dataset(args.dataset) if args.dataset else None
    if args.out and ds is None and args.simulate is None:
        raise ValueError("--out: a result needs readings; give a DATASET or --simulate")
    m = ds.machine if ds is not None and args.machine is None else _machine(args.machine)
    path = dbb.wang_path(m, **geometry)
    print(path.format_table(args.every))
    if args.patterns:
        sizes = _values(args.pattern_errors, "--pattern-errors") or {"EX0C": 0.01, "EY0C": 0.01,
                                                                     "EZ0C": 0.01, "EA0C": 50e-6}
        pats = dbb.wang_patterns(m, sizes, **geometry)
        plot_wang_patterns(pats, args.patterns, path)
        print(f"\npatterns written to {args.patterns}")
    # the path geometry belongs in the result only when it made the trace
    ds_path_is_plan = ds is None
    if ds is None and args.simulate is not None:
        plan = dbb.wang_plan(m, setup=args.setup, path=path)
        ds = simulate(m, [{k: v for k, v in e.items() if k != "tracking"} for e in plan],
                      errors=_values(args.simulate, "--simulate", PAPER_WANG),
                      sigma={"dbb": args.sigma}, seed=args.seed)
        if args.save_dataset:
            save_dataset(ds, args.save_dataset)
    if ds is not None:
        # an offset that is the spindle's (EX0C on an A/C trunnion) under the spindle's name,
        # as every fivecal command names it
        estimate = [s.strip() for s in args.estimate.split(",")] if args.estimate else \
            list(dict.fromkeys(spindle_equivalent(ds.machine, n) for n in dbb.WANG_ERRORS))
        with _quiet_fit_warnings():  # judged once below, in one line
            ident = dbb.wang_identify(ds, estimate=estimate, setup=args.setup)
        print()
        print(ident.report())
        if args.out:
            write_result(args.out, ident.result, "wang", ident.procedure_values(path if ds_path_is_plan else None))
            print(f"\nresult written to {args.out}")
        if args.plot:
            t = dbb.trace_from_dataset(ds, args.setup)
            t.label = f"measured ({args.setup})"
            r = ident.result
            # The fitted model's readings: residual = predicted - measured length.
            src = np.asarray(r.residual_source)
            _, _, idx = dbb.ball_positions(ds, args.setup)
            res_by_obs = {int(o): float(v) for o, v in zip(src, r.residuals)}
            fit = dbb.Trace(t.angles, t.readings + np.array([res_by_obs[i] for i in idx]), label="fitted model")
            notes = ["identified (least squares):"] + [
                f"  {n:<6}{r.values[n] * dbb.display_scale(n)[0]:+9.2f} ± "
                f"{r.std[n] * dbb.display_scale(n)[0]:.2f} {dbb.display_scale(n)[1]}" for n in estimate]
            notes += ["", f"residual rms {r.rms * 1e3:.2f} µm", "angle: tracking angle from +X"]
            plot_polar([t, fit], args.plot, path.bar_length, f"Wang et al. DBB trace, setup {args.setup}",
                       annotations=notes, plane=tuple(getattr(t, "plane", "XY")),
                       colors=["#d62728", "#222222"])
            print(f"polar plot written to {args.plot}")

        return fit_status("dbb wang", [("", ident.result.assessment())], args.force, (args.out, args.plot))
    return 0


# ---- circular --------------------------------------------------------------
def _diagnosis_options(args) -> dict:
    pitch = None
    if args.cyclic_pitch:
        parts = [p.strip() for p in args.cyclic_pitch.split(",")]
        try:
            vals = ["auto" if p.lower() == "auto" else (float(p) if p else 0.0) for p in parts]
        except ValueError:
            raise ValueError(f"--cyclic-pitch: {args.cyclic_pitch!r}; give mm or 'auto', one value or two "
                             "(axis 1,axis 2)")
        if len(vals) not in (1, 2) or any(v != "auto" and (not (v >= 0) or v == float("inf")) for v in vals):
            raise ValueError(f"--cyclic-pitch: {args.cyclic_pitch!r}; one or two pitches >= 0 mm or 'auto'")
        pitch = vals[0] if len(vals) == 1 else vals
    machine = args.machine_name
    if machine is None and getattr(args, "machine", None):
        machine = _machine(args.machine).name
    return {"trim": not args.no_trim, "feed_in": args.feed_in, "spike_width": args.spike_width,
            "cyclic_pitch": pitch, "significance": 0.0 if args.all_diagnoses else 3.0,
            "machine": machine, "date": args.date}


def _add_diagnosis_options(p) -> None:
    p.add_argument("--cyclic-pitch", metavar="MM[,MM]",
                   help="pitch of the cyclic error to fit (ball-screw or scale pitch), one for both plane axes "
                   "or one per axis; 'auto' searches it; default: not fitted")
    p.add_argument("--spike-width", type=POSITIVE, default=3.0,
                   help="decay of a reversal spike, deg of path angle (default 3)")
    p.add_argument("--all-diagnoses", action="store_true",
                   help="keep every diagnosis, also those below 3 standard uncertainties")
    p.add_argument("--no-trim", action="store_true",
                   help="keep feed-in/feed-out (overshoot) arcs beyond 360 deg instead of removing them")
    p.add_argument("--feed-in", type=_float_type(0.0), default=None,
                   help="deg of feed-in arc to remove at the start (default: half the sweep beyond 360 deg)")
    p.add_argument("--machine-name", help="machine name for the report and plot header")
    p.add_argument("--date", help="test date for the report and plot header")


def _run_word(direction: int) -> str:
    return "CCW" if direction > 0 else ("CW" if direction < 0 else "no net turn")


#: Largest bare tolerance of a diagnosis in its file unit: 1 mm of a length,
#: 1 mrad of squareness, 1 mm/m of scale mismatch (a bare µm number left in a script).
_BARE_LIMITS = {("length", None, 0): 1.0, ("angle", None, 0): 1e-3, ("length", "length", 1): 1e-3}


def _circular_tolerances(items) -> dict:
    """``--tolerance G=15um,backlash.X+=4um,squareness=20urad``: ISO 230-4
    values (G, F, H) and diagnoses with a unit; a bare number is in the file
    unit (mm, rad, mm/mm), refused when implausibly large."""
    out = {}
    for text in items or ():
        for item in [t for t in str(text).split(",") if t.strip()]:
            if "=" not in item:
                raise ValueError(f"--tolerance: expected NAME=VALUE (e.g. G=15um), got '{item.strip()}'")
            k, v = (x.strip() for x in item.split("=", 1))
            kind, den, degree = dbb.CircularResult.tolerance_dimension(k)
            if k in out:
                raise ValueError(f"--tolerance: {k} is given twice")
            out[k] = parse_value(v, f"--tolerance {k}", kind, den, degree,
                                 bare_limit=_BARE_LIMITS[(kind, den, degree)], limit_hint=", a ball bar value")
    return out


def _direction_words(text, n: int):
    """``--direction cw,ccw``: one run direction per file (+1 CCW, -1 CW)."""
    if text is None:
        return [None] * n
    words = [w.strip().lower() for w in str(text).split(",")]
    table = {"ccw": 1, "cw": -1}
    if len(words) != n or any(w not in table for w in words):
        raise ValueError(f"--direction {text}: give cw or ccw for each of the {n} run file(s), comma separated "
                         "(e.g. --direction cw,ccw)")
    return [table[w] for w in words]


def _read_run(path: str, args, direction):
    """One run file: two columns (angle, reading) or readings only with
    --sweep (the arc the samples span, deg), --start and the direction."""
    one_column = args.sweep is not None
    if one_column:
        d = direction or dbb.claimed_direction(path)
        if not d:
            raise ValueError(f"{path}: readings only; say which way it runs: --direction cw|ccw (one per file) "
                             "or a file name with cw / ccw in it")
        return dbb.read_trace_csv(path, sweep=d * args.sweep, start=args.start, units=args.units,
                                  angle_units=args.angle_units)
    t = dbb.read_trace_csv(path, units=args.units, angle_units=args.angle_units)
    if direction and t.direction and direction != t.direction:
        raise ValueError(f"{path}: --direction says {_run_word(direction)} but its angles run "
                         f"{_run_word(t.direction)}")
    return t


def _thermal(args) -> dict:
    """The thermal compensation from --sidecar ("thermal") and the options;
    a value given both ways is refused."""
    th = {}
    if args.sidecar:
        side = read_json(args.sidecar, "circular test sidecar")
        if not isinstance(side, dict):
            raise ValueError(f"{args.sidecar}: expected an object with \"thermal\"")
        unknown = [k for k in side if k not in ("thermal", "machine", "date", "feed")]
        if unknown:
            raise ValueError(f"{args.sidecar}: {unknown[0]}: unknown key (expected thermal, machine, date, feed)")
        th = dict(side.get("thermal") or {})
        for k in ("machine", "date", "feed"):
            if k in side:
                opt = {"machine": "machine_name"}.get(k, k)
                if getattr(args, opt) is not None:
                    raise ValueError(f"{args.sidecar}: {k} is also given on the command line; give it once")
                setattr(args, opt, side[k])
    for key, opt in (("bar_expansion", "bar_expansion"), ("bar_temperature", "bar_temperature"),
                     ("machine_expansion", "machine_expansion"), ("machine_temperature", "machine_temperature")):
        v = getattr(args, opt)
        if v is None:
            continue
        if key in th:
            raise ValueError(f"--{opt.replace('_', '-')}: also in {args.sidecar} (thermal.{key}); give it once")
        th[key] = v
    if th:
        th = dbb.check_thermal(th)
    return th


def _expansion(text) -> float:
    """An expansion coefficient: ``11.5ppm`` (µm/m/K) or a number in 1/K."""
    t = str(text).strip().lower().replace("/k", "").replace("µm/m", "ppm").replace("um/m", "ppm")
    try:
        return float(t[:-3]) * 1e-6 if t.endswith("ppm") else float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}': give 1/K (11.5e-6) or ppm/K (11.5ppm)") from None


def _circular(args) -> int:
    tolerances = _circular_tolerances(args.tolerance)
    standard = dbb.check_standard(args.standard)
    thermal = _thermal(args)
    if args.sweep is not None and not args.runs:
        raise ValueError("--sweep: for readings-only run files; give the files")
    if any(str(p).lower().endswith(".b5r") for p in args.runs):
        return _b5r(args, tolerances)
    if args.radius is None:
        raise ValueError("--radius: required (the nominal radius = bar length, mm)")
    traces, ds = [], None
    if args.simulate is not None:
        m = _machine(args.machine)
        _check_step(args.step, 360.0)
        plan = dbb.planar_plan(m, args.plane, args.radius, step=args.step)
        ds = simulate(m, plan, errors=_values(args.simulate, "--simulate"), sigma={"dbb": args.sigma},
                      seed=args.seed)
        setups = ["P-", "P+"]
        source = "simulated setup {}"
    elif args.dataset:
        ds = load_dataset(args.dataset)
        setups = [x.strip() for x in args.setups.split(",") if x.strip()]
        source = f"{args.dataset}: setup {{}}"
    else:
        if not args.runs:
            raise ValueError("give one or two CSV files (angle, reading), --dataset or --simulate")
        for path, d in zip(args.runs, _direction_words(args.direction, len(args.runs))):
            t = _read_run(path, args, d)
            # the direction is the data's; a file named cw / ccw that turns the other way is refused
            dbb.check_direction(t, path)
            t.label = _run_word(t.direction) + f" ({os.path.basename(path)})"
            traces.append(t)
        if args.machine:
            ds = dbb.planar_dataset(_machine(args.machine), traces, args.plane, args.radius)
    if ds is not None and not traces:
        for sid in setups:
            t = dbb.trace_from_dataset(ds, sid)
            dbb.check_direction(t, source.format(sid), sid)
            t.label = _run_word(t.direction) + f" ({sid})"
            traces.append(t)
        ds = ds.subset([i for sid in setups for i in dbb.ball_positions(ds, sid)[2]])
    if len(traces) > 2:
        raise ValueError(f"{len(traces)} runs; give one or two (CW and CCW)")
    res = dbb.circular_test(traces, args.radius, args.plane, args.feed, thermal=thermal or None,
                            standard=standard, **_diagnosis_options(args))
    print(res.report())
    fit = None
    if ds is not None:
        # the machine errors under their ISO 230-1 names: identify's fit of the same
        # readings, every error under its prior, judged by identify's verdict
        m = ds.machine
        # an offset that is the spindle's is estimated under the spindle's name only
        # (as every fivecal command names it), not twice under two names
        twins = [n for n in m.parameter_names() if spindle_equivalent(m, n) != n]
        with _quiet_fit_warnings():
            fit = identify(ds, fix=twins or None)
        print("\nmachine errors (identify's fit of the same readings, every error under its prior):")
        print(fit.report())
    grade = res.grade(tolerances) if tolerances else None
    if grade is not None:
        print("\n  grade against the tolerances: " + grade["grade"])
        for i in grade["items"]:
            print(f"    {i['label']:<24}{i['run']:<8}{i['shown']:>22}  tolerance {i['tolerance_shown']:>12}  "
                  f"{i['grade']}")
    if args.out:
        # without a machine there is no machine-error fit: the document carries
        # the ISO 230-4 values alone, marked so that no consumer uses it
        write_result(args.out, fit if fit is not None else _NO_FIT, "circular",
                     res.procedure_values(tolerances))
        print(f"\nresult written to {args.out}")
    if args.plot:
        plot_circular_test(res, args.plot)
        print(f"polar plot written to {args.plot}")

    # ISO 230-4 values of each run and the least-squares diagnosis: one
    # non-finite number (a degenerate trace) makes the whole test unusable.
    values = {f"run {i + 1} {k}": float(getattr(r, k)) for i, r in enumerate(res.runs)
              for k in ("circular_deviation", "radial_deviation_max", "radial_deviation_min", "mean_radius")}
    values.update({f"diagnosis {k}": v for k, v in res.diagnosis.items()})
    std = {f"diagnosis {k}": v for k, v in res.diagnosis_std.items()}
    verdicts = [("ISO 230-4 values", _values_verdict(values, std))]
    if fit is not None:
        verdicts.append(("machine errors", fit.assessment()))
    rc = fit_status("dbb circular", verdicts, args.force, (args.out, args.plot, args.html))
    if args.html:
        reason = "" if rc == EXIT_OK else "the ISO 230-4 values or the machine-error fit are not usable (see the " \
            "command's output)"
        path = write_circular_report(res, args.html, grade=grade, usable=rc == EXIT_OK, reason=reason,
                                     scale=args.scale, sources=list(args.runs) or [args.dataset or "simulated"])
        print(f"HTML report written to {path}")
    if rc == EXIT_OK and grade is not None and grade["grade"] != "PASS":
        bad = [f"{i['label']} {i['run']} {i['shown']} > {i['tolerance_shown']}" if i["grade"] == "FAIL" else
               f"{i['label']} not determined (not fitted or below 3σ; --all-diagnoses grades it)"
               for i in grade["items"] if i["grade"] != "PASS"]
        print(f"fivecal dbb circular: {grade['grade']} against the tolerances: {'; '.join(bad)}", file=sys.stderr)
        return EXIT_FIT
    return rc


def _b5r(args, tolerances) -> int:
    """A Renishaw .b5r file: its header and the diagnostics Renishaw's
    software computed, read and ranked; the raw trace is not read (its
    layout is not public: docs/dbb.md, "Renishaw .b5r files")."""
    if len(args.runs) != 1:
        raise ValueError("a .b5r file holds a whole test: give one .b5r file alone")
    if tolerances:
        raise ValueError("--tolerance: a .b5r file's diagnostics are Renishaw's, read as written; grade them in "
                         "Renishaw's software or give the trace as CSV")
    doc = b5r.read_b5r(args.runs[0], nominal_radius=args.radius)
    print(doc.report())
    if args.out:
        write_result(args.out, _NO_FIT, "circular", {"b5r": doc.to_dict()})
        print(f"\nresult written to {args.out}")
    return EXIT_OK


# ---- volumetric --------------------------------------------------------------
def _volumetric(args) -> int:
    """The planes' circular tests, each as ``dbb circular`` reads, corrects
    and grades one, then combined; one verdict over every plane."""
    given = [p for p in ("XY", "YZ", "ZX") if getattr(args, p.lower())]
    if args.simulate is not None and given:
        raise ValueError(f"--{given[0].lower()}: run files and --simulate both given; give one")
    if args.simulate is not None and args.sweep is not None:
        raise ValueError("--sweep: for readings-only run files; --simulate makes its own runs")
    tolerances = _circular_tolerances(args.tolerance)
    standard = dbb.check_standard(args.standard)
    thermal = _thermal(args)
    opts = dict(_diagnosis_options(args), thermal=thermal or None, standard=standard)
    results, sources = {}, {}
    if args.simulate is not None:
        m = _machine(args.machine)
        _check_step(args.step, 360.0)
        for plane in ("XY", "YZ", "ZX"):
            plan = dbb.planar_plan(m, plane, args.radius, step=args.step, setup_prefix=plane)
            ds = simulate(m, plan, errors=_values(args.simulate, "--simulate"), sigma={"dbb": args.sigma},
                          seed=args.seed)
            traces = []
            for sid in (f"{plane}-", f"{plane}+"):
                t = dbb.trace_from_dataset(ds, sid)
                t.label = _run_word(t.direction) + f" ({sid})"
                traces.append(t)
            results[plane] = dbb.circular_test(traces, args.radius, plane, args.feed, **opts)
            sources[plane] = [f"simulated setups {plane}- and {plane}+"]
    else:
        for plane in given:
            paths = getattr(args, plane.lower())
            if len(paths) > 2:
                raise ValueError(f"--{plane.lower()}: {len(paths)} files; give one or two (CW and CCW)")
            traces = []
            # --direction names the runs of each plane in the order its files are given
            for path, d in zip(paths, _direction_words(args.direction, len(paths))):
                t = _read_run(path, args, d)
                dbb.check_direction(t, path)
                t.label = _run_word(t.direction) + f" ({os.path.basename(path)})"
                traces.append(t)
            results[plane] = dbb.circular_test(traces, args.radius, plane, args.feed, **opts)
            sources[plane] = list(paths)
    if len(results) < 2:
        raise ValueError(f"{len(results)} plane(s) given; give the runs of two or three planes (--xy, --yz, --zx "
                         "CSV files) or --simulate with --machine")
    vol = dbb.volumetric_evaluation(results)
    print(vol.report())
    grades = {p: r.grade(tolerances) for p, r in results.items()} if tolerances else {}
    for p, g in grades.items():
        print(f"\n  {p}: grade against the tolerances: {g['grade']}")
        for i in g["items"]:
            print(f"    {i['label']:<24}{i['run']:<8}{i['shown']:>22}  tolerance {i['tolerance_shown']:>12}  "
                  f"{i['grade']}")
    if args.out:
        # the one result document; the planes' ISO 230-4 values and diagnoses are its
        # procedure values (no machine-error fit here: `dbb circular --machine` per plane gives one)
        values = {"volumetric": vol.to_dict()}
        if grades:
            values["grades"] = grades
        write_result(args.out, _NO_FIT, "circular", values)
        print(f"\nresult written to {args.out}")
    if args.plot:
        plot_volumetric(vol, args.plot)
        print(f"polar plot written to {args.plot}")

    values = {f"{p} diagnosis {k}": v for p, r in results.items() for k, v in r.diagnosis.items()}
    std = {f"{p} diagnosis {k}": r.diagnosis_std[k] for p, r in results.items() for k in r.diagnosis}
    rc = fit_status("dbb volumetric", [("", _values_verdict(values, std))], args.force,
                    (args.out, args.plot, args.html))
    if args.html:
        reason = "" if rc == EXIT_OK else "the ISO 230-4 values are not usable (see the command's output)"
        path = write_volumetric_report(vol, args.html, grades=grades, usable=rc == EXIT_OK, reason=reason,
                                       scale=args.scale, sources=sources)
        print(f"HTML report written to {path}")
    bad = [f"{p} {i['label']} {i['run']} {i['shown']} > {i['tolerance_shown']}" if i["grade"] == "FAIL" else
           f"{p} {i['label']} not determined (not fitted or below 3σ; --all-diagnoses grades it)"
           for p, g in grades.items() for i in g["items"] if i["grade"] != "PASS"]
    if rc == EXIT_OK and bad:
        word = "FAIL" if any(g["grade"] == "FAIL" for g in grades.values()) else "NOT DETERMINED"
        print(f"fivecal dbb volumetric: {word} against the tolerances: {'; '.join(bad)}", file=sys.stderr)
        return EXIT_FIT
    return rc


# ---- plot ------------------------------------------------------------------
def _plot(args) -> int:
    """One polar panel per dataset setup and bar length (each in its own
    plane), and one for the CSV traces (the plane of --plane): planes and bar
    lengths are never mixed on one chart."""
    panels, csv_traces = [], []
    csv_plane = plane_name(args.plane) if args.plane else "XY"
    for inp in args.inputs:
        if inp.lower().endswith(".json"):
            ds = load_dataset(inp)
            wanted = [s.strip() for s in (args.setup or "").split(",") if s.strip()]
            known = {s for s, _, _ in dbb_groups(ds)}
            for sid in wanted:
                if sid not in known:
                    dbb.trace_from_dataset(ds, sid)  # raises, naming the setups the dataset has
            for sid, length, idx in dbb_groups(ds):
                if wanted and sid not in wanted:
                    continue
                t = dbb.trace_from_dataset(ds.subset(idx), sid)
                if args.plane and plane_name(args.plane) != t.plane:
                    raise ValueError(f"--plane {args.plane}: setup {sid} of {inp} runs in the {t.plane} plane")
                t.label = sid or os.path.basename(inp)
                panels.append({"traces": [t], "nominal_radius": length, "plane": t.plane,
                               "title": f"setup {sid or '(none)'} · plane {t.plane} · bar {length:g} mm",
                               "annotations": [f"{len(idx)} samples ({os.path.basename(inp)})"]})
        else:
            csv_traces.append(dbb.read_trace_csv(inp))
    if csv_traces:
        if args.radius is None:
            raise ValueError("--radius: required for CSV traces (the nominal radius, mm)")
        panels.append({"traces": csv_traces, "nominal_radius": args.radius, "plane": csv_plane,
                       "title": f"CSV traces · plane {csv_plane} · R {args.radius:g} mm"})
    if not panels:
        raise ValueError("no DBB traces to plot")
    if args.scale is not None:
        for p in panels:
            p["scale"] = args.scale
    title = args.title or "DBB trace"
    if len(panels) == 1:
        p = panels[0]
        out = plot_polar(p["traces"], args.out, p["nominal_radius"], f"{title}: {p['title']}", scale=args.scale,
                         plane=p["plane"], annotations=p.get("annotations", ()))
    else:
        out = plot_polar_grid(panels, args.out, title, ncols=2 if len(panels) in (2, 4) else 3)
    print(f"polar plot written to {out} ({len(panels)} panel{'s' if len(panels) != 1 else ''})")
    return 0


def _add_four_step_options(pj) -> None:
    pj.add_argument("dataset", nargs="?", help="dataset JSON with the four DBB setups")
    pj.add_argument("--machine", help="machine JSON (with --simulate or --csv)")
    pj.add_argument("--simulate", metavar="ERRORS",
                    help="simulate the test: NAME=VALUE,... (mm, rad), a JSON file, or 'paper' (Tables 2-3; "
                    "on another pair the carrier gets A's values and the carried axis C's)")
    pj.add_argument("--csv", metavar="SETUP=FILE,...", help="readings of the four steps from CSV files")
    pj.add_argument("--sigma", type=SIGMA, default=0.0003, help="simulated reading noise, mm (default 0.0003)")
    pj.add_argument("--seed", type=SEED, default=1, help="random seed, 0 <= seed < 2^64 (default 1)")
    pj.add_argument("--step", type=POSITIVE, default=1.0, help="deg between samples of a planned test")
    pj.add_argument("--setups", help="setup ids of the four steps (default <carrier>1,<carrier>2,"
                    "<carried>1,<carried>2, e.g. A1,A2,C1,C2)")
    pj.add_argument("--a-pivot-offset", metavar="D1,D2",
                    help="carrier (A) pivot start-position error P0P0' (mm) in its plane axes (A: Y,Z; B: Z,X; "
                    "C: X,Y), eq. 1")
    pj.add_argument("--c-pivot-offset", metavar="D1,D2",
                    help="carried (C) pivot start-position error P0P0' (mm) in its plane axes, eq. 1")
    pj.add_argument("--uniform-angles", action="store_true", help="angles from eq. 2 instead of the commands")
    pj.add_argument("--a-removal", choices=["full", "position", "none"], default="full",
                    help="how the carrier's (A's) errors are removed from the carried axis (default full)")
    pj.add_argument("--no-refer", action="store_true",
                    help="keep the positions in the pivot plane (do not refer them to the axis points)")
    pj.add_argument("--no-engine", action="store_true", help="skip the general engine")
    pj.add_argument("--save-dataset", help="write the simulated / imported dataset here")
    pj.add_argument("--out", help="write the result JSON here (the general engine's machine errors; the "
                    "method's values in its procedure section)")
    pj.add_argument("--plot", help="write polar plots of the four steps (PNG)")
    pj.add_argument("--force", action="store_true", help=_FORCE_HELP)


def _add_run_options(p, which: str) -> None:
    """What reads and corrects a circular test's run files, shared by
    ``dbb circular`` and ``dbb volumetric`` (one plane's files, or each
    plane's): readings-only files, units, the test conditions and the
    thermal compensation, the standard. ``which``: whose directions
    --direction gives."""
    finite = _float_type()
    p.add_argument("--sweep", type=_float_type(10.0), default=None, metavar="DEG",
                   help="readings-only files: the arc the samples span, deg (360, or 360 + feed-in + feed-out "
                   "when the recording includes the overshoot arcs, removed as usual)")
    p.add_argument("--start", type=finite, default=0.0, metavar="DEG",
                   help="readings-only files: angle of the first sample, deg (default 0)")
    p.add_argument("--direction", metavar="cw|ccw[,...]",
                   help=f"run direction of {which} (readings-only files need it unless the file name says cw or "
                   "ccw; two-column files are checked against it)")
    p.add_argument("--units", choices=["mm", "um"], default=None,
                   help="unit of the readings when the file's header names none (default mm)")
    p.add_argument("--angle-units", choices=["deg", "rad"], default=None,
                   help="unit of the angle column when the header names none (default deg)")
    p.add_argument("--sidecar", metavar="JSON",
                   help="test conditions: {\"thermal\": {bar_expansion, bar_temperature, machine_expansion, "
                   "machine_temperature}, \"machine\", \"date\", \"feed\"}")
    p.add_argument("--bar-expansion", type=_expansion, default=None, metavar="ALPHA",
                   help="thermal compensation: the bar's expansion coefficient, 1/K or ppm/K (11.5ppm)")
    p.add_argument("--bar-temperature", type=finite, default=None, metavar="DEGC", help="bar temperature, °C")
    p.add_argument("--machine-expansion", type=_expansion, default=None, metavar="ALPHA",
                   help="thermal compensation: the machine scales' expansion coefficient, 1/K or ppm/K")
    p.add_argument("--machine-temperature", type=finite, default=None, metavar="DEGC",
                   help="machine temperature, °C")
    p.add_argument("--standard", default="ISO 230-4",
                   help="standard the values follow: ISO 230-4 (ASME B5.54, JIS B 6194 and GB/T 17421.4 are "
                   "refused: their definitions are not public, `fivecal docs dbb`)")


def register(sub) -> None:
    """Add the ``dbb`` subcommand group to the main parser's subparsers."""
    FINITE = _float_type()
    RD = argparse.RawDescriptionHelpFormatter
    pd = sub.add_parser("dbb", help="double ball bar tests: four-step, jiang, wang, circular, volumetric, plot",
                        formatter_class=RD,
                        description="Double ball bar tests (`fivecal docs dbb`).",
                        epilog="example:\n  fivecal dbb jiang --machine c600u.json --simulate paper --sigma 0.0003")
    dsub = pd.add_subparsers(dest="dbb_command", required=True)

    pj = dsub.add_parser("jiang", formatter_class=RD,
                         help="Jiang & Cripps four-step test of a pair of rotary axes",
                         description="Four-step DBB test of the two rotary axes (table or head pair: A/C, "
                         "B/C, either order), each without and with the 50 mm extension: eqs. 1-20 of Jiang & "
                         "Cripps 2015, then the same readings through the general engine. The axis nearer the "
                         "foundation (the carrier, the paper's A) is tested first. Input: a dataset with the "
                         "four DBB setups (default <carrier>1 <carrier>2 <carried>1 <carried>2, e.g. A1 A2 C1 "
                         "C2, B1 B2 C1 C2), four CSV traces (angle = axis command in deg, reading in mm) or a "
                         "simulation.",
                         epilog="examples:\n"
                         "  fivecal dbb jiang --machine c600u.json --simulate paper --sigma 0.0003 --plot jiang.png\n"
                         "  fivecal dbb jiang --machine hu40t.json --simulate paper --plot bc.png   (B/C trunnion)\n"
                         "  fivecal dbb jiang dataset.json --c-pivot-offset 0,0.8 --out result.json\n"
                         "  fivecal dbb jiang --machine c600u.json --csv A1=a1.csv,A2=a2.csv,C1=c1.csv,C2=c2.csv")
    _add_four_step_options(pj)
    pj.set_defaults(func=_jiang)

    pf = dsub.add_parser("four-step", formatter_class=RD,
                         help="four-step ball bar test of a rotary pair (as planned by `fivecal plan four-step`)",
                         description="The four-step DBB test of the two rotary axes (the plan of `fivecal plan "
                         "four-step`): the general engine fits every reading (the eight location errors and the "
                         "bar lengths; identify's verdict), and the Jiang & Cripps method (eqs. 1-20) runs beside "
                         "it as a check. The same analysis as `dbb jiang`; its result names the procedure "
                         "four-step.",
                         epilog="examples:\n"
                         "  fivecal dbb four-step --machine vmc0656.json --simulate EY0A=0.01,EX0C=-0.02 "
                         "--out result.json\n"
                         "  fivecal plan four-step vmc0656.json --out plan.json   (add errors, sigma to it)\n"
                         "  fivecal simulate plan.json --out ds.json\n"
                         "  fivecal dbb four-step ds.json --out result.json\n"
                         "  fivecal export linuxcnc result.json --machine vmc0656.json --kins xyzac-trt --out hal")
    _add_four_step_options(pf)
    pf.set_defaults(func=_four_step_cmd)

    pw = dsub.add_parser("wang", formatter_class=RD, help="Wang et al. simultaneous A/C test",
                         description="The A/C path that keeps the table ball on a horizontal circle "
                         "(Table 1 listing), the simulated patterns of single errors, and least-squares "
                         "identification from a whole trace with the identifiability report.",
                         epilog="examples:\n"
                         "  fivecal dbb wang --machine vmc0656.json --every 45\n"
                         "  fivecal dbb wang --machine vmc0656.json --patterns wang_patterns.png\n"
                         "  fivecal dbb wang --machine vmc0656.json --simulate paper --sigma 0.0003 --plot trace.png\n"
                         "  fivecal dbb wang dataset.json --setup W1")
    pw.add_argument("dataset", nargs="?", help="dataset JSON with the Wang trace (identify)")
    pw.add_argument("--machine", help="machine JSON (default: the dataset's machine)")
    pw.add_argument("--table-ball", metavar="X,Y,Z", help="table ball, workpiece frame (mm); default 0,150,130")
    pw.add_argument("--radius", type=POSITIVE, default=80.0, help="circle radius (mm), default 80")
    pw.add_argument("--height", type=FINITE, default=60.0,
                    help="spindle ball above the circle plane (mm), default 60 (100 mm bar)")
    pw.add_argument("--every", type=POSITIVE, default=45.0, help="table rows every N deg (default 45)")
    pw.add_argument("--patterns", metavar="PNG", help="write the single-error patterns (polar plots)")
    pw.add_argument("--pattern-errors", metavar="ERRORS", help="errors for --patterns (default 10 µm, 50 µrad)")
    pw.add_argument("--simulate", metavar="ERRORS", help="simulate a trace: NAME=VALUE,..., a JSON file or 'paper'")
    pw.add_argument("--sigma", type=SIGMA, default=0.0003, help="simulated reading noise, mm")
    pw.add_argument("--seed", type=SEED, default=1, help="random seed, 0 <= seed < 2^64 (default 1)")
    pw.add_argument("--setup", default="W1", help="DBB setup id of the trace (default W1)")
    pw.add_argument("--estimate", help="errors to identify (default EX0C,EY0C,EZ0C,EA0C)")
    pw.add_argument("--save-dataset", help="write the simulated dataset here")
    pw.add_argument("--out", help="write the identification JSON here")
    pw.add_argument("--plot", help="write the polar plot of the trace (PNG)")
    pw.add_argument("--force", action="store_true", help=_FORCE_HELP)
    pw.set_defaults(func=_wang)

    pc = dsub.add_parser("circular", formatter_class=RD, help="planar circular test (ISO 230-4, diagnosis)",
                         description="ISO 230-4 circular deviation G, radial deviation F, hysteresis H, "
                         "least-squares centre and radius, and a least-squares diagnosis of centre offset, "
                         "scale mismatch, squareness, backlash per axis, servo mismatch, reversal spikes, "
                         "lateral play, straightness, radial play and cyclic error, ranked by contribution "
                         "to circularity. Feed-in/feed-out arcs beyond 360 deg are removed first. Input: CSV "
                         "files (angle deg, reading mm; CW and/or CCW), a dataset, or a simulation.",
                         epilog="examples:\n"
                         "  fivecal dbb circular cw.csv ccw.csv --radius 100 --plane XY --feed 1000 --plot xy.png\n"
                         "  fivecal dbb circular --machine c600u.json --simulate EXX1=2e-5,EC0Y=3e-5,EXXb=0.002 "
                         "--radius 100\n"
                         "  fivecal dbb circular ren_cw.txt ren_ccw.txt --radius 100 --sweep 360 --units um "
                         "(readings only)\n"
                         "  fivecal dbb circular cw.csv ccw.csv --radius 100 --tolerance G=15um,backlash=4um "
                         "--html report/\n"
                         "  fivecal dbb circular cw.csv ccw.csv --radius 100 --sidecar conditions.json "
                         "(thermal compensation)\n"
                         "  fivecal dbb circular test.b5r   (Renishaw's diagnostics, as written)")
    pc.add_argument("runs", nargs="*", help="run files: CSV (angle, reading) or readings only with --sweep, one "
                    "or two runs; or one Renishaw .b5r file (its diagnostics)")
    pc.add_argument("--radius", type=POSITIVE, default=None,
                    help="nominal radius = bar length (mm); required except for a .b5r file (which names it)")
    _add_run_options(pc, "each file")
    pc.add_argument("--html", metavar="DIR", help="write the HTML report (verdict, polar plot, diagnosis) here")
    pc.add_argument("--scale", type=POSITIVE, default=None,
                    help="polar plot ring spacing in µm (default automatic; stated on the plot)")
    pc.add_argument("--plane", default="XY", help="XY, YZ or ZX (angles from the first axis to the second)")
    pc.add_argument("--feed", type=POSITIVE, default=None, help="feed (mm/min): servo mismatch as a time")
    pc.add_argument("--dataset", help="dataset JSON instead of CSV files")
    pc.add_argument("--setups", default="P-,P+", help="setup ids of the runs in --dataset")
    pc.add_argument("--machine", help="machine JSON: for --simulate, and with CSV runs for the machine-error fit "
                    "(identify's, the result's parameters)")
    pc.add_argument("--tolerance", action="append", metavar="NAME=VALUE",
                    help="grade ISO 230-4 values: G (circular deviation of each run), F (largest |radial "
                    "deviation|), H (hysteresis), and diagnoses by name, kind or axis letter (backlash=4um, "
                    "backlash.X+=4um, squareness=20urad, scale_mismatch=10um/m, cyclic_error=2um), with a unit; "
                    "a bare number is in the file unit (mm, rad); FAIL or a toleranced diagnosis not determined "
                    "exits 1")
    pc.add_argument("--simulate", metavar="ERRORS", help="simulate CW and CCW runs with these errors")
    pc.add_argument("--sigma", type=SIGMA, default=0.0003, help="simulated reading noise, mm")
    pc.add_argument("--seed", type=SEED, default=1, help="random seed, 0 <= seed < 2^64 (default 1)")
    pc.add_argument("--step", type=POSITIVE, default=1.0, help="deg between simulated samples")
    pc.add_argument("--out", help="write the result JSON here")
    pc.add_argument("--plot", help="write the CW/CCW polar plot (PNG)")
    pc.add_argument("--force", action="store_true", help=_FORCE_HELP)
    _add_diagnosis_options(pc)
    pc.set_defaults(func=_circular)

    pv = dsub.add_parser("volumetric", formatter_class=RD,
                         help="three-plane circular tests (XY, YZ, ZX): results by plane and combined",
                         description="Circular tests of two or three planes with one radius, each read, "
                         "corrected and analysed as 'dbb circular' does, then combined: the largest circular "
                         "deviation, the width of the shell holding every plane's centred trace (volumetric), "
                         "the scale mismatch closure and each axis' backlash from the planes that see it. "
                         "Tolerances grade every plane; one verdict covers them all.",
                         epilog="examples:\n"
                         "  fivecal dbb volumetric --xy xy_cw.csv xy_ccw.csv --yz yz_cw.csv yz_ccw.csv "
                         "--zx zx_cw.csv zx_ccw.csv --radius 100 --plot vol.png\n"
                         "  fivecal dbb volumetric --xy xy_cw.txt xy_ccw.txt --yz yz_cw.txt yz_ccw.txt --radius 100 "
                         "--sweep 360 --direction cw,ccw --units um   (readings only)\n"
                         "  fivecal dbb volumetric ... --radius 100 --sidecar conditions.json --tolerance G=15um "
                         "--html report/\n"
                         "  fivecal dbb volumetric --machine c600u.json --simulate EXX1=2e-5,EZZb=0.002 "
                         "--radius 100")
    for plane in ("xy", "yz", "zx"):
        pv.add_argument(f"--{plane}", nargs="+", metavar="FILE",
                        help=f"{plane.upper()} runs: one or two files, two columns (angle, reading) or readings "
                        "only with --sweep")
    pv.add_argument("--radius", type=POSITIVE, required=True, help="nominal radius = bar length (mm)")
    _add_run_options(pv, "each plane's files, in the order they are given (the same for every "
                     "plane)")
    pv.add_argument("--tolerance", action="append", metavar="NAME=VALUE",
                    help="grade every plane's ISO 230-4 values and diagnoses, as for 'dbb circular' (G=15um, "
                    "backlash=4um, squareness=20urad, ...), with a unit; a bare number is in the file unit (mm, rad); "
                    "FAIL in any plane, or a toleranced diagnosis not determined, exits 1")
    pv.add_argument("--html", metavar="DIR",
                    help="write the HTML report here: the combined page and each plane's report in DIR/<plane>/")
    pv.add_argument("--scale", type=POSITIVE, default=None,
                    help="polar plot ring spacing in µm of the planes' reports (default automatic)")
    pv.add_argument("--feed", type=POSITIVE, default=None, help="feed (mm/min)")
    pv.add_argument("--machine", help="machine JSON for --simulate")
    pv.add_argument("--simulate", metavar="ERRORS", help="simulate CW and CCW runs in the three planes")
    pv.add_argument("--sigma", type=SIGMA, default=0.0003, help="simulated reading noise, mm")
    pv.add_argument("--seed", type=SEED, default=1, help="random seed, 0 <= seed < 2^64 (default 1)")
    pv.add_argument("--step", type=POSITIVE, default=1.0, help="deg between simulated samples")
    pv.add_argument("--out", help="write the result JSON here")
    pv.add_argument("--plot", help="write the three polar plots (PNG)")
    pv.add_argument("--force", action="store_true", help=_FORCE_HELP)
    _add_diagnosis_options(pv)
    pv.set_defaults(func=_volumetric)

    pp = dsub.add_parser("plot", formatter_class=RD, help="polar plot of DBB traces",
                         description="Polar plot of one or more traces: CSV files (angle deg, reading mm) "
                         "or the DBB setups of a dataset JSON. Each dataset setup gets its own panel "
                         "(its plane and bar length from the data); the CSV traces share one panel in "
                         "the --plane plane. Angles: counter-clockwise from the first axis of the "
                         "plane towards the second, seen from the positive normal (XY: from +X, seen "
                         "from +Z); CSV angles are read in that convention.",
                         epilog="examples:\n  fivecal dbb plot cw.csv ccw.csv --radius 100 --out xy.png\n"
                         "  fivecal dbb plot dataset.json --setup W1 --out w1.png")
    pp.add_argument("inputs", nargs="+", help="CSV files and/or dataset JSON files")
    pp.add_argument("--radius", type=POSITIVE, default=None,
                    help="nominal radius of the CSV traces (mm); dataset setups use their bar length")
    pp.add_argument("--setup", help="dataset setups to plot (comma separated; default all)")
    pp.add_argument("--plane", default=None, help="plane of the CSV traces: XY, YZ or ZX (default XY)")
    pp.add_argument("--scale", type=POSITIVE, default=None, help="ring spacing in µm (default automatic)")
    pp.add_argument("--title", default=None)
    pp.add_argument("--out", required=True, help="PNG to write")
    pp.set_defaults(func=_plot)
