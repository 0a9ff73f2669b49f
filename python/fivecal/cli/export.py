"""``fivecal export linuxcnc | kinematics | program``: the command-line face of
fivecal.io.linuxcnc, fivecal.io.controllers and the NC programs of the test plans."""
from __future__ import annotations

import argparse
import json
import math
import os

from .. import files
from ..compensation import usable_errors
from ..io import controllers as K, dbb_program as D, linuxcnc as L, nc_options as O, nc_programs as N
from ..io import beckhoff, fanuc, heidenhain, siemens
from ..io.plan_readings import _read_spec
from ..tolerances import PATH_OPTION, path_tolerance
from .common import _read_machine, deprecated_alias

#: ball bar rotary paths: the smallest bar-length tolerance (µm) between blocks
MIN_TOLERANCE_UM = 1e-4
#: ball bar rotary paths: the default bar-length tolerance between blocks: a
#: ball bar reads 0.1 µm, so the path's own chords do not show in its trace
#: (0.02 µm before, five times finer than any bar reads, for twice the blocks)
DEFAULT_PATH_TOLERANCE = "0.1um"


def _volume(text: str) -> dict:
    out = {}
    for item in [t for t in text.replace(";", ",").split(",") if t.strip()]:
        if "=" not in item or ":" not in item:
            raise ValueError(f"--volume: expected AXIS=MIN:MAX pairs like X=-200:200,A=-90:30, got "
                             f"'{item.strip()}'")
        k, v = item.split("=", 1)
        lo, hi = v.split(":", 1)
        try:
            out[k.strip().upper()] = (float(lo), float(hi))
        except ValueError:
            raise ValueError(f"--volume {k.strip()}: '{v}' is not MIN:MAX in mm or degrees") from None
    return out


def _run(args) -> int:
    machine = _read_machine(args.machine)
    limits = L.parse_max_change(args.max_change)
    limit = None if limits is None else limits["mm"]
    old = L.read_hal_pins(args.old, args.kins) if args.old else None
    volume = _volume(args.volume) if args.volume else None
    if not (0 < args.comp_step < float("inf")):
        raise ValueError(f"--comp-step: expected a positive finite step, got {args.comp_step}")
    exp = L.export(args.result, machine, args.kins, args.out, old_pins=old, max_change=limit,
                   force=args.force, volume=volume, comp_step=args.comp_step, what=args.result)
    print(exp.summary())
    if exp.replaced:
        print(f"{args.out}: replaced the earlier export ({', '.join(exp.replaced)})")
    print(f"files in {args.out}; recipe: `fivecal docs linuxcnc`")
    return 0


#: the controller vendors' file writers (python/fivecal/io/<vendor>.py): each
#: has ``write(exp, machine) -> {suffix: text}`` and ``read(path) -> {name: value}``;
#: the numerics behind them are the core's one export path (``vendor.h``)
WRITERS: dict = {
    "fanuc": fanuc,
    "siemens": siemens,
    "heidenhain": heidenhain,
    "beckhoff": beckhoff,
}

#: units of vendor values and (limit unit, factor to it) for the plausibility
#: guard; a direction vector's components change like an angle in rad
_GUARD_UNITS = {"mm": ("mm", 1.0), "um": ("mm", 1e-3), "µm": ("mm", 1e-3), "0.001mm": ("mm", 1e-3),
                "0.0001mm": ("mm", 1e-4), "rad": ("rad", 1.0), "urad": ("rad", 1e-6), "µrad": ("rad", 1e-6),
                "deg": ("rad", math.pi / 180), "0.001deg": ("rad", math.pi / 180e3),
                "0.0001deg": ("rad", math.pi / 180e4), "": ("rad", 1.0)}


def _options(items) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ValueError(f"--set: expected KEY=VALUE, got '{item}'")
        k, v = item.split("=", 1)
        if not k.strip():
            raise ValueError(f"--set: expected KEY=VALUE, got '{item}'")
        out[k.strip()] = v.strip()
    return out


