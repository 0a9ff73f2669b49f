"""Command line: fivecal identify | simulate | compensate | design | sphere | demo | import.

Errors are one clear line on stderr, never a traceback (set FIVECAL_DEBUG=1
to see one). Exit status: 0 success, 1 the fit failed / did not converge / is
not usable, 2 bad input or a refused request, 3 internal error (a bug). Long runs draw a progress bar on stderr
when it is a terminal (FIVECAL_PROGRESS=1 forces it, =0 silences it).
"""
from __future__ import annotations

import argparse
import io
import math
import os
import re
import signal
import sys
import time
import warnings

from . import __version__, schema


def _identify(args) -> int:
    import warnings

    from .dataset import load_dataset
    from .identification import identify

    from .progress import busy

    from .history.cli import identify_history

    hist = identify_history(args)
    ds = load_dataset(args.dataset)
    with busy(f"fitting {len(ds)} observations"), warnings.catch_warnings():
        warnings.simplefilter("ignore", category=_fit_warning())  # said once below, in one line
        result = identify(ds, estimate=args.estimate, fix=args.fix, robust=args.robust,
                          allow_unidentifiable=args.allow_unidentifiable,
                          variance_components=args.variance_components)
    print(result.report())
    # An unusable fit is still written (marked so in the report and refused by
    # `fivecal compensate`): it is what one inspects to find out why.
    if args.out:
        result.save(args.out)
        print(f"\nresult written to {args.out}")
    if args.report:
        from .report.document import write_report

        path = write_report(result, args.report, title=f"fivecal identification — {os.path.basename(args.dataset)}",
                            summary=f"dataset {args.dataset}, estimate {args.estimate}"
                                    + (f", fixed {args.fix}" if args.fix else ""),
                            history=hist)
        print(f"\nreport: {os.path.abspath(path)} (with result.json and the plots as PNG)")
    if hist is not None and args.record:
        from .history.cli import record_identify

        record_identify(args, result, hist)
    a = result.assessment()
    if not a.usable:
        written = [x for x in (args.out, args.report) if x]
        print(f"fivecal identify: not usable: {a.reason}"
              + (f" ({' and '.join(written)} written, marked not usable)" if written else ""),
              file=sys.stderr)
        return EXIT_FIT
    if hist is not None and (hist.tolerances or hist.volumetric_tolerance is not None):
        from .history.cli import grade_identify

        # a machine out of tolerance must stop a script as `history compare` does,
        # not only turn a box red in the report
        if grade_identify(result, hist) == "fail":
            print("fivecal identify: FAIL against the tolerances (see the grade above)", file=sys.stderr)
            return EXIT_FIT
    return EXIT_OK


def _convert(args) -> int:
    from .dataset import load_dataset, save_dataset

    ds = load_dataset(args.dataset)
    save_dataset(ds, args.out)
    fmt = "Parquet" if args.out.lower().endswith((".parquet", ".pq")) else "JSON"
    print(f"{args.dataset} -> {args.out}: {len(ds)} observations ({fmt})")
    return EXIT_OK


def _fit_warning():
    from .guards import FitWarning

    return FitWarning


def _values_verdict(values, std=None, converged: bool = True, iterations=None):
    """The :class:`fivecal.guards.Assessment` of a fit that gives plain
    values (and standard uncertainties) rather than a Result: judged on
    convergence and finiteness like ``identify``'s."""
    from . import guards

    params = {n: {"value": v, **({"std": std[n]} if std and n in std else {})} for n, v in values.items()}
    return guards.assess({"parameters": params, "converged": bool(converged), "iterations": iterations})


def fit_status(command: str, verdicts, force: bool = False, written=()) -> int:
    """The exit status of a command that fits, judged as ``fivecal identify``
    judges its fit: 0 when every verdict is usable; otherwise one line on
    stderr saying why and 1 (the outputs are still written, to inspect) or,
    with ``--force``, the same line as a warning and 0. ``verdicts``: pairs
    (what, Assessment)."""
    why = [f"{what}: {a.reason}" if what else a.reason for what, a in verdicts if not a.usable]
    if not why:
        return EXIT_OK
    written = [x for x in written if x]
    if force:
        print(f"fivecal {command}: warning: not usable: {'; '.join(why)} (used anyway: --force)", file=sys.stderr)
        return EXIT_OK
    print(f"fivecal {command}: not usable: {'; '.join(why)}"
          + (f" ({' and '.join(written)} written, to inspect)" if written else "")
          + "; --force accepts it", file=sys.stderr)
    return EXIT_FIT


def _read_json(path: str, what: str):
    from .files import read_json

    return schema.validate(read_json(path, what), schema.guess_kind(what), path)


def _axis_values(text: str, option: str) -> dict:
    out = {}
    for item in [t for t in text.replace(";", ",").split(",") if t.strip()]:
        if "=" not in item:
            raise ValueError(f"{option}: expected AXIS=VALUE pairs like X=0,Z=100, got '{item.strip()}'")
        k, v = item.split("=", 1)
        k = k.strip().upper()
        if len(k) != 1 or not k.isalpha():
            raise ValueError(f"{option}: '{k}' is not an axis letter (AXIS=VALUE pairs like X=0,Z=100)")
        if k in out:
            raise ValueError(f"{option}: axis {k} given twice")
        try:
            x = float(v)
        except ValueError:
            raise ValueError(f"{option}: {k}: '{v.strip()}' is not a number") from None
        if not math.isfinite(x):
            raise ValueError(f"{option}: {k}: '{v.strip()}' is not a finite number")
        out[k] = x
    return out


# ---- option types: a bad value is refused by argparse naming the option -----
def _integer_type(low: int, high=None, what: str = "an integer"):
    def parse(text: str) -> int:
        t = text.strip()
        try:
            v = int(t, 10)
        except ValueError:
            try:
                f = float(t)
            except ValueError:
                f = float("nan")
            if not (math.isfinite(f) and f == math.floor(f)):
                raise argparse.ArgumentTypeError(f"expected {what}, got '{text}'") from None
            v = int(f)
        if v < low or (high is not None and v >= high):
            bound = f">= {low}" if high is None else f"in {low} .. {high - 1}"
            raise argparse.ArgumentTypeError(f"expected {what} {bound}, got '{text}'")
        return v

    return parse


