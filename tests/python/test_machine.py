"""Machine model tests: example machines, nominal kinematics against closed forms,
first-order agreement with Zhang & Zhang's machining-test equations, input
validation and inverse kinematics.

Conventions (DESIGN.md): lengths mm, rotary commands degrees, angular errors rad.
"""
from __future__ import annotations

import copy
import json
import math
import pathlib
import warnings
import zlib

import numpy as np
import pytest

import fivecal

ROOT = pathlib.Path(__file__).resolve().parents[2]
MACHINES = ROOT / "examples" / "machines"
EXAMPLES = ["hu40t", "kx8", "c600u", "vmc0656"]

# Expected content of each example file (topology, axes in topology order).
EXPECTED = {
    "hu40t": ("wCBXfZYSt", "CBXZYS", [0.0, 0.0, 100.0]),
    "kx8": ("wCAYbXZSt", "CAYXZS", [0.0, 0.0, 250.0]),
    "c600u": ("wCAfXYZSt", "CAXYZS", [0.0, 0.0, 150.0]),
    "vmc0656": ("wCAfXYZSt", "CAXYZS", [0.0, 0.0, 250.0]),
}

# Command ranges used to draw random poses (mm / degrees).
RANGES = {"X": (-250, 250), "Y": (-250, 250), "Z": (-250, 250),
          "A": (-110, 110), "B": (-90, 90), "C": (-360, 360), "S": (0, 360)}


def load(name: str) -> fivecal.Machine:
    return fivecal.Machine.load(MACHINES / f"{name}.json")


def load_dict(name: str) -> dict:
    return json.loads((MACHINES / f"{name}.json").read_text())


def random_axes(m: fivecal.Machine, n: int, rng: np.random.Generator) -> dict:
    return {a: rng.uniform(*RANGES[a], n) for a in m.axis_names}


# --------------------------------------------------------------------------
# Example machines
# --------------------------------------------------------------------------

@pytest.mark.parametrize("name", EXAMPLES)
def test_example_machine_files_are_clean(name):
    d = load_dict(name)
    assert set(d) == {"name", "topology", "axes", "tool"}
    assert set(d["tool"]) == {"tip"}
    for letter, ax in d["axes"].items():
        assert set(ax) <= {"type", "direction", "point"}, letter
        assert abs(np.linalg.norm(ax["direction"]) - 1.0) < 1e-15, letter
        if ax["type"] == "linear":
            assert "point" not in ax, letter


@pytest.mark.parametrize("name", EXAMPLES)
def test_example_machine_loads(name):
    m = load(name)
    topology, axis_names, tip = EXPECTED[name]
    assert m.topology == topology
    assert m.axis_names == axis_names
    np.testing.assert_array_equal(m.tip, tip)
    # to_dict / from_dict round trip keeps the kinematics.
    m2 = fivecal.Machine.from_dict(m.to_dict())
    q = random_axes(m, 20, np.random.default_rng(0))
    np.testing.assert_allclose(m2.tool_point(q), m.tool_point(q), rtol=0, atol=1e-12)


def test_example_chains():
    assert (load("hu40t").workpiece_chain, load("hu40t").tool_chain) == ("XBC", "ZYS")
    assert (load("kx8").workpiece_chain, load("kx8").tool_chain) == ("YAC", "XZS")
    assert (load("c600u").workpiece_chain, load("c600u").tool_chain) == ("AC", "XYZS")


def test_kx8_a_axis_is_tilted_45_degrees_about_y():
    a = next(ax for ax in load("kx8").axes if ax["name"] == "A")
    u = np.asarray(a["direction"])
    assert u[1] == 0.0
    assert math.degrees(math.acos(abs(u[0]))) == pytest.approx(45.0, abs=1e-12)
    # A = 180 deg turns the (vertical) C axis into a horizontal axis.
    m = load("kx8")
    _, v = m.tool_pose({"A": [180.0], "C": [0.0], "X": 0, "Y": 0, "Z": 0})
    np.testing.assert_allclose(np.abs(v[0]), [1.0, 0.0, 0.0], atol=1e-15)


