"""``fivecal import KIND FILE --machine M.json --out dataset.json``."""
from __future__ import annotations

import argparse

from .. import files
from ..io import plan_readings as P, tables
from ..io.tables import KINDS


def _run_planned(args) -> int:
    """Readings lined up with a plan: R-test dwell readings, LinuxCNC probe log."""
    files.check_outputs([("FILE", args.file), ("--plan", args.plan), ("--pins", args.pins)], [("--out", args.out)])
    if args.kind == "probe-log":
        for opt in ("machine", "sidecar", "column", "setup", "length", "tool_ball", "table_ball", "header",
                    "units", "angle_units"):
            if getattr(args, opt, None):
                raise ValueError(f"--{opt.replace('_', '-')}: not used by a probe-log import (the plan gives "
                                 "the machine, the touches and the artefact; the log holds the program's mm and "
                                 "degrees)")
        d = P.probe_log_dataset(args.file, args.plan, args.kins, args.pins)
    else:
        for opt in ("machine", "sidecar", "column", "setup", "length", "tool_ball", "table_ball"):
            if getattr(args, opt, None):
                raise ValueError(f"--{opt.replace('_', '-')}: not used with --plan (the plan gives the machine, "
                                 "the axes, the balls and the mounting of each reading)")
        if args.kins or args.pins:
            raise ValueError(f"--{'kins' if args.kins else 'pins'}: belongs to a probe-log import")
        d = P.rtest_readings(args.file, args.plan, units=args.units, delimiter=args.delimiter,
                             decimal=args.decimal, header=args.header, sigma=args.sigma, ignore=args.ignore or (),
                             angle_units=args.angle_units)
    P.write(d, args.out)
    n = sum(1 for e in P.read_plan(args.plan)[1] if e.get("type") in {o["type"] for o in d["observations"]})
    counts = {}  # per type, in the order the plan first uses it (a mixed facet/sphere plan)
    for o in d["observations"]:
        counts[o["type"]] = counts.get(o["type"], 0) + 1
    what = " and ".join(f"{c} {t}" for t, c in counts.items())
    print(f"{args.file}: {what} observations of the {n} planned (plan {args.plan}) written to {args.out}")
    return 0