def _guarded(values, key: str):
    """(name, change in the guard's unit, guard unit) of the values an export changes."""
    out = []
    for v in values:
        if v["fixed"]:
            continue
        if v["unit"] not in _GUARD_UNITS:
            raise ValueError(f"{v['name']}: unit '{v['unit']}' is not one the plausibility guard knows")
        unit, f = _GUARD_UNITS[v["unit"]]
        out.append((v["name"], v[key] * f, unit))
    return out


def _run_vendor(args) -> int:
    writer = WRITERS[args.vendor]
    machine = _read_machine(args.machine)
    # the identified tool offset goes in: its length along the spindle is
    # the controller's tool length (the core drops what lies across it)
    errors = usable_errors(args.result, machine, args.force, args.result, tool_offset=True)
    try:
        cov = K.result_covariance(args.result, machine)
    except ValueError as e:
        if not args.force:
            raise ValueError(f"{e}; --force exports without the change's uncertainty") from None
        cov = None
    volume = _volume(args.volume) if args.volume else None
    limits = L.parse_max_change(args.max_change, angular=True)
    old = writer.read(args.old) if args.old else None
    exp = K.vendor_export(machine, args.vendor, errors, cov, poses=K.pose_grid(machine, volume),
                          options=_options(args.set), old=old)
    exp.result = os.fspath(args.result) if isinstance(args.result, (str, os.PathLike)) else ""
    if old is not None:
        # the identification is relative to the machine file: a controller
        # running other values than the file states has another nominal
        differs = [dict(v, change=float(d)) for v, d in zip(exp.values, exp.old_minus_nominal)]
        # 'off' is the change guard's switch; this one is --force-old's, so it
        # keeps the default limits when the change guard is off
        old_limits = limits if limits is not None else L.default_max_change()
        L.check_changes(f"--old {args.old} against the machine file {args.machine} (the identified errors are "
                        "relative to the machine file: make it describe what the controller runs, or --force-old)",
                        _guarded(differs, "change"), old_limits, args.force or args.force_old)
    L.check_changes(f"{args.vendor} values (--force-change writes them anyway)", _guarded(exp.values, "change"),
                    limits, args.force or args.force_change)
    contents = {f"{args.vendor}{suffix}": text for suffix, text in writer.write(exp, machine).items()}
    contents["export.json"] = json.dumps(exp.record(), indent=1) + "\n"
    _write_vendor_folder(args.out, contents)
    print(exp.report())
    print(f"written to {args.out}: {', '.join(sorted(contents))}; verify after loading: `fivecal docs controllers`")
    return 0


def _write_vendor_folder(out: str, contents: dict) -> None:
    """The export's folder, all or nothing; one holding files an export did
    not write is refused, naming one."""
    dest = os.path.realpath(out)
    if os.path.lexists(dest):
        if not os.path.isdir(dest):
            raise ValueError(f"--out {out}: exists and is not a folder")
        own = set(contents) | {"export.json"}
        foreign = [n for n in sorted(os.listdir(dest))
                   if n not in own and not any(n.startswith(v + ".") for v in WRITERS)]
        if foreign:
            raise ValueError(f"--out {out}: holds {foreign[0]}, which fivecal export did not write; it replaces "
                             "only a folder of its own files: choose a new or empty folder")
    files.write_folder(dest, contents, f"--out {out}")


def _run_kinematics(args) -> int:
    machine = _read_machine(args.machine)
    errors = usable_errors(args.result, machine, args.force, args.result)
    volume = _volume(args.volume) if args.volume else None
    fmt = _kinematics_format(args.format, args.out)
    limits = L.parse_max_change(args.max_change, angular=True)
    ab = K.absorb(machine, args.model, errors, poses=K.pose_grid(machine, volume),
                  directions=args.directions, compensation=True)
    # the same plausibility guard as export linuxcnc: the values are changes
    # from the nominal model
    L.check_changes(f"{args.model} model", [(p.label, float(v), p.unit) for p, v in zip(ab.parameters, ab.values)],
                    limits, args.force)
    if fmt == "json":
        text = json.dumps(K.export_dict(machine, ab), indent=1) + "\n"
    elif fmt == "csv":
        text = K.export_csv(machine, ab)
    else:
        text = K.export_text(machine, ab)
    return _write_or_print(text, args.out, f"written: {args.out}")