@pytest.mark.parametrize("name", EXAMPLES)
def test_parameter_names(name):
    m = load(name)
    names = m.parameter_names()
    assert len(names) == len(set(names))
    expected = set()
    for a in m.axis_names:
        expected |= {f"E{c}0{a}" for c in "XYZABC"}
        expected |= {f"E{c}{a}{d}" for c in "XYZABC" for d in (1, 2, 3)}
        if a != "S":
            expected.add(f"E{a}{a}b")
    expected |= {"tip.x", "tip.y", "tip.z"}
    assert set(names) == expected
    for missing in set("XYZABC") - set(m.axis_names):
        assert f"EX0{missing}" not in names
    # the ISO 230-1 names the papers use
    if name == "hu40t":
        assert {"EX0C", "EA0C", "EB0C", "EA0B", "EC0B", "EB0Z", "EA0Y", "EC0Y"} <= set(names)
    if name in ("c600u", "vmc0656"):
        assert {"EY0A", "EZ0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C"} <= set(names)
    assert m.parameter_kind("EX0C") == "location"
    assert m.parameter_kind("EXX2") == "motion"
    assert m.parameter_kind("EXXb") == "backlash"
    assert m.parameter_kind("tip.z") == "tip"
    assert m.parameter_is_angular("EA0C") and not m.parameter_is_angular("EX0C")
    assert m.parameter_is_angular("ECCb") and not m.parameter_is_angular("EXXb")


@pytest.mark.parametrize("name", EXAMPLES)
def test_zero_pose_tool_point_is_tip(name):
    m = load(name)
    zero = {a: [0.0] for a in m.axis_names}
    np.testing.assert_array_equal(m.tool_point(zero), [m.tip])
    # spindle omitted (taken as 0) and scalar values
    np.testing.assert_array_equal(
        m.tool_point({a: 0.0 for a in m.axis_names if a != "S"}), [m.tip])
    # tip.x|y|z are offsets of the tip in F at the zero pose
    off = {"tip.x": 0.01, "tip.y": -0.02, "tip.z": 0.03}
    np.testing.assert_allclose(m.tool_point(zero, errors=off),
                               [m.tip + [0.01, -0.02, 0.03]], rtol=0, atol=1e-14)


# --------------------------------------------------------------------------
# Nominal forward kinematics of the A/C tables against a hand-derived closed form
# --------------------------------------------------------------------------
#
# Topology wCAfXYZSt: tool chain X, Y, Z, S from the foundation (linear points
# are 0), workpiece chain A then C. With DESIGN.md's T_k and no errors:
#
#   tool point in F:  t = x e_x + y e_y + z e_z + p_S + Rot_z(s) (tip - p_S)
#                     (u_S = +e_z; T_S = Trans(p_S) Rot_z(s), then Trans(tip - p_S))
#   workpiece:        T_fw = Trans(p_A) Rot(u_A, a) Trans(p_C - p_A) Rot(u_C, c) Trans(-p_C)
#   tool point in W:  P = inv(T_fw) t = p_C + Rot(u_C, c)^T [Rot(u_A, a)^T (t - p_A) - (p_C - p_A)]
#
# The ISO 841 table axes are u_A = -e_x and u_C = -e_z, so Rot(u_A, a)^T = Rot_x(+a)
# and Rot(u_C, c)^T = Rot_z(+c):
#   Rot_x(a) v = (v_x,  v_y cos a - v_z sin a,  v_y sin a + v_z cos a)
#   Rot_z(c) w = (w_x cos c - w_y sin c,  w_x sin c + w_y cos c,  w_z)
# Tool axis (spindle direction e_z, unchanged by Rot_z(s)):
#   v = Rot_z(c) Rot_x(a) e_z = (sin a sin c,  -sin a cos c,  cos a).

