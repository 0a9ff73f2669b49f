"""``fivecal export linuxcnc``: the command-line face of fivecal.io.linuxcnc."""
from __future__ import annotations

import argparse

from . import linuxcnc as L


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
    print(f"files in {args.out}; recipe: docs/linuxcnc.md")
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
    if args.out:
        with open(args.out, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"written: {args.out}")
    else:
        print(text, end="")
    return 0


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
        "values carry in Siemens and Heidenhain documentation (docs/controllers.md). No vendor "
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
