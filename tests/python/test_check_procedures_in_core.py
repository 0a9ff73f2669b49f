"""The sphere check's and the R-test's evaluation moved from Python into the
core (issue 29, item 2: ``procedures/sphere_check.h`` EvaluateSphereCheck,
``procedures/rtest.h`` EvaluateRTest, and the spindle naming rule
SpindleEquivalent / SpindleNames / PivotParameters beside them), and so did
their plans' numbers: the sphere check's positions spread over each rotary
axis' range (SphereCheckPositions) and the linear axes of an R-test path
(RTestPathCommands, for the plan and for the program's points between two
samples). The Python
they replaced is frozen here, only here, and the library's answers on
random cases must equal it to about 1e-12 relative. Bad input is refused at
the core boundary with a ValueError naming the field."""
from __future__ import annotations

import os
from typing import Dict, List

import numpy as np
import pytest

import fivecal
from fivecal import _core
from fivecal.identification import identify
from fivecal.io import nc_programs
from fivecal.procedures import rtest, sphere_check, sphere_test

MACHINES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines")
NAMES = ["c600u", "hu40t", "kx8", "vmc0656"]
BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
TIP = 3.0
REL = 1e-12


def _machine(name):
    return fivecal.Machine.load(os.path.join(MACHINES, f"{name}.json"))


def _close(new, old, rel=REL, abs_=1e-15):
    np.testing.assert_allclose(np.asarray(new, float), np.asarray(old, float), rtol=rel, atol=abs_)


# ---------------------------------------------------------------------------
# The old Python (sphere_check.py and rtest.py before the move), verbatim logic
# ---------------------------------------------------------------------------
def _old_rotary_axes(machine) -> List[str]:
    return [a for a in machine.axis_names if machine.is_rotary(a) and a != "S"]


def _old_spindle_equivalent(machine, name: str) -> str:
    if len(name) != 4 or name[0] != "E" or name[1] not in "XYZ" or name[2] != "0":
        return name
    axis, k = name[3], "XYZ".index(name[1])
    if "S" not in machine.axis_names or not machine.is_rotary(axis) or axis == "S":
        return name
    axes = machine.to_dict()["axes"]
    chain = machine.workpiece_chain if axis in machine.workpiece_chain else machine.tool_chain
    for a in chain[:chain.index(axis)]:
        u = np.abs(np.asarray(axes[a]["direction"], float))
        if machine.is_rotary(a) and u[k] < 1.0 - 1e-9:
            return name
    s = np.abs(np.asarray(axes["S"]["direction"], float))
    across = np.argsort(s, kind="stable")[:2]
    return f"E{name[1]}0S" if k in across else name


def _old_spindle_names(machine, errors) -> Dict[str, float]:
    out: Dict[str, float] = {}
    for n, v in errors.items():
        c = _old_spindle_equivalent(machine, n)
        out[c] = out.get(c, 0.0) + (v if c == n or n[3] not in machine.workpiece_chain else -float(v))
    return out


def _old_pivot_parameters(machine, axis: str, backlash: bool = True) -> List[str]:
    d = np.abs(np.asarray(machine.to_dict()["axes"][axis]["direction"], float))
    pick = sorted(np.argsort(d, kind="stable")[:2])
    names = [_old_spindle_equivalent(machine, f"E{'XYZ'[k]}0{axis}") for k in pick] + \
            [f"E{'ABC'[k]}0{axis}" for k in pick]
    return names + ([f"E{axis}{axis}b"] if backlash else [])


def _old_previous_values(prev_params, machine):
    out = dict(prev_params)
    for n, (v, s) in list(out.items()):
        c = _old_spindle_equivalent(machine, n)
        if c != n and c not in out:
            out[c] = (_old_spindle_names(machine, {n: v})[c], s)
    return out


