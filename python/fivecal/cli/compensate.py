"""``fivecal compensate``: compensated G-code and error tables from identified errors."""
from __future__ import annotations

import argparse
import os

from ..compensation import (MAX_CORRECTION, MAX_CORRECTION_DEG, compensate_gcode_file, usable_errors,
                            write_error_table)
from .common import _axis_values, _integer_type, _read_machine


def _limits(text: str) -> tuple:
    """--max-correction MM[,DEG]: the plausibility limits; 'off' switches them off."""
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


def _compensate(args) -> int:
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


def register(sub) -> None:
    pc = sub.add_parser("compensate", help="compensated G-code and error tables from identified errors",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Rewrite the G0/G1 moves of an absolute (G90) ISO G-code program so "
                        "that the erroneous machine puts the tool where the nominal one would: X Y Z and the "
                        "rotary words are replaced by the commands of the inverse kinematics on the "
                        "identified error model; comments, N numbers, F, S, M and all other words, "
                        "spacing and case are kept. Program words are read as machine axis commands "
                        "(mm, or inch after G20/G70; degrees). With --table, write the identified location "
                        "errors as a controller-neutral CSV or JSON table with the sign convention.",
                        epilog="examples:\n"
                        "  fivecal compensate result.json machine.json part.nc --out part_comp.nc\n"
                        "  fivecal compensate result.json machine.json --table errors.csv\n"
                        "  fivecal compensate result.json machine.json part.nc --out part_comp.nc "
                        "--work-offset X=-120,Y=35 --tool-tip 0,0,150")
    pc.add_argument("result", help="result document of any fivecal procedure (identify, sphere-check, rtest, dbb, ...; --out), or a JSON object name -> value, mm/rad")
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
                    "compensated words (default 4, one more for a linear word on an inch line; a word written "
                    "with more keeps its own)")
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