def _float_type(low=None, high=None, low_open: bool = False, what: str = "a number"):
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got '{text}'") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"expected a finite number, got '{text}'")
        if low is not None and (v < low or (low_open and v == low)):
            raise argparse.ArgumentTypeError(f"must be {'>' if low_open else '>='} {low:g}, got '{text}'")
        if high is not None and v >= high:
            raise argparse.ArgumentTypeError(f"must be < {high:g}, got '{text}'")
        return v

    return parse


SEED = _integer_type(0, 2 ** 64, "an integer seed")
COUNT = _integer_type(0)

# ---- sizes: how much a count or a step makes a command allocate --------------
#: The most samples, plan entries, program points or Monte Carlo trials one
#: option may ask for. A real test records a few thousand; a typo (-n 1000000000,
#: --step 1e-6) is refused naming its option (exit 2), never a MemoryError.
MAX_SAMPLES = 1_000_000      # samples of one simulated trace (the core's bound as well)
MAX_PLAN_ENTRIES = 100_000   # entries of a written plan (each a JSON object) or program points
MAX_TRIALS = 1_000_000       # JCGM 101 asks for about 10^6 trials for a 95 % interval
MAX_WORKERS = 1024           # threads or worker processes on one machine (the core's thread bound)


def check_size(option: str, count: float, what: str = "plan entries", limit: int = MAX_PLAN_ENTRIES) -> int:
    """``count`` (what ``option`` asks for) as an int; refused naming ``option`` above ``limit``."""
    if not count <= limit:
        raise ValueError(f"{option}: asks for {count:.4g} {what}; at most {limit}")
    return int(count)


def check_step(option: str, step: float, span: float, unit: str = "deg", what: str = "plan entries",
               per: int = 1, limit: int = MAX_PLAN_ENTRIES) -> int:
    """The number of samples ``step`` apart over ``span`` (times ``per``, e.g.
    one set per test); refused naming ``option`` above ``limit``."""
    if not (step > 0 and math.isfinite(step)):
        raise ValueError(f"{option}: expected a step > 0 {unit}, got {step}")
    count = (math.floor(abs(span) / step + 1e-9) + 1) * per
    if not count <= limit:
        raise ValueError(f"{option}: {step:g} {unit} gives {count:.4g} {what} over {abs(span):g} {unit}"
                         f"{f' ({per} times)' if per > 1 else ''}; at most {limit} (use a larger step)")
    return int(count)


def count_type(low: int = 0, limit: int = MAX_PLAN_ENTRIES, what: str = "an integer"):
    """An argparse type: an integer from ``low`` to ``limit`` (both included)."""
    return _integer_type(low, limit + 1, what)


TRIALS = count_type(2, MAX_TRIALS, "a number of trials")
SIGMA = _float_type(0.0, what="a noise level in mm")
POSITIVE = _float_type(0.0, low_open=True)
PROBABILITY = _float_type(0.0, 1.0, low_open=True, what="a probability")


def _limits(text: str) -> tuple:
    """--max-correction MM[,DEG]: the plausibility limits; 'off' switches them off."""
    from .compensation import MAX_CORRECTION, MAX_CORRECTION_DEG

    if text is None:
        return MAX_CORRECTION, MAX_CORRECTION_DEG
    parts = [t.strip() for t in text.split(",")]
    if len(parts) > 2 or not all(parts):
        raise ValueError(f"--max-correction: expected MM or MM,DEG (e.g. 0.5 or 0.5,0.2) or 'off', got '{text}'")
    out = []
    for t in parts:
        if t.lower() in ("off", "none"):
            out.append(None)
            continue
        try:
            v = float(t)
        except ValueError:
            raise ValueError(f"--max-correction: '{t}' is not a number") from None
        if not v > 0 or v != v or v == float("inf"):
            raise ValueError(f"--max-correction: {t}: expected a positive limit")
        out.append(v)
    return (out[0], out[1] if len(out) == 2 else (MAX_CORRECTION_DEG if out[0] is not None else None))


def _read_machine(path):
    """The machine of a machine file, or of a dataset file (its "machine")."""
    from .machine import Machine

    doc = _read_json(path, "the machine")
    if isinstance(doc, dict) and "observations" in doc and isinstance(doc.get("machine"), dict):
        doc = doc["machine"]  # a dataset file: use its machine
    try:
        return Machine.from_dict(doc)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def _compensate(args) -> int:
    from .compensation import compensate_gcode_file, usable_errors, write_error_table

    machine = _read_machine(args.machine)
    max_mm, max_deg = _limits(args.max_correction)
    # Refuses a result that did not converge, is not finite, failed the chi-square
    # test or left requested parameters undetermined, unless --force.
    errors = usable_errors(args.result, machine, args.force, args.result)
    if not args.program and not args.table:
        raise ValueError("nothing to do: give a PROGRAM (with --out) and/or --table FILE")
    if args.table:
        kinds = ("location", "backlash", "motion") if args.table_all else ("location",)
        rows = write_error_table(args.table, args.result, machine, kinds=kinds, force=args.force)
        print(f"{len(rows)} identified {'machine' if args.table_all else 'location'} errors of "
              f"{machine.name} written to {args.table} (sign convention in its header)")
    if args.program:
        if not args.out:
            raise ValueError("--out OUT.nc is required with a PROGRAM")
        if os.path.abspath(args.out) == os.path.abspath(args.program):
            raise ValueError(f"--out {args.out}: refusing to overwrite the input program")
        tip = None
        if args.tool_tip:
            try:
                tip = [float(x) for x in args.tool_tip.split(",")]
            except ValueError:
                raise ValueError(f"--tool-tip: expected x,y,z in mm, got '{args.tool_tip}'") from None
        res = compensate_gcode_file(args.program, args.out, machine, errors,
                                    start=_axis_values(args.start, "--start") if args.start else None,
                                    work_offset=_axis_values(args.work_offset, "--work-offset")
                                    if args.work_offset else None,
                                    orientation=not args.position_only, tool_tip=tip,
                                    min_decimals=args.decimals, progress=None,
                                    max_correction=max_mm, max_correction_deg=max_deg, force=args.force)
        print(f"{args.program}: {res.summary()}")
        print(f"compensated program written to {args.out}")
    return 0