_FORMATS = {".json": "json", ".csv": "csv", ".txt": "text", ".text": "text"}


def _kinematics_format(fmt, out) -> str:
    """The format to write: ``--format``, or the one ``--out``'s extension
    names; a file whose extension says another format, or none fivecal
    writes, is refused."""
    if not out:
        return fmt or "text"
    ext = os.path.splitext(out)[1].lower()
    named = _FORMATS.get(ext)
    if named is None:
        raise ValueError(f"--out {out}: the extension '{ext or '(none)'}' names no format fivecal writes; "
                         "use .json, .csv or .txt")
    if fmt and fmt != named:
        raise ValueError(f"--out {out}: a .{ext[1:]} file, but --format {fmt}; give a file name that says the "
                         f"format (or --format {named})")
    return named


def _write_or_print(text: str, out, message: str) -> int:
    """``text`` to the file ``out`` (then ``message``), or to stdout."""
    if out:
        files.write_text(out, text, label="--out")
        print(message)
    else:
        print(text, end="")
    return 0


def _run_program(args) -> int:
    O.check_cli(args)
    machine, plan, artefact, tip = _read_spec(args.spec)
    types = sorted({str(e.get("type")) for e in plan})
    # the program runs the plan's entries (its kind: --kind, else the one
    # nc_programs.PLAN_PROGRAMS gives the plan's entry types)
    program = args.kind
    if program == "auto":
        programs = {N.PLAN_PROGRAMS.get(t) for t in types}
        if programs == set(N.TOUCH_PROGRAMS):
            programs = {N.TOUCH_PROGRAMS[0]}  # facet and sphere touches: one G38.2 cycle in plan order
        if len(programs) != 1 or None in programs:
            raise ValueError(f"{args.spec}: plan entries of type {', '.join(types)}; a program runs facet "
                             "and sphere touches (together or apart), ball3d or dbb entries: give --kind or "
                             "split the plan")
        program = programs.pop()
    touches = program in N.TOUCH_PROGRAMS
    need_kins = touches or (program == "rtest" and args.mode == "tcp")
    if need_kins and not args.kins:
        raise ValueError(f"--kins: a {program} program{' in tcp mode' if program == 'rtest' else ''} runs with "
                         "LinuxCNC's tool-centre-point kinematics; give xyzac-trt or xyzbc-trt")
    if touches and not tip > 0:
        raise ValueError(f"{args.spec}: probe.tip_radius: the stylus ball radius (mm) is needed for the "
                         "contact points")
    try:
        text = _program_text(args, program, machine, plan, artefact, tip)
    except O.OptionError as e:
        # a plan-dependent bound a writer checks: name the option as typed
        if e.option == "tip_radius":
            raise ValueError(f"{args.spec}: probe.tip_radius: {e.text}") from None
        raise e.for_cli() from None
    blocks = sum(1 for ln in text.splitlines() if ln[:1] in "GM")
    return _write_or_print(text, args.out,
                           f"{program} program, {len(plan)} plan entries, {blocks} blocks: written to {args.out}")


