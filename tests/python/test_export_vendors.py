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
    # and the record says what a sphere check verifies of it: all of it here (no tables)
    assert rec["sphere_check"] == {"verifies": "kinematics", "unverifiable_values": 0, "unverifiable": None}
    # --old: the file just written is the controller's state; the change is the same
    out2 = d / f"out2-{vendor}"
    src = out / next(f for f in written if f.startswith(vendor))
    rc = main(["export", vendor, str(d / "check.json"), "--machine", os.path.join(MACHINES, "c600u.json"),
               "--out", str(out2), "--old", str(src), "--force-old", *_sets(vendor)])
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


@pytest.mark.parametrize("vendor", VENDORS)
def test_each_guard_has_its_own_switch(check, vendor, capsys):
    """--old that differs from the machine file and a change beyond
    --max-change are two refusals with two switches: each lifts its own
    guard only; --force (as before) lifts both."""
    d, _, _ = check
    machine = os.path.join(MACHINES, "c600u.json")
    first = d / f"guard0-{vendor}"
    assert main(["export", vendor, str(d / "check.json"), "--machine", machine, "--out", str(first),
                 *_sets(vendor)]) == 0
    old = first / next(f for f in sorted(os.listdir(first)) if f.startswith(vendor))
    # the old values are the new ones of the first export: they differ from
    # the machine file by the change, and the change is the same again
    base = ["export", vendor, str(d / "check.json"), "--machine", machine, "--old", str(old),
            "--max-change", "1e-5,1e-9", *_sets(vendor)]
    capsys.readouterr()
    assert main([*base, "--out", str(d / f"guard1-{vendor}"), "--force-change"]) == 2
    err = capsys.readouterr().err
    assert "--old" in err and "--force-old" in err, err
    assert main([*base, "--out", str(d / f"guard2-{vendor}"), "--force-old"]) == 2
    err = capsys.readouterr().err
    assert f"{vendor} values (--force-change" in err and "against the machine file" not in err, err
    assert not os.path.exists(d / f"guard1-{vendor}") and not os.path.exists(d / f"guard2-{vendor}")
    assert main([*base, "--out", str(d / f"guard3-{vendor}"), "--force-old", "--force-change"]) == 0
    assert main([*base, "--out", str(d / f"guard4-{vendor}"), "--force"]) == 0
    capsys.readouterr()