def _old_sphere_check(ds, previous=None, calibrated_stylus=True, backlash=None, sphere=None):
    m = ds.machine
    obs = ds.observations
    spheres = sorted({o["target"] for o in obs if o.get("type") == "sphere"})
    sid = sphere or spheres[0]
    moved = [a for a in _old_rotary_axes(m) if np.ptp([float(o["axes"].get(a, 0.0)) for o in obs]) > 1e-6]
    names = []
    for a in moved:
        dirs = {int(o.get("direction", {}).get(a, 0)) for o in obs}
        both = {1, -1} <= dirs
        names += _old_pivot_parameters(m, a, backlash=both if backlash is None else backlash)
    fix = ["tip.x", "tip.y", "tip.z"] if calibrated_stylus else []
    r = identify(ds, names, fix=fix)
    std = r.std
    pivots, lash = {}, {}
    for a in moved:
        pivots[a] = {n: (r.values.get(n, 0.0), std.get(n, float("nan")))
                     for n in _old_pivot_parameters(m, a, backlash=False)}
        b = f"E{a}{a}b"
        if b in r.estimated:
            lash[a] = (r.values.get(b, 0.0), std.get(b, float("nan")))
    prev = _old_previous_values(previous or {}, m)
    change = {}
    for a in moved:
        for n, (v, s) in pivots[a].items():
            if n in prev:
                change[n] = (v - prev[n][0], float(np.hypot(s, prev[n][1])))
    key = [tuple(round(float(o["axes"].get(a, 0.0)), 6) for a in moved) for o in obs]
    order = list(dict.fromkeys(key))
    art = {s["id"]: s for s in ds.to_dict()["artefact"].get("spheres", [])}
    R = float(art[sid]["radius"]) + float(ds._core.tip_radius)
    c0 = np.asarray(art[sid]["center"], float)
    before, after, labels = [], [], []
    Pn, Pi = sphere_test.table_points(ds), sphere_test.table_points(ds, r)
    for k in order:
        idx = [i for i, kk in enumerate(key) if kk == k and obs[i].get("target") == sid]
        if len(idx) < 3:
            continue
        before.append(sphere_test.fit_sphere_centre(Pn[idx], R, c0))
        after.append(sphere_test.fit_sphere_centre(Pi[idx], R, c0))
        labels.append(", ".join(f"{a} {v:g}°" for a, v in zip(moved, k)))
    before, after = np.array(before), np.array(after)

    def spread(c):
        return float(np.linalg.norm(c - c.mean(axis=0), axis=1).max()) if len(c) else 0.0

    informed = {n: float(v) for n, v in (getattr(r, "informed", {}) or {}).items() if n in names}
    return dict(result=r, axes=moved, pivots=pivots, backlash=lash, change=change, before=before, after=after,
                labels=labels, dispersion_before=spread(before), dispersion_after=spread(after),
                condition_number=float(r.condition_number), informed=informed)


def _old_rtest(ds, identify_=True, estimate=None):
    groups: Dict[str, list] = {}
    for o in ds.observations:
        if o.get("type") == "ball3d":
            groups.setdefault(o.get("setup", "") or "(no setup)", []).append(o["measured"])
    tests = {}
    for name, rows in groups.items():
        d = np.asarray(rows, float)
        tests[name] = (len(d), d.max(axis=0) - d.min(axis=0), d)
    result, est = None, []
    if identify_:
        est = list(estimate or [n for a in _old_rotary_axes(ds.machine)
                                for n in _old_pivot_parameters(ds.machine, a, backlash=False)])
        result = identify(ds, est)
    return tests, result, est


# ---------------------------------------------------------------------------
# The comparisons
# ---------------------------------------------------------------------------
def _all_location_names(m):
    return [n for n in m.parameter_names() if len(n) == 4 and n[2] == "0"] + ["EQ0C", "EX0Q", "tip.x", "EXX1"]


@pytest.mark.parametrize("name", NAMES)
def test_spindle_rule_and_pivot_parameters_equal_the_old_python(name):
    m = _machine(name)
    for n in _all_location_names(m):
        assert sphere_check.spindle_equivalent(m, n) == _old_spindle_equivalent(m, n), n
    rng = np.random.default_rng(7)
    for _ in range(5):
        errors = {n: float(rng.normal(0, 0.01)) for n in m.parameter_names() if len(n) == 4 and n[2] == "0"}
        new, old = sphere_check.spindle_names(m, errors), _old_spindle_names(m, errors)
        assert list(new) == list(old)
        _close([new[k] for k in old], list(old.values()))
    for a in _old_rotary_axes(m):
        for b in (True, False):
            assert sphere_check.pivot_parameters(m, a, b) == _old_pivot_parameters(m, a, b)
    assert sphere_check._rotary_axes(m) == _old_rotary_axes(m)
    assert rtest.location_errors(m) == [n for a in _old_rotary_axes(m) for n in _old_pivot_parameters(m, a, False)]