def _simulate(args) -> int:
    from .dataset import save_dataset
    from .machine import Machine
    from .simulation import simulate

    spec = _read_json(args.spec, "the simulation spec")
    if not isinstance(spec, dict):
        raise ValueError(f"{args.spec}: expected a JSON object with machine, plan, errors, ...")
    machine = spec.get("machine")
    if isinstance(machine, str):  # a path relative to the spec file
        machine = Machine.load(os.path.join(os.path.dirname(os.path.abspath(args.spec)), machine))
    if machine is None:
        raise ValueError(f"{args.spec}: 'machine' missing (a machine object or a path)")
    probe = spec.get("probe") or {}
    if not isinstance(probe, dict):
        raise ValueError(f"{args.spec}: probe: expected an object like {{\"tip_radius\": 3.0}}")
    try:
        ds = simulate(machine, spec.get("plan", []), errors=spec.get("errors"), artefact=spec.get("artefact"),
                      tip_radius=probe.get("tip_radius", 0.0),
                      sigma=args.sigma if args.sigma is not None else spec.get("sigma", 0.0),
                      seed=args.seed if args.seed is not None else spec.get("seed", 0), setup=spec.get("setup"))
    except ValueError as e:
        raise ValueError(f"{args.spec}: {e}") from None
    save_dataset(ds, args.out)
    print(f"simulated {len(ds)} observations on {ds.machine.name}; dataset written to {args.out}")
    return 0


def _demo(args) -> int:
    from .demo import run_demo

    run_demo(args.out, seed=args.seed)
    return 0


def _docs(args) -> int:
    from . import manual

    if args.name:
        print(manual.doc_path(args.name))
        return EXIT_OK
    names = manual.doc_names()
    if not names:
        manual.doc_path("")  # raises: says the documentation is not installed
    print(f"fivecal documentation in {manual.docs_dir()} (`fivecal docs NAME` prints a page's path):")
    for n in names:
        print(f"  {n:<28} {os.path.basename(manual.doc_path(n))}")
    return EXIT_OK


def _design_spec(path: str) -> dict:
    from .machine import Machine

    spec = _read_json(path, "design spec")
    if not isinstance(spec, dict):
        raise ValueError(f"{path}: expected a JSON object (a simulation spec with a candidate plan)")
    machine = spec.get("machine")
    if isinstance(machine, str):  # a path relative to the spec file
        machine = Machine.load(os.path.join(os.path.dirname(os.path.abspath(path)), machine))
    if machine is None:
        raise ValueError(f"{path}: 'machine' missing (a machine object or a path)")
    spec["machine"] = Machine.from_dict(machine).to_dict()
    return spec


def _design(args) -> int:
    from . import design

    spec = _design_spec(args.spec)
    machine, artefact = spec["machine"], spec.get("artefact") or {}
    probe = spec.get("probe") or {}
    if not isinstance(probe, dict) or not isinstance(artefact, dict):
        raise ValueError(f"{args.spec}: {'probe' if not isinstance(probe, dict) else 'artefact'}: expected an object")
    try:
        tip_radius = float(probe.get("tip_radius", 0.0))
    except (TypeError, ValueError):
        raise ValueError(f"{args.spec}: probe.tip_radius: expected a number") from None
    groups = None
    if spec.get("candidates"):
        c = spec["candidates"]
        if not isinstance(c, dict):
            raise ValueError(f"{args.spec}: candidates: expected an object with 'indexations' (and 'limits', "
                             "'min_dot', ...)")
        plan, groups = design.candidate_plan(machine, artefact, c.get("indexations", []), tip_radius=tip_radius,
                                             limits=c.get("limits"), min_dot=c.get("min_dot", -0.02),
                                             targets=c.get("targets"), sphere_normals=c.get("sphere_normals"))
        if not plan:
            raise ValueError(f"{args.spec}: no accessible candidate touch at the given indexations")
    else:
        plan = spec.get("plan")
        if not plan:
            raise ValueError(f"{args.spec}: give the candidate touches as 'plan' or 'candidates'")
    try:
        ks = [int(x) for x in str(args.k).split(",") if x.strip()]
    except ValueError:
        ks = []
    if not ks or min(ks) < 1:
        raise ValueError(f"-k: expected a number of indexations (>= 1) or a comma-separated list, got '{args.k}'")
    check_size("-k", max(ks), "indexations")
    try:
        required = [int(x) for x in args.require.split(",") if x.strip()] if args.require else None
    except ValueError:
        raise ValueError(f"--require: expected comma-separated visit numbers, got '{args.require}'") from None
    if required:
        check_size("--require", max(abs(r) for r in required), "(a visit number)")
    pool = design._as_dataset(plan, machine, artefact, tip_radius, None)
    rows = None
    for i, k in enumerate(ks):
        d = design.design_plan(pool, k, args.estimate, groups=groups, fix=args.fix, required=required,
                               criterion=args.criterion, method=args.method, max_touches=args.max_touches,
                               sigma=args.sigma, progress=False if args.no_progress else "auto")
        d.plan = [plan[j] for j in d.observations]
        if len(ks) == 1:
            print(d.report())
        else:
            if rows is None:
                print(f"fivecal design ({args.criterion}, estimate {args.estimate}): candidate pool "
                      f"{len(set(d.pool_groups))} indexations, {d.reference.n_observations} touches")
                rows = [{"plan": "complete", "indexations": len(set(d.pool_groups)),
                         "touches": d.reference.n_observations, "condition_number": d.reference.condition_number,
                         "d_criterion": d.reference.d_criterion, "d_std": d.reference.d_std}]
            rows.append({"plan": f"designed k={k}", "indexations": len(d.groups), "touches": d.quality.n_observations,
                         "condition_number": d.quality.condition_number, "d_criterion": d.quality.d_criterion,
                         "d_std": d.quality.d_std})
        if args.out:
            out = args.out.replace("{k}", str(k)) if "{k}" in args.out or len(ks) == 1 else \
                f"{os.path.splitext(args.out)[0]}_k{k}{os.path.splitext(args.out)[1] or '.json'}"
            result = dict(spec)
            result.pop("candidates", None)
            result["plan"] = d.plan
            finite = lambda x: x if x == x and abs(x) != float("inf") else None  # noqa: E731
            result["design"] = {"criterion": args.criterion, "estimate": args.estimate, "k": k,
                                "condition_number": finite(d.quality.condition_number),
                                "candidate_condition_number": finite(d.reference.condition_number),
                                "groups": d.groups}
            from ._json import plain
            from .files import write_json

            write_json(out, plain(result, "design"))
            print(f"designed plan (a simulation spec) written to {out}")
    if rows is not None:
        print(design.format_comparison(rows))
    return 0


