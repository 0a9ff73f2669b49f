"""The fixed-frame 6D pose kind (camera fiducial, 6D tracker): a machine with
rotary axes on both sides (C on the table, B on the head) seen by one 6D
tracker that follows a fiducial frame on the tool and one on the table. The
tracker's pose and the fiducials' offsets and orientations are estimated
with the machine errors."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal

from shared_machines import TABLE_HEAD as MACHINE  # noqa: E402
ORIGIN, ANGLES = [2000.0, -500.0, 400.0], [0.5, -1.0, 155.0]  # tracker pose, mm / deg
TOOL_ROT, WORK_ROT = [0.2, -0.1, 0.4], [0.0, 0.3, -1.2]       # nominal fiducial orientations, rad
TRUTH = {"EA0B": 3e-5, "EC0B": -4e-5, "EX0C": 0.03, "EY0C": -0.02, "EA0C": 2e-5, "EB0C": -3e-5,
         "EB0Z": 5e-5, "EXX1": 2e-5}
SETUP = {"instrument.T1.x": 0.3, "instrument.T1.y": -0.2, "instrument.T1.c": 2e-3, "instrument.T1.a": 1e-3,
         "instrument.T1.tool_z": 0.05, "instrument.T1.work_x": 0.04, "instrument.T1.work_y": -0.03,
         "instrument.T1.tool_a": 0.01, "instrument.T1.tool_c": -0.02, "instrument.T1.work_b": 0.015}
# As for the point kind: the tool target's y (along B) moves with the tracker.
FIXED = ["instrument.T1.tool_y"]
NOISE = {"pose": 0.01, "pose_angle": 5e-5}


def _plan(rng, n=40, targets=("tool", "work")):
    plan = []
    for _ in range(n):
        axes = {"X": float(rng.uniform(-200, 200)), "Y": float(rng.uniform(-200, 200)),
                "Z": float(rng.uniform(-100, 100)), "B": float(rng.uniform(-60, 60)), "C": float(rng.uniform(0, 360))}
        for target in targets:
            point, rot = ([0, 0, 150], TOOL_ROT) if target == "tool" else ([120, 40, 20], WORK_ROT)
            plan.append({"type": "pose", "instrument": "T1", "target": target, "target_point": point,
                         "target_rotation": rot, "axes": axes, "instrument_origin": ORIGIN,
                         "instrument_angles": ANGLES})
    return plan


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.from_dict(MACHINE)


def _data(machine, seed, **kw):
    rng = np.random.default_rng(seed)
    return fivecal.simulate(machine, _plan(rng, **kw), errors=TRUTH, setup=SETUP, sigma=NOISE, seed=seed)


def _fit(machine, seed):
    ds = _data(machine, seed)
    return ds, fivecal.identify(ds, list(TRUTH), fix=FIXED)


def test_both_sides_tracker_pose_and_fiducial_orientations_recovered_within_3_sigma(machine):
    ds, r = _fit(machine, 3)
    assert r.verdict == "ok", (r.verdict, r.adequacy)
    full = {**TRUTH, **SETUP}
    for n in r.estimated:
        assert abs(r.values[n] - full.get(n, 0.0)) < 3 * r.std[n], (n, r.values[n], full.get(n, 0.0), r.std[n])
    # The tracker pose, the fiducials' offsets and orientations are the
    # default setup: estimated without being asked for.
    want = ({f"instrument.T1.{f}" for f in "xyzabc"} | {f"instrument.T1.tool_{f}" for f in "xzabc"}
            | {f"instrument.T1.work_{f}" for f in "xyzabc"})
    assert want <= set(r.estimated)
    # The orientation rows are weighed in rad: their residuals are at the
    # declared 50 urad, not at the position rows' 10 um.
    rows = np.asarray(r.residuals).reshape(-1, 6)
    assert 2e-5 < np.sqrt(np.mean(rows[:, 3:] ** 2)) < 1e-4
    assert 4e-3 < np.sqrt(np.mean(rows[:, :3] ** 2)) < 2e-2


def test_coverage_of_the_pose_fit_over_100_simulations(machine):
    inside1 = inside2 = total = 0
    full = {**TRUTH, **SETUP}
    for seed in range(100):
        _, r = _fit(machine, 100 + seed)
        for n in list(TRUTH) + list(SETUP):
            z = abs(r.values[n] - full[n]) / r.std[n]
            total += 1
            inside1 += z < 1.0
            inside2 += z < 1.96
    assert 0.62 <= inside1 / total <= 0.74, inside1 / total
    assert 0.92 <= inside2 / total <= 0.98, inside2 / total


def test_residual_table_names_rotation_rows_and_writes_them_in_urad(machine, tmp_path):
    ds, r = _fit(machine, 3)
    table = r.residual_table()
    assert [t["component"] for t in table[:6]] == ["x", "y", "z", "rx", "ry", "rz"]
    r.write_residuals(tmp_path / "res.csv")
    lines = (tmp_path / "res.csv").read_text().splitlines()
    assert lines[0].endswith("component,residual_um")
    assert float(lines[4].split(",")[-1]) == pytest.approx(table[3]["residual"] * 1e6, abs=1e-4)
    assert float(lines[1].split(",")[-1]) == pytest.approx(table[0]["residual"] * 1e3, abs=1e-4)


def test_variance_components_scale_position_and_rotation_rows_apart(machine):
    # Declared twice the true position noise and half the true rotation
    # noise (through the instrument's sigma): each row group gets its own
    # factor, in its own unit.
    doc = _data(machine, 21, n=60).to_dict()
    for o in doc["observations"]:
        del o["sigma"]
    doc["instruments"] = {"T1": {"sigma": [0.02, 0.02, 0.02, 2.5e-5, 2.5e-5, 2.5e-5]}}
    r = fivecal.identify(fivecal.Dataset.from_dict(doc), list(TRUTH), fix=FIXED, variance_components=True)
    vc = r.variance_components
    assert set(vc) == {"pose", "pose_rad"}, vc
    assert vc["pose"]["declared_sigma"] == pytest.approx(0.02)
    assert vc["pose_rad"]["declared_sigma"] == pytest.approx(2.5e-5)
    assert vc["pose"]["sigma"] == pytest.approx(NOISE["pose"], rel=0.15), vc
    assert vc["pose_rad"]["sigma"] == pytest.approx(NOISE["pose_angle"], rel=0.15), vc
    assert r.verdict == "ok", r.adequacy
    # Five times too small: refused as a misfit, the group's noise in urad.
    doc["instruments"] = {"T1": {"sigma": [0.01, 0.01, 0.01, 1e-5, 1e-5, 1e-5]}}
    with pytest.warns(Warning, match="not usable"):
        r = fivecal.identify(fivecal.Dataset.from_dict(doc), list(TRUTH), fix=FIXED, variance_components=True)
    assert r.verdict == "inadequate"
    assert "pose_rad residuals" in r.adequacy and "10 urad declared" in r.adequacy, r.adequacy


def test_a_single_pose_cannot_place_the_tracker_and_says_so(machine):
    # One axis position repeated: the tracker's pose and the fiducial's
    # offset and orientation trade off exactly; identify names them.
    rng = np.random.default_rng(7)
    plan = _plan(rng, 1, targets=("tool",)) * 8
    setup = {k: v for k, v in SETUP.items() if "work" not in k}
    ds = fivecal.simulate(machine, plan, errors=TRUTH, setup=setup, sigma=NOISE, seed=7)
    with pytest.raises(ValueError, match=r"not determined.*instrument\.T1\."):
        fivecal.identify(ds, [], fix=FIXED)


def test_orientation_rows_alone_leave_positions_undetermined(machine):
    # A pose target seen at many poses but with its position rows weighed
    # out (sigma 1 m): the orientation rows see no translation, so the
    # tracker's position and the fiducial offsets are reported undetermined,
    # not given a number.
    doc = _data(machine, 8).to_dict()
    for o in doc["observations"]:
        o["sigma"] = [1e3, 1e3, 1e3, 5e-5, 5e-5, 5e-5]
    ds = fivecal.Dataset.from_dict(doc)
    with pytest.warns(Warning, match="did not determine"):
        r = fivecal.identify(ds, ["EA0B", "EC0B", "EA0C", "EB0C"], fix=FIXED, allow_unidentifiable=True)
    undetermined = {n for g in r.unidentifiable for n in g}
    assert {"instrument.T1.x", "instrument.T1.y", "instrument.T1.z"} & undetermined, r.unidentifiable


def test_file_round_trip_sigma_rows_and_bad_fields(machine):
    doc = _data(machine, 1, n=3).to_dict()
    o = doc["observations"][0]
    assert o["type"] == "pose" and o["instrument"] == "T1" and "setup" not in o
    assert o["target_rotation"] == pytest.approx(TOOL_ROT)
    # The simulator declares its noise per row: mm, then rad.
    assert o["sigma"] == pytest.approx([0.01] * 3 + [5e-5] * 3)
    again = fivecal.Dataset.from_dict(json.loads(json.dumps(doc)))
    assert again.to_dict()["observations"] == doc["observations"]
    for field, value, words in (("measured_rotation", [0, 0], "measured_rotation"),
                                ("measured_rotation", [0, 0, 7.0], "measured_rotation"),
                                ("target_rotation", [0, "x", 0], "target_rotation"),
                                ("sigma", 0.01, r"sigma.*\[mm, mm, mm, rad, rad, rad\]"),
                                ("sigma", [0.01, 0.01, 0.01, 1e-4, 1e-4], "sigma"),
                                ("sigma", [0.01, 0.01, 0.01, 1e-4, 1e-4, -1], "sigma"),
                                ("target", "table", "target")):
        bad = json.loads(json.dumps(doc))
        bad["observations"][1][field] = value
        with pytest.raises(ValueError, match=words):
            fivecal.Dataset.from_dict(bad)
    bad = json.loads(json.dumps(doc))
    del bad["observations"][2]["measured_rotation"]
    with pytest.raises(ValueError, match=r"observations\[2\]\.measured_rotation"):
        fivecal.Dataset.from_dict(bad)


def test_a_recorded_pose_dataset_gets_noise_on_every_row_for_monte_carlo(machine):
    from fivecal import uncertainty

    ds = _data(machine, 2, n=20)
    plan, fit = uncertainty.simulation_plan(ds, estimate=list(TRUTH), fix=FIXED)
    s = np.asarray(plan.input_sigma).reshape(-1, 6)
    # The position inputs at the fit's position rows' noise (mm), the
    # rotation inputs at the rotation rows' (rad): near the true ones, never 0.
    assert np.all((s[:, :3] > 0.7 * NOISE["pose"]) & (s[:, :3] < 1.3 * NOISE["pose"])), s[0]
    assert np.all((s[:, 3:] > 0.7 * NOISE["pose_angle"]) & (s[:, 3:] < 1.3 * NOISE["pose_angle"])), s[0]
    # the fit's sigma is its position rows' (mm); the rotation rows' is apart
    assert 0.7 * NOISE["pose"] < fit.sigma < 1.3 * NOISE["pose"]
    assert 0.7 * NOISE["pose_angle"] < fit.residual_units["rad"]["sigma"] < 1.3 * NOISE["pose_angle"]
    plan, _ = uncertainty.simulation_plan(ds, estimate=list(TRUTH), fix=FIXED,
                                          sigma={"pose": 0.01, "pose_angle": 5e-5})
    assert np.asarray(plan.input_sigma).reshape(-1, 6)[0] == pytest.approx([0.01] * 3 + [5e-5] * 3)
    with pytest.raises(ValueError, match="sigma.pose_angel"):
        uncertainty.simulation_plan(ds, estimate=list(TRUTH), fix=FIXED, sigma={"pose_angel": 1e-4})
