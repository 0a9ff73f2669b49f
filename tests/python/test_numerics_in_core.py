"""Numerics moved from Python into the C++ core (issue #29, item 2), each
pinned to the Python it replaced: a copy of the old code lives here (only
here), and the library's answer on representative inputs must equal it to
about 1e-9 relative.

* the cyclic-error pitch search of the planar circular test and its
  Bonferroni gate (was ``dbb._search_cyclic_pitch`` and a block of
  ``dbb.circular_test``; now ``AnalyzeCircularTest`` with a searched pitch);
* the Wang four-point extraction's SVD (was ``dbb.wang_four_point``; now
  ``AnalyzeWangFourPoint``);
* the centre of a sphere of known radius (was ``sphere_check._centre``; now
  ``FitSphereCentre`` beside ``FitSphere``);
* the bar restored along its direction by the linear axes (was
  ``dbb_program._Bar.restore``, Newton with ``pinv``; now ``BarLengthCommands``
  beside ``ToolBallCommands``);
* one ``rotary_directions`` for the design layer and TANGO, with one rule for
  an axis an indexation does not name;
* one controller absorber for the generic pivot models, LinuxCNC's trt and
  5axiskins (was ``io/controllers.absorb``, a finite-difference Gauss-Newton,
  and 5axiskins in numpy; now ``Absorb`` and ``linuxcnc_5axis`` in
  ``cpp/src/controllers``);
* the neutral kinematics table and the screw kinematics it describes (was
  numpy in ``io/controllers``; now ``kinematics_table.cc``);
* compensation batched over poses (was a per-pose loop in
  ``compensation.compensate_poses``; now ``CompensateCommands``);
* the facet residual of LinuxCNC's probe depths and simulated probe planes
  (was n.(P - a) - r in ``io/linuxcnc.py``; now the core's facet kind through
  ``predict_residuals``).
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

import fivecal
from fivecal import _core, compensation, design
from fivecal.io import controllers as K
from fivecal.io import dbb_program
from fivecal.io import linuxcnc as L
from fivecal.procedures import dbb, sphere_check, sphere_test, tango
from test_linuxcnc import MACHINES as LINUXCNC_MACHINES, TRUE_LOCATION, _octagon, _probe_plan

MACHINES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines")
REL = 1e-9


def _close(new, old, rel=REL, abs_=1e-12):
    np.testing.assert_allclose(np.asarray(new, float), np.asarray(old, float), rtol=rel, atol=abs_)


# ---------------------------------------------------------------------------
# Cyclic pitch search and its significance gate (old Python, verbatim logic)
# ---------------------------------------------------------------------------
def _old_search_cyclic_pitch(runs, radius, axis, fit):
    phis, resid, steps = [], [], []
    for r in runs:
        phi = np.radians(r.angles)
        cols = [np.ones_like(phi)]
        for k in range(1, 9):
            cols += [np.cos(k * phi), np.sin(k * phi)]
        B = np.column_stack(cols)
        coef, *_ = np.linalg.lstsq(B, r.readings, rcond=None)
        phis.append(phi)
        resid.append(r.readings - B @ coef)
        x = radius * (np.cos(phi) if axis == 1 else np.sin(phi))
        steps.append(np.max(np.abs(np.diff(x))) if x.size > 1 else radius)
    phi, res = np.concatenate(phis), np.concatenate(resid)
    x = radius * (np.cos(phi) if axis == 1 else np.sin(phi))
    proj = np.cos(phi) if axis == 1 else np.sin(phi)
    p_min, p_max = 4.0 * max(steps), radius / 2.0
    if not p_min < p_max:
        raise ValueError(f"cyclic_pitch auto: the samples are {max(steps):.3g} mm apart along the axis; too "
                         f"sparse to find a pitch below R/2 = {p_max:g} mm (sample more densely or give the pitch)")
    dinv = 1.0 / (16.0 * radius)
    inv = np.arange(1.0 / p_max, 1.0 / p_min + dinv, dinv)
    best, power = None, -1.0
    for chunk in np.array_split(inv, max(1, inv.size // 64)):
        arg = 2 * np.pi * np.outer(chunk, x)
        C, S = proj * np.cos(arg), proj * np.sin(arg)
        cc, ss, cs = (C * C).sum(1), (S * S).sum(1), (C * S).sum(1)
        cr, sr = C @ res, S @ res
        det = cc * ss - cs * cs
        pw = (ss * cr * cr - 2 * cs * cr * sr + cc * sr * sr) / np.where(det > 0, det, np.inf)
        j = int(np.argmax(pw))
        if pw[j] > power:
            power, best = float(pw[j]), float(chunk[j])
    fine = np.linspace(best - dinv, best + dinv, 9)
    fine = fine[fine > 0]
    rms = [fit(1.0 / f if axis == 1 else 0.0, 1.0 / f if axis == 2 else 0.0, 0.0).diagnosis.rms for f in fine]
    return 1.0 / float(fine[int(np.argmin(rms))]), int(inv.size)


def _old_auto(runs, radius, pitches, significance=3.0):
    """The old circular_test's pitch handling on already trimmed runs:
    (pitches, searched, final core result, dropped)."""
    packed = [(r.angles, r.readings, int(r.direction)) for r in runs]

    def fit(p1, p2, sig):
        return _core.circular_test(packed, float(radius), 0.0, cyclic_pitch1=p1, cyclic_pitch2=p2,
                                   significance=sig)

    pitches = list(pitches)
    searched = {}
    for k in (1, 2):
        if pitches[k - 1] == "auto":
            pitches[k - 1], searched[k] = _old_search_cyclic_pitch(runs, float(radius), k, fit)
    core = fit(pitches[0], pitches[1], float(significance))
    dropped = []
    if searched and significance > 0:
        d = fit(pitches[0], pitches[1], 0.0).diagnosis
        vals = dict(zip(d.names, np.asarray(d.values)))
        sds = dict(zip(d.names, np.asarray(d.std)))
        for k, n_tried in searched.items():
            c, sn = f"cyclic_error.{k}.cos", f"cyclic_error.{k}.sin"
            tail = math.erfc(significance / math.sqrt(2.0))
            need = math.sqrt(-2.0 * math.log(tail / n_tried))
            z = math.hypot(vals[c] / sds[c], vals[sn] / sds[sn]) if c in vals else 0.0
            if z < need:
                dropped.append(f"cyclic_error.{k} (pitch {pitches[k - 1]:.4g} mm searched among {n_tried}: "
                               f"{z:.2g} sigma, {need:.2g} needed)")
                pitches[k - 1] = 0.0
        if dropped:
            core = fit(pitches[0], pitches[1], float(significance))
    return pitches, searched, core, dropped


R = 100.0


def _run(direction, seed, cyc1=None, cyc2=None, step=0.5, sigma=0.0003):
    """A CCW (+1) or CW (-1) run with a little scale, squareness and backlash
    and, optionally, a periodic error (amplitude, pitch, phase) per axis."""
    n = int(round(360.0 / step))
    deg = direction * step * np.arange(n)
    phi = np.radians(deg)
    x1, x2 = R * np.cos(phi), R * np.sin(phi)
    v1, v2 = -direction * np.sign(np.round(np.sin(phi), 12)), direction * np.sign(np.round(np.cos(phi), 12))
    e1 = 6e-6 * x1 - 5e-6 * x2 + 0.0006 * v1
    e2 = -3e-6 * x2 + 0.0005 * v2
    if cyc1:
        a, p, ph = cyc1
        e1 = e1 + a * np.cos(2 * np.pi * x1 / p + ph)
    if cyc2:
        a, p, ph = cyc2
        e2 = e2 + a * np.cos(2 * np.pi * x2 / p + ph)
    rng = np.random.default_rng(seed)
    d = np.hypot(x1 + e1, x2 + e2) - R + rng.normal(0.0, sigma, n)
    return dbb.Trace(deg, d, direction)


CYCLIC_CASES = {
    "axis 2 found": ([_run(-1, 31, cyc2=(0.003, 8.0, 0.7)), _run(1, 32, cyc2=(0.003, 8.0, 0.7))], (0, "auto"), 3.0),
    "nothing periodic": ([_run(-1, 33), _run(1, 34)], ("auto", "auto"), 3.0),
    "both found": ([_run(-1, 35, (0.002, 7.0, 0.2), (0.004, 11.0, 1.1)),
                    _run(1, 36, (0.002, 7.0, 0.2), (0.004, 11.0, 1.1))], ("auto", "auto"), 3.0),
    "one run, no gate": ([_run(1, 37, cyc1=(0.003, 12.5, -0.4))], ("auto", 0), 0.0),
    "given and searched": ([_run(-1, 38, (0.002, 10.0, 0.0), (0.003, 9.0, 0.3)),
                            _run(1, 39, (0.002, 10.0, 0.0), (0.003, 9.0, 0.3))], (10.0, "auto"), 3.0),
}


@pytest.mark.parametrize("case", sorted(CYCLIC_CASES))
def test_cyclic_pitch_search_and_gate_equal_the_old_python(case):
    runs, pitch, sig = CYCLIC_CASES[case]
    res = dbb.circular_test(runs, R, cyclic_pitch=pitch, significance=sig, trim=False)
    pitches, searched, core, dropped = _old_auto(runs, R, pitch, sig)
    _close(res.cyclic_pitch, pitches)
    assert set(res.cyclic_pitch_searched) == set(searched)
    d = core.diagnosis
    # the fitted values (the derived backlash.k means follow them)
    fitted = [n for n in res.diagnosis if n not in res.derived]
    assert fitted == list(d.names)
    _close([res.diagnosis[n] for n in fitted], np.asarray(d.values), abs_=1e-15)
    _close([res.diagnosis_std[n] for n in fitted], np.asarray(d.std), abs_=1e-15)
    assert res.not_significant == list(d.not_significant) + dropped
    _close(res.diagnosis_rms, d.rms)


def test_cyclic_pitch_search_refuses_sparse_samples_as_before():
    runs = [_run(-1, 40, step=8.0), _run(1, 41, step=8.0)]
    with pytest.raises(ValueError) as new:
        dbb.circular_test(runs, R, cyclic_pitch="auto", trim=False)
    with pytest.raises(ValueError) as old:
        _old_auto(runs, R, ("auto", "auto"))
    assert str(new.value) == str(old.value)


# ---------------------------------------------------------------------------
# Wang four-point extraction
# ---------------------------------------------------------------------------
def _old_wang_four_point(machine, readings=None, angles=(135.0, 225.0, 315.0, 405.0),
                         errors=dbb.WANG_ERRORS, scale=None):
    angles = np.asarray(angles, float)
    scale = dict(scale or {})
    sc = np.array([scale.get(n, 50e-6 if n.startswith(("EA", "EB", "EC")) else 0.01) for n in errors])
    pats = dbb.wang_patterns(machine, {n: float(v) for n, v in zip(errors, sc)})
    S = np.empty((len(angles), len(errors)))
    for j, n in enumerate(errors):
        p = pats[n]
        for i, a in enumerate(angles):
            k = np.flatnonzero(np.abs(p.tracking - a) < 1e-6)
            S[i, j] = p.readings[k[0]] / sc[j]
    _, sv, vt = np.linalg.svd(S * sc)
    tol = max(S.shape) * np.finfo(float).eps * 1e6 * sv[0]
    rank = int((sv > tol).sum())
    null = vt[rank:].T
    estimable = [n for j, n in enumerate(errors) if np.abs(null[j]).max(initial=0.0) < 1e-6]
    values = None
    if readings is not None and rank == len(errors):
        r = np.array([float(readings[a]) for a in angles])
        values = dict(zip(errors, np.linalg.lstsq(S, r, rcond=None)[0].tolist()))
    return S, sc, sv / sv[0], rank, null, estimable, values


@pytest.fixture(scope="module")
def vmc():
    return fivecal.Machine.load(os.path.join(MACHINES, "vmc0656.json"))


@pytest.mark.parametrize("errors", [dbb.WANG_ERRORS, ("EX0C", "EY0C", "EZ0C"), ("EX0C", "EY0C", "EA0C", "EB0C")])
def test_wang_four_point_equals_the_old_python(vmc, errors):
    truth = {"EX0C": 0.007, "EY0C": -0.005, "EZ0C": 0.006, "EA0C": 30e-6, "EB0C": -20e-6}
    plan = dbb.wang_plan(vmc)
    ds = fivecal.simulate(vmc, [{k: v for k, v in e.items() if k != "tracking"} for e in plan],
                          errors={n: truth[n] for n in errors}, sigma={"dbb": 0.0})
    readings = {e["tracking"]: o["reading"] for e, o in zip(plan, ds.observations)}
    new = dbb.wang_four_point(vmc, readings, errors=errors)
    S, sc, sv, rank, null, estimable, values = _old_wang_four_point(vmc, readings, errors=errors)
    _close(new.sensitivity, S)
    _close(new.scale, sc)
    _close(new.singular_values, sv, abs_=1e-13)
    assert new.rank == rank and new.estimable == estimable
    assert new.null_space.shape == null.shape
    # the null space is a subspace: compare its projector (signs are free)
    _close(new.null_space @ new.null_space.T, null @ null.T, abs_=1e-12)
    if values is None:
        assert new.values is None
    else:
        assert list(new.values) == list(values)
        _close(list(new.values.values()), list(values.values()))


# ---------------------------------------------------------------------------
# Centre of a sphere of known radius
# ---------------------------------------------------------------------------
def _old_centre(points, start, radius):
    c = start.astype(float).copy()
    for _ in range(20):
        d = points - c
        r = np.linalg.norm(d, axis=1)
        J = -d / r[:, None]
        step = np.linalg.lstsq(J, -(r - radius), rcond=None)[0]
        c += step
        if np.abs(step).max() < 1e-12:
            break
    return c


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("n, cap", [(3, 40.0), (5, 60.0), (12, 90.0), (33, 180.0)])
def test_known_radius_centre_equals_the_old_python(seed, n, cap):
    rng = np.random.default_rng(seed)
    radius = 15.5
    centre = np.array([80.0, 50.0, 60.0]) + rng.normal(0, 0.05, 3)
    # touches on a cap of half-angle `cap` deg about +Z (+ a little noise)
    th = np.radians(rng.uniform(0, cap, n))
    az = rng.uniform(0, 2 * np.pi, n)
    u = np.column_stack([np.sin(th) * np.cos(az), np.sin(th) * np.sin(az), np.cos(th)])
    pts = centre + (radius + rng.normal(0, 0.001, n))[:, None] * u
    start = np.array([80.0, 50.0, 60.0])
    _close(sphere_test.fit_sphere_centre(pts, radius, start), _old_centre(pts, start, radius), abs_=1e-9)


def test_sphere_check_centres_equal_the_old_python():
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    ball = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
    truth = {"EY0A": 0.012, "EZ0A": -0.008, "EB0C": 2e-5, "EAAb": 1e-5, "ECCb": -1.5e-5}
    truth = {k: v for k, v in truth.items() if k in m.parameter_names()}
    plan = sphere_check.plan(m, ball, tip_radius=3.0)
    ds = fivecal.simulate(m, plan, errors=truth, artefact={"spheres": [ball]}, tip_radius=3.0, sigma=0.001,
                          seed=5)
    c = sphere_check.evaluate(ds)
    obs = ds.observations
    key = [tuple(round(float(o["axes"].get(a, 0.0)), 6) for a in c.axes) for o in obs]
    Pn, Pi = sphere_test.table_points(ds), sphere_test.table_points(ds, c.result)
    c0, Rb = np.array(ball["center"]), ball["radius"] + 3.0
    before, after = [], []
    for k in dict.fromkeys(key):
        idx = [i for i, kk in enumerate(key) if kk == k]
        if len(idx) >= 3:
            before.append(_old_centre(Pn[idx], c0, Rb))
            after.append(_old_centre(Pi[idx], c0, Rb))
    _close(c.centres_before, before, abs_=1e-9)
    _close(c.centres_after, after, abs_=1e-9)


# ---------------------------------------------------------------------------
# The bar restored by the linear axes
# ---------------------------------------------------------------------------
def _old_restore(bar, Q, short=0.0):
    lin = [a for a in "XYZ" if a in bar.m.axis_names]
    Q = {a: np.array(v, float) for a, v in Q.items()}
    for _ in range(4):
        p = bar.ball(Q)
        cols = [bar.ball({**Q, a: Q[a] + 1.0}) - p for a in lin]
        J = np.stack(cols, axis=2)
        d = p - bar.table
        r = np.linalg.norm(d, axis=1)
        err = r - (bar.length - short)
        if np.abs(err).max() < 1e-12:
            break
        dp = -(err / r)[:, None] * d
        step = np.einsum("nij,nj->ni", np.linalg.pinv(J), dp)
        for k, a in enumerate(lin):
            Q[a] = Q[a] + step[:, k]
    return Q


def _bar_cases():
    c600u = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    hu40t = tango.hu40t_machine()  # X on the workpiece side
    out = [(c600u, dbb.four_step_plan(c600u, step=15.0))]
    e = {"type": "dbb", "setup": "H1", "tool_ball": [0.0, 0.0, 100.0], "table_ball": [30.0, -20.0, 40.0],
         "length": 120.0}
    rng = np.random.default_rng(4)
    hplan = []
    for _ in range(12):
        axes = {"X": rng.uniform(-50, 50), "Y": rng.uniform(-50, 50), "Z": rng.uniform(-50, 50),
                "B": rng.uniform(-60, 60), "C": rng.uniform(-180, 180), "S": 0.0}
        hplan.append(dict(e, axes=axes))
    out.append((fivecal.Machine.from_dict(hu40t), hplan))
    return out


@pytest.mark.parametrize("case", [0, 1])
@pytest.mark.parametrize("short", [0.0, 1.5])
def test_bar_restore_equals_the_old_python(case, short):
    m, plan = _bar_cases()[case]
    setups = {}
    for e in plan:
        setups.setdefault(e["setup"], []).append(e)
    for entries in setups.values():
        bar = dbb_program._Bar(m, entries[0])
        Q = {a: np.array([float(e["axes"].get(a, 0.0)) for e in entries]) for a in m.axis_names}
        # off the bar by up to a few mm, so that the restore has work to do
        rng = np.random.default_rng(len(entries))
        for a in "XYZ":
            Q[a] = Q[a] + rng.uniform(-3, 3, len(entries))
        new, old = bar.restore(Q, short), _old_restore(bar, Q, short)
        assert list(new) == list(old)
        for a in m.axis_names:
            _close(new[a], old[a], abs_=1e-9)
        np.testing.assert_allclose(bar.deviation(new), -short, atol=1e-10)


# ---------------------------------------------------------------------------
# rotary_directions: one implementation, one rule for an axis not named
# ---------------------------------------------------------------------------
def test_tango_and_design_share_one_rotary_directions():
    assert tango.rotary_directions is design.rotary_directions


def test_an_axis_an_indexation_does_not_name_is_at_zero():
    """An indexation that does not name an axis holds it at 0 (the command
    the plan writes for it), so moving back to 0 is a move with a
    direction; every axis asked for gets its direction at every
    indexation."""
    seq = [{"B": 30}, {"C": 90}, {"B": 30, "C": 90}, {"C": -45}]
    assert design.rotary_directions(seq, "BC") == [
        {"B": 1, "C": 1}, {"B": -1, "C": 1}, {"B": 1, "C": 1}, {"B": -1, "C": -1}]
    # the rule TANGO's plans always used, unchanged on indexations naming every axis
    full = [{"B": 30, "C": -90}, {"B": 60, "C": -180}, {"B": 45, "C": -180}, {"B": 45, "C": 0}]
    assert design.rotary_directions(full, "BC") == [
        {"B": 1, "C": -1}, {"B": 1, "C": -1}, {"B": -1, "C": -1}, {"B": -1, "C": 1}]
    assert design.rotary_directions(seq, "BC", start={"B": -1, "C": -1})[0] == {"B": 1, "C": -1}


def test_a_sphere_check_plan_records_the_return_to_zero_of_the_other_axis():
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    rot = sphere_check._rotary_axes(m)
    plan = sphere_check.plan(m, {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}, tip_radius=3.0)
    # the second axis' visits: the first axis is back at 0, reached by a move up
    # from the last (lowest) position of its descending pass
    first, second = rot[0], rot[1]
    later = [p for p in plan if abs(p["axes"][second]) > 1e-9]
    assert later and all(p["axes"][first] == 0.0 for p in later)
    assert all(p["direction"][first] == 1 for p in later)


def test_the_moved_functions_refuse_bad_input_naming_the_field():
    pts = np.array([[0.0, 0.0, 15.5], [3.0, 0.0, 15.2], [0.0, 3.0, 15.2], [-3.0, 0.0, 15.2]])
    with pytest.raises(ValueError, match=r"points\[1\]"):
        sphere_test.fit_sphere_centre(np.where(np.arange(12).reshape(4, 3) == 4, np.nan, pts), 15.5, [0, 0, 0])
    with pytest.raises(ValueError, match="radius"):
        sphere_test.fit_sphere_centre(pts, -1.0, [0, 0, 0])
    with pytest.raises(ValueError, match="points: need at least 3"):
        sphere_test.fit_sphere_centre(pts[:2], 15.5, [0, 0, 0])
    with pytest.raises(ValueError, match="start"):
        sphere_test.fit_sphere_centre(pts, 15.5, [0, 0])
    with pytest.raises(ValueError, match=r"scale\[1\]"):
        _core.wang_four_point(np.eye(2), np.array([1.0, 0.0]))
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    q = np.zeros((2, len(m.axis_names)))
    q[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"poses\[1\]"):
        _core.bar_length_commands(m._core, np.array([0, 0, 100.0]), np.zeros(3), 50.0, q)


# ---------------------------------------------------------------------------
# One controller absorber (was io/controllers.py: parameters, absorb with a
# finite-difference Gauss-Newton, and 5axiskins in numpy; now
# cpp/src/controllers/absorb.cc and linuxcnc_5axis.cc)
# ---------------------------------------------------------------------------
def _old_perpendicular(u):
    u = u / np.linalg.norm(u)
    order = np.argsort(np.abs(u), kind="stable")[:2]
    out = []
    for i in sorted(order):
        e = np.eye(3)[i] - (np.eye(3)[i] @ u) * u
        for f in out:
            e = e - (e @ f) * f
        out.append(e / np.linalg.norm(e))
    return out


def _old_parameters(machine, model, directions=False, tool_length=True):
    """(label, unit, column) of the old io/controllers.parameters (the
    topology checks aside)."""
    names = machine.parameter_names()
    idx = {n: i for i, n in enumerate(names)}

    def col(entries):
        c = np.zeros(len(names))
        for n, v in entries:
            c[idx[n]] = v
        return c

    rot = [a for a in machine.axes if a["type"] == "rotary" and a["name"] != "S"]
    if model == "5axiskins":
        directions, pivots, tool_length = False, False, True
    elif model in ("xyzac-trt", "xyzbc-trt"):
        directions, pivots, tool_length = False, True, False
    else:
        pivots = True
    out = []
    for a in rot if pivots else []:
        r = a["name"]
        for e in _old_perpendicular(np.asarray(a["direction"], float)):
            out.append((f"{r} pivot {'xyz'[int(np.argmax(np.abs(e)))]}", "mm",
                        col([(f"E{c}0{r}", v) for c, v in zip("XYZ", e)])))
    for a in rot if directions else []:
        r = a["name"]
        for e in _old_perpendicular(np.asarray(a["direction"], float)):
            out.append((f"{r} direction about {'xyz'[int(np.argmax(np.abs(e)))]}", "rad",
                        col([(f"E{c}0{r}", v) for c, v in zip("ABC", e)])))
    if tool_length:
        _, v = machine.tool_pose({n: 0.0 for n in machine.axis_names})
        out.append(("tool length", "mm", col([(f"tip.{c}", -float(x)) for c, x in zip("xyz", v[0])])))
    return out


def _old_absorb(machine, model, errors, poses, directions=False, tool_length=True):
    """The old io/controllers.absorb, verbatim logic: (labels, values, held,
    theta, shift, residual, residual_old, rms, max, rms_old, max_old)."""
    params = _old_parameters(machine, model, directions, tool_length)

    def points(theta, q):
        return np.asarray(_core.tool_poses(machine._core, theta, q, None, None, False)[0])

    def stats(r):
        n = np.linalg.norm(r, axis=1)
        return float(np.sqrt(np.mean(n ** 2))), float(n.max())

    q = machine.axes_matrix(poses)
    th_true, th0 = machine.theta(errors), machine.theta(None)
    truth = points(th_true, q)
    n, k = len(q), len(params)
    B = np.array([p[2] for p in params]).T if k else np.zeros((len(th0), 0))
    steps = np.array([1e-3 if p[1] == "mm" else 1e-6 for p in params])

    def jac(phi):
        J = np.zeros((3 * n, k + 3))
        for c in range(k):
            d = np.zeros(k)
            d[c] = steps[c]
            J[:, c] = ((points(th0 + B @ (phi + d), q) - points(th0 + B @ (phi - d), q)) / (2 * steps[c])).ravel()
        J[:, k:] = np.tile(np.eye(3), (n, 1))
        return J

    phi = np.zeros(k)
    J = jac(phi)
    keep, basis = [], []
    for c in list(range(k, k + 3)) + list(range(k)):
        v = J[:, c].copy()
        for b in basis:
            v -= (b @ v) * b
        if np.linalg.norm(v) > 1e-8 * max(np.linalg.norm(J[:, c]), 1e-300):
            keep.append(c)
            basis.append(v / np.linalg.norm(v))
    held = [params[c][0] for c in range(k) if c not in keep]
    shift = np.zeros(3)
    for _ in range(4):
        r = (truth - points(th0 + B @ phi, q) - shift).ravel()
        x = np.linalg.lstsq(J[:, keep], r, rcond=None)[0]
        step = np.zeros(k + 3)
        step[keep] = x
        phi, shift = phi + step[:k], shift + step[k:]
        if np.abs(step).max() < 1e-12:
            break
        J = jac(phi)
    theta = th0 + B @ phi
    residual = truth - points(theta, q) - shift
    r0 = truth - points(th0, q)
    r0 = r0 - r0.mean(axis=0)
    return ([p[0] for p in params], phi, held, theta, shift, residual, r0) + stats(residual) + stats(r0)


def _old_fiveaxis_forward(pivot_length, joints):
    j = np.atleast_2d(np.asarray(joints, dtype=float))
    b, c = np.radians(j[:, 3]), np.radians(j[:, 4])
    p = np.radians(180.0) - b
    L = pivot_length
    r = np.column_stack([L * np.sin(p) * np.cos(c), L * np.sin(p) * np.sin(c), L * np.cos(p)])
    return j[:, :3] + r + np.array([0.0, 0.0, L])


def _old_fiveaxis_inverse(pivot_length, world):
    w = np.atleast_2d(np.asarray(world, dtype=float))
    zero = np.column_stack([np.zeros((len(w), 3)), w[:, 3:5]])
    return np.column_stack([w[:, :3] - _old_fiveaxis_forward(pivot_length, zero), w[:, 3:5]])


def _old_match_5axis(machine):
    rot = {a["name"]: a for a in machine.axes if a["type"] == "rotary" and a["name"] != "S"}
    side = {n: "workpiece" if n in machine.workpiece_chain else "tool" for n in machine.axis_names}
    sign = {}
    for n in "XYZ":
        a = next(x for x in machine.axes if x["name"] == n)
        s = float(np.asarray(a["direction"], float)["XYZ".index(n)])
        sign[n] = s if side[n] == "tool" else -s
    sign["C"] = float(np.sign(rot["C"]["direction"][2]))
    sign["B"] = -float(np.sign(rot["B"]["direction"][1]))
    return {"sign": sign, "pivot_length": float(rot["B"]["point"][2] - machine.tip[2]), "origin": machine.tip}


def _machine(topology, rot, tip=(0, 0, 150), linear=None):
    axes = {"X": {"type": "linear", "direction": [1, 0, 0]}, "Y": {"type": "linear", "direction": [0, 1, 0]},
            "Z": {"type": "linear", "direction": [0, 0, 1]}, "S": {"type": "rotary", "direction": [0, 0, 1]}}
    axes.update(linear or {})
    axes.update(rot)
    return fivecal.Machine.from_dict({"name": topology, "topology": topology, "axes": axes,
                                      "tool": {"tip": list(tip)}})


ABSORB_MACHINES = {
    "hu40t": (lambda: fivecal.Machine.load(os.path.join(MACHINES, "hu40t.json")), "table-table"),
    "c600u": (lambda: fivecal.Machine.load(os.path.join(MACHINES, "c600u.json")), "table-table"),
    "head-head": (lambda: _machine("wXYfZCBSt", {
        "C": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 300]},
        "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, 300]}}, tip=(0, 0, 50)), "head-head"),
    "table-head": (lambda: _machine("wCXYfZBSt", {
        "C": {"type": "rotary", "direction": [0, 0, -1], "point": [5, -3, 0]},
        "B": {"type": "rotary", "direction": [0, 1, 0], "point": [0, 0, 250]}}), "table-head"),
    "xyzac-trt": (lambda: _machine("wCAfXYZSt", {
        "C": {"type": "rotary", "direction": [0, 0, 1], "point": [12, -7, 0]},
        "A": {"type": "rotary", "direction": [1, 0, 0], "point": [0, 20, -45]}}), "xyzac-trt"),
    "xyzbc-trt": (lambda: _machine("wCBYfXZSt", {
        "C": {"type": "rotary", "direction": [0, 0, -1], "point": [4, 9, 0]},
        "B": {"type": "rotary", "direction": [0, 1, 0], "point": [-30, 0, -60]}}, tip=(1, 2, 100),
        linear={"Y": {"type": "linear", "direction": [0, -1, 0]}}), "xyzbc-trt"),
    "5axiskins": (lambda: _machine("wXYfZCBSt", {
        "C": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 300]},
        "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, 300]}}, tip=(0, 0, 50)), "5axiskins"),
}


def _absorb_errors(m, kind):
    rot = [a["name"] for a in m.axes if a["type"] == "rotary" and a["name"] != "S"]
    e = {}
    for i, r in enumerate(rot):
        s = 1.0 if i == 0 else -0.7
        e.update({f"EX0{r}": 0.021 * s, f"EY0{r}": -0.013 * s, f"EZ0{r}": 0.017 * s})
        if kind in ("tilts", "all"):
            e.update({f"EA0{r}": 3e-5 * s, f"EB0{r}": -2e-5 * s, f"EC0{r}": 2.5e-5 * s})
    if kind == "all":
        e.update({"EC0Y": 4e-5, "EXX1": 2e-5, "EZ0S": -0.02, "ECC1": 1e-5})
    return {k: v for k, v in e.items() if k in m.parameter_names()}


@pytest.mark.parametrize("kind", ["pivots", "tilts", "all"])
@pytest.mark.parametrize("directions", [False, True])
@pytest.mark.parametrize("name", sorted(ABSORB_MACHINES))
def test_controller_absorber_equals_the_old_python(name, directions, kind):
    make, model = ABSORB_MACHINES[name]
    m = make()
    errors = _absorb_errors(m, kind)
    poses = K.pose_grid(m, n_linear=2, n_tilt=5, n_turn=6)
    new = K.absorb(m, model, errors, poses=poses, directions=directions)
    labels, phi, held, theta, shift, res, res0, rms, mx, rms0, mx0 = _old_absorb(m, model, errors, poses,
                                                                                  directions=directions)
    assert [p.label for p in new.parameters] == labels and new.held == held
    for p, (_, unit, column) in zip(new.parameters, _old_parameters(m, model, directions)):
        assert p.unit == unit
        _close(p.column, column, abs_=0)
    # The old Jacobian was a central difference (steps 1e-3 mm, 1e-6 rad),
    # the new one analytic: values agree to the difference of the Jacobians
    # times the residual, far below a nanometre.
    _close(new.values, phi, rel=1e-9, abs_=1e-12)
    _close(new.workpiece_shift, shift, rel=1e-9, abs_=1e-12)
    _close(new.theta, theta, rel=1e-9, abs_=1e-12)
    _close(new.residual, res, rel=1e-9, abs_=1e-12)
    _close(new.residual_old, res0, abs_=1e-15)
    _close([new.rms, new.max, new.rms_old, new.max_old], [rms, mx, rms0, mx0], rel=1e-9, abs_=1e-12)


def test_5axiskins_kinematics_equal_the_old_python():
    m = ABSORB_MACHINES["5axiskins"][0]()
    rng = np.random.default_rng(8)
    j = np.column_stack([rng.uniform(-80, 80, (30, 3)), rng.uniform(-95, 95, 30), rng.uniform(-400, 400, 30)])
    for L_ in (250.0, 0.0, 123.456):
        _close(K.fiveaxis_forward(L_, j), _old_fiveaxis_forward(L_, j), abs_=0)
        _close(K.fiveaxis_inverse(L_, j), _old_fiveaxis_inverse(L_, j), abs_=0)
    old, new = _old_match_5axis(m), K._match_5axis(m)
    assert new["sign"] == old["sign"] and new["pivot_length"] == old["pivot_length"]
    _close(new["origin"], old["origin"], abs_=0)
    q = {"X": j[:, 0], "Y": j[:, 1], "Z": j[:, 2], "B": j[:, 3], "C": j[:, 4], "S": np.zeros(30)}
    _close(K.fiveaxis_joints(m, q), np.column_stack([old["sign"][a] * q[a] for a in "XYZBC"]), abs_=0)


# ---------------------------------------------------------------------------
# Compensation batched over poses (was a per-pose loop in
# compensation.compensate_poses; now CompensateCommands, one core call)
# ---------------------------------------------------------------------------
def _old_compensate(machine, errors, axes, directions=None, orientation=True, max_rotary_correction=0.1,
                    reference_theta=None, reference_shift=None):
    q = machine.axes_matrix(axes)
    n = len(q)
    d = machine.directions_matrix(directions, n)
    theta, core = machine.theta(errors), machine._core
    ref = machine.theta(None) if reference_theta is None else np.asarray(reference_theta, float)
    P, A = _core.tool_poses(core, ref, q, None)
    if reference_shift is not None:
        P = P + np.asarray(reference_shift, float).reshape(1, 3)
    rot = np.array([a in "ABC" for a in machine.axis_names])
    out = np.empty_like(q)
    oriented = np.zeros(n, dtype=bool)
    for i in range(n):
        di = None if d is None else d[i:i + 1]
        sol = None
        if orientation:
            try:
                c = _core.inverse(core, theta, P[i:i + 1], A[i:i + 1], q[i], di)[0]
                if not rot.any() or np.abs(c[rot] - q[i, rot]).max() <= max_rotary_correction:
                    sol = c
                    oriented[i] = True
            except ValueError:
                sol = None
        if sol is None:
            try:
                sol = _core.inverse(core, theta, P[i:i + 1], None, q[i], di)[0]
            except ValueError as e:
                raise ValueError(f"pose {i}: {e}") from None
        out[i] = sol
    return out, oriented


@pytest.mark.parametrize("name", ["hu40t", "c600u", "head-head", "table-head", "xyzbc-trt"])
@pytest.mark.parametrize("orientation", [True, False])
def test_batched_compensation_equals_the_old_per_pose_loop(name, orientation):
    m = ABSORB_MACHINES[name][0]()
    errors = _absorb_errors(m, "all")
    errors.update({k: v for k, v in {"EXXb": 0.002, "ECCb": 1e-5}.items() if k in m.parameter_names()})
    rng = np.random.default_rng(11)
    n = 40
    axes = {}
    for a in m.axes:
        if a["name"] == "S":
            axes["S"] = np.zeros(n)
        elif a["type"] == "linear":
            axes[a["name"]] = rng.uniform(-100, 100, n)
        else:
            axes[a["name"]] = rng.uniform(-60, 60, n)
    # tool axis along the table's C axis (a singularity): the orientation falls back
    axes[[a["name"] for a in m.axes if a["type"] == "rotary" and a["name"] != "S"][-1]][:3] = 0.0
    dirs = {a: rng.choice([-1, 1], n) for a in m.axis_names if a != "S"}
    new = compensation.compensate_poses(m, errors, axes, directions=dirs, orientation=orientation,
                                        progress=False, max_correction=None, max_correction_deg=None)
    out, oriented = _old_compensate(m, errors, axes, dirs, orientation)
    _close(m.axes_matrix(new.axes), out, rel=0, abs_=0)  # the same core calls: identical
    assert list(new.orientation) == list(oriented)
    if orientation:
        assert 0 < oriented.sum() < n
    th = m.theta(None) + 0.0
    th[m.parameter_names().index(next(iter(errors)))] = 0.005
    new = compensation.compensate_poses(m, errors, axes, directions=dirs, orientation=orientation,
                                        progress=False, max_correction=None, max_correction_deg=None,
                                        reference_theta=th, reference_shift=[0.01, -0.02, 0.003])
    out, oriented = _old_compensate(m, errors, axes, dirs, orientation, reference_theta=th,
                                    reference_shift=[0.01, -0.02, 0.003])
    _close(m.axes_matrix(new.axes), out, rel=0, abs_=0)
    assert list(new.orientation) == list(oriented)


def test_batched_compensation_names_the_pose_it_cannot_reach():
    m = ABSORB_MACHINES["c600u"][0]()
    q = np.zeros((3, len(m.axis_names)))
    P, A = _core.tool_poses(m._core, m.theta(None), q, None)
    P[1, 0] = 1e9  # a unit slip: no command reaches it
    with pytest.raises(ValueError, match=r"^pose 1: inverse: points\[0\]\[0\]"):
        _core.compensate_commands(m._core, m.theta({"EX0C": 0.01}), P, A, q)
    with pytest.raises(ValueError, match=r"nominal: 2 columns"):
        _core.compensate_commands(m._core, m.theta(None), P, A, q[:, :2])


# ---------------------------------------------------------------------------
# The facet residual of io/linuxcnc's probe checks: the core's, not a copy
# ---------------------------------------------------------------------------
def _old_depths(m, obs, art, r, errors):
    facets = {f["id"]: f for f in art["facets"]}
    out = []
    for o in obs:
        f = facets[o["target"]]
        n = np.asarray(f["normal"], float)
        n = n / np.linalg.norm(n)
        p = m.tool_point({a: np.array([o["axes"][a]]) for a in m.axis_names}, errors=errors)[0]
        out.append(float(n @ (p - np.asarray(f["point"], float)) - r))
    return np.array(out)


def _old_trigger(m, kins, poses, art, r, errors):
    out = []
    for t, c in poses:
        jj = np.array([[0, 0, 0, t, c], [1, 0, 0, t, c], [0, 1, 0, t, c], [0, 0, 1, t, c]], float)
        p = m.tool_point(L.commands(m, kins, jj), errors=errors)
        M = (p[1:] - p[0]).T
        g, h = [], []
        for f in art["facets"]:
            n = np.asarray(f["normal"], float)
            n = n / np.linalg.norm(n)
            g.append((n @ M).tolist())
            h.append(float(n @ (p[0] - np.asarray(f["point"], float)) - r))
        out.append({"rot": [t, c], "g": g, "h": h})
    return out


@pytest.mark.parametrize("errors", [None, TRUE_LOCATION])
def test_linuxcnc_probe_checks_use_the_core_facet_residual(errors):
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(LINUXCNC_MACHINES[kins])
    art = _octagon()
    plan = _probe_plan(m, art)
    pins = L.nominal_pins(m, kins)
    geo = L._touch_geometry(m, kins, plan, art, 3.0)
    rng = np.random.default_rng(2)
    log = "".join(f"{w[0] + rng.uniform(-0.2, 0.2):f} {w[1]:f} {w[2]:f} {t:f} 0 {c:f} 0 0 0\n"
                  for t, c, w, _, _ in geo)
    obs = L.read_probe_log(log, m, kins, plan, pins)
    new = L.probe_depths(m, kins, plan, art, 3.0, log, pins, errors=errors)
    _close(new, _old_depths(m, obs, art, 3.0, errors), rel=0, abs_=1e-12)
    assert np.abs(new).max() > 0.01  # the jitter shows: the comparison can fail
    model = L.probe_trigger_model(m, kins, plan, art, 3.0, errors=errors)
    old = _old_trigger(m, kins, [tuple(p["rot"]) for p in model], art, 3.0, errors)
    assert [p["rot"] for p in model] == [p["rot"] for p in old]
    for a, b in zip(model, old):
        _close(a["h"], b["h"], rel=0, abs_=1e-12)
        _close(a["g"], b["g"], rel=0, abs_=1e-11)
    with pytest.raises(ValueError, match="probe depths are of facet touches"):
        L.probe_depths(m, kins, [dict(p, type="sphere") for p in plan], art, 3.0, log, pins)


# ---------------------------------------------------------------------------
# The neutral kinematics table and the kinematics it describes (was numpy in
# io/controllers.py; now cpp/src/controllers/kinematics_table.cc)
# ---------------------------------------------------------------------------
def _old_rot_zyx(a, b, c):
    ca, sa, cb, sb, cc, sc = math.cos(a), math.sin(a), math.cos(b), math.sin(b), math.cos(c), math.sin(c)
    return np.array([[cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa],
                     [sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa],
                     [-sb, cb * sa, cb * ca]])


def _old_kinematics_table(machine, th):
    names = machine.parameter_names()
    val = dict(zip(names, th))
    axes = {a["name"]: a for a in machine.axes}
    rows, frames = [], {}
    for chain_name, chain in (("workpiece", machine.workpiece_chain), ("tool", machine.tool_chain)):
        R, t, parent = np.eye(3), np.zeros(3), np.zeros(3)
        for n in chain:
            a = axes[n]
            p = np.asarray(a.get("point") or [0.0, 0.0, 0.0], float)
            loc = [val.get(f"E{c}0{n}", 0.0) for c in "XYZABC"]
            t = t + R @ (np.asarray(loc[:3]) + p - parent)
            R = R @ _old_rot_zyx(*loc[3:])
            parent = p
            if n != "S":
                rows.append({"axis": n, "chain": chain_name, "type": a["type"],
                             "direction": R @ np.asarray(a["direction"], float), "point": t.copy(),
                             "nominal_point": p})
        frames[chain_name] = (R, t, parent)
    Rw, tw, pw = frames["workpiece"]
    Rt, tt, pt = frames["tool"]
    tip = machine.tip + np.array([val.get(f"tip.{c}", 0.0) for c in "xyz"])
    out_rows = []
    for r in rows:
        d = r["direction"]
        row = {"axis": r["axis"], "chain": r["chain"], "type": r["type"], "direction": d}
        if r["type"] == "rotary":
            o = r["point"]
            row["point"] = o + ((r["nominal_point"] - o) @ d) * d
        out_rows.append(row)
    _, v = machine.tool_pose({n: 0.0 for n in machine.axis_names},
                             errors={n: float(x) for n, x in zip(names, th) if x != 0.0})
    return {"axes": out_rows, "tool_tip": tt + Rt @ (tip - pt), "tool_axis": Rw @ np.asarray(v[0]),
            "part_origin": tw - Rw @ pw, "part_rotation": Rw}


def _old_axis_angle(u, q):
    u = u / np.linalg.norm(u)
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.eye(3) + math.sin(q) * K + (1 - math.cos(q)) * K @ K


def _old_table_tool_points(table, axes):
    names = [r["axis"] for r in table["axes"]]
    qs = {n: np.atleast_1d(np.asarray(axes.get(n, 0.0), dtype=float)) for n in names}
    n = max(len(v) for v in qs.values())
    out = np.zeros((n, 3))
    Rw = np.asarray(table.get("part_rotation", np.eye(3)), dtype=float)
    Wt = np.asarray(table.get("part_origin", np.zeros(3)), dtype=float)
    rows = {c: [r for r in table["axes"] if r["chain"] == c] for c in ("workpiece", "tool")}
    for i in range(n):
        def apply(chain, x, inverse):
            for r in (chain if inverse else list(reversed(chain))):
                qv = float(np.broadcast_to(qs[r["axis"]], (n,))[i])
                d = np.asarray(r["direction"], float)
                if r["type"] == "linear":
                    x = x - qv * d if inverse else x + qv * d
                else:
                    x = np.asarray(r["point"], float) + _old_axis_angle(d, math.radians(-qv if inverse else qv)) \
                        @ (x - np.asarray(r["point"], float))
            return x
        p = apply(rows["tool"], np.asarray(table["tool_tip"], float), False)
        out[i] = Rw.T @ (apply(rows["workpiece"], p, True) - Wt)
    return out


@pytest.mark.parametrize("name", sorted(ABSORB_MACHINES))
def test_kinematics_table_and_its_kinematics_equal_the_old_python(name):
    m = ABSORB_MACHINES[name][0]()
    e = _absorb_errors(m, "tilts")
    e.update({k: v for k, v in {"tip.x": 0.01, "tip.z": -0.02, "EC0Y": 4e-5, "EB0Z": -3e-5,
                                "EX0S": 0.004}.items() if k in m.parameter_names()})
    th = m.theta(e)
    new, old = K.kinematics_table(m, th), _old_kinematics_table(m, th)
    assert [(r["axis"], r["chain"], r["type"], "point" in r) for r in new["axes"]] == \
        [(r["axis"], r["chain"], r["type"], "point" in r) for r in old["axes"]]
    for a, b in zip(new["axes"], old["axes"]):
        _close(a["direction"], b["direction"], abs_=1e-15)
        if "point" in b:
            _close(a["point"], b["point"], abs_=1e-12)
    for k in ("tool_tip", "tool_axis", "part_origin", "part_rotation"):
        _close(new[k], old[k], abs_=1e-15)
    rng = np.random.default_rng(6)
    poses = {a["name"]: rng.uniform(-120, 120, 25) for a in m.axes}
    poses["S"] = np.zeros(25)
    _close(K.table_tool_points(new, poses), _old_table_tool_points(old, poses), abs_=1e-12)
    # a scalar command broadcasts, a missing axis is 0, as before
    few = {new["axes"][0]["axis"]: 30.0, new["axes"][-1]["axis"]: np.array([1.0, -2.0, 5.0])}
    _close(K.table_tool_points(new, few), _old_table_tool_points(old, few), abs_=1e-12)
    with pytest.raises(ValueError, match=r"axes\[1\]"):
        K.table_tool_points(new, {new["axes"][0]["axis"]: np.array([0.0, np.nan])})
