"""The one export path every controller vendor goes through (issue 32), run
for each registered vendor: ``fivecal export <vendor>`` on a simulated sphere
check writes the controller's file and export.json; the file reads back to
the values; the values' round trip through the vendor's own kinematics
reproduces the absorbed model; the change's 1σ is the scatter of the change
over repeated checks; the plausibility guard and the refusals hold.

Each vendor's own tests (test_export_<vendor>.py, tests/cpp/test_vendor_<vendor>.cc)
check its manual's conventions; this file checks what every vendor shares.
"""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.cli.export import WRITERS
from fivecal.compensation import load_errors
from fivecal.io import controllers as K
from fivecal.procedures import sphere_check as sc

MACHINES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines")
BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
TIP = 3.0
TRUTH = {"EY0A": 0.012, "EZ0A": -0.008, "EB0A": 2e-5, "EX0C": 0.015, "EY0C": -0.01, "EAAb": 1e-5, "ECCb": 1.5e-5}
#: the conventions each vendor needs stated for c600u (A on C, table-table),
#: where its public manual leaves them open (docs/controllers.md)
OPTIONS: dict = {
    "fanuc": {"increment": "IS-C", "tool-length": "100", "axis-order": "XYZAC"},
    "siemens": {"record": "1"},  # the swivel data record's number: never guessed
    "heidenhain": {"table-axis-sign": "iso", "tool-length": "100"},
    "beckhoff": {"syntax": "kinematik", "axes": "XYZAC", "tool_length": "0"},
}
VENDORS = K.vendors()


def test_every_registered_vendor_has_a_writer_and_every_writer_a_vendor():
    assert sorted(WRITERS) == sorted(VENDORS)


def _sets(vendor):
    out = []
    for k, v in OPTIONS.get(vendor, {}).items():
        out += ["--set", f"{k}={v}"]
    return out


@pytest.fixture(scope="module")
def check(tmp_path_factory):
    """A sphere check of c600u with pivot errors, as a result document."""
    d = tmp_path_factory.mktemp("vendors")
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    plan = sc.plan(m, BALL, tip_radius=TIP)
    ds = fivecal.simulate(m, plan, errors=TRUTH, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=0.001, seed=5)
    fivecal.save_dataset(ds, str(d / "ds.json"))
    assert main(["sphere-check", str(d / "ds.json"), "--out", str(d / "check.json")]) == 0
    return d, m, plan


@pytest.mark.parametrize("vendor", VENDORS)
def test_export_writes_the_file_and_the_record_and_reads_back(check, vendor, capsys):
    d, m, _ = check
    out = d / f"out-{vendor}"
    rc = main(["export", vendor, str(d / "check.json"), "--machine", os.path.join(MACHINES, "c600u.json"),
               "--out", str(out), *_sets(vendor)])
    text = capsys.readouterr().out
    assert rc == 0, text
    rec = json.load(open(out / "export.json"))
    assert rec["kind"] == "fivecal controller export" and rec["vendor"] == vendor
    assert rec["round_trip_max_mm"] < 1e-6
    changed = [v for v in rec["values"] if not v["fixed"] and abs(v["change"]) > 1e-9]
    assert changed, "the pivot errors change no value"
    assert all(v["sigma"] is not None and v["sigma"] > 0 for v in changed)
    # the controller's file reads back to the new values
    written = [f for f in os.listdir(out) if f != "export.json"]
    assert written
    back = {}
    for f in written:
        try:
            back.update(WRITERS[vendor].read(str(out / f)))
        except ValueError:
            continue   # a second file of another layout (a CSV beside a table)
    # a file written at the controller's input increment reads back to it
    tol = max(1e-6, getattr(WRITERS[vendor], "resolution", lambda o: 0.0)(OPTIONS.get(vendor, {})))
    for v in rec["values"]:
        if not v["fixed"]:
            assert back[v["name"]] == pytest.approx(v["new"], abs=tol), v["name"]
    # the absorbed fivecal parameters are what verification after loading reads
    assert set(rec["absorbed"]["names"]) >= {"EY0C", "EZ0A"}
    # --old: the file just written is the controller's state; the change is the same
    out2 = d / f"out2-{vendor}"
    src = out / next(f for f in written if f.startswith(vendor))
    rc = main(["export", vendor, str(d / "check.json"), "--machine", os.path.join(MACHINES, "c600u.json"),
               "--out", str(out2), "--old", str(src), "--force", *_sets(vendor)])
    assert rc == 0, capsys.readouterr().out
    rec2 = json.load(open(out2 / "export.json"))
    for a, b in zip(rec["values"], rec2["values"]):
        assert b["change"] == pytest.approx(a["change"], abs=1e-12)
        assert b["old"] == pytest.approx(a["new"], abs=tol)


