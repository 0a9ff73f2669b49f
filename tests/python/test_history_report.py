"""Trend, compare and pass/fail in the HTML report when a history exists (issue 18, item 5)."""
from __future__ import annotations

import re

import fivecal
from fivecal import history
from fivecal.history import fleetsim
from fivecal.report.history import History


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
    assert re.search(r"This calibration \([^)]*\): <b>FAIL</b>", text)      # 14 µm > 12 µm
    assert (tmp_path / "rep" / "history_trend.png").exists()
    # the store and machine id form of the call
    path = fivecal.write_report(results[4], tmp_path / "rep2", history=store, machine_id="HU-1")
    text = open(path, encoding="utf-8").read()
    assert "Calibration history" in text and "Pass / fail" not in text


# -- fivecal identify --report DIR --history STORE --machine-id ID -----------

import json  # noqa: E402
import os  # noqa: E402

import pytest  # noqa: E402

from fivecal.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def nights(tmp_path_factory):
    """Seven nightly sphere checks of one machine (files named by date), EX0C
    stepping by 4 µm on the fifth; the first six recorded through the CLI."""
    d = tmp_path_factory.mktemp("nights")
    m = fleetsim.machine()
    plan = fleetsim.sphere_check_plan(m)
    paths = []
    for night in range(7):
        ds = fivecal.simulate(m, plan, errors={"EX0C": 0.010 + (0.004 if night >= 4 else 0.0), "EB0C": 3e-5},
                              artefact={"spheres": [fleetsim.SPHERE]}, tip_radius=3.0, sigma=0.0006,
                              seed=100 + night)
        p = d / f"{fleetsim.night_time(night)[:10]}.json"
        p.write_text(ds._core.to_json())
        paths.append(str(p))
    store = str(d / "shop.fcdb")
    for night, p in enumerate(paths[:6]):
        # the step's night alarms: recorded, and exit 1 as a FAIL (`fivecal docs history`)
        assert main(["identify", p, "--estimate", "location", "--store", store, "--machine-id", "HU-7",
                     "--record", "--procedure", "sphere"]) == (1 if night == 4 else 0), night
    return d, paths, store


def test_identify_record_puts_each_night_in_the_store_at_its_date(nights, capsys):
    d, paths, store = nights
    with history.Store(store) as s:
        cals = s.list("HU-7")
        assert [c.time for c in cals] == [fleetsim.night_time(n)[:10] + "T00:00:00Z" for n in range(6)]
        assert {c.procedure for c in cals} == {"sphere"} and cals[0].source == paths[0]
        assert cals[0].digest == history.dataset_digest(paths[0])
        assert s.machine("HU-7") is not None


def test_identify_report_with_history_through_the_cli(nights, tmp_path, capsys):
    d, paths, store = nights
    rep = tmp_path / "rep"
    assert main(["identify", paths[6], "--estimate", "location", "--report", str(rep), "--history", store,
                 "--machine-id", "HU-7", "--tolerance", "EX0C=0.012", "--volumetric-tolerance", "0.05"]) == 1
    out, err = capsys.readouterr()
    # out of tolerance stops a script (exit 1), with the grade on stdout and why on stderr
    assert "FAIL against the tolerances" in err and ": FAIL" in out and "EX0C" in out
    text = (rep / "report.html").read_text(encoding="utf-8")
    for title in ("Calibration history", "Compared with the previous calibration", "Pass / fail"):
        assert f">{title}</h2>" in text
    assert "7 calibrations of <b>HU-7</b>" in text and "(not in the store)" in text
    assert "EX0C changed at 2026-01-05" in text                      # the step of night 4
    # this result compared with the night before it, at its own date (from the file name)
    assert "2026-01-06T00:00:00Z → 2026-01-07T00:00:00Z" in text
    assert "This calibration (2026-01-07T00:00:00Z): <b>FAIL</b>" in text      # 14 µm > 12 µm
    # the tolerance is on values: the comparison of changes is not graded with it
    cmp = text[text.index(">Compared with the previous calibration<"):text.index(">Pass / fail<")]
    assert "tolerance" not in cmp and "pass" not in cmp
    assert (rep / "history_trend.png").stat().st_size > 20000
    with history.Store(store) as s:
        assert len(s.list("HU-7")) == 6                                # the report alone records nothing