def ac_table_closed_form(x, y, z, a_deg, c_deg, s_deg, tip, pA, pC, pS):
    a, c, s = np.radians(a_deg), np.radians(c_deg), np.radians(s_deg)
    tx, ty, tz = tip[0] - pS[0], tip[1] - pS[1], tip[2] - pS[2]
    t = np.stack([x + pS[0] + tx * np.cos(s) - ty * np.sin(s),
                  y + pS[1] + tx * np.sin(s) + ty * np.cos(s),
                  z + pS[2] + tz], axis=1)
    v = t - pA
    w = np.stack([v[:, 0],
                  v[:, 1] * np.cos(a) - v[:, 2] * np.sin(a),
                  v[:, 1] * np.sin(a) + v[:, 2] * np.cos(a)], axis=1)
    w = w - (np.asarray(pC) - np.asarray(pA))
    P = np.stack([w[:, 0] * np.cos(c) - w[:, 1] * np.sin(c),
                  w[:, 0] * np.sin(c) + w[:, 1] * np.cos(c),
                  w[:, 2]], axis=1) + pC
    V = np.stack([np.sin(a) * np.sin(c), -np.sin(a) * np.cos(c), np.cos(a)], axis=1)
    return P, V


def _ac_variants():
    out = []
    for name in ("c600u", "vmc0656"):
        out.append((name, load_dict(name)))
        # Same machine with non-intersecting axes, an off-axis tip and a spindle
        # pivot off the origin, so that every point in the closed form matters.
        d = load_dict(name)
        d["axes"]["A"]["point"] = [0.0, 20.0, -80.0]
        d["axes"]["C"]["point"] = [3.0, -5.0, 40.0]
        d["axes"]["S"]["point"] = [2.0, -1.0, 0.0]
        d["tool"]["tip"] = [5.0, -3.0, 150.0]
        out.append((name + "-offset", d))
    return out


@pytest.mark.parametrize("label,d", _ac_variants(), ids=[v[0] for v in _ac_variants()])
def test_ac_table_nominal_kinematics_closed_form(label, d):
    m = fivecal.Machine.from_dict(d)
    rng = np.random.default_rng(zlib.crc32(label.encode()))
    q = random_axes(m, 100, rng)
    ax = {k: d["axes"][k] for k in "ACS"}
    P_ref, V_ref = ac_table_closed_form(
        q["X"], q["Y"], q["Z"], q["A"], q["C"], q["S"], np.asarray(d["tool"]["tip"], float),
        np.asarray(ax["A"]["point"], float), np.asarray(ax["C"]["point"], float),
        np.asarray(ax["S"]["point"], float))
    P, V = m.tool_pose(q)
    np.testing.assert_allclose(P, P_ref, rtol=0, atol=1e-10)
    np.testing.assert_allclose(V, V_ref, rtol=0, atol=1e-14)