def _sphere_check(args) -> int:
    from .dataset import load_dataset
    from .files import write_text
    from .procedures import sphere_check

    ds = load_dataset(args.dataset)
    check = sphere_check.evaluate(ds, previous=args.previous, calibrated_stylus=not args.free_stylus,
                                  backlash=False if args.no_backlash else None, sphere=args.sphere)
    print(check.report())
    if args.out:
        write_text(args.out, sphere_check.to_json(check) + "\n")
        print(f"\ncheck written to {args.out} (give it as --previous to the next check)")
    return fit_status("sphere-check", [("the pivot fit", check.result.assessment())], args.force,
                      written=[args.out])


def _rtest(args) -> int:
    from .dataset import load_dataset
    from .procedures import rtest

    out = rtest.evaluate(load_dataset(args.dataset), identify=not args.no_identify)
    tol = None if args.tolerance is None else args.tolerance * 1e-3
    print(out.report(tol))
    verdicts = [("the location-error fit", out.result.assessment())] if out.result is not None else []
    status = fit_status("rtest", verdicts, args.force)
    failed = tol is not None and not all(t.passes(tol) for t in out.tests.values())
    return EXIT_FIT if failed and status == EXIT_OK else status


def _sphere(args) -> int:
    from .procedures.sphere_test import format_sphere_tests, sphere_test
    from .dataset import load_dataset
    from .guards import require_usable

    ds = load_dataset(args.dataset)
    tests = {"nominal model": sphere_test(ds, None, args.sphere)}
    if args.values:
        res = _read_json(args.values, "result")
        # A result that did not converge, is not finite, inadequate or
        # undetermined would make the "identified model" column a confident
        # figure of nothing: refused as `fivecal compensate` refuses it.
        require_usable(res, args.force, args.values)
        params = res.get("parameters", res) if isinstance(res, dict) else None
        if not isinstance(params, dict):
            raise ValueError(f"{args.values}: expected a result JSON with 'parameters'")
        values = {}
        for k, v in params.items():
            v = v.get("value") if isinstance(v, dict) else v
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{args.values}: parameters.{k}: expected a finite number as the value")
            values[k] = v
        tests["identified model"] = sphere_test(ds, values, args.sphere)
    t0 = next(iter(tests.values()))
    print(f"fivecal sphere test: sphere {t0.sphere}, {len(t0.observations)} touches on {ds.machine.name}")
    print(format_sphere_tests(tests))
    if len(tests) == 2:
        a, b = (t.fit.out_of_sphericity for t in tests.values())
        print(f"\nout of sphericity reduced {a / b:.3g}-fold by the identified model" if b > 0 else "")
    return fit_status("sphere", [(f"sphere fit ({name})",
                                  _values_verdict({"center.x": t.fit.center[0], "center.y": t.fit.center[1],
                                                   "center.z": t.fit.center[2], "radius": t.fit.radius,
                                                   "out of sphericity": t.fit.out_of_sphericity},
                                                  converged=t.fit.converged, iterations=t.fit.iterations))
                                 for name, t in tests.items()], args.force)


