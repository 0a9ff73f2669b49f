"""``fivecal plan sphere-check | sphere-test | rtest | four-step | wang``:
the test plans of fivecal.procedures from a machine file, written as a
simulation spec (machine, plan, artefact, probe) that ``fivecal export
program`` turns into G-code and ``fivecal simulate`` into a dataset."""
from __future__ import annotations

import argparse
import math
import os

from .._json import plain
from ..files import write_json
from ..procedures import dbb, rtest, sphere_check, sphere_test
from .common import (POSITIVE, _axis_values, _float_type, _read_machine, check_size, check_step, count_type,
                     deprecated_alias)
from .dbb import _values


#: Positions per rotary axis of a sphere check at most (-n, --positions): one
#: a degree over a full turn, far more than a pivot needs.
MAX_POSITIONS = 360
#: mm: positions and lengths (the core's kMaxLinear)
MAX_LINEAR = 1e5


def _vector(text: str, option: str, n: int = 3) -> list:
    parts = [t.strip() for t in str(text).split(",")]
    try:
        v = [float(t) for t in parts]
    except ValueError:
        v = []
    if len(v) != n or not all(math.isfinite(x) for x in v):
        raise ValueError(f"{option}: expected {n} numbers separated by commas, got '{text}'")
    if max(abs(x) for x in v) > MAX_LINEAR:  # the core's machine-size bound, named here by option
        raise ValueError(f"{option}: {max(v, key=abs):g} mm is beyond {MAX_LINEAR / 1e3:g} m; values this "
                         "large look like µm (fivecal expects mm)")
    return v


def _range(text: str, option: str) -> tuple:
    """LO:HI (degrees)."""
    parts = str(text).split(":")
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"{option}: expected LO:HI in degrees (e.g. -90:30), got '{text}'") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"{option}: '{text}' is not a range LO:HI with LO < HI")
    return lo, hi


def _ranges(text: str, option: str, machine) -> dict:
    """AXIS=LO:HI,AXIS=LO:HI for rotary axes of ``machine``."""
    out = {}
    for item in [t for t in str(text).split(",") if t.strip()]:
        if "=" not in item:
            raise ValueError(f"{option}: expected AXIS=LO:HI pairs like A=-90:30,C=-180:180, got '{item.strip()}'")
        a, r = item.split("=", 1)
        a = a.strip().upper()
        _check_rotary(machine, a, option)
        if a in out:
            raise ValueError(f"{option}: axis {a} given twice")
        out[a] = _range(r, f"{option} {a}")
    return out


def _check_rotary(machine, axis: str, option: str) -> None:
    rot = [a for a in machine.axis_names if machine.is_rotary(a) and a != "S"]
    if axis not in rot:
        raise ValueError(f"{option}: '{axis}' is not a rotary axis of machine {machine.name!r} "
                         f"(rotary axes: {', '.join(rot) or 'none'})")


def _positions(items, machine, option: str = "--positions") -> dict:
    """Repeated AXIS=V1,V2,... (degrees)."""
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"{option}: expected AXIS=V1,V2,... in degrees (e.g. C=-120,0,120), got '{item}'")
        a, vals = item.split("=", 1)
        a = a.strip().upper()
        _check_rotary(machine, a, option)
        if a in out:
            raise ValueError(f"{option}: axis {a} given twice")
        try:
            v = [float(x) for x in vals.split(",") if x.strip()]
        except ValueError:
            raise ValueError(f"{option} {a}: expected numbers separated by commas, got '{vals}'") from None
        if len(v) < 3 or not all(math.isfinite(x) for x in v):
            raise ValueError(f"{option} {a}: {len(v)} positions; a pivot needs at least 3 finite ones")
        out[a] = v
    return out


def _machine(path: str):
    return _read_machine(path)


