"""identify's fit path for long data (fit_path): the normal equations
accumulated in chunks give the dense fit's result, the option is checked, and
long data take that path by themselves; on every registered observation
kind, the templated ones (no analytic derivatives) included, and on mixed
data."""
import os

import numpy as np
import pytest

import fivecal

HERE = os.path.dirname(os.path.abspath(__file__))
TRUE = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
TABLE = [50.0, 0.0, 80.0]


def rtest(m, n, seed=3):
    # An R-test: the nominal tool ball on the table ball at every pose.
    rng = np.random.default_rng(seed)
    tilt, turn = np.radians(rng.uniform(0, 60, n)), np.radians(rng.uniform(0, 360, n))
    tool_axes = np.column_stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), np.cos(tilt)])
    axes = m.inverse(np.tile(TABLE, (n, 1)), tool_axes)
    meas = m.tool_point(axes, TRUE) - np.array(TABLE) + rng.normal(0, 5e-4, (n, 3))
    return fivecal.ball_dataset(m, "ball3d", axes, m.tip, TABLE, measured=meas, setup="R1")


def test_both_paths_give_the_same_fit(c600u):
    ds = rtest(c600u, 3000)
    d = fivecal.identify(ds, list(TRUE), fit_path="dense")
    s = fivecal.identify(ds, list(TRUE), fit_path="normal_equations", num_threads=2)
    assert (d.fit_path, s.fit_path) == ("dense", "normal_equations")
    assert d.estimated == s.estimated and s.verdict == d.verdict == "ok"
    for k in d.estimated:
        assert abs(d.values[k] - s.values[k]) < 1e-9 * d.std[k], k
        assert s.std[k] == pytest.approx(d.std[k], rel=1e-8), k
    assert s.chi2 == pytest.approx(d.chi2, rel=1e-9)
    assert s.rms == pytest.approx(d.rms, rel=1e-9)
    np.testing.assert_allclose(s.residuals, d.residuals, atol=1e-9 * d.rms)


def test_long_data_take_the_normal_equations_and_bad_requests_are_refused(c600u):
    assert fivecal.identify(rtest(c600u, 2000), list(TRUE)).fit_path == "dense"
    assert fivecal.identify(rtest(c600u, 200_000), list(TRUE)).fit_path == "normal_equations"
    ds = rtest(c600u, 500)
    with pytest.raises(ValueError, match="fit_path"):
        fivecal.identify(ds, list(TRUE), fit_path="sparse")
    with pytest.raises(ValueError, match="robust"):
        fivecal.identify(ds, list(TRUE), fit_path="normal_equations", robust="huber")


# ---- every observation kind: the streaming fit is the dense fit ----
#
# One small well-posed dataset per registered kind (a kind that has no case
# here fails the test below). The kinds without analytic derivatives (point,
# pose, distance, machined) enter the streaming fit through their templated
# functors; their rows must be the dense path's to rounding as well.

def _spec_data(name, types=None, estimate=(), sigma=None, seed=3):
    # An example spec, its plan cut to `types`, the truth cut to `estimate`
    # (so that the model explains the data: verdict ok).
    import json

    path = os.path.join(HERE, "..", "..", "examples", "specs", name)
    with open(path) as f:
        s = json.load(f)
    m = fivecal.Machine.load(os.path.join(os.path.dirname(path), s["machine"]))
    plan = [p for p in s["plan"] if types is None or p["type"] in types]
    errors = {k: v for k, v in s["errors"].items() if k in estimate}
    return fivecal.simulate(m, plan, errors=errors, artefact=s["artefact"], tip_radius=s["probe"]["tip_radius"],
                            setup=s.get("setup", {}), sigma=sigma or s.get("sigma", 0.001), seed=seed)


def _facet():
    est = ["EA0B", "EC0B", "EX0C", "EA0C", "EB0C", "EB0Z"]
    return _spec_data("hu40t_tango.json", {"facet"}, est), dict(estimate=est)


def _sphere():
    # Two spheres and their scale bar (the artefact rows come after the touches).
    est = ["EX0C", "EA0C", "EB0C", "EA0B", "EC0B", "EB0Z", "EA0Y", "EC0Y"]
    return _spec_data("hu40t_spheres.json", None, est, sigma=0.001), dict(estimate=est)


def _cylinder():
    from fivecal.procedures import tango

    ds = tango.kx8_curved_dataset(strategy="S1+S2", seed=5)
    return ds, dict(estimate=tango.TABLE_5_1_NAMES)


def _dbb():
    from fivecal.procedures import dbb
    from test_dbb import TRUTH as DBB_TRUTH

    m = fivecal.Machine.load(os.path.join(HERE, "..", "..", "examples", "machines", "c600u.json"))
    ds = fivecal.simulate(m, dbb.four_step_plan(m), errors=DBB_TRUTH, sigma={"dbb": 3e-4}, seed=12)
    return ds, dict(estimate=list(DBB_TRUTH))


