"""``fivecal export linuxcnc | kinematics | program``: the command-line face of
fivecal.io.linuxcnc, fivecal.io.controllers and the NC programs of the test plans."""
from __future__ import annotations

import argparse
import math

from ..cli import count_type
from . import linuxcnc as L

#: R-test points between two samples at most (--subdivide)
MAX_SUBDIVIDE = 1000
#: ball bar rotary paths: the smallest bar-length tolerance (µm) between blocks
MIN_TOLERANCE_UM = 1e-4


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
    from ..cli import _read_machine

    machine = _read_machine(args.machine)
    limit = None
    if str(args.max_change).lower() != "off":
        try:
            limit = float(args.max_change)
        except ValueError:
            raise ValueError(f"--max-change: '{args.max_change}' is not a number of mm or 'off'") from None
        if not limit > 0 or limit != limit or limit == float("inf"):
            raise ValueError(f"--max-change: expected a positive number of mm, got {args.max_change}")
    old = L.read_hal_pins(args.old, args.kins) if args.old else None
    volume = _volume(args.volume) if args.volume else None
    if not (args.comp_step > 0):
        raise ValueError(f"--comp-step: expected a positive step, got {args.comp_step}")
    exp = L.export(args.result, machine, args.kins, args.out, old_pins=old, max_change=limit,
                   force=args.force, volume=volume, comp_step=args.comp_step, what=args.result)
    print(exp.summary())
    print(f"files in {args.out}; recipe: `fivecal docs linuxcnc`")
    return 0


def _run_kinematics(args) -> int:
    import json

    from ..cli import _read_machine
    from ..compensation import usable_errors
    from . import controllers as K

    machine = _read_machine(args.machine)
    errors = usable_errors(args.result, machine, args.force, args.result)
    volume = _volume(args.volume) if args.volume else None
    ab = K.absorb(machine, args.model, errors, poses=K.pose_grid(machine, volume),
                  directions=args.directions, compensation=True)
    if args.format == "json":
        text = json.dumps(K.export_dict(machine, ab), indent=1) + "\n"
    elif args.format == "csv":
        text = K.export_csv(machine, ab)
    else:
        text = K.export_text(machine, ab)
    return _write_or_print(text, args.out, f"written: {args.out}")


def _write_or_print(text: str, out, message: str) -> int:
    """``text`` to the file ``out`` (then ``message``), or to stdout."""
    if out:
        with open(out, "w", encoding="utf-8") as f:
            f.write(text)
        print(message)
    else:
        print(text, end="")
    return 0


_PLAN_KINDS = {"facet": "probing", "sphere": "sphere", "ball3d": "rtest", "dbb": "dbb"}


def _read_spec(path: str):
    """machine, plan, artefact and stylus radius of a simulation spec (or a
    dataset whose observations are the plan)."""
    import os

    from ..cli import _read_json
    from ..machine import Machine

    spec = _read_json(path, "the plan (a simulation spec)")
    if not isinstance(spec, dict):
        raise ValueError(f"{path}: expected a JSON object with machine, plan, artefact, probe")
    machine = spec.get("machine")
    if isinstance(machine, str):  # a path relative to the spec file
        machine = Machine.load(os.path.join(os.path.dirname(os.path.abspath(path)), machine))
    elif isinstance(machine, dict):
        machine = Machine.from_dict(machine)
    else:
        raise ValueError(f"{path}: 'machine' missing (a machine object or a path)")
    plan = spec.get("plan", spec.get("observations"))
    if not isinstance(plan, list) or not plan or not all(isinstance(e, dict) for e in plan):
        raise ValueError(f"{path}: 'plan' missing or empty (a list of plan entries, `fivecal docs formats`)")
    probe = spec.get("probe") or {}
    if not isinstance(probe, dict):
        raise ValueError(f"{path}: probe: expected an object like {{\"tip_radius\": 3.0}}")
    return machine, plan, spec.get("artefact") or {}, float(probe.get("tip_radius", 0.0))