def _uncertainty(args) -> int:
    from . import uncertainty
    from .machine import Machine

    def load(path):
        from .files import read_json

        d = read_json(path, "spec or dataset")
        d = schema.validate(d, "dataset" if isinstance(d, dict) and "observations" in d else "spec", path)
        if isinstance(d, dict) and isinstance(d.get("machine"), str):  # a path relative to the file
            d["machine"] = Machine.load(os.path.join(os.path.dirname(os.path.abspath(path)),
                                                     d["machine"])).to_dict()
        return d

    import warnings

    inputs = [load(p) for p in args.inputs]
    if len(inputs) == 1:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", category=_fit_warning())  # judged below, in one line
            mc = uncertainty.monte_carlo(inputs[0], args.estimate, trials=args.trials, threads=args.threads,
                                         seed=args.seed, progress=not args.no_progress,
                                         probability=args.probability, significant_digits=args.digits,
                                         fix=args.fix, sigma=args.sigma)
        print(mc.report())
        if args.plot:
            mc.plot(args.plot)
            print(f"\nhistograms written to {args.plot}")
        if args.out:
            mc.save(args.out, include_samples=args.samples)
            print(f"result written to {args.out}")
        verdicts = []
        if mc.fit is not None:  # a dataset: the noise is drawn around its fit
            verdicts.append(("the fit of the dataset", mc.fit.assessment()))
        verdicts.append(("Monte Carlo", _values_verdict(mc.mean, mc.std, converged=mc.used > 0)))
        if mc.used == 0:
            verdicts[-1][1].reason = f"none of the {mc.trials} trials converged"
        return fit_status("uncertainty", verdicts, args.force, (args.out, args.plot))
    try:
        days = [int(x) for x in args.days.split(",")] if args.days else None
    except ValueError:
        raise ValueError(f"--days: expected one integer day label per INPUT, comma separated (e.g. 1,1,2,2), "
                         f"got '{args.days}'") from None
    if days is not None and len(days) != len(inputs):
        raise ValueError(f"--days: {len(days)} labels for {len(inputs)} cycles")
    u = uncertainty.gum_input_covariance(inputs, args.estimate, day=days, pooling=args.pool,
                                         probability=args.probability, k=args.k, fix=args.fix)
    print(u.report())
    if args.out:
        u.save(args.out)
        print(f"\nresult written to {args.out}")
    # The sensitivities come from the fit of the first cycle: judged as
    # `fivecal identify` would judge it.
    from .identification import identify

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=_fit_warning())  # said once, in one line
        reference = identify(inputs[0], args.estimate, fix=args.fix)
    return fit_status("uncertainty", [(f"the fit of {args.inputs[0]}", reference.assessment()),
                                      ("GUM", _values_verdict(u.values, u.std))], args.force, (args.out,))


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that outputs are rolled back."""


def _on_sigterm(signum, frame):
    raise _Terminated()


class _PipeSafeStdout(io.TextIOBase):
    """stdout that goes quiet when the reader closes the pipe (``fivecal ... |
    head``): the command carries on (its files are still written) and exits
    with its own status, without a "Broken pipe" message."""

    def __init__(self, stream):
        self._stream = stream
        self._closed_pipe = False

    def _silence(self) -> None:
        self._closed_pipe = True
        # The Python docs recipe: point the descriptor at devnull so the
        # interpreter's final flush does not fail again.
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self._stream.fileno())
            finally:
                os.close(devnull)
        except (OSError, ValueError, io.UnsupportedOperation):
            pass

    def write(self, text):
        if not self._closed_pipe:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._silence()
        return len(text)

    def flush(self):
        if not self._closed_pipe:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._silence()

    def writable(self):
        return True

    def isatty(self):
        return self._stream.isatty()

    def fileno(self):
        return self._stream.fileno()

    @property
    def encoding(self):
        return getattr(self._stream, "encoding", "utf-8")


def _existing(path) -> bool:
    return isinstance(path, str) and os.path.exists(path)


def _declared_files(args):
    """(inputs, outputs) named on the command line, as (label, path) pairs."""
    inputs, outputs = [], []
    for attr, label in (("dataset", "dataset"), ("spec", "spec"), ("result", "result"), ("machine", "machine"),
                        ("program", "program"), ("values", "--values")):
        v = getattr(args, attr, None)
        if _existing(v):
            inputs.append((label, v))
    for attr, label in (("inputs", "INPUT"), ("runs", "run")):
        for v in getattr(args, attr, None) or []:
            if _existing(v):
                inputs.append((label, v))
    for attr in ("simulate", "pattern_errors"):
        v = getattr(args, attr, None)
        if _existing(v):
            inputs.append((f"--{attr.replace('_', '-')}", v))
    csv = getattr(args, "csv", None)
    if isinstance(csv, str):
        for part in csv.split(","):
            if "=" in part and _existing(part.split("=", 1)[1].strip()):
                inputs.append(("--csv", part.split("=", 1)[1].strip()))
    if args.command == "demo":
        return inputs, []
    for attr in ("out", "table", "plot", "patterns", "save_dataset"):
        v = getattr(args, attr, None)
        if isinstance(v, str) and not (attr == "out" and "{k}" in v):
            outputs.append((f"--{attr.replace('_', '-')}", v))
    report = getattr(args, "report", None)
    if isinstance(report, str):
        outputs += [("--report", os.path.join(report, "result.json")), ("--report", os.path.join(report, "report.html"))]
    return inputs, outputs


def _run(args) -> int:
    """The command inside a files.transaction: an output that is an input
    is refused before any work; if the command fails or is interrupted, the
    outputs it wrote are removed (or restored to their previous content)."""
    from . import files

    files.check_outputs(*_declared_files(args))
    old_stdout = sys.stdout
    sys.stdout = _PipeSafeStdout(old_stdout)
    old_term = None
    try:
        old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread: leave the signal alone
        pass
    try:
        # An exception (bad input, Ctrl-C, SIGTERM) rolls the outputs back; a
        # command that ran to its end keeps them, whatever its exit status
        # (a fit that did not converge is still written, and says so).
        with files.transaction():
            rc = args.func(args)
            sys.stdout.flush()
        return rc
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        sys.stdout = old_stdout


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (the subcommand parsers share it),
    and option values that start with '-' taken as values when they are
    numbers: argparse alone takes ``--height -1e-3`` or ``--tool-ball
    -5,0,100`` for an option (only plain ``-0.5`` passes), and a coordinate
    or an offset is negative as often as not. No fivecal option looks like a
    number, so nothing is lost."""

    #: a number (with exponent) or a comma separated list of them, starting with '-'
    _NEGATIVE_VALUE = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)*$")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = self._NEGATIVE_VALUE

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _warning_line(command: str):
    """A ``warnings.showwarning`` that prints ``fivecal COMMAND: warning: MESSAGE``
    on one line: a user of the command line is shown neither the source line
    that warned nor a path inside the package. Python API users keep the
    standard display (it is installed only while a command runs)."""
    def show(message, category, filename, lineno, file=None, line=None):
        stream = sys.stderr if file is None else file
        try:
            stream.write(f"fivecal {command}: warning: {' '.join(str(message).split())}\n")
        except (OSError, ValueError):  # stderr closed: a warning must not end the command
            pass

    return show


def _one_line(e: BaseException) -> str:
    if isinstance(e, OSError) and e.filename is not None and e.strerror:
        text = f"{e.filename}: {e.strerror}"
    else:
        text = str(e) or type(e).__name__
    return " ".join(text.split())


#: --help of --force for the commands that judge their own fit.
_FORCE_HELP = ("exit 0 even when the fit is not usable (not converged, non-finite, inadequate or "
               "undetermined); the reason is still printed. Only to inspect the values")

#: Exit statuses of every command (README "Exit codes").
EXIT_OK = 0        # success
EXIT_FIT = 1       # the fit failed, did not converge, or is inadequate / not usable
EXIT_INPUT = 2     # bad input or a refused request (unusable result, correction limit, ...)
EXIT_INTERNAL = 3  # a bug: FIVECAL_DEBUG=1 shows the traceback