def _random_check(name, seed):
    m = _machine(name)
    rng = np.random.default_rng(seed)
    truth = {n: float(rng.normal(0, 2e-5) if n[1] in "ABC" or n.endswith("b") else rng.normal(0, 0.015))
             for a in _old_rotary_axes(m) for n in _old_pivot_parameters(m, a)}
    plan = sphere_check.plan(m, BALL, tip_radius=TIP, n=int(rng.integers(3, 7)),
                             both_sides=bool(rng.integers(0, 2)))
    ds = fivecal.simulate(m, plan, errors=truth, artefact={"spheres": [BALL]}, tip_radius=TIP,
                          sigma=0.001, seed=seed)
    # a previous check under table-axis names and spindle names alike, some std zero
    prev = {n: (float(v + rng.normal(0, 0.002)), float(abs(rng.normal(0, 0.001))) * int(rng.integers(0, 2)))
            for n, v in truth.items()}
    prev.update({f"E{n[1]}0{a}": (0.003, 0.0005) for a in _old_rotary_axes(m) for n in ("EX", "EY")})
    return m, ds, prev, rng


@pytest.mark.filterwarnings("ignore::fivecal.FitWarning")  # some cases leave a simulated reversal out on purpose
@pytest.mark.parametrize("name,seed", [(n, s) for n in NAMES for s in (1, 2)])
def test_sphere_check_equals_the_old_python(name, seed):
    m, ds, prev, rng = _random_check(name, seed)
    backlash = [None, True, False][int(rng.integers(0, 3))]
    stylus = bool(rng.integers(0, 2)) or seed == 1
    old = _old_sphere_check(ds, previous=prev, calibrated_stylus=stylus, backlash=backlash)
    doc = {"parameters": {n: {"value": v, "std": s} for n, (v, s) in prev.items()}}
    new = sphere_check.evaluate(ds, previous=doc, calibrated_stylus=stylus, backlash=backlash)
    assert new.axes == old["axes"] and new.groups == old["labels"]
    assert new.result.estimated == old["result"].estimated and new.result.verdict == old["result"].verdict
    for a in old["axes"]:
        assert list(new.pivots[a]) == list(old["pivots"][a])
        _close([p for v in new.pivots[a].values() for p in v], [p for v in old["pivots"][a].values() for p in v])
    assert new.backlash.keys() == old["backlash"].keys()
    _close([p for v in new.backlash.values() for p in v], [p for v in old["backlash"].values() for p in v])
    assert list(new.change) == list(old["change"]) and new.change
    _close([p for v in new.change.values() for p in v], [p for v in old["change"].values() for p in v])
    _close(new.centres_before, old["before"])
    _close(new.centres_after, old["after"])
    # a dispersion is a difference of centres some 100 mm from the origin
    # (numpy's pairwise mean against Eigen's): equal to 1e-12 of that scale
    _close([new.dispersion_before, new.dispersion_after], [old["dispersion_before"], old["dispersion_after"]],
           abs_=1e-12 * np.abs(old["before"]).max())
    _close(new.condition_number, old["condition_number"])
    assert new.informed.keys() == old["informed"].keys()
    _close(list(new.informed.values()), list(old["informed"].values()))


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_rtest_equals_the_old_python(seed):
    m = _machine("c600u")
    rng = np.random.default_rng(seed)
    truth = {n: float(rng.normal(0, 1e-5) if n[1] in "ABC" else rng.normal(0, 0.01))
             for n in ["EX0C", "EY0C", "EA0C", "EB0C", "EY0A", "EZ0A", "EB0A", "EC0A"]}
    ball = [float(x) for x in rng.uniform([80, -60, 60], [150, 60, 120])]
    plan = [e for t in rtest.TESTS for e in rtest.plan(m, t, table_ball=ball, step=float(rng.choice([10, 15, 20])))]
    ds = fivecal.simulate(m, plan, errors=truth, sigma={"ball3d": 0.0005}, seed=seed)
    estimate = None if seed != 5 else ["EX0S", "EY0C", "EA0C", "EB0C", "EY0S", "EZ0A", "EB0A", "EC0A"]
    new = rtest.evaluate(ds, estimate=estimate)
    tests, r, est = _old_rtest(ds, estimate=estimate)
    assert list(new.tests) == list(tests)
    for t, (n, rng_, d) in tests.items():
        assert new.tests[t].samples == n
        _close(new.tests[t].ranges, rng_)
        _close(new.tests[t].deviations, d)
    assert new.estimated == est and new.result.estimated == r.estimated
    _close([new.result.values[n] for n in r.estimated], [r.values[n] for n in r.estimated])
    _close([new.result.std[n] for n in r.estimated], [r.std[n] for n in r.estimated])
    only = rtest.evaluate(ds, identify=False)
    assert only.result is None and list(only.tests) == list(tests)