def _program_text(args, program, machine, plan, artefact, tip) -> str:
    # an option left out takes the writer's default for this kind of program
    opt = lambda name, default: default if getattr(args, name) is None else getattr(args, name)  # noqa: E731
    touch = dict(clearance=args.clearance, overtravel=args.overtravel, feed=opt("feed", 60.0),
                 retract=args.retract, safe=args.safe, dwell=opt("dwell", 0.0), log=args.log)
    # with spheres on the artefact (a scale bar beside the facets, as in
    # TANGO) even a facet-only plan takes the cycle whose moves keep out of them
    mixed, spheres = N.TOUCH_PROGRAMS
    dialect = args.dialect
    if dialect != "linuxcnc" and not (program == spheres or (program == mixed and N.touch_cycle(plan, artefact))):
        raise ValueError(f"--dialect {dialect}: written for sphere and mixed facet/sphere probing cycles; "
                         f"a {program} program is LinuxCNC G-code only")
    if program == mixed and N.touch_cycle(plan, artefact):
        return N.touch_program(machine, args.kins, plan, artefact, tip, overshoot=args.overshoot,
                               dialect=dialect, **touch)
    if program == mixed:
        return L.probing_program(machine, args.kins, plan, artefact, tip, **touch)
    if program == spheres:
        return N.sphere_program(machine, args.kins, plan, artefact, tip, overshoot=args.overshoot,
                                dialect=dialect, **touch)
    if program == "rtest":
        return N.rtest_program(machine, plan, mode=args.mode, kins=args.kins, feed=opt("feed", 500.0),
                               dwell=opt("dwell", 1.0), subdivide=args.subdivide)
    feed = opt("feed", 1000.0)
    tol = path_tolerance(args.path_tolerance)     # mm
    if not tol >= MIN_TOLERANCE_UM * 1e-3:
        # The path is split until the bar length holds within it: points grow as 1/sqrt(tolerance).
        raise ValueError(f"{PATH_OPTION}: expected at least {MIN_TOLERANCE_UM:g} µm, got {args.path_tolerance}")
    if args.kins:  # joint words: rotary paths only (planar setups are refused, named)
        return D.rotary_dbb_program(machine, plan, feed=feed, feed_in=args.feed_in, kins=args.kins,
                                    tolerance=tol)
    return D.dbb_program(machine, plan, feed=feed, feed_in=args.feed_in, tolerance=tol)


def _register_vendor(esub, RD, vendor: str, writer) -> None:
    info = K.vendor_info(vendor)
    opts = "\n".join(f"  --set {k}=...  {h}" for k, h in sorted(info["options"].items()))
    pv = esub.add_parser(
        vendor, formatter_class=RD, help=info["title"],
        description=f"{info['title']}: the values that best absorb the identified errors over the working "
        "volume (least squares through the controller's own kinematic model), old beside new, the change's "
        "1σ from the identification's covariance, the tool-point error the controller's model cannot absorb, "
        "and the round trip through the controller's kinematics as the manual defines it. Writes the "
        f"controller's file(s) and export.json (the record `fivecal sphere-check --expect` verifies after "
        "loading). Refuses a result that is not usable, a change beyond --max-change (unless --force-change) "
        "and --old values that differ from the machine file by more (unless --force-old); --force lifts all "
        "of these. Where the public manual leaves a convention open, it asks for it (--set). Sources and recipe: "
        "`fivecal docs controllers`." + (f"\n\nconventions (--set KEY=VALUE):\n{opts}" if opts else ""),
        epilog=f"example:\n  fivecal export {vendor} result.json --machine machine.json --out {vendor}-export/")
    pv.add_argument("result", help="result document of any fivecal procedure (identify, sphere-check, ...; --out)")
    pv.add_argument("--machine", required=True, help="machine definition JSON (or a dataset JSON): what the "
                    "controller runs now")
    pv.add_argument("--out", required=True, help="folder to write the files into (a folder of an earlier "
                    "export is replaced, all or nothing; one holding other files is refused)")
    pv.add_argument("--set", action="append", metavar="KEY=VALUE", help="a convention the public manual "
                    "leaves open (repeat for several; the keys are listed above)")
    pv.add_argument("--old", metavar="FILE", help=f"the controller's current values: a file of the format "
                    f"this export writes (default: the machine file's nominal geometry)")
    pv.add_argument("--volume", metavar="RANGES", help="working volume of the fit, e.g. "
                    "X=-200:200,B=-90:30 (mm, degrees; default linear +-100, a rotary axis along z a "
                    "full turn, other rotary axes -90:90)")
    pv.add_argument("--max-change", default=f"{L.DEFAULT_MAX_CHANGE},{L.DEFAULT_MAX_CHANGE_RAD}",
                    help=f"plausibility limit on any value's change, MM[,RAD] (default {L.DEFAULT_MAX_CHANGE} "
                    f"mm, {L.DEFAULT_MAX_CHANGE_RAD} rad; degrees and direction components by their angle; "
                    "'off' switches the change guard off; the --old check then keeps the defaults)")
    pv.add_argument("--force-change", action="store_true", help="write a change beyond --max-change (the "
                    "other guards stay)")
    pv.add_argument("--force-old", action="store_true", help="take --old values that differ from the machine "
                    "file's nominal beyond --max-change (the defaults when it is 'off'; e.g. a controller whose "
                    "origin is not the machine file's; the other guards stay)")
    pv.add_argument("--force", action="store_true", help="all of --force-change and --force-old, and use a "
                    "result that is not usable or has no covariance; only to inspect the values")
    pv.set_defaults(func=_run_vendor, vendor=vendor, out_is_folder=True)