# --------------------------------------------------------------------------
# Zhang & Zhang (004_*): first-order machining errors of an A/C table
# --------------------------------------------------------------------------
#
# The paper's model, eq. (5) (its eq. (1) is printed as a Z rotation under the
# label F_A R and eq. (3) as an X rotation under A_C R; only the reading below
# reproduces its eqs. (6) and (14)/(16)):
#
#   F_W = Rot_x(alpha) [ A_delta + A_xi Rot_z(gamma) [ C_delta + C_xi W_N ] ],  W_N = (0, L, H)
#
# alpha the tilting A axis, gamma the rotary C axis, A_xi and C_xi the small
# rotations I + [xi]x of its eq. (2). A and C intersect at the origin of {F}.
#
# Mapping to DESIGN.md (workpiece chain A then C, p_A = p_C = 0):
#   T_fw W = E_A Rot(u_A, A) eps_A  Trans(p_C - p_A) E_C Rot(u_C, C) eps_C  W
#   * A_delta, A_xi sit between the A and C rotations, i.e. they locate the C axis
#     relative to the A axis: A_delta = (EX0C, EY0C, EZ0C),
#     A_xi = (EA0C, EB0C, EC0C) (E_C = Trans . Rz(EC0C) Ry(EB0C) Rx(EA0C) =
#     I + [(EA0C, EB0C, EC0C)]x to first order: same signs as eq. (2)).
#     The paper calls A_xi_x, A_delta_y, A_delta_z "the kinematic errors of the tilt
#     axis"; with constant values they are exactly EA0C, EY0C, EZ0C.
#     The A-axis location errors proper (EY0A, EZ0A, EB0A, EC0A) sit before the A
#     rotation: a constant EY0A/EZ0A shifts F_W identically at every pose and
#     cancels in the paper's differences (checked below).
#   * C_delta, C_xi act after the C rotation (they turn with the table): a set-up
#     error of the workpiece. They are applied by placing the feature at
#     W = C_delta + Rz Ry Rx(C_xi) W_N in the workpiece frame. C_delta_z is taken
#     as 0: the paper drops it (it would just change H).
#   * Commands: on the paper's frame machine (u_A = +e_x, u_C = +e_z) A = alpha,
#     C = gamma; on the ISO C600U-like example (u_A = -e_x, u_C = -e_z)
#     A = -alpha, C = -gamma (Rot(-u, -q) = Rot(u, q)).
#
# The paper's machining error is a difference, between two poses, of F_W
# projected on a sensitive direction r, minus its nominal value. fivecal gives the
# tool point P in the workpiece frame, P = inv(T_fw) t, which is affine in the
# linear commands on these machines (tool-side chain error free):
#   P(X e_i) - P(0) = R^T e_i  (R = rotation of T_fw),  t(0) = tip,
# so F_W = T_fw W = tip + R (W - P(0)) exactly, from tool_point alone.
#
# Closed forms (first order):
#   test 1, alpha = 90, gamma = 180 vs 0, r1 = (0,-1,0):
#     eq. (6)  h   = -2 A_xi_x (C_delta_y + L) + 2 A_xi_y C_delta_x
#   test 2, (alpha, gamma) = (90, 180) vs (0, 0), r2 = (0,0,1):
#     eq. (10) to first order:
#              dl2 = A_delta_y - A_delta_z - C_delta_y + (H - L) C_xi_x - (H + L) A_xi_x
#     (printed eq. (11) has (H - L)(C_xi_x - A_xi_x): its A_xi_x coefficient
#     contradicts eq. (9)/(10), whose terms -A_xi_x (H + ..) - A_xi_x (L + ..) give
#     -(H + L) A_xi_x, and eq. (16). The printed "A_delta_y . L - H . A_delta_z" is
#     the nominal -L - H of eq. (9) that the text says is removed.)
#   test 3, same poses, r1 = (0,-1,0):
#     eq. (16) dl3 = A_delta_y + A_delta_z + C_delta_y + C_xi_x (L - H) - A_xi_x (H + L)

ZZ_L, ZZ_H = 150.0, 60.0
# "tens of um / tens of urad"
ZZ_A_DELTA = np.array([0.012, -0.025, 0.018])       # mm  -> EX0C, EY0C, EZ0C
ZZ_A_XI = np.array([35e-6, -22e-6, 41e-6])          # rad -> EA0C, EB0C, EC0C
ZZ_C_DELTA = np.array([0.015, -0.020, 0.0])         # mm, workpiece set-up
ZZ_C_XI = np.array([-28e-6, 17e-6, 30e-6])          # rad, workpiece set-up


def _rot_zyx(a, b, c):
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    Rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    Ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    Rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    return Rz @ Ry @ Rx


def _zz_machine(kind):
    if kind == "paper-frame":
        return fivecal.Machine.from_dict({
            "name": "Zhang-Zhang A/C table", "topology": "wCAfXYZt",
            "axes": {"C": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]},
                     "A": {"type": "rotary", "direction": [1, 0, 0], "point": [0, 0, 0]},
                     "X": {"type": "linear", "direction": [1, 0, 0]},
                     "Y": {"type": "linear", "direction": [0, 1, 0]},
                     "Z": {"type": "linear", "direction": [0, 0, 1]}},
            "tool": {"tip": [0, 0, 0]}}), 1.0
    return load("c600u"), -1.0