def _sphere(args) -> dict:
    r = args.radius
    if args.sphere is None:  # required, said here: argparse would not count the old spelling as given
        raise ValueError("--sphere-centre: the sphere centre X,Y,Z (workpiece frame, mm) is required")
    c = _vector(args.sphere, "--sphere-centre")
    if args.tip_radius is None or not args.tip_radius > 0:
        raise ValueError("--tip-radius: the stylus ball radius (mm) is needed for the contact points")
    if "." in args.sphere_id or not args.sphere_id.strip():
        raise ValueError(f"--sphere-id: expected a name without '.', got '{args.sphere_id}'")
    return {"id": args.sphere_id, "center": c, "radius": r}


def _rings(text):
    if text is None:
        return None
    out = []
    for item in [t for t in text.split(",") if t.strip()]:
        try:
            lat, n = item.split(":")
            lat, n = float(lat), int(n)
        except ValueError:
            raise ValueError(f"--rings: expected LATITUDE:COUNT pairs like 0:8,45:4,90:1, got '{item}'") from None
        if not (-90 <= lat <= 90) or n < 1:
            raise ValueError(f"--rings: '{item}': latitude in -90..90 degrees and a count >= 1")
        out.append((lat, n))
    check_size("--rings", sum(n for _, n in out), "touch directions per indexation")
    return out


def _write(args, machine, plan, what: str, artefact=None, tip_radius=None) -> int:
    if not plan:
        raise ValueError(f"{what}: the options leave no plan entry (check the ranges and limits)")
    spec = {"_comment": f"fivecal plan {args.plan_command} for {machine.name}: {len(plan)} entries; "
                        "`fivecal export program` writes its G-code, `fivecal simulate` a dataset",
            "machine": machine.to_dict(), "plan": plan}
    if artefact:
        spec["artefact"] = artefact
    if tip_radius is not None:
        spec["probe"] = {"tip_radius": tip_radius}
    if args.errors:
        if not os.path.exists(args.errors) and any("=" not in t for t in args.errors.split(",") if t.strip()):
            raise ValueError(f"--errors: expected NAME=VALUE pairs (mm, rad) or a JSON file, got '{args.errors}'")
        spec["errors"] = _values(args.errors, "--errors")
    write_json(args.out, plain(spec, "plan"))
    groups = {}
    for e in plan:
        k = e.get("setup") or e.get("target") or ""
        groups[k] = groups.get(k, 0) + 1
    print(f"{what} plan for {machine.name}: {len(plan)} entries "
          f"({', '.join(f'{k} {n}' for k, n in groups.items())}); written to {args.out}")
    return 0


def _sphere_check(args) -> int:
    m = _machine(args.machine)
    ball = _sphere(args)
    limits = _ranges(args.limits, "--limits", m) if args.limits else None
    pos = _positions(args.positions, m) if args.positions else None
    if args.n < 3:
        raise ValueError(f"-n: {args.n} positions per axis; a pivot needs at least 3")
    for a, v in (pos or {}).items():
        check_size(f"--positions {a}", len(v), "positions", MAX_POSITIONS)
    plan = sphere_check.plan(m, ball, tip_radius=args.tip_radius, n=args.n, axis_positions=pos, limits=limits,
                             both_sides=not args.one_side, min_dot=args.min_dot)
    return _write(args, m, plan, "sphere check", {"spheres": [ball]}, args.tip_radius)


def _sphere_test(args) -> int:
    m = _machine(args.machine)
    ball = _sphere(args)
    if not args.at:
        raise ValueError("--at: give the indexations, e.g. --at B=0,C=0 --at B=30,C=90 (repeatable)")
    visits = []
    for text in args.at:
        v = _axis_values(text, "--at")
        for a in v:
            _check_rotary(m, a, "--at")
        visits.append(v)
    limits = _ranges(args.limits, "--limits", m) if args.limits else None
    rings = _rings(args.rings)
    if rings is not None:
        check_size("--rings", sum(n for _, n in rings) * len(visits), f"touches at {len(visits)} indexations")
    plan = sphere_test.sphere_plan(m, ball, visits, tip_radius=args.tip_radius, rings=rings,
                                   min_dot=args.min_dot, limits=limits)
    return _write(args, m, plan, "sphere test", {"spheres": [ball]}, args.tip_radius)


