"""The fixed-frame point kind (laser tracker, camera, CMM): a machine with
rotary axes on both sides (C on the table, B on the head) seen by one
tracker that follows a target on the tool and one on the table. The
tracker's pose in the machine frame is estimated with the machine errors."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal

from shared_machines import TABLE_HEAD as MACHINE  # noqa: E402
ORIGIN, ANGLES = [2000.0, -500.0, 400.0], [0.5, -1.0, 155.0]  # tracker pose, mm / deg
# Location errors of both rotary axes, a squareness and a scale gain. The
# pivot positions of the head (EX0B, EZ0B) are not among them: with the
# tracker's position free they move the whole tool side like the tracker
# does (the machine frame is the linear axes'), and identify refuses them.
TRUTH = {"EA0B": 3e-5, "EC0B": -4e-5, "EX0C": 0.03, "EY0C": -0.02, "EA0C": 2e-5, "EB0C": -3e-5,
         "EB0Z": 5e-5, "EXX1": 2e-5}
SETUP = {"instrument.T1.x": 0.3, "instrument.T1.y": -0.2, "instrument.T1.c": 2e-3, "instrument.T1.a": 1e-3,
         "instrument.T1.tool_z": 0.05, "instrument.T1.work_x": 0.04, "instrument.T1.work_y": -0.03}
# The target on the tool can only be told apart from the tracker's position
# along what the head's rotation turns it; its y (along B) is fixed as known.
FIXED = ["instrument.T1.tool_y"]


def _plan(rng, n=60):
    plan = []
    for _ in range(n):
        axes = {"X": float(rng.uniform(-200, 200)), "Y": float(rng.uniform(-200, 200)),
                "Z": float(rng.uniform(-100, 100)), "B": float(rng.uniform(-60, 60)), "C": float(rng.uniform(0, 360))}
        for target, point in (("tool", [0, 0, 150]), ("work", [120, 40, 20])):
            plan.append({"type": "point", "instrument": "T1", "target": target, "target_point": point,
                         "axes": axes, "instrument_origin": ORIGIN, "instrument_angles": ANGLES})
    return plan


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.from_dict(MACHINE)


def _fit(machine, seed):
    rng = np.random.default_rng(seed)
    ds = fivecal.simulate(machine, _plan(rng), errors=TRUTH, setup=SETUP, sigma={"point": 0.005}, seed=seed)
    return ds, fivecal.identify(ds, list(TRUTH), fix=FIXED)


def test_both_sides_and_the_tracker_pose_recovered_within_3_sigma(machine):
    ds, r = _fit(machine, 3)
    assert r.verdict == "ok", (r.verdict, r.adequacy)
    full = {**TRUTH, **SETUP}
    for n in r.estimated:
        assert abs(r.values[n] - full.get(n, 0.0)) < 3 * r.std[n], (n, r.values[n], full.get(n, 0.0), r.std[n])
    # The tracker pose is part of the default setup: estimated without being asked for.
    assert {f"instrument.T1.{f}" for f in "xyzabc"} <= set(r.estimated)


def test_coverage_of_the_point_fit_over_100_simulations(machine):
    inside = total = 0
    full = {**TRUTH, **SETUP}
    for seed in range(100):
        _, r = _fit(machine, 100 + seed)
        for n in TRUTH:
            total += 1
            inside += abs(r.values[n] - full[n]) < 1.96 * r.std[n]
    assert 0.92 <= inside / total <= 0.98, inside / total


def test_head_pivot_with_a_free_tracker_is_refused_as_confounded(machine):
    ds, _ = _fit(machine, 4)
    with pytest.raises(ValueError, match=r"EX0B.*instrument\.T1\.x|instrument\.T1\.x.*EX0B"):
        fivecal.identify(ds, list(TRUTH) + ["EX0B"], fix=FIXED)


def test_tracker_pose_left_fixed_is_inadequate_naming_the_setup(machine):
    rng = np.random.default_rng(5)
    ds = fivecal.simulate(machine, _plan(rng), errors=TRUTH, setup=SETUP, sigma={"point": 0.005}, seed=5)
    r = fivecal.identify(ds, list(TRUTH), fix=FIXED + [f"instrument.T1.{f}" for f in "xyzabc"])
    assert r.verdict == "inadequate"
    assert "setup not estimated" in r.adequacy


def test_file_round_trip_and_bad_fields(machine):
    rng = np.random.default_rng(1)
    ds = fivecal.simulate(machine, _plan(rng, 3), errors=TRUTH, setup=SETUP, sigma={"point": 0.005}, seed=1)
    doc = ds.to_dict()
    o = doc["observations"][0]
    assert o["type"] == "point" and o["target"] == "tool" and o["instrument"] == "T1" and "setup" not in o
    assert o["instrument_angles"] == pytest.approx(ANGLES)
    again = fivecal.Dataset.from_dict(json.loads(json.dumps(doc)))
    assert again.to_dict()["observations"] == doc["observations"]
    for field, value, words in (("target", "table", "target"), ("instrument", 3, "instrument"),
                                ("target_point", [0, 0], "target_point"), ("measured", [1, 2, float("nan")], "measured"),
                                ("instrumnt_origin", [0, 0, 0], "instrumnt_origin")):
        bad = json.loads(json.dumps(doc))
        bad["observations"][1][field] = value
        with pytest.raises(ValueError, match=words):
            fivecal.Dataset.from_dict(bad)


def test_report_plots_the_machine_signature_not_the_tracker_placement(machine, tmp_path):
    """The point figure's top row is what the tracker saw beyond the nominal
    machine, taken through the fitted tracker pose: with a perfect machine
    it is noise (µm) although the tracker stands 0.3 mm and 0.1° off its
    nominal pose; with the machine's errors it shows their tens of µm."""
    import matplotlib

    matplotlib.use("Agg")
    from fivecal.report import plots

    rng = np.random.default_rng(5)
    plan = _plan(rng, 40)
    for errors, low, high in (({}, 0.0, 0.02), (TRUTH, 0.02, 1.0)):
        ds = fivecal.simulate(machine, plan, errors=errors, setup=SETUP, sigma={"point": 0.001}, seed=5)
        r = fivecal.identify(ds, list(TRUTH), fix=FIXED)
        fig = plots.component_figure(r, "point")
        top = np.concatenate([np.abs(ln.get_ydata()) for ax in fig.axes[:3] for ln in ax.get_lines()[:-1]])
        bottom = np.concatenate([np.abs(ln.get_ydata()) for ax in fig.axes[3:6] for ln in ax.get_lines()[:-1]])
        assert low * 1e3 <= np.nanmax(top) <= high * 1e3, (errors, np.nanmax(top))
        assert np.nanmax(bottom) < 6.0  # residual after the fit: noise, µm
        assert "instrument frame" in fig._suptitle.get_text() and "T1" in fig._suptitle.get_text()
    path = fivecal.write_report(r, tmp_path / "rep")
    assert (tmp_path / "rep" / "point_components.png").is_file()
    assert "Tracker / camera points" in open(path, encoding="utf-8").read()
    plots.plot_components(r, str(tmp_path / "point.png"), "point")