# ---------------------------------------------------------------------------
# Bad input, refused at the core boundary naming the field
# ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def check_data():
    m, ds, prev, _ = _random_check("c600u", 9)
    return m, ds


def test_sphere_check_refuses_bad_input_naming_the_field(check_data):
    m, ds = check_data
    with pytest.raises(ValueError, match=r"^previous\.EX0C: value is not finite"):
        _core.sphere_check(ds._core, previous={"EX0C": (float("inf"), 0.0)})
    with pytest.raises(ValueError, match=r"^previous\.EY0C: std"):
        _core.sphere_check(ds._core, previous={"EY0C": (0.0, -1.0)})
    with pytest.raises(ValueError, match=r"^backlash: 2"):
        _core.sphere_check(ds._core, backlash=2)
    with pytest.raises(ValueError, match=r"^sphere: no touches of sphere 'S9' \(touched: S1\)"):
        _core.sphere_check(ds._core, sphere="S9")
    with pytest.raises(ValueError, match="sphere: no touches of sphere 'S9'"):
        sphere_check.evaluate(ds, sphere="S9")
    with pytest.raises(ValueError, match=r"^axis: 'CA' is not one axis letter"):
        _core.pivot_parameters(m._core, "CA")
    with pytest.raises(ValueError, match=r"^axis: machine '.*' has no rotary axis 'X'"):
        _core.pivot_parameters(m._core, "X")
    # a previous check written with an infinite value is refused, not turned into an infinite change
    with pytest.raises(ValueError, match=r"previous\.EX0C"):
        sphere_check.evaluate(ds, previous={"parameters": {"EX0C": {"value": float("inf"), "std": 0.0}}})
    # what the check does not compare with is not read: a previous fit's set-up, any value
    c = sphere_check.evaluate(ds, previous={"parameters": {"sphere.S1.x": {"value": float("nan"), "std": 0.0},
                                                           "EY0C": {"value": 0.0, "std": 0.0}}})
    assert list(c.change) == ["EY0C"]
    # no sphere touches at all: the dataset's ball3d data is not a sphere check
    rds = fivecal.simulate(m, rtest.plan(m, "K1", table_ball=[120.0, -40.0, 80.0], step=30), errors={},
                           sigma={"ball3d": 0.0005}, seed=1)
    with pytest.raises(ValueError, match="no sphere touches"):
        _core.sphere_check(rds._core)
    with pytest.raises(ValueError, match="no ball3d observations"):
        _core.rtest(ds._core)
    with pytest.raises(ValueError, match=r"^estimate\[1\]: an empty parameter name"):
        _core.rtest(rds._core, estimate=["EX0S", ""])
    with pytest.raises(ValueError, match="EQ0Q"):
        rtest.evaluate(rds, estimate=["EQ0Q"])


# ---------------------------------------------------------------------------
# The K tests' rotary poses (was rtest._roles and rtest._sequence)
# ---------------------------------------------------------------------------
def _old_roles(machine):
    rot = _old_rotary_axes(machine)
    if len(rot) != 2:
        raise ValueError(f"R-test K tests: machine {machine.name!r} has {len(rot)} rotary axes "
                         f"({', '.join(rot) or 'none'}); the tests are defined for two")
    axes = machine.to_dict()["axes"]
    z = [abs(float(np.asarray(axes[a]["direction"], float)[2])) for a in rot]
    turn = rot[int(np.argmax(z))]
    return {"turn": turn, "tilt": [a for a in rot if a != turn][0]}


def _old_sequence(machine, test, step, tilt, tilt_range):
    r = _old_roles(machine)
    turn, tl = r["turn"], r["tilt"]
    full = list(np.arange(0.0, 360.0 + 1e-9, step))
    if test == "K1":
        return [{turn: float(c), tl: 0.0} for c in full]
    if test == "K2":
        lo, hi = tilt_range
        return [{turn: 0.0, tl: float(a)} for a in np.arange(lo, hi + 1e-9, step)]
    if test == "K3":
        return [{turn: float(c), tl: float(tilt)} for c in full]
    if test == "K4":
        return [{turn: float(c), tl: float(tilt * np.sin(np.radians(c)))} for c in full]
    raise ValueError(test)