def register(sub) -> None:
    """Add ``export`` (with ``export linuxcnc``) to the main parser's subparsers."""
    RD = argparse.RawDescriptionHelpFormatter
    pe = sub.add_parser("export", help="controller files from identified errors (LinuxCNC; kinematics tables)",
                        formatter_class=RD, description="Write what a controller needs from an "
                        "identification result.",
                        epilog="example:\n  fivecal export linuxcnc result.json --machine machine.json "
                        "--kins xyzac-trt --out lcnc/")
    esub = pe.add_subparsers(dest="export_command", required=True)
    pl = esub.add_parser(
        "linuxcnc", formatter_class=RD,
        help="xyzac-trt / xyzbc-trt kinematics pins and joint compensation files",
        description="Pins of LinuxCNC's xyzac-trt-kins / xyzbc-trt-kins that best absorb the "
        "identified errors over the working volume (least squares), with old and new values side "
        "by side and the tool-point error left; a type-0 COMP_FILE per axis with an identified "
        "error motion along itself or backlash. Refuses a result that is not usable and a pin "
        "change beyond --max-change unless --force.",
        epilog="example:\n  fivecal export linuxcnc result.json --machine machine.json "
        "--kins xyzac-trt --out lcnc/ --old current-kins.hal")
    pl.add_argument("result", help="result document of any fivecal procedure (identify, sphere-check, rtest, dbb, ...; --out), or a JSON object name -> value")
    pl.add_argument("--machine", required=True, help="machine definition JSON (or a dataset JSON)")
    pl.add_argument("--kins", required=True, choices=list(L.KINS), help="LinuxCNC kinematics module")
    pl.add_argument("--out", required=True, help="folder to write the files into (a folder of an earlier "
                    "export is replaced, all or nothing; one holding other files is refused)")
    pl.add_argument("--old", metavar="HAL", help="the controller's current pins: the HAL file that sets them "
                    "(setp, or sets on the signal a net links them to; read as halcmd reads it, "
                    "`fivecal docs linuxcnc`; default: the machine file's nominal geometry)")
    pl.add_argument("--max-change", default=str(L.DEFAULT_MAX_CHANGE),
                    help=f"plausibility limit on any pin change in mm (default {L.DEFAULT_MAX_CHANGE}; "
                    "'off' switches it off)")
    pl.add_argument("--volume", metavar="RANGES", help="working volume of the fit, e.g. "
                    "X=-200:200,Y=-150:150,Z=-100:0,A=-90:30,C=-180:180 (mm, degrees; default linear "
                    "+-100, tilt -90:90, C a full turn)")
    pl.add_argument("--comp-step", type=float, default=5.0, help="spacing of the compensation "
                    "table points (mm or degrees, default 5)")
    pl.add_argument("--force", action="store_true", help="use a result that is not usable or exceed "
                    "--max-change; only to inspect the values")
    pl.set_defaults(func=_run, out_is_folder=True)
    pk = esub.add_parser(
        "kinematics", formatter_class=RD,
        help="what a controller's kinematic model absorbs; a neutral kinematics table",
        description="Fit a controller model (generic table-table / head-head / table-head pivot "
        "model, or LinuxCNC xyzac-trt / xyzbc-trt / 5axiskins) to the identified errors over the "
        "working volume (least squares): its parameters, the tool-point error left (rms, max, by "
        "region), the error left when fivecal's G-code compensation runs on top, and the model as "
        "pivot points and axis directions in the machine frame, old and new, with the names the "
        "values carry in Siemens and Heidenhain documentation (`fivecal docs controllers`). No vendor "
        "file format is written.",
        epilog="example:\n  fivecal export kinematics result.json --machine machine.json "
        "--model table-table --directions --format csv --out kinematics.csv")
    pk.add_argument("result", help="result document of any fivecal procedure (identify, sphere-check, rtest, dbb, ...; --out), or a JSON object name -> value")
    pk.add_argument("--machine", required=True, help="machine definition JSON (or a dataset JSON)")
    pk.add_argument("--model", required=True, choices=list(K.MODELS), help="controller model")
    pk.add_argument("--directions", action="store_true", help="the model also holds the rotary "
                    "axes' directions (generic models only)")
    pk.add_argument("--volume", metavar="RANGES", help="working volume of the fit, e.g. "
                    "X=-200:200,B=-90:30 (mm, degrees; default linear +-100, a rotary axis along z a "
                    "full turn, other rotary axes -90:90)")
    pk.add_argument("--format", choices=("text", "csv", "json"), default=None,
                    help="default: the one --out's extension names (.json, .csv, .txt), text on standard output")
    pk.add_argument("--out", help="file to write, .json, .csv or .txt (default: standard output)")
    pk.add_argument("--max-change", default=f"{L.DEFAULT_MAX_CHANGE},{L.DEFAULT_MAX_CHANGE_RAD}",
                    help=f"plausibility limit on any parameter change, MM[,RAD] (default {L.DEFAULT_MAX_CHANGE} "
                    f"mm, {L.DEFAULT_MAX_CHANGE_RAD} rad; 'off' switches it off)")
    pk.add_argument("--force", action="store_true", help="use a result that is not usable or exceed "
                    "--max-change; only to inspect the values")
    pk.set_defaults(func=_run_kinematics)
    for vendor, writer in WRITERS.items():
        _register_vendor(esub, RD, vendor, writer)
    pp = esub.add_parser(
        "program", formatter_class=RD,
        help="ISO G-code that runs a test plan: probing, sphere cycle, R-test, ball bar",
        description="Write the NC program of a fivecal plan (the 'plan' of a simulation spec, "
        "`fivecal docs formats`): facet touches and sphere touches (apart or mixed in one plan, as fivecal "
        "design writes them) as G38.2 probing cycles for LinuxCNC "
        "with its tool-centre-point kinematics (--kins; probe log with PROBEOPEN, read back by "
        "fivecal.io.linuxcnc.read_probe_log), R-test K tests with a G4 dwell at each sample (axis "
        "commands, LinuxCNC joint values with --kins, or world moves with --mode tcp), ball bar "
        "circles and rotary-axis paths with feed-in and feed-out (`fivecal docs linuxcnc`). Check every "
        "program's clearance moves against your fixtures before running it on a machine.",
        epilog="examples:\n  fivecal export program sphere_spec.json --kins xyzac-trt --out sphere.ngc\n"
        "  fivecal export program plan14.json --kins xyzbc-trt --out tango.ngc   (fivecal design's facets "
        "and balls)\n"
        "  fivecal export program rtest_spec.json --mode tcp --kins xyzac-trt --out k4.ngc\n"
        "  fivecal export program fourstep_spec.json --feed 500 --out fourstep.ngc")
    pp.add_argument("spec", help="simulation spec JSON: machine (object or path), plan, artefact, probe")
    pp.add_argument("--kind", default="auto", choices=["auto", *N.PROGRAMS],
                    help="program kind (default: from the plan's entry types; probing takes facet and "
                    "sphere touches together)")
    pp.add_argument("--kins", choices=list(L.KINS), help="LinuxCNC kinematics (needed for probing, "
                    "sphere and --mode tcp; for rtest / dbb: write LinuxCNC joint values, for dbb rotary "
                    "paths only)")
    pp.add_argument("--out", help="file to write (default: standard output)")
    pp.add_argument("--feed", type=float, help="mm/min: probing moves (default 60), R-test path "
                    "(500), ball bar path (1000; rotary paths in inverse time for the balls' relative speed); "
                    "at most 100000")
    g = pp.add_argument_group("probing and sphere cycles")
    g.add_argument("--clearance", type=float, default=1.0, help="start of each G38.2 off "
                   "the contact, mm (at most 50)")
    g.add_argument("--overtravel", type=float, default=1.0, help="end of each G38.2 beyond "
                   "the contact, mm (at most 10, and at most the radius of a touched sphere)")
    g.add_argument("--retract", type=float, default=5.0, help="retract along the touch "
                   "direction, mm (at least --clearance, at most 500)")
    g.add_argument("--safe", type=float, default=100.0, help="lift along the tool axis for "
                   "indexing, mm (at most 2000)")
    g.add_argument("--overshoot", type=float, default=1.0, help="sphere and mixed "
                   "facet/sphere plans: degrees beyond a position to reach it from the side the plan asks for "
                   "(0: off; at most 45)")
    g.add_argument("--dwell", type=float, default=None, help="seconds: after each indexing "
                   "(default 0); R-test: at each sample (default 1); at most 3600")
    g.add_argument("--log", default="probe-log.txt", help="probe log file name (PROBEOPEN)")
    g.add_argument("--dialect", default="linuxcnc", choices=list(N.DIALECTS),
                   help="the controller whose words the sphere / probing cycle is written in: its probing move "
                   "(G38.2, Siemens MEAS=1, Fanuc G31, Beckhoff G100; Heidenhain: G-code, no public probing "
                   "move found), log (PROBEOPEN, WRITE, DPRNT, #MSG SAVE; every log reads back as LinuxCNC's) "
                   "and tool centre point switch (`fivecal docs linuxcnc`; default linuxcnc)")
    g = pp.add_argument_group("R-test and ball bar")
    g.add_argument("--mode", choices=["axes", "tcp"], default="axes", help="R-test words: axis commands "
                   "(joint values with --kins) or world coordinates with TCP on")
    # bounded by io.nc_options, the one rule every program writer checks
    g.add_argument("--subdivide", type=int, default=0,
                   help="R-test: points between two samples (at most 1000)")
    g.add_argument("--feed-in", type=float, default=1.5, help="ball bar: feed-in / feed-out, "
                   "mm (at most 50, and less than the circle's radius or the bar length)")
    g.add_argument(PATH_OPTION, default=DEFAULT_PATH_TOLERANCE, metavar="MM",
                   help="ball bar rotary paths: largest change of the nominal bar length between two blocks, "
                   f"mm, or with a unit: 0.1um (default {DEFAULT_PATH_TOLERANCE}, the reading resolution of a "
                   "ball bar: the path's own chords stay invisible in the trace; at most 1 mm; a bare number "
                   "above 0.01 is refused as probably µm)")
    deprecated_alias(g, "--tolerance", PATH_OPTION)   # µm before; scripts keep working, bare µm is refused
    pp.set_defaults(func=_run_program)
