"""Trend, compare and pass/fail in the HTML report when a history exists (issue 18, item 5)."""
from __future__ import annotations

import fivecal
from fivecal import history
from fivecal.history import fleetsim
from fivecal.history.report import History


def test_report_has_history_sections(tmp_path):
    m = fleetsim.machine()
    plan = fleetsim.sphere_check_plan(m)
    store = str(tmp_path / "s.fcdb")
    results = []
    with history.Store(store) as s:
        for night in range(6):
            ex = 0.010 + (0.004 if night >= 4 else 0.0)
            ds = fivecal.simulate(m, plan, errors={"EX0C": ex}, artefact={"spheres": [fleetsim.SPHERE]},
                                  tip_radius=3.0, sigma=0.0006, seed=night)
            r = fivecal.identify(ds, "location")
            results.append(r)
            if night < 5:
                s.add(r, machine_id="HU-1", procedure="sphere", time=fleetsim.night_time(night))
    # the report of night 5, not yet stored: shown as the newest entry
    path = fivecal.write_report(results[5], tmp_path / "rep", history=History(
        store, "HU-1", tolerances={"EX0C": 0.012}, volumetric_tolerance=0.05))
    text = open(path, encoding="utf-8").read()
    for title in ("Calibration history", "Compared with the previous calibration", "Pass / fail"):
        assert f">{title}</h2>" in text
    assert "EX0C changed at 2026-01-05" in text          # the 4 µm step on night 4
    assert "covariance term is 0" in text and "Predicted volumetric error" in text
    assert "Latest calibration: <b>FAIL</b>" in text      # 14 µm > 12 µm
    assert (tmp_path / "rep" / "history_trend.png").exists()
    # the store and machine id form of the call
    path = fivecal.write_report(results[4], tmp_path / "rep2", history=store, machine_id="HU-1")
    text = open(path, encoding="utf-8").read()
    assert "Calibration history" in text and "Pass / fail" not in text
