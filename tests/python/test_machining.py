"""Machining tests in error-sensitive directions (issue 5, item 6; Zhang &
Zhang, shared/seeds/004_*): the test poses and sensitive directions, machining
errors predicted by the full model, identification of the tilt-axis errors
from measured machining errors.

The paper's eqs. (6), (11), (16) against the kinematic model are checked in
test_machine.py (``_zz_case``: exact F_W differences, the corrected eq. (11),
the printed eq. (11)'s (H - L) A_xi_x slip); here the same case is reused to
check that ``fivecal.procedures.machining`` predicts those differences (to second order)
and encodes the same closed forms.

Must show: the identification recovers the three tilt-axis errors (EA0C,
EY0C, EZ0C: the paper's A_xi_x, A_delta_y, A_delta_z) from simulated
machining errors.

Units: mm, rad.
"""
from __future__ import annotations

import pathlib

import numpy as np
import pytest

import fivecal
from fivecal.procedures import machining

from test_machine import ZZ_A_DELTA, ZZ_A_XI, ZZ_C_DELTA, ZZ_C_XI, ZZ_H, ZZ_L, _zz_case, _zz_machine

ROOT = pathlib.Path(__file__).resolve().parents[2]
KINDS = ["paper-frame", "c600u"]


def zz_values(scale=1.0):
    errors = dict(zip(["EX0C", "EY0C", "EZ0C", "EA0C", "EB0C", "EC0C"], [*ZZ_A_DELTA * scale, *ZZ_A_XI * scale]))
    setup = dict(zip(machining.WORKPIECE_SETUP, [*ZZ_C_DELTA * scale, *ZZ_C_XI * scale]))
    return errors, setup


def test_zhang_tests_poses_and_directions(c600u):
    tests = machining.zhang_tests(c600u, L=150.0, H=60.0)
    assert [t["id"] for t in tests] == ["T1", "T2", "T3"]
    assert [t["direction"] for t in tests] == [[0, -1, 0], [0, 0, 1], [0, -1, 0]]
    # C600U: A about -X, C about -Z, so the paper's alpha = 90, gamma = 180 are A = -90, C = -180
    assert tests[0]["pose"]["A"] == -90 and tests[0]["pose"]["C"] == -180
    assert tests[0]["reference"] == {"A": -90.0, "C": 0.0, "S": 0.0}
    assert tests[1]["reference"]["A"] == 0 and tests[2]["reference"]["C"] == 0
    # the cutting programme puts the nominal tool point on the feature
    for p in machining.poses(c600u, tests):
        for pose in (p["pose"], p["reference"]):
            P = c600u.tool_point({a: [v] for a, v in pose.items()})
            np.testing.assert_allclose(P[0], [0, 150, 60], atol=1e-9)
    with pytest.raises(ValueError, match="rotary axes A and C"):
        machining.zhang_tests(fivecal.Machine.load(ROOT / "examples" / "machines" / "hu40t.json"), 150, 60)


@pytest.mark.parametrize("kind", KINDS)
def test_prediction_is_the_papers_machining_error(kind):
    """fivecal.procedures.machining.predict (cut-point deviation in the table frame) equals
    test_machine's exact F_W differences to second order, and first_order is
    the paper's eqs. (6), (11) corrected, (16)."""
    m, *_, model, paper, _ = _zz_case(kind, 1.0)
    tests = machining.zhang_tests(m, ZZ_L, ZZ_H)
    errors, setup = zz_values()
    e = machining.predict(m, tests, errors, setup)
    f = machining.first_order(ZZ_L, ZZ_H, errors, setup)
    ref = np.array([model[k] for k in ("eq6", "eq11", "eq16")])
    np.testing.assert_allclose(f, [paper[k] for k in ("eq6", "eq11", "eq16")], rtol=1e-12)
    assert np.all(np.abs(e - ref) < 1e-3 * np.abs(ref))
    e2 = machining.predict(m, tests, *zz_values(0.5))
    *_, model2, _, _ = _zz_case(kind, 0.5)
    ref2 = np.array([model2[k] for k in ("eq6", "eq11", "eq16")])
    np.testing.assert_allclose((e2 - ref2) / (e - ref), 0.25, atol=0.02)   # second order
    np.testing.assert_allclose(machining.predict(m, tests), 0.0, atol=1e-12)