def _run_program(args) -> int:
    from . import dbb_program as D
    from . import nc_programs as N

    machine, plan, artefact, tip = _read_spec(args.spec)
    types = sorted({str(e.get("type")) for e in plan})
    kind = args.kind
    if kind == "auto":
        kinds = {_PLAN_KINDS.get(t) for t in types}
        if kinds == {"probing", "sphere"}:
            kinds = {"probing"}  # facet and sphere touches: one G38.2 cycle in plan order
        if len(kinds) != 1 or None in kinds:
            raise ValueError(f"{args.spec}: plan entries of type {', '.join(types)}; a program runs facet "
                             "and sphere touches (together or apart), ball3d or dbb entries: give --kind or "
                             "split the plan")
        kind = kinds.pop()
    need_kins = kind in ("probing", "sphere") or (kind == "rtest" and args.mode == "tcp")
    if need_kins and not args.kins:
        raise ValueError(f"--kins: a {kind} program{' in tcp mode' if kind == 'rtest' else ''} runs with "
                         "LinuxCNC's tool-centre-point kinematics; give xyzac-trt or xyzbc-trt")
    if kind in ("probing", "sphere") and not tip > 0:
        raise ValueError(f"{args.spec}: probe.tip_radius: the stylus ball radius (mm) is needed for the "
                         "contact points")
    feed = args.feed
    # with spheres on the artefact (a scale bar beside the facets, as in
    # TANGO) even a facet-only plan takes the cycle whose moves keep out of them
    if kind == "probing" and (any(e.get("type") == "sphere" for e in plan) or artefact.get("spheres")):
        text = N.touch_program(machine, args.kins, plan, artefact, tip, clearance=args.clearance,
                               overtravel=args.overtravel, feed=feed or 60.0, retract=args.retract,
                               safe=args.safe, overshoot=args.overshoot, dwell=args.dwell, log=args.log)
    elif kind == "probing":
        text = L.probing_program(machine, args.kins, plan, artefact, tip, clearance=args.clearance,
                                 overtravel=args.overtravel, feed=feed or 60.0, retract=args.retract,
                                 safe=args.safe, dwell=args.dwell, log=args.log)
    elif kind == "sphere":
        text = N.sphere_program(machine, args.kins, plan, artefact, tip, clearance=args.clearance,
                                overtravel=args.overtravel, feed=feed or 60.0, retract=args.retract,
                                safe=args.safe, overshoot=args.overshoot, dwell=args.dwell, log=args.log)
    elif kind == "rtest":
        text = N.rtest_program(machine, plan, mode=args.mode, kins=args.kins, feed=feed or 500.0,
                               dwell=args.dwell if args.dwell > 0 else 1.0, subdivide=args.subdivide)
    else:
        if not (args.tolerance >= MIN_TOLERANCE_UM and math.isfinite(args.tolerance)):
            # The path is split until the bar length holds within it: points grow as 1/sqrt(tolerance).
            raise ValueError(f"--tolerance: expected a number of µm >= {MIN_TOLERANCE_UM:g}, got {args.tolerance}")
        if args.kins:  # joint words: rotary paths only (planar setups are refused, named)
            text = D.rotary_dbb_program(machine, plan, feed=feed or 1000.0, feed_in=args.feed_in,
                                        kins=args.kins, tolerance=args.tolerance * 1e-3)
        else:
            text = D.dbb_program(machine, plan, feed=feed or 1000.0, feed_in=args.feed_in,
                                 tolerance=args.tolerance * 1e-3)
    blocks = sum(1 for ln in text.splitlines() if ln[:1] in "GM")
    return _write_or_print(text, args.out,
                           f"{kind} program, {len(plan)} plan entries, {blocks} blocks: written to {args.out}")


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
    pl.add_argument("result", help="result JSON of fivecal identify (or a JSON object name -> value)")
    pl.add_argument("--machine", required=True, help="machine definition JSON (or a dataset JSON)")
    pl.add_argument("--kins", required=True, choices=list(L.KINS), help="LinuxCNC kinematics module")
    pl.add_argument("--out", required=True, help="folder to write the files into")
    pl.add_argument("--old", metavar="HAL", help="the controller's current pins: a HAL file with "
                    "'setp <kins>-kins.<pin> <value>' lines (default: the machine file's nominal geometry)")
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
    pl.set_defaults(func=_run)
    from . import controllers as K
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
    pk.add_argument("result", help="result JSON of fivecal identify (or a JSON object name -> value)")
    pk.add_argument("--machine", required=True, help="machine definition JSON (or a dataset JSON)")
    pk.add_argument("--model", required=True, choices=list(K.MODELS), help="controller model")
    pk.add_argument("--directions", action="store_true", help="the model also holds the rotary "
                    "axes' directions (generic models only)")
    pk.add_argument("--volume", metavar="RANGES", help="working volume of the fit, e.g. "
                    "X=-200:200,B=-90:30 (mm, degrees; default linear +-100, a rotary axis along z a "
                    "full turn, other rotary axes -90:90)")
    pk.add_argument("--format", choices=("text", "csv", "json"), default="text")
    pk.add_argument("--out", help="file to write (default: standard output)")
    pk.add_argument("--force", action="store_true", help="use a result that is not usable; only to "
                    "inspect the values")
    pk.set_defaults(func=_run_kinematics)
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
    pp.add_argument("--kind", default="auto", choices=["auto", "probing", "sphere", "rtest", "dbb"],
                    help="program kind (default: from the plan's entry types; probing takes facet and "
                    "sphere touches together)")
    pp.add_argument("--kins", choices=list(L.KINS), help="LinuxCNC kinematics (needed for probing, "
                    "sphere and --mode tcp; for rtest / dbb: write LinuxCNC joint values, for dbb rotary "
                    "paths only)")
    pp.add_argument("--out", help="file to write (default: standard output)")
    pp.add_argument("--feed", type=float, help="mm/min: probing moves (default 60), R-test path (500), "
                    "ball bar path (1000; rotary paths in inverse time for the balls' relative speed)")
    g = pp.add_argument_group("probing and sphere cycles")
    g.add_argument("--clearance", type=float, default=1.0, help="start of each G38.2 off the contact, mm")
    g.add_argument("--overtravel", type=float, default=1.0, help="end of each G38.2 beyond the contact, mm")
    g.add_argument("--retract", type=float, default=5.0, help="retract along the touch direction, mm")
    g.add_argument("--safe", type=float, default=100.0, help="lift along the tool axis for indexing, mm")
    g.add_argument("--overshoot", type=float, default=1.0, help="sphere and mixed facet/sphere plans: degrees "
                   "beyond a position to reach it from the side the plan asks for (0: off)")
    g.add_argument("--dwell", type=float, default=0.0, help="seconds: after each indexing; R-test: at "
                   "each sample (default 1)")
    g.add_argument("--log", default="probe-log.txt", help="probe log file name (PROBEOPEN)")
    g = pp.add_argument_group("R-test and ball bar")
    g.add_argument("--mode", choices=["axes", "tcp"], default="axes", help="R-test words: axis commands "
                   "(joint values with --kins) or world coordinates with TCP on")
    g.add_argument("--subdivide", type=count_type(0, MAX_SUBDIVIDE), default=0,
                   help=f"R-test: points between two samples (at most {MAX_SUBDIVIDE})")
    g.add_argument("--feed-in", type=float, default=1.5, help="ball bar: feed-in / feed-out, mm")
    g.add_argument("--tolerance", type=float, default=0.02, help="ball bar rotary paths: largest change "
                   "of the nominal bar length between two blocks, µm (default 0.02)")
    pp.set_defaults(func=_run_program)