def _workpiece_point_in_F(m, sign, alpha, gamma, W, errors):
    axes = {"X": [0, 1, 0, 0.0], "Y": [0, 0, 1, 0.0], "Z": [0, 0, 0, 1.0],
            "A": [sign * alpha] * 4, "C": [sign * gamma] * 4}
    P = m.tool_point(axes, errors=errors)
    RT = (P[1:] - P[0]).T            # column i = R^T e_i
    return m.tip + RT.T @ (np.asarray(W, float) - P[0])


def _zz_case(kind, scale):
    m, sign = _zz_machine(kind)
    Ad, Ax = ZZ_A_DELTA * scale, ZZ_A_XI * scale
    Cd, Cx = ZZ_C_DELTA * scale, ZZ_C_XI * scale
    errors = dict(zip(["EX0C", "EY0C", "EZ0C", "EA0C", "EB0C", "EC0C"], [*Ad, *Ax]))
    WN = np.array([0.0, ZZ_L, ZZ_H])
    W = Cd + _rot_zyx(*Cx) @ WN

    def FW(alpha, gamma, err=True):
        return _workpiece_point_in_F(m, sign, alpha, gamma, W if err else WN,
                                     errors if err else None)

    r1, r2 = np.array([0, -1.0, 0]), np.array([0, 0, 1.0])
    L, H = ZZ_L, ZZ_H
    model = {
        "eq6": r1 @ (FW(90, 180) - FW(90, 0)) - r1 @ (FW(90, 180, False) - FW(90, 0, False)),
        "eq11": r2 @ (FW(90, 180) - FW(0, 0)) - r2 @ (FW(90, 180, False) - FW(0, 0, False)),
        "eq16": r1 @ (FW(90, 180) - FW(0, 0)) - r1 @ (FW(90, 180, False) - FW(0, 0, False)),
    }
    paper = {
        "eq6": -2 * Ax[0] * (Cd[1] + L) + 2 * Ax[1] * Cd[0],
        "eq11": Ad[1] - Ad[2] - Cd[1] + (H - L) * Cx[0] - (H + L) * Ax[0],
        "eq16": Ad[1] + Ad[2] + Cd[1] + Cx[0] * (L - H) - Ax[0] * (H + L),
    }
    printed_eq11 = Ad[1] - Ad[2] - Cd[1] + (H - L) * (Cx[0] - Ax[0])
    return m, sign, errors, W, FW, model, paper, printed_eq11