def test_sensitive_directions_single_out_the_tilt_axis_errors(c600u):
    """The tests see EA0C, EY0C, EZ0C and the workpiece set-up, and none of
    the A-axis position errors EY0A, EZ0A, nor EC0C (first order)."""
    tests = machining.zhang_tests(c600u, 150.0, 60.0)
    names = ["EA0C", "EY0C", "EZ0C", "EY0A", "EZ0A", "EC0C", "workpiece.y"]
    S = machining.sensitivity(c600u, tests, names)
    col = dict(zip(names, S.T))
    np.testing.assert_allclose(col["EA0C"], [-300, -210, -210], rtol=1e-9)     # -2L, -(H+L), -(H+L)
    np.testing.assert_allclose(col["EY0C"], [0, 1, 1], atol=1e-12)
    np.testing.assert_allclose(col["EZ0C"], [0, -1, 1], atol=1e-12)
    np.testing.assert_allclose(col["workpiece.y"], [0, -1, 1], atol=1e-12)
    for n in ("EY0A", "EZ0A", "EC0C"):
        np.testing.assert_allclose(col[n], 0.0, atol=1e-12)
    assert np.linalg.matrix_rank(S[:, :3]) == 3


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_identifies_the_tilt_axis_errors(c600u, seed):
    """Truth: all six location errors of C relative to A, A-axis position
    errors, a known workpiece set-up; machining errors measured with 1 µm
    noise. EA0C, EY0C, EZ0C come back within 3 sigma (sigma from the 1 µm)."""
    rng = np.random.default_rng(seed)
    truth = {"EX0C": rng.uniform(-0.03, 0.03), "EY0C": rng.uniform(-0.03, 0.03), "EZ0C": rng.uniform(-0.03, 0.03),
             "EA0C": rng.uniform(-5e-5, 5e-5), "EB0C": rng.uniform(-5e-5, 5e-5), "EC0C": rng.uniform(-5e-5, 5e-5),
             "EY0A": 0.02, "EZ0A": -0.015}
    setup = {"workpiece.x": 0.01, "workpiece.y": -0.02, "workpiece.a": 2e-5, "workpiece.b": -1e-5}
    tests = machining.zhang_tests(c600u, 150.0, 60.0)
    measured = machining.predict(c600u, tests, truth, setup) + rng.normal(0, 0.001, 3)
    for t, v in zip(tests, measured):
        t["measured"] = float(v)
    r = machining.identify(c600u, tests, setup=setup, sigma=0.001)
    assert r.converged and r.rank == 3
    for n in machining.TILT_AXIS_ERRORS:
        assert abs(r.values[n] - truth[n]) < 3 * r.std[n], (n, r.values[n], truth[n], r.std[n])
    assert r.std["EA0C"] < 5e-6 and r.std["EY0C"] < 0.002 and r.std["EZ0C"] < 0.002
    assert "EA0C" in r.report()
    # the paper's linear solution gives the same to second order
    S = machining.sensitivity(c600u, tests, machining.TILT_AXIS_ERRORS)
    rest = machining.predict(c600u, tests, {k: v for k, v in truth.items() if k not in machining.TILT_AXIS_ERRORS},
                             setup)
    lin = np.linalg.solve(S, measured - rest)
    np.testing.assert_allclose(lin, [r.values[n] for n in machining.TILT_AXIS_ERRORS],
                               atol=1e-3 * np.max(np.abs(lin)) + 1e-9)


def test_more_tests_estimate_sigma(c600u):
    tests = machining.zhang_tests(c600u, 150.0, 60.0) + machining.zhang_tests(c600u, 100.0, 40.0)
    truth = {"EA0C": 3e-5, "EY0C": 0.02, "EZ0C": -0.01}
    rng = np.random.default_rng(4)
    for t, v in zip(tests, machining.predict(c600u, tests, truth) + rng.normal(0, 0.001, 6)):
        t["measured"] = float(v)
    r = machining.identify(c600u, tests)
    assert 0.0002 < r.sigma < 0.003
    assert all(abs(r.values[n] - truth[n]) < 4 * r.std[n] for n in truth)


def test_setup_and_tilt_errors_are_confounded(c600u):
    tests = machining.zhang_tests(c600u, 150.0, 60.0)
    with pytest.raises(ValueError, match="confounded.*EZ0C.*workpiece.y"):
        machining.identify(c600u, tests, estimate=["EA0C", "EZ0C", "workpiece.y"])
    with pytest.raises(ValueError, match="unknown parameter 'EQ0C'"):
        machining.identify(c600u, tests, estimate=["EQ0C"])
    with pytest.raises(ValueError, match="4 parameters but only 3"):
        machining.identify(c600u, tests, estimate=["EA0C", "EY0C", "EZ0C", "EB0C"])
    with pytest.raises(ValueError, match="pose: missing"):
        machining.predict(c600u, [{"point": [0, 1, 2], "direction": [0, 0, 1]}])