@pytest.mark.parametrize("name", NAMES)
def test_k_test_poses_equal_the_old_python(name):
    m = _machine(name)
    rng = np.random.default_rng(11)
    assert rtest._roles(m) == _old_roles(m)
    for _ in range(4):
        step = float(rng.choice([0.7, 5.0, 7.3, 15.0, 22.5]))
        tilt = float(rng.uniform(-90, 90))
        tilt_range = tuple(sorted(float(x) for x in rng.uniform(-120, 120, 2)))
        for t in rtest.TESTS:
            new, old = rtest._sequence(m, t, step, tilt, tilt_range), _old_sequence(m, t, step, tilt, tilt_range)
            assert len(new) == len(old) and all(list(a) == list(b) for a, b in zip(new, old)), (t, step)
            _close([v for e in new for v in e.values()], [v for e in old for v in e.values()])


def test_k_test_poses_refuse_bad_input_naming_the_field():
    m = _machine("c600u")
    for kw, field in [(dict(test="K5"), "test"), (dict(step=0.0), "step"), (dict(step=float("nan")), "step"),
                      (dict(tilt=float("inf")), "tilt"), (dict(tilt_range=(30.0, -30.0)), "tilt_range")]:
        args = dict(test="K2", step=15.0, tilt=-45.0, tilt_range=(-90.0, 90.0)) | kw
        with pytest.raises(ValueError, match=rf"^{field}: "):
            _core.rtest_sequence(m._core, **args)
    three = fivecal.Machine.from_dict({"name": "3ax", "topology": "wfXYZt",
                                       "axes": {a: {"type": "linear", "direction": d} for a, d in
                                                (("X", [1, 0, 0]), ("Y", [0, 1, 0]), ("Z", [0, 0, 1]))},
                                       "tool": {"tip": [0, 0, 100]}})
    with pytest.raises(ValueError, match="has 0 rotary axes \\(none\\); the tests are defined for two"):
        _core.rtest_axis_roles(three._core)


# ---------------------------------------------------------------------------
# The plans' numbers (was sphere_check.positions, the linear axes of
# rtest.plan with rtest.tip_offset, and nc_programs.rtest_points' subdivision)
# ---------------------------------------------------------------------------
def _old_positions(machine, n=5, limits=None):
    out = {}
    for a in _old_rotary_axes(machine):
        lo, hi = (limits or {}).get(a, (-180.0, 180.0) if a in ("C",) else (-90.0, 90.0))
        lo, hi = float(lo), float(hi)
        if not hi > lo:
            raise ValueError(f"limits.{a}: ({lo:g}, {hi:g}) is not a range")
        full = hi - lo >= 360.0 - 1e-9
        k = int(n)
        out[a] = [float(v) for v in (np.linspace(lo, hi, k, endpoint=False) if full else np.linspace(lo, hi, k))]
    return out


def _old_tip_offset(machine, axes, tool_ball):
    q = {a: np.array([float(v)]) for a, v in axes.items()}
    return machine.tool_point(q)[0] - machine.tool_point(q, tip=np.asarray(tool_ball, float))[0]


def _old_rtest_plan(m, test, table_ball, tool_ball=None, step=15.0, tilt=-45.0, tilt_range=(-90.0, 90.0)):
    seq = rtest._sequence(m, test, float(step), float(tilt), tilt_range)
    tb = np.asarray(table_ball, float)
    tool = np.asarray(tool_ball if tool_ball is not None else m.tip, float)
    entries = []
    prev = {a: 0.0 for a in m.axis_names}
    for k, rot in enumerate(seq):
        start = dict(prev)
        start.update(rot)
        lin = m.inverse([tb + _old_tip_offset(m, start, tool)], start=start)
        axes = {a: float(v[0]) for a, v in lin.items()}
        axes.update(rot)
        direction = {a: (1 if rot[a] >= prev.get(a, 0.0) else -1) for a in rot}
        entries.append({"axes": axes, "direction": direction})
        prev = axes
    return entries