def test_identify_report_of_an_older_night_grades_that_night(nights, tmp_path):
    d, paths, store = nights
    rep = tmp_path / "rep"
    assert main(["identify", paths[2], "--estimate", "location", "--report", str(rep), "--history", store,
                 "--machine-id", "HU-7", "--tolerance", "EX0C=0.012"]) == 0
    text = (rep / "report.html").read_text(encoding="utf-8")
    assert "this report's is the one of 2026-01-03T00:00:00Z (#3 in the store)" in text
    assert "2026-01-02T00:00:00Z → 2026-01-03T00:00:00Z" in text
    assert "This calibration (2026-01-03T00:00:00Z): <b>PASS</b>" in text      # 10 µm, before the step


def test_identify_history_options_are_checked_before_the_fit(nights, tmp_path, capsys):
    d, paths, store = nights
    bad = tmp_path / "notastore.fcdb"
    bad.write_text("{}")
    cases = [(["--history", store, "--report", str(tmp_path / "r")], "--machine-id"),
             (["--history", store, "--machine-id", "HU-7"], "--report DIR"),
             (["--tolerance", "EX0C=0.01", "--report", str(tmp_path / "r")], "needs --store"),
             (["--history", str(tmp_path / "missing.fcdb"), "--machine-id", "M", "--report", str(tmp_path / "r")],
              "no such calibration store"),
             (["--history", str(bad), "--machine-id", "M", "--report", str(tmp_path / "r")],
              "not a calibration store"),
             (["--history", store, "--machine-id", "HU-7", "--report", str(tmp_path / "r"), "--tolerance", "EX0C=x"],
              "not a number"),
             (["--history", store, "--machine-id", "HU-7", "--report", str(tmp_path / "r"),
               "--volumetric-tolerance", "-1"], "positive")]
    for extra, needle in cases:
        capsys.readouterr()
        assert main(["identify", paths[0], "--estimate", "location", *extra]) == 2, extra
        err = capsys.readouterr().err
        assert needle in err and "fitting" not in err, (extra, err)
    assert not (tmp_path / "r").exists() and not (tmp_path / "missing.fcdb").exists()


def test_identify_report_with_history_renders_in_chromium(nights, tmp_path):
    from test_report import render_check

    d, paths, store = nights
    rep = tmp_path / "rep"
    assert main(["identify", paths[6], "--estimate", "location", "--report", str(rep), "--history", store,
                 "--machine-id", "HU-7", "--tolerance", "EX0C=0.012"]) == 1     # FAIL: still reported
    found = render_check(rep / "report.html", tmp_path)
    assert found["broken"] == [] and min(found["widths"]) > 500
    for section in ("Calibration history", "Compared with the previous calibration", "Pass / fail"):
        assert section in found["h2"]


def test_identify_report_of_an_unusable_fit_fails_it_and_compares_nothing(nights, tmp_path):
    """A night whose residuals are 10x the declared noise: the report grades
    that night (FAIL, not usable) instead of the newest usable one, and
    draws no comparison from it."""
    d, paths, store = nights
    data = json.loads(open(paths[6]).read())
    for o in data["observations"]:
        o["sigma"] = 0.00006
    bad = tmp_path / "2026-01-08.json"
    bad.write_text(json.dumps(data))
    rep = tmp_path / "rep"
    assert main(["identify", str(bad), "--estimate", "location", "--report", str(rep), "--history", store,
                 "--machine-id", "HU-7", "--tolerance", "EX0C=0.02"]) == 1
    text = (rep / "report.html").read_text(encoding="utf-8")
    assert "1 not usable, left out of the trend" in text
    assert "This calibration (2026-01-08T00:00:00Z): <b>FAIL</b> (the fit itself is not usable: inadequate)" in text
    assert ">Compared with the previous calibration</h2>" not in text