@pytest.mark.parametrize("vendor", VENDORS)
def test_the_values_reproduce_the_absorbed_machine_through_the_vendors_kinematics(check, vendor):
    _, m, _ = check
    exp = K.vendor_export(m, vendor, TRUTH, options=OPTIONS.get(vendor))
    poses = exp.absorption.poses
    pts = K.vendor_tool_points(m, vendor, [v["new"] for v in exp.values], poses, OPTIONS.get(vendor))
    # the erroneous machine's tool points, less what the controller's model
    # cannot absorb, are the vendor's points up to a rigid work offset
    truth = m.tool_point(poses, TRUTH)
    table = K.kinematics_table(m, exp.absorption.theta)
    in_part = (pts - table["part_origin"]) @ table["part_rotation"]
    left = truth - exp.absorption.workpiece_shift - in_part
    assert np.abs(left - exp.absorption.residual).max() < 1e-6
    # the way back: the new values are the absorbed model
    back = K.vendor_to_theta(m, vendor, [v["new"] for v in exp.values], poses, OPTIONS.get(vendor))
    assert back["max_mm"] < 1e-6
    assert np.abs(back["theta"] - exp.absorption.theta).max() < 1e-7


@pytest.mark.parametrize("vendor", VENDORS)
def test_the_changes_sigma_is_its_scatter_over_repeated_checks(check, vendor):
    """Coverage of σ: 40 sphere checks of the same machine with fresh noise;
    the scatter of each changed value about its mean is the σ the export
    gives (ratio within the chi-square band for 40 samples)."""
    _, m, plan = check
    changes, sigmas = [], []
    for seed in range(40):
        ds = fivecal.simulate(m, plan, errors=TRUTH, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=0.001,
                              seed=100 + seed)
        doc = sc.evaluate(ds).to_dict()
        exp = K.vendor_export(m, vendor, load_errors(doc, m), K.result_covariance(doc, m),
                              options=OPTIONS.get(vendor))
        changes.append([v["change"] for v in exp.values])
        sigmas.append([v["sigma"] for v in exp.values])
    changes, sigmas = np.array(changes), np.array(sigmas)
    big = [k for k in range(changes.shape[1]) if np.median(sigmas[:, k]) > 0]
    assert big
    for k in big:
        ratio = np.std(changes[:, k], ddof=1) / np.median(sigmas[:, k])
        assert 0.6 < ratio < 1.5, (exp.values[k]["name"], ratio)


@pytest.mark.parametrize("vendor", VENDORS)
def test_refusals_name_the_option_the_value_or_the_limit(check, vendor, capsys):
    d, _, _ = check
    base = ["export", vendor, str(d / "check.json"), "--machine", os.path.join(MACHINES, "c600u.json")]
    assert main([*base, "--out", str(d / "x1"), "--set", "no-such-key=1", *_sets(vendor)]) == 2
    assert "no-such-key" in capsys.readouterr().err
    assert main([*base, "--out", str(d / "x2"), "--max-change", "0.0001,1e-9", *_sets(vendor)]) == 2
    assert "--max-change" in capsys.readouterr().err
    assert main([*base, "--out", str(d / "x3"), "--set", "oops", *_sets(vendor)]) == 2
    assert "KEY=VALUE" in capsys.readouterr().err
    assert not os.path.exists(d / "x1") and not os.path.exists(d / "x2")


def test_result_covariance_is_the_documents_std_and_correlation(check):
    d, m, _ = check
    doc = json.load(open(d / "check.json"))
    cov = K.result_covariance(str(d / "check.json"), m)
    names = m.parameter_names()
    est = [e for e in doc["estimated"] if e in names]
    assert est and cov.shape == (len(names), len(names))
    i, j = names.index(est[0]), names.index(est[1])
    a, b = doc["estimated"].index(est[0]), doc["estimated"].index(est[1])
    sa, sb = doc["parameters"][est[0]]["std"], doc["parameters"][est[1]]["std"]
    assert cov[i, i] == pytest.approx(sa ** 2) and cov[i, j] == pytest.approx(doc["correlation"][a][b] * sa * sb)
    # not estimated: no uncertainty claimed, and none invented
    assert cov[names.index("EX0A"), names.index("EX0A")] == 0.0
    assert np.allclose(cov, cov.T)
    bad = dict(doc)
    bad.pop("correlation")
    with pytest.raises(ValueError, match="correlation"):
        K.result_covariance(bad, m)