def _run(args) -> int:
    if args.kind == "probe-log" and not args.plan:
        raise ValueError("--plan: a probe-log import needs the plan the program was written from")
    if args.plan:
        if args.kind not in P.PLANNED:
            raise ValueError(f"--plan: lines up R-test readings (rtest) or a LinuxCNC probe log (probe-log), "
                             f"not a {args.kind} table")
        return _run_planned(args)
    if args.kins or args.pins:
        raise ValueError(f"--{'kins' if args.kins else 'pins'}: belongs to a probe-log import")
    if not args.machine:
        raise ValueError("--machine: the machine JSON is required (or --plan for R-test readings)")
    files.check_outputs([("FILE", args.file), ("--machine", args.machine), ("--sidecar", args.sidecar)],
                        [("--out", args.out)])
    ds = tables.write_dataset(
        args.file, args.out, args.kind, args.machine, sidecar=args.sidecar, units=args.units,
        angle_units=args.angle_units, columns=tables.parse_columns(args.column), ignore=args.ignore or (),
        delimiter=args.delimiter, decimal=args.decimal, setup=args.setup, length=args.length,
        tool_ball=args.tool_ball, table_ball=args.table_ball, sigma=args.sigma, header=args.header,
        instrument=args.instrument, target=args.target, target_point=args.target_point,
        instrument_origin=args.instrument_origin, instrument_angles=args.instrument_angles, align=args.align,
        target_rotation=args.target_rotation, station=args.station)
    counts = {}
    for t in ds.observation_types:
        counts[t] = counts.get(t, 0) + 1
    print(f"{args.file}: {len(ds)} observations ({', '.join(f'{n} {t}' for t, n in counts.items())}) "
          f"written to {args.out}")
    if ds.import_note:
        print(ds.import_note)
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "import", help="turn an instrument table (CSV or text) into a dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Read a table with a header row, one observation per row: a column per machine axis "
        "(X Y Z A B C S, any case), the measured columns of KIND, and optionally id, sigma, setup, "
        "dir_<axis>. Units come from the header (reading_um, B_rad, 'dx [um]') or the options. Separators "
        "',' ';' tab or spaces; with ';', tab or spaces a decimal comma is read (1,234). Lines starting "
        "with # are comments. Columns of each kind: `fivecal docs import`.",
        epilog="examples:\n"
        "  fivecal import probing touches.csv --machine hu40t.json --sidecar artefact.json --out ds.json\n"
        "  fivecal import dbb trace.csv --machine m.json --setup A1 --length 100 "
        "--tool-ball 0,0,100 --table-ball 100,0,0 --column reading=dL --units um --out ds.json\n"
        "  fivecal import rtest rtest.txt --machine m.json --sidecar rtest.json --out ds.json\n"
        "  fivecal import rtest nest_readings.csv --plan rtest_plan.json --out ds.json\n"
        "  fivecal import probe-log probe-log.txt --plan check_plan.json --kins xyzac-trt --out ds.json\n"
        "  fivecal import point tracker.csv --machine table.json --target work --target-point 0,50,0 "
        "--out ds.json\n"
        "  fivecal import pose camera_xyzw.txt --machine machine.json --sidecar import/camera_xyzw.json --units m "
        "--ignore timestamp --out ds.json\n"
        "      (a camera's 6D log: quaternion columns qx qy qz qw, or q0..q3 with \"rotation\": {\"form\": "
        "\"quaternion\", \"order\": \"wxyz\"} in the sidecar; examples/camera_positioner)\n"
        "  fivecal import machined cmm_report.csv --machine c600u.json --setup P1 --out ds.json")
    p.add_argument("kind", metavar="KIND", choices=list(KINDS) + ["rtest", "tracker", "6d", "tracer", "probe-log"],
                   help="probing | dbb | ball3d (rtest) | point (tracker) | pose (6d) | distance (tracer) | "
                   "machined (a CMM report of a machined test part) | fivecal (a type column, any kind) | "
                   "probe-log (LinuxCNC's PROBEOPEN log of a program of `fivecal export program`, with --plan)")
    p.add_argument("file", metavar="FILE", help="the table (CSV or whitespace text)")
    p.add_argument("--machine", help="machine JSON (not with --plan: the plan's machine is used)")
    p.add_argument("--out", required=True, help="dataset JSON to write")
    p.add_argument("--sidecar", help="JSON with what the table lacks: probe, artefact, setup, length, "
                   "tool_ball, table_ball, sigma")
    p.add_argument("--units", help="unit of measured columns (reading, dx dy dz, sigma) whose header names "
                   "none: um or mm (default mm)")
    p.add_argument("--angle-units", help="unit of rotary axis columns whose header names none: deg "
                   "(default) or rad")
    p.add_argument("--column", action="append", metavar="FIELD=HEADER",
                   help="read FIELD from the column HEADER, e.g. reading=dL_um (repeatable)")
    p.add_argument("--ignore", action="append", metavar="HEADER", help="skip this column (repeatable)")
    p.add_argument("--delimiter", help="column separator: comma, semicolon, tab, space (default: from the "
                   "header line)")
    p.add_argument("--decimal", choices=["comma", "point"], help="decimal mark (default: comma unless it "
                   "separates the columns)")
    p.add_argument("--setup", help="dbb / ball3d: the mounting's name; machined: the test part's name when the "
                   "table has no part column (default P1); no '.'")
    p.add_argument("--length", type=float, help="dbb: nominal bar length, mm")
    p.add_argument("--tool-ball", metavar="X,Y,Z", help="dbb / ball3d: tool ball centre, machine frame at "
                   "the zero pose, mm")
    p.add_argument("--table-ball", metavar="X,Y,Z", help="dbb / ball3d: table ball centre, workpiece frame, mm")
    p.add_argument("--sigma", type=float, help="measurement standard deviation, mm (default: the kind's)")
    p.add_argument("--header", metavar="NAMES", help="the column names, comma separated, of a file without a "
                   "header row")
    g = p.add_argument_group("readings of a planned test (`fivecal plan`, `fivecal export program`)")
    g.add_argument("--plan", help="the plan the program was written from: rtest: the readings (dx dy dz, one "
                   "per dwell) line up with its samples by an id column or in program order; probe-log: with "
                   "its touches")
    g.add_argument("--kins", choices=["xyzac-trt", "xyzbc-trt"], help="probe-log: the LinuxCNC kinematics "
                   "the program ran with")
    g.add_argument("--pins", metavar="HAL", help="probe-log: HAL file with the kinematics pins the controller "
                   "ran with (default: the machine's nominal geometry)")
    g = p.add_argument_group("point, pose and distance (tracker, camera, CMM, interferometer)")
    g.add_argument("--instrument", help="the instrument's name (default T1); its pose parameters are "
                   "instrument.<name>.x|y|z|a|b|c")
    g.add_argument("--target", choices=["tool", "work"], help="the machine side carrying the target (default: "
                   "the only side with axes)")
    g.add_argument("--target-point", metavar="X,Y,Z", help="nominal target, mm: machine frame at the zero pose "
                   "(tool; default the tool tip) or workpiece frame (work; default 0,0,0)")
    g.add_argument("--instrument-origin", metavar="X,Y,Z", help="nominal instrument origin in the machine "
                   "frame, mm")
    g.add_argument("--instrument-angles", metavar="A,B,C", help="nominal instrument orientation, degrees, "
                   "Rz(c)Ry(b)Rx(a)")
    g.add_argument("--target-rotation", metavar="RX,RY,RZ", help="pose: nominal orientation of the target frame "
                   "on its side, rotation vector, rad (default 0)")
    g.add_argument("--station", help="distance: the station of every row of a file without a station column "
                   "(the stations' places are in the sidecar's 'stations')")
    g.add_argument("--align", action=argparse.BooleanOptionalAction, default=None,
                   help="set the nominal instrument pose by a rigid alignment of the measured points to the "
                   "nominal machine's (default: when no pose is given); --no-align keeps the identity")
    p.set_defaults(func=_run)