#: a C table and a B head: the tool length is determined (the head turns the
#: tool), unlike on c600u, where it trades with the work offset
TABLE_HEAD = {"name": "th", "topology": "wCXYfZBSt", "axes": {
    "C": {"type": "rotary", "direction": [0, 0, -1], "point": [30, -20, 0]},
    "X": {"type": "linear", "direction": [-1, 0, 0]}, "Y": {"type": "linear", "direction": [0, -1, 0]},
    "Z": {"type": "linear", "direction": [0, 0, 1]},
    "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, 350]},
    "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [0, 0, 120]}}
HEAD_OPTIONS: dict = {
    "fanuc": {"increment": "IS-C", "tool-length": "100", "holder-offset": "5", "axis-order": "XYZBC"},
    "siemens": {"record": "1"},
    "heidenhain": {"table-axis-sign": "iso", "tool-length": "100"},
    "beckhoff": {"syntax": "kinematik", "axes": "XYZBC", "tool_length": "0"},
}
TOOL_LENGTH_ERROR = 0.05   # mm, along the spindle


@pytest.fixture(scope="module")
def head_check(tmp_path_factory):
    """Sphere touches on a table-head machine whose tool is 50 µm longer
    than its machine file says, identified with the tool length free (the
    stylus's sideways offsets fixed: they trade with the C pivot here), as
    the result document `fivecal identify --out` writes."""
    d = tmp_path_factory.mktemp("toollength")
    machine_file = d / "th.json"
    machine_file.write_text(json.dumps(TABLE_HEAD))
    m = fivecal.Machine.load(str(machine_file))
    plan = sc.plan(m, BALL, tip_radius=TIP)
    truth = {"tip.z": TOOL_LENGTH_ERROR, "EX0C": 0.01}
    ds = fivecal.simulate(m, plan, errors=truth, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=0.001, seed=7)
    fivecal.save_dataset(ds, str(d / "ds.json"))
    assert main(["identify", str(d / "ds.json"), "--estimate", "EX0C,EY0C", "--fix", "tip.x,tip.y",
                 "--out", str(d / "check.json")]) == 0
    return d, m, str(machine_file)


@pytest.mark.parametrize("vendor", VENDORS)
def test_an_identified_tool_length_error_reaches_the_vendors_tool_length(head_check, vendor, capsys):
    """From the command line: the tool length identified (tip.z,
    along the spindle) changes the value that holds the tool's length in the
    vendor's file by that length, with a σ that carries its uncertainty;
    Siemens keeps no tool length in the swivel data record (tool data), so
    nothing of it goes there. Without it (load_errors' default, as LinuxCNC
    compensation takes it) the change is missing."""
    from fivecal.cli.export import _GUARD_UNITS
    d, m, machine_file = head_check
    doc = json.load(open(d / "check.json"))
    tip = doc["parameters"]["tip.z"]
    assert abs(tip["value"] - TOOL_LENGTH_ERROR) < 3 * tip["std"], tip
    out = d / f"tl-{vendor}"
    sets = [x for k, v in HEAD_OPTIONS[vendor].items() for x in ("--set", f"{k}={v}")]
    assert main(["export", vendor, str(d / "check.json"), "--machine", machine_file, "--out", str(out), *sets]) == 0
    capsys.readouterr()
    rec = json.load(open(out / "export.json"))
    without = K.vendor_export(m, vendor, load_errors(doc, m), K.result_covariance(doc, m),
                              options=HEAD_OPTIONS[vendor])
    assert "tip.z" not in load_errors(doc, m)
    mm = lambda v: _GUARD_UNITS[v["unit"]][1] * v["change"]  # noqa: E731
    diff = [(abs(mm(a) - mm(b)), a) for a, b in zip(rec["values"], without.values)
            if not a["fixed"] and _GUARD_UNITS[a["unit"]][0] == "mm"]
    size, value = max(diff, key=lambda x: x[0])
    if vendor == "siemens":
        assert size < 1e-9
        return
    assert size == pytest.approx(abs(tip["value"]), rel=1e-6), value["name"]
    sigma_mm = _GUARD_UNITS[value["unit"]][1] * value["sigma"]
    assert sigma_mm >= 0.9 * tip["std"], (value["name"], sigma_mm, tip["std"])
    assert abs(size - TOOL_LENGTH_ERROR) < 3 * sigma_mm, (value["name"], size, sigma_mm)


@pytest.mark.parametrize("vendor", VENDORS)
def test_max_change_off_leaves_the_old_check_on(check, vendor, capsys):
    """--max-change off switches the change guard off, not the check that
    --old describes the machine file's controller: --old values 1 mm from the
    machine file's pivot are still refused (at the default limits) until
    --force-old."""
    d, _, _ = check
    machine = os.path.join(MACHINES, "c600u.json")
    doc = json.load(open(machine))
    doc["axes"]["C"]["point"] = [float(x) + (1.0 if i == 0 else 0.0) for i, x in enumerate(doc["axes"]["C"]["point"])]
    moved = d / "c600u_moved.json"
    moved.write_text(json.dumps(doc))
    first = d / f"moved-{vendor}"
    assert main(["export", vendor, str(d / "check.json"), "--machine", str(moved), "--out", str(first),
                 *_sets(vendor)]) == 0
    old = first / next(f for f in sorted(os.listdir(first)) if f.startswith(vendor))
    base = ["export", vendor, str(d / "check.json"), "--machine", machine, "--old", str(old),
            "--max-change", "off", *_sets(vendor)]
    capsys.readouterr()
    assert main([*base, "--out", str(d / f"off1-{vendor}")]) == 2
    err = capsys.readouterr().err
    assert "--old" in err and "against the machine file" in err and "--force-old" in err, err
    assert not os.path.exists(d / f"off1-{vendor}")
    assert main([*base, "--out", str(d / f"off2-{vendor}"), "--force-old"]) == 0
    capsys.readouterr()