def _old_rtest_points(machine, entries, subdivide):
    rot = [a for a in machine.axis_names if machine.is_rotary(a) and a != "S"]
    full = lambda axes: {a: float(axes.get(a, 0.0)) for a in machine.axis_names if a != "S"}  # noqa: E731
    pts = []
    for i, e in enumerate(entries):
        q = full(e["axes"])
        if i and subdivide:
            q0 = pts[-1]["axes"]
            tb = np.asarray(e["table_ball"], float)
            for s in np.arange(1, subdivide + 1) / (subdivide + 1):
                r = {a: q0[a] + s * (q[a] - q0[a]) for a in rot}
                at = {**q0, **r}
                lin = machine.inverse([tb + _old_tip_offset(machine, at, e["tool_ball"])], start=at)
                pts.append({"axes": {**{a: float(v[0]) for a, v in lin.items() if a != "S"}, **r}, "sample": None})
        pts.append({"axes": q, "sample": i, "id": e.get("id")})
    return pts


@pytest.mark.parametrize("name", NAMES)
def test_sphere_check_positions_equal_the_old_python(name):
    m = _machine(name)
    rng = np.random.default_rng(13)
    rot = _old_rotary_axes(m)
    cases = [(5, None), (3, None), (360, None), (7, {"C": (0.0, 360.0)}), (4, {"C": (-30.0, 300.0)})]
    for _ in range(6):
        lim = {a: tuple(sorted(float(x) for x in rng.uniform(-200, 200, 2))) for a in rot if rng.integers(0, 2)}
        cases.append((int(rng.integers(3, 40)), lim | {"X": (0.0, 1.0)}))
    for n, lim in cases:
        new, old = sphere_check.positions(m, n, lim), _old_positions(m, n, lim)
        assert list(new) == list(old)
        for a in old:
            assert len(new[a]) == len(old[a]) == n
            _close(new[a], old[a])
    with pytest.raises(ValueError, match=rf"^limits\.{rot[0]}: \(30, -30\) is not a range$"):
        sphere_check.positions(m, 5, {rot[0]: (30, -30)})
    with pytest.raises(ValueError, match=r"^n: 361 positions per axis"):
        _core.sphere_check_positions(m._core, 361, {})
    with pytest.raises(ValueError, match=r"^n: 2 positions per axis"):
        sphere_check.positions(m, 2)


@pytest.mark.parametrize("name", NAMES)
def test_rtest_plan_axes_equal_the_old_python(name):
    m = _machine(name)
    rng = np.random.default_rng(17)
    for _ in range(3):
        ball = [float(x) for x in rng.uniform([60, -80, 40], [160, 80, 140])]
        tool = None if rng.integers(0, 2) else [float(x) for x in rng.uniform(-5, 5, 3) + m.tip]
        step = float(rng.choice([5.0, 7.3, 15.0, 30.0]))
        tilt = float(rng.uniform(-60, 60))
        for t in rtest.TESTS:
            new = rtest.plan(m, t, table_ball=ball, tool_ball=tool, step=step, tilt=tilt)
            old = _old_rtest_plan(m, t, ball, tool, step, tilt)
            assert len(new) == len(old)
            for e, o in zip(new, old):
                assert list(e["axes"]) == list(o["axes"]) and e["direction"] == o["direction"]
                _close(list(e["axes"].values()), list(o["axes"].values()))


@pytest.mark.parametrize("name", NAMES)
def test_rtest_program_points_equal_the_old_python(name):
    m = _machine(name)
    plan = [e for t in ("K1", "K4") for e in rtest.plan(m, t, table_ball=[110.0, -30.0, 70.0], step=45.0)]
    for sub in (0, 1, 4):
        new, old = nc_programs.rtest_points(m, plan, subdivide=sub), _old_rtest_points(m, plan, sub)
        assert [(p["sample"], list(p["axes"])) for p in new] == [(p["sample"], list(p["axes"])) for p in old]
        _close([v for p in new for v in p["axes"].values()], [v for p in old for v in p["axes"].values()])


def test_rtest_path_commands_refuse_bad_input_naming_the_field():
    m = _machine("c600u")
    na = len(m.axis_names)
    with pytest.raises(ValueError, match=r"^rotary: 2 columns"):
        _core.rtest_path_commands(m._core, np.zeros((3, 2)), np.zeros(na), np.ones(3), np.ones(3), True)
    with pytest.raises(ValueError, match=r"^start: 1 values"):
        _core.rtest_path_commands(m._core, np.zeros((3, na)), np.zeros(1), np.ones(3), np.ones(3), True)
    with pytest.raises(ValueError, match=r"^table_ball: not finite"):
        _core.rtest_path_commands(m._core, np.zeros((3, na)), np.zeros(na), np.array([0, np.nan, 0]), np.ones(3),
                                  True)