def _rtest(args) -> int:
    m = _machine(args.machine)
    tests = [t.strip().upper() for t in args.tests.split(",") if t.strip()]
    bad = [t for t in tests if t not in rtest.TESTS]
    if not tests or bad:
        raise ValueError(f"--tests: '{bad[0] if bad else args.tests}' is not an R-test K test "
                         f"(tests: {', '.join(rtest.TESTS)})")
    if len(set(tests)) != len(tests):
        raise ValueError(f"--tests: a test given twice in '{args.tests}'")
    if args.setup is not None and ("." in args.setup or not args.setup.strip()):
        raise ValueError(f"--setup: expected a mounting name without '.', got '{args.setup}'")
    table_ball = _vector(args.table_ball, "--table-ball")
    tool_ball = _vector(args.tool_ball, "--tool-ball") if args.tool_ball else None
    tilt_range = _range(args.tilt_range, "--tilt-range")
    # K1, K3 and K4 sample a full turn, K2 the tilt range.
    spans = [tilt_range[1] - tilt_range[0] if t == "K2" else 360.0 for t in tests]
    check_step("--step", args.step, max(spans), per=len(tests))
    plan = []
    for t in tests:
        plan += rtest.plan(m, t, table_ball=table_ball, tool_ball=tool_ball, step=args.step, tilt=args.tilt,
                           tilt_range=tilt_range, setup=args.setup)
    return _write(args, m, plan, f"R-test {','.join(tests)}")


def _four_step(args) -> int:
    m = _machine(args.machine)
    pair = dbb.four_step_pair(m)  # says why a machine's geometry does not allow the test
    setups = None
    if args.setups:
        setups = [s.strip() for s in args.setups.split(",")]
        if len(setups) != 4 or not all(setups) or any("." in s for s in setups) or len(set(setups)) != 4:
            raise ValueError(f"--setups: expected four different names without '.', got '{args.setups}'")
    if not args.extended_length > args.length:
        raise ValueError(f"--extended-length: {args.extended_length:g} mm is not longer than --length "
                         f"{args.length:g} mm")
    a_range = _range(args.carrier_range, "--carrier-range") if args.carrier_range else None
    c_range = _range(args.carried_range, "--carried-range") if args.carried_range else None
    # Each axis is swept twice (short and long bar); without a range at most a turn.
    check_step("--step", args.step, max(r[1] - r[0] if r else 360.0 for r in (a_range, c_range)), per=4)
    plan = dbb.four_step_plan(
        m, length=args.length, extended_length=args.extended_length, a_range=a_range, c_range=c_range,
        step=args.step, tool_ball=_vector(args.tool_ball, "--tool-ball") if args.tool_ball else None,
        setups=setups)
    return _write(args, m, plan, f"four-step ball bar ({pair['carrier']} then {pair['carried']})")


def _wang(args) -> int:
    m = _machine(args.machine)
    tb = _vector(args.table_ball, "--table-ball") if args.table_ball else (0.0, 150.0, 130.0)
    if "." in args.setup or not args.setup.strip():
        raise ValueError(f"--setup: expected a mounting name without '.', got '{args.setup}'")
    check_step("--step", args.step, 360.0)  # the tracking angle makes one turn
    plan = dbb.wang_plan(m, setup=args.setup, table_ball=tb, radius=args.radius, height=args.height,
                         step=args.step)
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in plan]
    return _write(args, m, plan, "Wang simultaneous ball bar")