def main(argv=None) -> int:
    """Entry point of the ``fivecal`` command; returns the exit status: 0 ok,
    1 the fit failed, did not converge or is not usable, 2 bad input or a
    refused request (one line), 3 an unexpected failure (a bug)."""
    p = _Parser(prog="fivecal", description="Geometric error identification for "
                                "five-axis machine tools (units: mm, degrees for rotary commands, rad "
                                "for angular errors).")
    p.add_argument("--version", action="version", version=f"fivecal {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    pi = sub.add_parser("identify", help="fit machine errors to a dataset",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Estimate the listed parameters plus the default setup set "
                        "(tip, touched facets, sphere centres, DBB lengths) and print a report.",
                        epilog="example:\n  fivecal identify tango.json --estimate S3 --out result.json\n"
                        "  fivecal identify fivecal_demo/dataset.json --estimate S3 --robust huber")
    pi.add_argument("dataset", help="dataset, JSON or Parquet (format: `fivecal docs formats`)")
    pi.add_argument("--estimate", default="auto",
                    help="parameter names and/or presets S1 S2 S3 S4 location auto, comma separated "
                    "(default: auto, as in Python: every error under its prior, the undetermined "
                    "ones listed)")
    pi.add_argument("--fix", default=None, help="names to keep fixed, comma separated")
    pi.add_argument("--robust", choices=["huber", "cauchy"], default=None,
                    help="robust loss that down-weights and flags outlier touches")
    pi.add_argument("--allow-unidentifiable", action="store_true",
                    help="fit even when parameters are confounded (they are named in the report)")
    pi.add_argument("--variance-components", action="store_true",
                    help="estimate the noise of each instrument group (probe, dbb, ball3d, point, pose, "
                    "pose_rad, distance) from the residuals instead of trusting the declared sigmas "
                    "(`fivecal docs identification`)")
    pi.add_argument("--out", help="write the result JSON here")
    pi.add_argument("--report", metavar="DIR", help="also write an HTML report (report.html, result.json, "
                    "plots as PNG) into this folder")
    from .history.cli import add_identify_options; add_identify_options(pi)  # noqa: E702
    pi.set_defaults(func=_identify)

    pv = sub.add_parser("convert", help="a dataset from JSON to Parquet or back (lossless)",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Read a dataset (JSON or Parquet, recognised by its content) and write "
                        "it as Parquet when OUT ends in .parquet or .pq (needs pyarrow: pip install "
                        "'fivecal[arrow]'), as JSON otherwise (`fivecal docs formats`).",
                        epilog="example:\n  fivecal convert trace.json trace.parquet\n"
                        "  fivecal convert trace.parquet trace.json")
    pv.add_argument("dataset", help="dataset to read (JSON or Parquet)")
    pv.add_argument("out", help="dataset to write: .parquet / .pq or .json")
    pv.set_defaults(func=_convert)

    ps = sub.add_parser("simulate", help="simulate a measurement on a machine with known errors",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Read a simulation spec (machine or machine path, errors, setup, "
                        "probe, artefact, plan, sigma, seed; see `fivecal docs formats`) and "
                        "write the dataset a real machine would record.",
                        epilog="example:\n  fivecal simulate spec.json --out dataset.json --sigma 0.0006")
    ps.add_argument("spec", help="simulation spec JSON")
    ps.add_argument("--out", required=True, help="dataset JSON to write")
    ps.add_argument("--sigma", type=SIGMA, default=None, help="noise (mm), overrides the spec")
    ps.add_argument("--seed", type=SEED, default=None, help="random seed (an integer 0 <= seed < 2^64), "
                    "overrides the spec")
    ps.set_defaults(func=_simulate)

    pd = sub.add_parser("demo", help="simulate, identify and validate the bundled HU40T TANGO example",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="example:\n  fivecal demo --out fivecal_demo")
    pd.add_argument("--out", default="fivecal_demo", help="report folder (default: fivecal_demo)")
    pd.add_argument("--seed", type=SEED, default=1, help="random seed of the simulated noise and of the "
                    "held-out indexations (default: 1)")
    pd.set_defaults(func=_demo)

    po = sub.add_parser("docs", help="where the user documentation is: list the pages or print one's path",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="The user documentation (docs/*.md and the README) is installed with "
                        "the package; messages point to it as `fivecal docs NAME`. Without NAME, list the "
                        "pages; with NAME (e.g. dbb, formats, readme), print the path of that page.",
                        epilog="examples:\n  fivecal docs\n  less \"$(fivecal docs dbb)\"")
    po.add_argument("name", nargs="?", help="a page: dbb, formats, identification, linuxcnc, readme, ...")
    po.set_defaults(func=_docs)

    from .procedures.dbb_cli import register as _register_dbb

    _register_dbb(sub)
    from .procedures.plan_cli import register as _register_plan; _register_plan(sub)  # noqa: E702
    from .io.linuxcnc_cli import register as _register_export; _register_export(sub)  # noqa: E702

    from .history.cli import register as _register_history; _register_history(sub)  # noqa: E702
    from .io.cli import register as _register_import

    _register_import(sub)

    pc = sub.add_parser("compensate", help="compensated G-code and error tables from identified errors",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Rewrite the G0/G1 moves of an absolute (G90) ISO G-code program so "
                        "that the erroneous machine puts the tool where the nominal one would: X Y Z and the "
                        "rotary words are replaced by the commands of the inverse kinematics on the "
                        "identified error model; comments, N numbers, F, S, M and all other words, "
                        "spacing and case are kept. Program words are read as machine axis commands "
                        "(mm or inch after G20, degrees). With --table, write the identified location "
                        "errors as a controller-neutral CSV or JSON table with the sign convention.",
                        epilog="examples:\n"
                        "  fivecal compensate result.json machine.json part.nc --out part_comp.nc\n"
                        "  fivecal compensate result.json machine.json --table errors.csv\n"
                        "  fivecal compensate result.json machine.json part.nc --out part_comp.nc "
                        "--work-offset X=-120,Y=35 --tool-tip 0,0,150")
    pc.add_argument("result", help="result JSON of fivecal identify (or a JSON object name -> value, mm/rad)")
    pc.add_argument("machine", help="machine definition JSON (or a dataset JSON: its machine is used)")
    pc.add_argument("program", nargs="?", help="G-code program to compensate")
    pc.add_argument("--out", help="compensated program to write (required with PROGRAM)")
    pc.add_argument("--table", metavar="FILE", help="write the identified errors as a table: CSV, or JSON "
                    "when FILE ends in .json")
    pc.add_argument("--table-all", action="store_true", help="table: include error motions and backlash, "
                    "not only the location errors")
    pc.add_argument("--start", metavar="AXES", help="axis positions before the first line, e.g. "
                    "X=0,Y=0,Z=300,B=0,C=0 (default: unknown; moves before every axis is known stay as "
                    "written)")
    pc.add_argument("--work-offset", metavar="AXES", help="machine command = program word + offset for the "
                    "linear axes (mm), e.g. X=-120.5,Y=35,Z=-410")
    pc.add_argument("--tool-tip", metavar="X,Y,Z", help="the cutting tool's tip in the machine frame at the "
                    "zero pose (mm), replacing the machine file's tool.tip")
    pc.add_argument("--decimals", type=_integer_type(0, 13), default=4, help="at least this many decimals for the "
                    "compensated words (default 4; a word written with more keeps its own)")
    pc.add_argument("--position-only", action="store_true", help="compensate the tool point only; keep the "
                    "rotary axes at their programmed values")
    pc.add_argument("--max-correction", metavar="MM[,DEG]", default=None,
                    help="plausibility limit: stop when a compensated command differs from the "
                    "programmed one by more than MM (linear axes) or DEG (rotary axes), like the "
                    "maximum-modification limit of controller calibration cycles (default 0.5,0.5; "
                    "'off' switches it off)")
    pc.add_argument("--force", action="store_true", help="use a result that is not usable (not "
                    "converged, non-finite, inadequate or undetermined); only to inspect it")
    pc.set_defaults(func=_compensate)

    pu = sub.add_parser("uncertainty", help="Monte Carlo (JCGM 101) or pooled-cycles GUM uncertainty "
                        "of the identified parameters",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="One INPUT (a simulation spec or a dataset): Monte Carlo -- re-draw the "
                        "measurement noise TRIALS times, re-fit on all cores, report the mean, standard "
                        "uncertainty and shortest coverage interval of every parameter and compare them "
                        "with the GUM (linearised) uncertainty as JCGM 101 section 8 validates it. Several "
                        "INPUTs (datasets of repeated cycles of one plan): GUM U_y = C U_x C^T with U_x "
                        "pooled by cycles or by days (thesis ch. 5), coverage factor stated.",
                        epilog="examples:\n"
                        "  fivecal uncertainty tango_spec.json --estimate S3 --trials 10000 "
                        "--out mc.json --plot mc.png\n"
                        "  fivecal uncertainty measured.json --estimate S3 --trials 2000 --threads 4\n"
                        "  fivecal uncertainty d1c1.json d1c2.json d2c1.json d2c2.json --days 1,1,2,2 "
                        "--pool days --estimate S3")
    pu.add_argument("inputs", nargs="+", metavar="INPUT",
                    help="simulation spec JSON (truth = its errors) or dataset JSON (noise around its "
                    "readings); several datasets = repeated cycles")
    pu.add_argument("--estimate", default="location",
                    help="parameter names and/or presets, comma separated (default: location)")
    pu.add_argument("--fix", default=None, help="names to keep fixed, comma separated")
    pu.add_argument("--trials", type=TRIALS, default=10000,
                    help="Monte Carlo trials M (default 10000)")
    pu.add_argument("--threads", type=count_type(0, MAX_WORKERS, "a number of threads"), default=0,
                    help="worker threads (default 0: all cores; the result does not depend on it)")
    pu.add_argument("--seed", type=SEED, default=1, help="master seed, 0 <= seed < 2^64 (default 1)")
    pu.add_argument("--sigma", type=SIGMA, default=None, help="noise (mm): overrides the spec's, or the "
                    "fit's residual sigma for a dataset")
    pu.add_argument("--probability", type=PROBABILITY, default=0.95, help="coverage probability (default 0.95)")
    pu.add_argument("--digits", type=_integer_type(1, 16), default=2, help="significant digits of u for the JCGM 101 "
                    "numerical tolerance (default 2)")
    pu.add_argument("--no-progress", action="store_true", help="no progress bar")
    pu.add_argument("--plot", help="write histograms (PNG) here")
    pu.add_argument("--samples", action="store_true", help="include the trial values in --out")
    pu.add_argument("--days", help="cycles: day label of each INPUT, comma separated (default: one day)")
    pu.add_argument("--pool", choices=["cycles", "days", "none"], default="cycles",
                    help="cycles: pool the input covariance by cycles (default) or by days")
    pu.add_argument("--k", type=POSITIVE, default=None, help="cycles: coverage factor (default: Student t "
                    "with the pooled degrees of freedom)")
    pu.add_argument("--out", help="write the result JSON here")
    pu.add_argument("--force", action="store_true", help=_FORCE_HELP)
    pu.set_defaults(func=_uncertainty)

    pg = sub.add_parser("design", help="choose K rotary indexations that minimise the condition number",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Read a simulation spec whose 'plan' is the pool of candidate touches "
                        "(visits: consecutive touches at one rotary pose), or whose 'candidates' lists "
                        "indexations ({'indexations': [{'B': 30, 'C': -90}, ...], 'limits': {'X': [-300, 300]}, "
                        "'min_dot': -0.02}: every facet or sphere touch facing the probe within the axis "
                        "limits), pick K indexations (greedy, then exchange) and write the chosen plan as "
                        "a simulation spec. Compares the condition number, a D-optimality figure and the "
                        "predicted uncertainties of the candidates and of the design (thesis Table 8-4).",
                        epilog="examples:\n"
                        "  fivecal design examples/design/hu40t_table_4_2.json -k 14 --estimate S3 "
                        "--out plan14.json\n"
                        "  fivecal simulate plan14.json --out plan14_data.json\n"
                        "  fivecal design examples/design/hu40t_table_4_2.json -k 21,22,23,24,25 "
                        "   (Table 8-4: several subsets)")
    pg.add_argument("spec", help="simulation spec JSON with the candidate plan")
    pg.add_argument("-k", required=True, help="indexations to pick (or a comma-separated list)")
    pg.add_argument("--estimate", default="S3", help="parameter names and/or presets (default: S3)")
    pg.add_argument("--fix", default=None, help="names to keep fixed, comma separated")
    pg.add_argument("--criterion", choices=["condition", "d"], default="condition",
                    help="minimise the condition number (default) or maximise the D-optimality")
    pg.add_argument("--method", choices=["exchange", "greedy"], default="exchange",
                    help="forward greedy selection, then exchange swaps while they improve (default), "
                    "or greedy only")
    pg.add_argument("--require", default=None, help="candidate visit numbers always kept, comma separated")
    pg.add_argument("--max-touches", type=COUNT, default=0, help="then drop single touches down to this many")
    pg.add_argument("--sigma", type=POSITIVE, default=0.0006, help="probing noise (mm) for the predicted "
                    "uncertainties (default 0.0006)")
    pg.add_argument("--no-progress", action="store_true", help="no progress bar")
    pg.add_argument("--out", help="write the designed plan (a simulation spec) here; '{k}' is replaced by K")
    pg.set_defaults(func=_design)

    pp = sub.add_parser("sphere", help="machine as a CMM: sphere test with the nominal and identified model",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Express the touches of a precision sphere in the table frame with the "
                        "nominal model (and with an identification result), fit a sphere by Gauss-Newton "
                        "and report the out of sphericity and residual statistics (thesis Table 6-3).",
                        epilog="example:\n  fivecal sphere sphere_data.json --values result.json")
    pp.add_argument("dataset", help="dataset JSON with sphere touches")
    pp.add_argument("--values", help="identification result JSON (the compensated model)")
    pp.add_argument("--sphere", default=None, help="sphere id (default: the only sphere touched)")
    pp.add_argument("--force", action="store_true", help="use a --values result that is not usable and "
                    "exit 0 on a sphere fit that is not (not converged or not finite); only to inspect them")
    pp.set_defaults(func=_sphere)

    pp = sub.add_parser("sphere-check", help="quick sphere check: rotary pivots, reversal, dispersion",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Evaluate a quick sphere check (a calibrated stylus, one sphere, a few "
                        "positions per rotary axis, approached from both sides), as controller cycles do: "
                        "the pivot of each rotary axis (position across the axis and tilt) and its reversal "
                        "error with their uncertainty, the change since the previous check, the dispersion of "
                        "the sphere positions before and after, and how well the positions determine them. "
                        "Plans: fivecal.procedures.sphere_check.plan (`fivecal docs design`).",
                        epilog="example:\n  fivecal sphere-check touches.json --previous last.json --out check.json")
    pp.add_argument("dataset", help="dataset JSON with the sphere touches")
    pp.add_argument("--previous", help="the previous check (--out of an earlier run, or a result JSON)")
    pp.add_argument("--out", help="write the check (parameters with value and std) as JSON")
    pp.add_argument("--sphere", default=None, help="sphere id (default: the first sphere touched)")
    pp.add_argument("--no-backlash", action="store_true", help="do not estimate the rotary reversal errors")
    pp.add_argument("--free-stylus", action="store_true",
                    help="estimate the stylus offsets too (default: the stylus is calibrated, tip.* fixed)")
    pp.add_argument("--force", action="store_true", help="exit 0 even when the fit is not usable")
    pp.set_defaults(func=_sphere_check)

    pp = sub.add_parser("rtest", help="R-test K tests: deviation ranges and the rotary axes' location errors",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Evaluate R-test data (ball3d observations, one setup per test): the "
                        "range of the recorded deviation in X, Y, Z per test, pass/fail against --tolerance, "
                        "and the location errors of the rotary axes fitted to all tests. Plans: "
                        "fivecal.procedures.rtest.plan (`fivecal docs design`).",
                        epilog="example:\n  fivecal rtest rtest_data.json --tolerance 20")
    pp.add_argument("dataset", help="dataset JSON with the ball3d observations")
    pp.add_argument("--tolerance", type=POSITIVE, default=None,
                    help="largest allowed range per direction, µm (exit 1 when a test exceeds it)")
    pp.add_argument("--no-identify", action="store_true", help="only the ranges, no location-error fit")
    pp.add_argument("--force", action="store_true", help="exit 0 even when the fit is not usable")
    pp.set_defaults(func=_rtest)

    old_stdout = sys.stdout
    sys.stdout = _PipeSafeStdout(old_stdout)  # --help | head too
    try:
        args = p.parse_args(argv)
    except SystemExit:
        sys.stdout.flush()
        raise
    finally:
        sys.stdout = old_stdout
    debug = os.environ.get("FIVECAL_DEBUG", "") not in ("", "0")
    old_showwarning = warnings.showwarning
    warnings.showwarning = _warning_line(args.command)
    try:
        return _run(args)
    except KeyboardInterrupt:
        print("fivecal: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print("fivecal: terminated", file=sys.stderr)
        return 143
    except RecursionError:
        if debug:
            raise
        print(f"fivecal {args.command}: error: input nested too deeply", file=sys.stderr)
        return 2
    except (ValueError, OSError) as e:
        # UnusableResultError and CorrectionLimitError are ValueErrors: a refused request
        if debug:
            raise
        print(f"fivecal {args.command}: error: {_one_line(e)}", file=sys.stderr)
        return EXIT_INPUT
    except Exception as e:  # an unexpected failure: still one line, with a way to see more
        if debug:
            raise
        print(f"fivecal {args.command}: internal error ({type(e).__name__}): {_one_line(e)} "
              "(set FIVECAL_DEBUG=1 for a traceback)", file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        warnings.showwarning = old_showwarning


if __name__ == "__main__":
    sys.exit(main())