def _ball3d():
    m = fivecal.Machine.load(os.path.join(HERE, "..", "..", "examples", "machines", "c600u.json"))
    return rtest(m, 300), dict(estimate=list(TRUE))


def _point():
    # A tracker following a reflector on the tool and one on the table, as
    # the pose kind's test (test_pose_kind) without the orientations.
    import test_pose_kind as pk

    m = fivecal.Machine.from_dict(pk.MACHINE)
    plan = [{k: v for k, v in p.items() if k != "target_rotation"} | {"type": "point"}
            for p in pk._plan(np.random.default_rng(4), n=20)]
    setup = {k: v for k, v in pk.SETUP.items() if k[-2:] not in ("_a", "_b", "_c")}
    ds = fivecal.simulate(m, plan, errors=pk.TRUTH, setup=setup, sigma={"point": 0.005}, seed=4)
    return ds, dict(estimate=list(pk.TRUTH), fix=pk.FIXED)


def _pose():
    import test_pose_kind as pk

    m = fivecal.Machine.from_dict(pk.MACHINE)
    return pk._data(m, 5), dict(estimate=list(pk.TRUTH), fix=pk.FIXED)


def _distance():
    import test_distance_kind as dk

    m = fivecal.Machine.from_dict(dk.MACHINE)
    return dk._data(m, 5, n=12), dict(estimate=list(dk.TRUTH), fix=dk.FIXED)


def _machined():
    import test_machining_kind as mk

    m = fivecal.Machine.load(os.path.join(HERE, "..", "..", "examples", "machines", "c600u.json"))
    return mk._faces(m, 11), dict(estimate=mk.LOCATION)


def _mixed():
    # Facet touches, tracker points and a 6D pose on one machine: analytic
    # and templated rows interleaved, a rotation unit among the rows.
    from shared_machines import TABLE_HEAD
    from test_pose_kind import ANGLES, ORIGIN, TOOL_ROT, WORK_ROT

    m = fivecal.Machine.from_dict(TABLE_HEAD)
    rng = np.random.default_rng(8)
    art = {"facets": [{"id": "F1", "point": [0, 0, 0], "normal": [0, 0, 1]},
                      {"id": "F2", "point": [60, 0, 0], "normal": [1, 0, 0]},
                      {"id": "F3", "point": [0, 60, 0], "normal": [0, 1, 0]}]}
    plan = []
    for _ in range(30):
        axes = {"X": float(rng.uniform(-200, 200)), "Y": float(rng.uniform(-200, 200)),
                "Z": float(rng.uniform(-100, 100)), "B": float(rng.uniform(-40, 40)), "C": float(rng.uniform(0, 360))}
        plan.append({"type": "point", "instrument": "T1", "target": "work", "target_point": [120, 40, 20],
                     "axes": axes, "instrument_origin": [1500.0, -200.0, 300.0]})
        plan.append({"type": "pose", "instrument": "CAM", "target": "tool", "target_point": [0, 0, 150],
                     "target_rotation": TOOL_ROT, "axes": axes, "instrument_origin": ORIGIN,
                     "instrument_angles": ANGLES})
        plan.append({"type": "pose", "instrument": "CAM", "target": "work", "target_point": [120, 40, 20],
                     "target_rotation": WORK_ROT, "axes": axes, "instrument_origin": ORIGIN,
                     "instrument_angles": ANGLES})
    for f, pts in (("F1", [[30, 20, 0], [-40, 10, 0], [10, -50, 0]]), ("F2", [[60, 10, 5], [60, -20, 15]]),
                   ("F3", [[10, 60, 5], [-30, 60, 15]])):
        for c in (0.0, 90.0, 180.0, 270.0):
            for p in pts:
                plan.append({"type": "facet", "target": f, "axes": {"B": 0.0, "C": c}, "point": p})
    truth = {"EX0C": 0.01, "EY0C": -0.02, "EA0B": 3e-5, "EC0B": -4e-5}
    ds = fivecal.simulate(m, plan, errors=truth, artefact=art, tip_radius=3.0,
                          sigma={"point": 0.005, "pose": 0.01, "pose_angle": 5e-5, "probe": 0.001}, seed=9)
    # Known: the stylus tip (the touches are at one B), the tool fiducial's
    # y (moves with the camera's) and the reflector (moves with the tracker).
    return ds, dict(estimate=list(truth), fix=["tip.x", "tip.y", "tip.z", "instrument.CAM.tool_y",
                                               "instrument.T1.work_x", "instrument.T1.work_y",
                                               "instrument.T1.work_z"])


CASES = {"facet": _facet, "sphere": _sphere, "cylinder": _cylinder, "dbb": _dbb, "ball3d": _ball3d,
         "point": _point, "pose": _pose, "distance": _distance, "machined": _machined}
KINDS = [k["name"] for k in fivecal._core.observation_kinds()]


