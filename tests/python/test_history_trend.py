"""Compare, grade, CUSUM design, pooled statistics and the trend plot (issue 18, item 2)."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal
from fivecal import history, uncertainty
from fivecal.cli import main
from fivecal.history import fleetsim


def cal(values: dict, std: dict, time="2026-01-01", machine_id="M", id=None, **kw):
    names = list(values)
    return history.Calibration(machine_id, history.utc_time(time), names, np.array([values[n] for n in names]),
                               np.diag([std[n] ** 2 for n in names]), id=id, **kw)


def test_compare_z_uses_both_uncertainties_and_no_covariance_term():
    a = cal({"EX0C": 0.010, "EB0C": 1e-5, "tip.z": 0.3}, {"EX0C": 3e-4, "EB0C": 1e-6, "tip.z": 1e-3})
    b = cal({"EX0C": 0.012, "EB0C": 1e-5}, {"EX0C": 4e-4, "EB0C": 2e-6})
    c = history.compare(a, b, tolerances={"EX0C": 0.001})
    (p,) = [q for q in c.parameters if q.name == "EX0C"]
    assert [q.name for q in c.parameters] == ["EX0C", "EB0C"]       # setup parameters are not compared
    assert p.delta == pytest.approx(0.002) and p.std_delta == pytest.approx(5e-4)
    assert p.z == pytest.approx(4.0) and c.significant() == ["EX0C"] and p.passed is False
    assert "covariance term is 0" in c.report()


def test_volumetric_change_is_the_machine_model_prediction():
    m = fleetsim.machine()
    a = cal({"EX0C": 0.0, "EB0C": 0.0}, {"EX0C": 1e-4, "EB0C": 1e-6})
    b = cal({"EX0C": 0.005, "EB0C": 2e-5}, {"EX0C": 1e-4, "EB0C": 1e-6})
    grid = history.default_grid(m)
    v = history.volumetric_change(m, a, b)
    e = np.linalg.norm(m.volumetric_error(grid, {"EX0C": 0.005, "EB0C": 2e-5}), axis=1)
    assert v.max_change == pytest.approx(e.max()) and v.max_a == 0.0 and v.max_b == pytest.approx(e.max())
    assert v.max_change > 0.005 and v.poses == len(e)          # the offset plus the tilt's share
    assert history.volumetric_change(m, b, b).max_change == 0.0
    # undetermined parameters are not the machine's: they do not enter the prediction
    c = cal({"EX0C": 0.005, "EB0C": 2e-5}, {"EX0C": 1e-4, "EB0C": 1e-6}, undetermined=["EB0C"])
    e2 = np.linalg.norm(m.volumetric_error(grid, {"EX0C": 0.005}), axis=1)
    assert history.volumetric_errors(m, c).max() == pytest.approx(e2.max())


def test_grade_pass_fail_undecided():
    c = cal({"EX0C": 0.004, "EB0C": 1e-5, "EA0C": 3.5e-5}, {"EX0C": 2e-4, "EB0C": 1e-6, "EA0C": 5e-6})
    g = history.grade(c, {"EX0C": 0.005, "EB0C": 1e-5, "EA0C": 2e-5})
    assert g.parameters["EX0C"]["grade"] == "pass"          # 4 + 0.4 <= 5 µm
    assert g.parameters["EB0C"]["grade"] == "undecided"     # on the limit within 2u
    assert g.parameters["EA0C"]["grade"] == "fail"          # 35 - 10 > 20 µrad
    assert g.verdict == "fail"
    assert history.grade(c, {"EX0C": 0.005}).verdict == "pass"
    c.verdict = "inadequate"
    assert history.grade(c, {"EX0C": 0.005}).verdict == "fail"
    m = fleetsim.machine()
    ok = cal({"EX0C": 0.004}, {"EX0C": 1e-4})
    assert history.grade(ok, {}, volumetric_tolerance=0.01, machine=m).volumetric["grade"] == "pass"
    assert history.grade(ok, {}, volumetric_tolerance=0.001, machine=m).verdict == "fail"


def test_siegmund_interval_matches_a_monte_carlo_of_the_self_starting_chart():
    # the decision interval solves Siegmund's ARL; a simulation of the actual
    # chart (self-starting, two-sided, restarting at alarms) must show the
    # stated false-alarm rate: 2 one-sided charts at ARL 200 -> 1 % per step
    design = history.ChartDesign.for_rate(0.01, charts=1)
    assert design.arl0_one_sided == pytest.approx(200)
    assert history.siegmund_arl(design.h, design.k) == pytest.approx(200, rel=1e-9)
    rng = np.random.default_rng(5)
    alarms = steps = 0
    for _ in range(300):
        x = rng.normal(0.02, 1e-3, 400) + 0.0
        ch = history.cusum(x, np.full(400, 1e-3), design.h, design.k)
        alarms += len(ch.alarms)
        steps += 399
    rate = alarms / steps
    assert 0.006 < rate < 0.014, rate
    # and a 3σ step is found within a few nights
    x = np.r_[np.zeros(20), np.full(10, 3e-3)] + rng.normal(0, 1e-3, 30)
    ch = history.cusum(x, np.full(30, 1e-3), design.h)
    assert ch.alarms and 20 <= ch.alarms[0] <= 23


def test_pooled_statistics_use_the_gum_pooling():
    rng = np.random.default_rng(3)
    cals, X, days = [], [], []
    for d in range(6):
        level = rng.normal(0, 0.002)          # the machine moves between days
        for k in range(3):
            x = level + rng.normal(0, 0.0005)
            X.append([x])
            days.append(d)
            cals.append(cal({"EX0C": x}, {"EX0C": 0.0005}, time=f"2026-01-0{d + 1}T0{k}:00:00Z"))
    p = history.pooled_statistics(cals, by="days")
    ref = uncertainty.pooled_covariance(np.array(X), days)
    assert p.dof == ref.dof == 12 and p.covariance[0, 0] == ref.covariance[0, 0]
    X = np.array(X)[:, 0].reshape(6, 3)
    manual = ((X - X.mean(axis=1, keepdims=True)) ** 2).sum() / 12
    assert p.covariance[0, 0] == pytest.approx(manual)
    assert 0.5 < p.std[0] / 0.0005 < 1.6                  # within-day: the noise only
    by_cycle = history.pooled_statistics(cals, by="cycles")
    assert by_cycle.std[0] > 2 * p.std[0]                 # across days: the machine's change
    assert "pooled over 6 days" in p.report()


def test_trend_plot(tmp_path):
    rng = np.random.default_rng(1)
    cals = []
    for n in range(20):
        x = 0.004 + (0.003 if n >= 12 else 0.0) + rng.normal(0, 2e-4)
        cals.append(cal({"EX0C": x, "EB0C": 1e-5 + rng.normal(0, 1e-6)}, {"EX0C": 2e-4, "EB0C": 1e-6},
                        time=fleetsim.night_time(n)))
    charts = history.detect(cals)
    assert charts["EX0C"].alarms and charts["EX0C"].alarms[0] == 12 and not charts["EB0C"].alarms
    p = history.plot_trend(cals, str(tmp_path / "t.png"), tolerances={"EX0C": 0.006}, charts=charts)
    from matplotlib.image import imread

    img = imread(p)
    assert img.shape[0] > 300 and img.shape[1] > 600
    red = (img[..., 0] > 0.8) & (img[..., 1] < 0.45) & (img[..., 2] < 0.45)
    assert red.sum() > 100                                # the tolerance lines and the alarm are drawn


def test_compare_two_result_files_on_the_command_line(tmp_path, capsys):
    m = fleetsim.machine()
    plan = fleetsim.sphere_check_plan(m)
    out = []
    for i, ex in enumerate((0.010, 0.013)):
        ds = fivecal.simulate(m, plan, errors={"EX0C": ex}, artefact={"spheres": [fleetsim.SPHERE]},
                              tip_radius=3.0, sigma=0.0006, seed=i)
        fivecal.identify(ds, "location").save(tmp_path / f"r{i}.json")
    (tmp_path / "m.json").write_text(json.dumps(m.to_dict()))
    assert main(["history", "compare", str(tmp_path / "r0.json"), str(tmp_path / "r1.json"),
                 "--machine", str(tmp_path / "m.json"), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    ex = d["parameters"]["EX0C"]
    assert ex["delta"] == pytest.approx(0.003, abs=1e-3) and abs(ex["z"]) > 5
    assert "EX0C" in d["significant"] and d["volumetric"]["max_change"] > 0.002
    assert main(["history", "compare", "1", "2"]) == 2
    assert "needs --store" in capsys.readouterr().err


def test_gum_from_the_stored_history_is_the_pooled_cycles_gum(tmp_path):
    m = fleetsim.machine()
    plan = fleetsim.sphere_check_plan(m)
    paths, times = [], ["2026-01-01T02:00:00Z", "2026-01-01T04:00:00Z", "2026-01-02T02:00:00Z",
                        "2026-01-02T04:00:00Z"]
    with history.Store(tmp_path / "s.fcdb") as s:
        for i, t in enumerate(times):
            ds = fivecal.simulate(m, plan, errors={"EX0C": 0.01 + 0.001 * (i >= 2)},
                                  artefact={"spheres": [fleetsim.SPHERE]}, tip_radius=3.0, sigma=0.0006, seed=i)
            p = str(tmp_path / f"d{i}.json")
            fivecal.save_dataset(ds, p)
            paths.append(p)
            s.add(fivecal.identify(ds, "location"), machine_id="M", time=t, source=p)
        cals = s.list("M")
    g = history.gum_from_history(cals, "location", by="days")
    ref = uncertainty.gum_input_covariance([fivecal.load_dataset(p) for p in paths], "location",
                                           day=[0, 0, 1, 1], pooling="days")
    assert g.pooling == "days" and g.dof == ref.dof
    assert g.std["EX0C"] == ref.std["EX0C"] and g.day == [0, 0, 1, 1]
    cals[0].source = str(tmp_path / "gone.json")
    with pytest.raises(ValueError, match="not available"):
        history.gum_from_history(cals)
