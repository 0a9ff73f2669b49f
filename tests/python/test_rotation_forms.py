"""Orientations as instruments write them (issue 31, "Rotations"): the core's
one conversion (quaternions in both orders, matrices, rotation vectors, Euler
angles in a named sequence) against independent constructions, and the pose
import reading each form, refusing what is not a rotation naming the line,
and taking a pose's six sigma values from the sidecar, its columns or an
instruments entry."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import fivecal
from fivecal import _core
from fivecal.io import import_dataset
from fivecal.io.alignment import rotation_zyx

import test_pose_kind as P

TOOL_SETUP = {k: v for k, v in P.SETUP.items() if ".work_" not in k}


def _rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rodrigues(v):
    """exp of a rotation vector, written out (an independent check of the core)."""
    v = np.asarray(v, float)
    t = np.linalg.norm(v)
    if t == 0:
        return np.eye(3)
    k = v / t
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K


def _vec(values, form, **kw):
    out, problems = _core.rotation_vectors(np.atleast_2d(np.asarray(values, float)), form, **kw)
    assert problems == [""] * len(out), problems
    return out


RNG = np.random.default_rng(31)
VECTORS = [RNG.normal(size=3) for _ in range(20)]
VECTORS = [v / np.linalg.norm(v) * RNG.uniform(0.01, 3.1) for v in VECTORS] + [np.zeros(3)]


@pytest.mark.parametrize("v", VECTORS)
def test_quaternion_both_orders_matrix_and_back(v):
    R = _rodrigues(v)
    t = np.linalg.norm(v)
    k = v / t if t else np.array([0.0, 0.0, 1.0])
    w, xyz = math.cos(t / 2), math.sin(t / 2) * k
    np.testing.assert_allclose(_vec([w, *xyz], "quaternion", order="wxyz")[0], v, atol=1e-12)
    np.testing.assert_allclose(_vec([*xyz, w], "quaternion", order="xyzw")[0], v, atol=1e-12)
    # -q is the same rotation
    np.testing.assert_allclose(_vec([-w, *(-xyz)], "quaternion", order="wxyz")[0], v, atol=1e-12)
    np.testing.assert_allclose(_vec(R.reshape(1, 9), "matrix")[0], v, atol=1e-9)
    np.testing.assert_allclose(_vec(np.degrees(v), "rotation_vector", unit="deg")[0], v, atol=1e-12)
    for form, kw in (("quaternion", {"order": "xyzw"}), ("matrix", {}), ("euler", {"sequence": "ZXZ"}),
                     ("euler", {"sequence": "xyz", "unit": "deg"})):
        back = _core.rotations_from_vectors(np.array([v]), form, **kw)
        np.testing.assert_allclose(_rodrigues(_vec(back, form, **kw)[0]), R, atol=1e-9)


@pytest.mark.parametrize("angles", [(0.3, -0.7, 2.1), (-2.5, 0.2, 0.4), (1.0, 1.2, -0.3)])
def test_euler_sequences_intrinsic_upper_extrinsic_lower(angles):
    a1, a2, a3 = angles
    R = _rz(a1) @ _ry(a2) @ _rx(a3)                       # intrinsic ZYX
    np.testing.assert_allclose(_rodrigues(_vec(angles, "euler", sequence="ZYX")[0]), R, atol=1e-12)
    # extrinsic xyz with (a3, a2, a1) is the same rotation
    np.testing.assert_allclose(_rodrigues(_vec([a3, a2, a1], "euler", sequence="xyz")[0]), R, atol=1e-12)
    # fivecal's instrument_angles a b c: Rz(c) Ry(b) Rx(a) = ZYX with (c, b, a)
    np.testing.assert_allclose(rotation_zyx(a3, a2, a1), R, atol=1e-12)
    deg = _vec(np.degrees(angles), "euler", sequence="ZYX", unit="deg")[0]
    np.testing.assert_allclose(_rodrigues(deg), R, atol=1e-12)
    R2 = _rx(a1) @ _rz(a2) @ _rx(a3)                      # a proper Euler sequence
    np.testing.assert_allclose(_rodrigues(_vec(angles, "euler", sequence="XZX")[0]), R2, atol=1e-12)


def test_not_a_rotation_is_refused_per_row():
    q = np.array([[1, 0, 0, 0], [0.9, 0.1, 0, 0], [0, 0, 0, 0], [1.0005, 0, 0, 0]], float)
    _, problems = _core.rotation_vectors(q, "quaternion", order="wxyz")
    assert problems[0] == "" and problems[3] == ""  # within the default 1e-3
    assert "norm 0.905539, not 1" in problems[1] and "not a rotation" in problems[1]
    assert "norm 0" in problems[2]
    mirror = np.diag([1.0, 1.0, -1.0]).reshape(1, 9)
    skew = (np.eye(3) + 0.01 * np.array([[0, 1, 0], [0, 0, 0], [0, 0, 0]])).reshape(1, 9)
    _, problems = _core.rotation_vectors(np.vstack([mirror, skew]), "matrix")
    assert "reflection" in problems[0]
    assert "differs from I by 0.01" in problems[1]


@pytest.mark.parametrize("kw,match", [
    ({"form": "quaternion", "order": "wyxz"}, r"rotation\.order: 'wyxz' is not a quaternion order"),
    ({"form": "euler", "sequence": "ZZX"}, r"rotation\.sequence: 'ZZX' is not an Euler sequence"),
    ({"form": "euler", "sequence": "ZyX"}, r"rotation\.sequence"),
    ({"form": "euler", "sequence": "ZYX", "unit": "grad"}, r"rotation\.unit: 'grad'"),
    ({"form": "spinor"}, r"rotation\.form: 'spinor' is not a rotation form"),
])
def test_bad_forms_are_refused_naming_the_field(kw, match):
    form = kw.pop("form")
    with pytest.raises(ValueError, match=match):
        _core.rotation_vectors(np.zeros((1, 3)), form, **kw)


# --------------------------------------------------------------------------
# The pose import, each form
# --------------------------------------------------------------------------
def _dataset(n=30, seed=7):
    m = fivecal.Machine.from_dict(P.MACHINE)
    plan = P._plan(np.random.default_rng(seed), n=n, targets=("tool",))
    return fivecal.simulate(m, plan, errors=P.TRUTH, setup=TOOL_SETUP, sigma=P.NOISE, seed=seed)


def _write(ds, path, columns, values, sep=" "):
    axes = [a for a in ds.machine.axis_names if a != "S"]
    lines = [sep.join(axes + ["tx", "ty", "tz"] + columns)]
    for o, v in zip(ds.observations, values):
        lines.append(sep.join([f"{o['axes'][a]:.9f}" for a in axes] + [f"{x:.9f}" for x in o["measured"]]
                              + [f"{x:.12g}" for x in v]))
    path.write_text("\n".join(lines) + "\n")


OPTS = dict(target="tool", target_point=[0, 0, 150], target_rotation=P.TOOL_ROT, instrument_origin=P.ORIGIN,
            instrument_angles=P.ANGLES)


def _vectors(ds):
    return np.array([o["measured_rotation"] for o in ds.observations])


@pytest.mark.parametrize("case", ["qw qx qy qz", "qx qy qz qw", "q1 q2 q3 q4 xyzw", "q0 q1 q2 q3 wxyz",
                                  "matrix", "euler ZYX deg", "euler xyz rad", "rpy ZYX deg", "rotvec deg"])
def test_each_form_imports_to_the_same_rotation_vectors(tmp_path, case):
    ds = _dataset()
    v = _vectors(ds)
    side = dict(OPTS)
    if case.startswith("q"):
        order = "xyzw" if case.split()[0] == "qx" or case.endswith("xyzw") else "wxyz"
        q = _core.rotations_from_vectors(v, "quaternion", order=order)
        cols = case.split()[:4]
        if cols[0] == "qx":  # named columns in scalar-last order: the names say which is which
            pass
        else:
            side["rotation"] = {"form": "quaternion", "order": order} if not cols[0] == "qw" else {}
        values = q
    elif case == "matrix":
        cols, values = [f"r{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)], _core.rotations_from_vectors(v, "matrix")
    elif case.startswith("euler"):
        _, seq, unit = case.split()
        cols = ["euler_1", "euler_2", "euler_3"]
        values = _core.rotations_from_vectors(v, "euler", sequence=seq, unit=unit)
        side["rotation"] = {"form": "euler", "sequence": seq, "unit": unit}
    elif case.startswith("rpy"):
        e = _core.rotations_from_vectors(v, "euler", sequence="ZYX", unit="deg")  # yaw, pitch, roll
        cols, values = ["roll", "pitch", "yaw"], e[:, ::-1]
        side["rotation"] = {"form": "euler", "sequence": "ZYX", "unit": "deg"}
    else:
        cols, values = ["measured_rx", "measured_ry", "measured_rz"], np.degrees(v)
        side["rotation"] = {"form": "rotation_vector", "unit": "deg"}
    f = tmp_path / "cam.txt"
    _write(ds, f, cols, values)
    got = import_dataset(f, "pose", P.MACHINE, sidecar=side)
    np.testing.assert_allclose(_rodrigues_all(_vectors(got)), _rodrigues_all(v), atol=1e-8)


def _rodrigues_all(vs):
    return np.array([_rodrigues(x) for x in vs])


def test_bad_quaternion_and_matrix_rows_are_refused_naming_the_line(tmp_path):
    ds = _dataset(n=6)
    v = _vectors(ds)
    q = _core.rotations_from_vectors(v, "quaternion", order="wxyz")
    q[3] *= 0.97  # norm 0.97: a broken column, not a rotation
    f = tmp_path / "q.txt"
    _write(ds, f, ["qw", "qx", "qy", "qz"], q)
    with pytest.raises(ValueError, match=r"q\.txt:5: quaternion \(wxyz\) .* has norm 0\.97, not 1"):
        import_dataset(f, "pose", P.MACHINE, sidecar=OPTS)
    # a looser tolerance, when the instrument writes few digits, lets it through (normalised)
    import_dataset(f, "pose", P.MACHINE, sidecar={**OPTS, "rotation": {"form": "quaternion", "tolerance": 0.05}})
    R = _core.rotations_from_vectors(v, "matrix")
    R[2, :3] *= -1  # first row negated: a reflection
    f = tmp_path / "r.txt"
    _write(ds, f, [f"r{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3)], R)
    with pytest.raises(ValueError, match=r"r\.txt:4: matrix .* is not a rotation.*reflection"):
        import_dataset(f, "pose", P.MACHINE, sidecar=OPTS)


@pytest.mark.parametrize("cols,side,match", [
    (["q1", "q2", "q3", "q4"], {}, r"do not say which value is the scalar w: give \"rotation\""),
    (["euler_1", "euler_2", "euler_3"], {}, r"Euler angles need their sequence"),
    (["qw", "qx", "qy", "qz"], {"rotation": {"form": "matrix"}}, r"rotation\.form: says matrix, but the columns"),
    (["qw", "qx", "qy"], {}, r"no 'qz' column; a quaternion needs the columns qw qx qy qz"),
    (["qw", "qx", "qy", "qz", "measured_rx", "measured_ry", "measured_rz"], {}, r"both give the orientation"),
    (["tx2"], {}, r"unknown column 'tx2'"),
    (["roll", "pitch", "yaw"], {"rotation": {"form": "euler", "sequence": "ZXZ"}}, r"turns about one axis twice"),
    (["euler_1", "euler_2", "euler_3"], {"rotation": {"form": "euler", "sequence": "ZZX"}},
     r"^sidecar rotation\.sequence: 'ZZX' is not an Euler sequence"),
    (["q1", "q2", "q3", "q4"], {"rotation": {"form": "quaternion", "order": "xyz"}},
     r"rotation\.order: 'xyz' is not a quaternion order"),
    (["q1", "q2", "q3", "q4"], {"rotation": {"form": "quaternion", "sequence": "ZYX"}},
     r"rotation\.sequence: belongs to a euler, not a quaternion"),
])
def test_orientation_columns_that_do_not_say_enough_are_refused(tmp_path, cols, side, match):
    ds = _dataset(n=3)
    f = tmp_path / "c.txt"
    _write(ds, f, cols, np.tile([1.0, 0, 0, 0, 0, 0, 0][:len(cols)], (3, 1)))
    with pytest.raises(ValueError, match=match):
        import_dataset(f, "pose", P.MACHINE, sidecar={**OPTS, **side})


def test_rotation_belongs_to_a_pose_import(tmp_path):
    f = tmp_path / "p.txt"
    f.write_text("X Y Z B C tx ty tz\n0 0 0 0 0 1 2 3\n")
    with pytest.raises(ValueError, match="rotation .* belongs to a pose import, not point"):
        import_dataset(f, "point", P.MACHINE, sidecar={"target": "tool", "rotation": {"form": "quaternion"}})


# --------------------------------------------------------------------------
# Per-component sigma of a pose
# --------------------------------------------------------------------------
SIGMA6 = [0.02, 0.02, 0.06, 2e-4, 2e-4, 5e-5]


def test_pose_sigma_from_sidecar_columns_and_instruments(tmp_path):
    ds = _dataset(n=40)
    v = _vectors(ds)
    f = tmp_path / "s.txt"
    _write(ds, f, ["measured_rx", "measured_ry", "measured_rz"], v)
    a = import_dataset(f, "pose", P.MACHINE, sidecar={**OPTS, "sigma": SIGMA6})
    assert all(o["sigma"] == pytest.approx(SIGMA6) for o in a.observations)
    # columns, in the instrument's units (µm, µrad): the same values
    cols = ["measured_rx", "measured_ry", "measured_rz", "sigma_x_um", "sigma_y_um", "sigma_z_um",
            "sigma_rx_urad", "sigma_ry_urad", "sigma_rz_urad"]
    g = tmp_path / "c.txt"
    _write(ds, g, cols, [list(r) + [s * 1e3 for s in SIGMA6[:3]] + [s * 1e6 for s in SIGMA6[3:]] for r in v])
    b = import_dataset(g, "pose", P.MACHINE, sidecar=OPTS)
    assert all(o["sigma"] == pytest.approx(SIGMA6) for o in b.observations)
    # per instrument: the dataset's instruments entry, the rows without a sigma of their own
    c = import_dataset(f, "pose", P.MACHINE, sidecar={**OPTS, "instruments": {"T1": {"sigma": SIGMA6}}})
    assert "sigma" not in c.observations[0] and c.to_dict()["instruments"] == {"T1": {"sigma": SIGMA6}}
    names = ["EA0B", "EC0B"]  # seen well at this noise by a tool target (which does not see the table's C)
    ra, rb, rc = (fivecal.identify(x, names, fix=P.FIXED) for x in (a, b, c))
    for n in ra.estimated:
        assert rb.values[n] == pytest.approx(ra.values[n], rel=1e-6, abs=1e-12)
        assert rc.std[n] == pytest.approx(ra.std[n], rel=1e-6)


@pytest.mark.parametrize("side,cols,match", [
    ({"sigma": 0.01}, [], r"a pose observation.s rows are in mm and rad, so one number cannot weigh them: give 6 values"),
    ({"sigma": [0.01, 0.01, 0.01]}, [], r"sigma: expected 6 values, one per row \(x y z rx ry rz: mm, mm, mm, rad, rad, rad\), got 3"),
    ({"sigma": [0.01, 0.01, 0.01, 1e-4, 1e-4, 0]}, [], r"sigma\[5\]: sigma 0 must be > 0|sigma"),
    ({}, ["sigma_x", "sigma_y"], r"gives part of a pose's noise; give all six"),
])
def test_pose_sigma_mistakes_are_refused(tmp_path, side, cols, match):
    ds = _dataset(n=3)
    f = tmp_path / "s.txt"
    _write(ds, f, ["measured_rx", "measured_ry", "measured_rz"] + cols,
           [list(r) + [0.01] * len(cols) for r in _vectors(ds)])
    with pytest.raises(ValueError, match=match):
        import_dataset(f, "pose", P.MACHINE, sidecar={**OPTS, **side})


def test_a_sidecar_file_takes_six_sigma_values_and_a_rotation(tmp_path):
    ds = _dataset(n=4)
    f = tmp_path / "s.txt"
    _write(ds, f, ["qx", "qy", "qz", "qw"], _core.rotations_from_vectors(_vectors(ds), "quaternion", order="xyzw"))
    side = tmp_path / "side.json"
    side.write_text(json.dumps({**OPTS, "sigma": SIGMA6, "rotation": {"form": "quaternion", "order": "xyzw"}}))
    got = import_dataset(f, "pose", P.MACHINE, sidecar=str(side))
    assert got.observations[0]["sigma"] == pytest.approx(SIGMA6)