@pytest.mark.parametrize("kind", ["paper-frame", "c600u"])
def test_zhang_eq5_mapping_is_exact(kind):
    """fivecal with EX0C..EC0C equals the paper's eq. (5) evaluated with exact
    rotations, at the test poses and at arbitrary ones."""
    m, sign, errors, W, FW, *_ = _zz_case(kind, 1.0)
    WN = np.array([0.0, ZZ_L, ZZ_H])
    for alpha, gamma in [(90, 180), (90, 0), (0, 0), (37.0, -71.0), (-64.0, 212.0)]:
        Rx = _rot_zyx(np.radians(alpha), 0, 0)
        Rz = _rot_zyx(0, 0, np.radians(gamma))
        ref = Rx @ (ZZ_A_DELTA + _rot_zyx(*ZZ_A_XI) @ Rz @ (ZZ_C_DELTA + _rot_zyx(*ZZ_C_XI) @ WN))
        np.testing.assert_allclose(FW(alpha, gamma), ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("kind", ["paper-frame", "c600u"])
@pytest.mark.parametrize("eq", ["eq6", "eq11", "eq16"])
def test_zhang_machining_errors_first_order(kind, eq):
    *_, model, paper, _ = _zz_case(kind, 1.0)
    *_, model_half, paper_half, _ = _zz_case(kind, 0.5)
    effect = abs(paper[eq])
    assert effect > 1e-3                        # the errors do show (mm)
    d1 = model[eq] - paper[eq]
    d2 = model_half[eq] - paper_half[eq]
    assert abs(d1) < 1e-3 * effect
    # second order: halving the errors divides the difference by ~4
    assert 0.2 < d2 / d1 < 0.3, (d1, d2)


@pytest.mark.parametrize("kind", ["paper-frame", "c600u"])
def test_zhang_printed_eq11_has_wrong_tilt_coefficient(kind):
    """Documents the paper's slip: printed eq. (11) is off by 2 L A_xi_x."""
    *_, model, _, printed = _zz_case(kind, 1.0)
    assert model["eq11"] - printed == pytest.approx(-2 * ZZ_L * ZZ_A_XI[0], rel=1e-3)


@pytest.mark.parametrize("kind", ["paper-frame", "c600u"])
def test_zhang_a_axis_position_errors_cancel(kind):
    """EY0A/EZ0A (before the A rotation) shift F_W by a constant: no machining error
    in the paper's pose differences, while EY0C/EZ0C (A_delta) do show."""
    m, sign, *_ = _zz_case(kind, 1.0)
    WN = np.array([0.0, ZZ_L, ZZ_H])
    d = {}
    for errs in ({"EY0A": 0.03, "EZ0A": -0.02}, {"EY0C": 0.03, "EZ0C": -0.02}):
        moved = [_workpiece_point_in_F(m, sign, a, c, WN, e)
                 for e in (errs, None) for a, c in ((90, 180), (0, 0))]
        d[tuple(errs)] = (moved[0] - moved[1]) - (moved[2] - moved[3])
    np.testing.assert_allclose(d[("EY0A", "EZ0A")], 0.0, atol=1e-12)
    assert d[("EY0C", "EZ0C")][2] == pytest.approx(0.03 - (-0.02), rel=1e-9)  # eq. (11)


# --------------------------------------------------------------------------
# Input validation
# --------------------------------------------------------------------------

def _c600u_axes():
    return {"X": [0, 1, 2.0], "Y": [0, 0, 0.0], "Z": [0, 0, 0.0],
            "A": [0, 10, 20.0], "C": [0, 30, 60.0]}


def test_bad_axes_input():
    m = load("c600u")
    ax = _c600u_axes()
    with pytest.raises(ValueError, match=r"unknown axis 'Q'"):
        m.tool_point({**ax, "Q": [0, 0, 0]})
    with pytest.raises(ValueError, match=r"missing axis A"):
        m.tool_point({k: v for k, v in ax.items() if k != "A"})
    with pytest.raises(ValueError, match=r"different lengths"):
        m.tool_point({**ax, "X": [0, 1]})
    with pytest.raises(ValueError, match=r"axes\.C\[1\].*not finite"):
        m.tool_point({**ax, "C": [0, np.nan, 1]})
    with pytest.raises(ValueError, match=r"axes\.X\[2\].*not finite"):
        m.tool_point({**ax, "X": [0, 1, np.inf]})
    with pytest.raises(ValueError, match=r"1-D"):
        m.tool_point({**ax, "X": [[0, 1, 2]]})


def test_bad_errors_input():
    m = load("c600u")
    ax = _c600u_axes()
    with pytest.raises(ValueError, match=r"unknown parameter 'EX0Q'"):
        m.tool_point(ax, errors={"EX0Q": 1e-3})
    with pytest.raises(ValueError, match=r"unknown parameter 'EX0B'.*no axis 'B'"):
        m.tool_point(ax, errors={"EX0B": 1e-3})
    with pytest.raises(ValueError, match=r"errors\.EX0C.*not finite"):
        m.tool_point(ax, errors={"EX0C": float("nan")})
    with pytest.raises(ValueError, match=r"errors\.EA0C.*not finite"):
        m.tool_point(ax, errors={"EA0C": -np.inf})
    with pytest.raises(ValueError, match=r"errors\.EX0C.*number"):
        m.tool_point(ax, errors={"EX0C": "abc"})


def test_bad_directions_input():
    m = load("c600u")
    ax = _c600u_axes()
    with pytest.raises(ValueError, match=r"directions\.X.*-1, 0 or \+1"):
        m.tool_point(ax, directions={"X": [1, 2, 1]})
    with pytest.raises(ValueError, match=r"directions\.C.*-1, 0 or \+1"):
        m.tool_point(ax, directions={"C": 2})
    with pytest.raises(ValueError, match=r"directions\.X: length 2"):
        m.tool_point(ax, directions={"X": [1, 1]})
    with pytest.raises(ValueError, match=r"directions: unknown axis 'Q'"):
        m.tool_point(ax, directions={"Q": [1, 1, 1]})


def _bad_machine(mod):
    d = load_dict("c600u")
    mod(d)
    return d


@pytest.mark.parametrize("mod,pattern", [
    (lambda d: d.update(topology="wCAfXYZQt"), r"topology.*unknown axis letter 'Q'"),
    (lambda d: d.update(topology="wCAfXYZCt"), r"topology.*duplicate axis 'C'"),
    (lambda d: d["axes"].update(C1=copy.deepcopy(d["axes"]["S"])), r"duplicate axis 'S'"),
    (lambda d: d["axes"].pop("A"), r"axis 'A' appears in topology .* no definition"),
    (lambda d: d["axes"].update(B={"type": "rotary", "direction": [0, 1, 0]}),
     r"axis 'B' is defined but not in topology"),
    (lambda d: d["axes"]["A"].update(direction=[0, 0, 0]), r"axes\.A\.direction: zero vector"),
    (lambda d: d["axes"]["A"].update(direction=[1, 0]), r"axes\.A\.direction"),
    (lambda d: d["axes"]["A"].update(type="linear"), r"axes\.A\.type"),
    (lambda d: d["axes"]["X"].update(point=[1, 0, 0]), r"axes\.X\.point"),
    (lambda d: d.update(topology="CAfXYZSt"), r"must start with 'w'"),
    (lambda d: d.update(topology="wCAXYZSt"), r"no foundation"),
    (lambda d: d.pop("topology"), r"machine\.topology: missing"),
], ids=["topology-letter", "topology-duplicate", "duplicate-axis", "missing-definition",
        "extra-definition", "zero-direction", "short-direction", "type", "linear-point",
        "no-w", "no-foundation", "no-topology"])
def test_bad_machine_dict(mod, pattern):
    with pytest.raises(ValueError, match=pattern):
        fivecal.Machine.from_dict(_bad_machine(mod))


def test_bad_machine_file(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(_bad_machine(lambda d: d["axes"]["C"].update(direction=[0, 0, 0]))))
    with pytest.raises(ValueError, match=r"bad\.json.*axes\.C\.direction: zero vector"):
        fivecal.Machine.load(p)


@pytest.mark.parametrize("field", ["direction", "point"])
def test_nan_in_machine_dict_is_a_value_error(field):
    # JSON cannot hold NaN; from_dict gets a Python float('nan').
    d = _bad_machine(lambda d: d["axes"]["A"].update({field: [float("nan"), 0, 0]}))
    with pytest.raises(ValueError):
        fivecal.Machine.from_dict(d)


@pytest.mark.parametrize("field,where", [("direction", r"machine\.axes\.A\.direction\[0\]"),
                                         ("point", r"machine\.axes\.A\.point\[0\]")])
def test_nan_in_machine_dict_names_the_field(field, where):
    d = _bad_machine(lambda d: d["axes"]["A"].update({field: [float("nan"), 0, 0]}))
    with pytest.raises(ValueError, match=where + r".*not finite"):
        fivecal.Machine.from_dict(d)


def test_machine_dict_accepts_numpy_vectors():
    d = _bad_machine(lambda d: d["axes"]["A"].update(direction=np.array([-1.0, 0, 0])))
    m = fivecal.Machine.from_dict(d)
    np.testing.assert_array_equal(m.tool_point(_c600u_axes()), load("c600u").tool_point(_c600u_axes()))


def test_radians_warning():
    m = load("hu40t")
    base = {"X": [0, 0, 0.0], "Y": [0, 0, 0.0], "Z": [0, 0, 0.0], "C": [0, 0, 0.0]}
    with pytest.warns(fivecal.RadiansWarning, match=r"axes\.B"):
        m.tool_point({**base, "B": [0, 1.5708, 3.14159]})
    with pytest.warns(fivecal.RadiansWarning, match=r"axes\.C"):
        m.tool_point({**base, "B": [0, 0, 0.0], "C": [0, 1.5708, 3.14159]})
    with warnings.catch_warnings():
        warnings.simplefilter("error", fivecal.RadiansWarning)
        m.tool_point({**base, "B": [0, 90, 180]})
        m.tool_point({**base, "B": [0, -45, 90], "C": [0, 7.5, 15]})
        # linear axes are never checked
        m.tool_point({**base, "B": [0, 90, 180], "X": [0, 1.5708, 3.14159]})


# --------------------------------------------------------------------------
# Inverse kinematics
# --------------------------------------------------------------------------

@pytest.mark.parametrize("name", EXAMPLES)
def test_inverse_round_trip(name):
    m = load(name)
    rng = np.random.default_rng(11)
    q = random_axes(m, 40, rng)
    q["S"] = np.zeros(40)
    P, V = m.tool_pose(q)
    # from the zero pose: any branch, but the same tool point and axis
    cmd = m.inverse(P, V)
    P2, V2 = m.tool_pose(cmd)
    np.testing.assert_allclose(P2, P, rtol=0, atol=1e-9)
    np.testing.assert_allclose(V2, V, rtol=0, atol=1e-12)
    # started next to the generating pose: the generating commands come back
    for i in range(10):
        start = {a: q[a][i] + 0.3 for a in m.axis_names}
        c = m.inverse(P[i:i + 1], V[i:i + 1], start=start)
        for a in m.axis_names:
            if a == "S":  # the spindle is not solved for: it keeps its start value
                assert c[a][0] == start[a]
            else:
                assert c[a][0] == pytest.approx(q[a][i], abs=1e-9), a
    # without tool axes the rotary axes stay where they are
    start = {a: q[a][0] for a in m.axis_names}
    c = m.inverse(P[:5], start=start)
    for a in m.axis_names:
        if a in "ABCS":
            np.testing.assert_array_equal(c[a], start[a])
    np.testing.assert_allclose(m.tool_point(c), P[:5], rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", EXAMPLES)
def test_inverse_with_errors_compensates(name):
    m = load(name)
    rng = np.random.default_rng(12)
    n = 30
    q = random_axes(m, n, rng)
    q["S"] = np.zeros(n)
    P, V = m.tool_pose(q)
    errors = {}
    for p in m.parameter_names():
        kind = m.parameter_kind(p)
        ang = m.parameter_is_angular(p)
        if kind == "location":
            errors[p] = rng.normal(0, 30e-6 if ang else 0.03)
        elif kind == "backlash":
            errors[p] = rng.normal(0, 10e-6 if ang else 0.005)
        elif kind == "tip":
            errors[p] = rng.normal(0, 0.01)
        elif p[-1] == "1":
            errors[p] = rng.normal(0, 20e-6)
    dirs = {a: rng.choice([-1, 1], n) for a in m.axis_names if a != "S"}
    cmd = m.inverse(P, V, errors=errors, directions=dirs, start={a: q[a][0] for a in m.axis_names})
    P2, V2 = m.tool_pose(cmd, errors=errors, directions=dirs)
    np.testing.assert_allclose(P2, P, rtol=0, atol=1e-6)
    np.testing.assert_allclose(V2, V, rtol=0, atol=1e-9)
    # the compensated commands really differ from the nominal ones
    P_nom_cmd = m.tool_point(cmd)
    assert np.abs(P_nom_cmd - P).max() > 1e-3


def test_inverse_unreachable_tool_axis():
    m = load("kx8")  # the 45 deg A axis only reaches tool axes with v_z >= 0
    with pytest.raises(ValueError, match=r"tool_axes\[0\].*cannot be reached"):
        m.inverse([[10.0, 20.0, 30.0]], [[0.0, 0.0, -1.0]])
    with pytest.raises(ValueError, match=r"points: expected shape"):
        m.inverse([[1.0, 2.0]])