def register(sub) -> None:
    """Add ``plan`` (sphere-check, sphere-test, rtest, four-step, wang) to the main parser."""
    RD = argparse.RawDescriptionHelpFormatter
    pp = sub.add_parser(
        "plan", help="a test plan from a machine file: sphere check, sphere test, R-test, ball bar",
        formatter_class=RD,
        description="Write the plan of a test (as a simulation spec: machine, plan, artefact, probe) from "
        "a machine file. `fivecal export program PLAN` writes the G-code that runs it; `fivecal simulate "
        "PLAN` (with --errors) the dataset a machine with those errors would record; the readings of the "
        "real test come back with `fivecal import` (`fivecal docs linuxcnc`).",
        epilog="examples:\n"
        "  fivecal plan sphere-check machine.json --sphere-centre 60,30,40 --radius 12.5 --tip-radius 3 "
        "--out check_plan.json\n"
        "  fivecal plan rtest machine.json --tests K1,K4 --table-ball 60,20,30 --step 15 --out rtest_plan.json\n"
        "  fivecal plan four-step machine.json --length 100 --out fourstep_plan.json\n"
        "  fivecal export program check_plan.json --kins xyzac-trt --out check.ngc")
    psub = pp.add_subparsers(dest="plan_command", required=True)

    def common(p):
        p.add_argument("machine", help="machine JSON (or a dataset JSON: its machine is used)")
        p.add_argument("--out", required=True, help="plan (simulation spec JSON) to write")
        p.add_argument("--errors", metavar="ERRORS", help="errors to put into the spec for `fivecal simulate`: "
                       "NAME=VALUE,... (mm, rad) or a JSON file")

    def sphere_opts(p):
        # --sphere names a sphere (its id) in sphere and sphere-check; here it was the centre: kept, hidden
        p.add_argument("--sphere-centre", dest="sphere", metavar="X,Y,Z",
                       help="sphere centre, workpiece frame, mm (required)")
        deprecated_alias(p, "--sphere", "--sphere-centre")
        p.add_argument("--radius", type=POSITIVE, required=True, help="sphere radius, mm")
        p.add_argument("--sphere-id", default="S1", help="the sphere's name (default S1)")
        p.add_argument("--tip-radius", type=POSITIVE, required=True, help="stylus ball radius, mm")
        p.add_argument("--limits", metavar="RANGES", help="rotary axis limits, e.g. A=-90:30,C=-180:180 (degrees)")
        p.add_argument("--min-dot", type=_float_type(-1.0, 1.0), default=0.0,
                       help="touch directions whose dot product with the tool axis is below this are left "
                       "out (default 0: at or above the sphere's equator as seen from the spindle)")

    p = psub.add_parser("sphere-check", formatter_class=RD,
                        help="quick sphere check: each rotary axis through a few positions, both sides",
                        description="Each rotary axis in turn through its positions (the others at 0), upwards "
                        "and then downwards so every position is reached from both sides; at each position the "
                        "touches of the sphere that face the probe. Evaluated by `fivecal sphere-check`.",
                        epilog="example:\n  fivecal plan sphere-check machine.json --sphere-centre 60,30,40 "
                        "--radius 12.5 --tip-radius 3 --positions A=-60,-15,30 --positions C=-120,0,120 "
                        "--out check_plan.json")
    common(p)
    sphere_opts(p)
    p.add_argument("-n", type=count_type(0, MAX_POSITIONS), default=5, help="positions per rotary axis spread over its "
                   f"range (default 5, at most {MAX_POSITIONS}; a full turn for C, --limits or +-90 otherwise)")
    p.add_argument("--positions", action="append", metavar="AXIS=V1,V2,...",
                   help="the positions of one axis in degrees instead of -n (repeatable, one per axis)")
    p.add_argument("--one-side", action="store_true", help="reach each position from one side only (no "
                   "reversal error)")
    p.set_defaults(func=_sphere_check)

    p = psub.add_parser("sphere-test", formatter_class=RD,
                        help="machine as a CMM: touch a sphere at given indexations",
                        description="Touch the sphere at each indexation (--at, repeatable) along the "
                        "directions of the point distribution (--rings, default the thesis' 33 points) that "
                        "face the probe. Evaluated by `fivecal sphere`.",
                        epilog="example:\n  fivecal plan sphere-test machine.json --sphere-centre 120,-60,80 "
                        "--radius 9.525 --tip-radius 3 --at B=0,C=0 --at B=30,C=90 --out sphere_plan.json")
    common(p)
    sphere_opts(p)
    p.add_argument("--at", action="append", metavar="AXES", help="an indexation, e.g. B=30,C=90 (repeatable)")
    p.add_argument("--rings", metavar="LAT:N,...", help="touch directions: rings of N points at latitude LAT "
                   "degrees, e.g. 0:12,30:8,60:4,90:1")
    p.set_defaults(func=_sphere_test)

    p = psub.add_parser("rtest", formatter_class=RD, help="R-test K tests (ISO 10791-6 style)",
                        description="ball3d samples of the K tests: K1 the turning axis through a full turn, "
                        "K2 the tilting axis over --tilt-range, K3 as K1 at the tilt --tilt, K4 both together "
                        "(tilt = --tilt * sin C). Each sample has an id (e.g. K1-3) that the program's dwell "
                        "comments and the readings file carry. Evaluated by `fivecal rtest`.",
                        epilog="example:\n  fivecal plan rtest machine.json --tests K1,K2,K4 --table-ball 60,20,30 "
                        "--tool-ball 0,0,140 --out rtest_plan.json")
    common(p)
    p.add_argument("--tests", default="K1,K2,K3,K4", help="comma separated (default K1,K2,K3,K4)")
    p.add_argument("--table-ball", required=True, metavar="X,Y,Z", help="table-side ball or nest centre, "
                   "workpiece frame, mm (off the turning axis)")
    p.add_argument("--tool-ball", metavar="X,Y,Z", help="tool-side centre, machine frame at the zero pose, mm "
                   "(default the machine's tool tip)")
    p.add_argument("--step", type=POSITIVE, default=15.0, help="degrees between samples (default 15)")
    p.add_argument("--tilt", type=_float_type(), default=-45.0, help="K3 tilt and K4 amplitude, degrees "
                   "(default -45; a negative value with '=': --tilt=-30)")
    p.add_argument("--tilt-range", default="-90:90", metavar="LO:HI",
                   help="K2 range, degrees (default -90:90; a negative LO with '=': --tilt-range=-90:60)")
    p.add_argument("--setup", help="one mounting name for all tests (default: one mounting per test, named "
                   "after it)")
    p.set_defaults(func=_rtest)

    p = psub.add_parser("four-step", formatter_class=RD, help="Jiang & Cripps four-step ball bar test",
                        description="DBB samples of the four steps (carrier axis with the short and the long "
                        "bar, then the carried axis), the axis commands of `fivecal dbb jiang`.",
                        epilog="example:\n  fivecal plan four-step machine.json --length 100 "
                        "--extended-length 150 --step 2 --out fourstep_plan.json")
    common(p)
    p.add_argument("--length", type=POSITIVE, default=100.0, help="bar length, mm (default 100)")
    p.add_argument("--extended-length", type=POSITIVE, default=150.0, help="bar with the extension, mm "
                   "(default 150)")
    p.add_argument("--step", type=POSITIVE, default=1.0, help="degrees between samples (default 1)")
    p.add_argument("--carrier-range", metavar="LO:HI", help="carrier (first) axis range, degrees (a negative "
                   "LO with '=': --carrier-range=-20:70)")
    p.add_argument("--carried-range", metavar="LO:HI", help="carried (second) axis range, degrees")
    p.add_argument("--tool-ball", metavar="X,Y,Z", help="the fixed ball, mm (default: the machine's choice)")
    p.add_argument("--setups", help="names of the four steps, comma separated")
    p.set_defaults(func=_four_step)

    p = psub.add_parser("wang", formatter_class=RD, help="Wang et al. simultaneous rotary ball bar path",
                        description="DBB samples along the path that keeps the table ball on a horizontal "
                        "circle around the still spindle ball (both rotary axes move). Evaluated by "
                        "`fivecal dbb wang`.",
                        epilog="example:\n  fivecal plan wang machine.json --radius 80 --height 60 "
                        "--out wang_plan.json")
    common(p)
    p.add_argument("--table-ball", metavar="X,Y,Z", help="table ball, workpiece frame, mm (default 0,150,130)")
    p.add_argument("--radius", type=POSITIVE, default=80.0, help="circle radius, mm (default 80)")
    p.add_argument("--height", type=_float_type(), default=60.0, help="spindle ball above the circle, mm "
                   "(default 60)")
    p.add_argument("--step", type=POSITIVE, default=1.0, help="degrees of tracking angle between samples")
    p.add_argument("--setup", default="W1", help="mounting name (default W1)")
    p.set_defaults(func=_wang)