def _same_fit(d, s):
    # To rounding: the normal equations square the Jacobian's condition, so
    # values agree to 1e-9 of their sigma and sigmas to 1e-8 relative (as in
    # the R-test comparison above); residual rows to 1e-9 of their rms.
    assert (d.fit_path, s.fit_path) == ("dense", "normal_equations")
    assert d.estimated == s.estimated and d.verdict == s.verdict and d.undetermined == s.undetermined
    assert (d.rank, d.dof, d.n_observations, d.converged) == (s.rank, s.dof, s.n_observations, s.converged)
    for k in d.estimated:
        assert abs(d.values[k] - s.values[k]) < 1e-9 * d.std[k], (k, d.values[k], s.values[k], d.std[k])
        assert s.std[k] == pytest.approx(d.std[k], rel=1e-8), k
    np.testing.assert_array_equal(s.residual_source, d.residual_source)
    np.testing.assert_allclose(s.residuals, d.residuals, rtol=0, atol=1e-9 * d.rms)
    assert s.chi2 == pytest.approx(d.chi2, rel=1e-9)  # twice the final cost
    assert s.sigma == pytest.approx(d.sigma, rel=1e-9) and s.rms == pytest.approx(d.rms, rel=1e-9)
    assert set(s.residual_units) == set(d.residual_units)
    for u, du in d.residual_units.items():
        for f in ("rows", "rms", "max_abs", "sigma"):
            assert s.residual_units[u][f] == pytest.approx(du[f], rel=1e-9), (u, f)


def test_every_registered_kind_has_a_case():
    assert set(CASES) == set(KINDS), "a registered kind has no dataset in CASES"


@pytest.mark.parametrize("kind", KINDS + ["mixed"])
def test_the_streaming_fit_is_the_dense_fit_on_every_kind(kind):
    ds, kw = (_mixed if kind == "mixed" else CASES[kind])()
    types = set(ds.observation_types)
    assert (types >= {"facet", "point", "pose"}) if kind == "mixed" else kind in types
    d = fivecal.identify(ds, fit_path="dense", **kw)
    assert d.verdict == "ok", (kind, d.verdict, d.adequacy)
    for threads in (1, 2):
        _same_fit(d, fivecal.identify(ds, fit_path="normal_equations", num_threads=threads, **kw))


def test_an_undetermined_request_on_templated_kinds_is_refused_on_both_paths():
    # The tool target's y moves every tool point as the tracker's y does
    # (test_pose_kind): estimated both, the request is undetermined.
    import test_pose_kind as pk

    m = fivecal.Machine.from_dict(pk.MACHINE)
    ds = pk._data(m, 6, n=15)
    for path in ("dense", "normal_equations"):
        with pytest.raises(ValueError, match=r"instrument\.T1\.tool_y"):
            fivecal.identify(ds, list(pk.TRUTH), fit_path=path)
    with pytest.warns(fivecal.FitWarning, match="did not determine"):
        d = fivecal.identify(ds, list(pk.TRUTH), fit_path="dense", allow_unidentifiable=True)
    with pytest.warns(fivecal.FitWarning, match="did not determine"):
        s = fivecal.identify(ds, list(pk.TRUTH), fit_path="normal_equations", allow_unidentifiable=True)
    assert s.verdict == d.verdict and s.undetermined == d.undetermined and "instrument.T1.tool_y" in s.undetermined


# ---- the column kernel (solve/long_kernel.h): truth and coverage ----

def test_the_column_kernel_recovers_the_truth_with_honest_sigmas(c600u):
    # Simulated R-test traces of a machine with known errors and 0.5 um
    # noise, fitted on the normal-equation path (the kind's column block):
    # every value within 4 sigma of the truth, and over 40 traces the
    # one-sigma intervals cover about 68 % (binomial: 0.68 +- 0.15 at 3 sd).
    z = []
    for seed in range(40):
        r = fivecal.identify(rtest(c600u, 1500, seed=100 + seed), list(TRUE), fit_path="normal_equations",
                             default_setup=False, num_threads=2)
        assert r.verdict == "ok" and r.fit_path == "normal_equations"
        z += [(r.values[k] - TRUE[k]) / r.std[k] for k in TRUE]
    z = np.abs(np.array(z))
    assert z.max() < 4.0, z.max()
    assert 0.55 < np.mean(z < 1.0) < 0.81, np.mean(z < 1.0)


def test_the_column_kernel_does_not_depend_on_the_thread_count(c600u):
    ds = rtest(c600u, 20_000, seed=7)
    a = fivecal.identify(ds, list(TRUE), fit_path="normal_equations", num_threads=1)
    for threads in (2, 3):
        b = fivecal.identify(ds, list(TRUE), fit_path="normal_equations", num_threads=threads)
        for k in TRUE:
            assert b.values[k] == a.values[k] and b.std[k] == a.std[k], (threads, k)
        np.testing.assert_array_equal(b.residuals, a.residuals)
