"""The FANUC parameter list: what write() prints, read() reads back (the new
values at the increment's resolution), old beside new with the change's 1σ
and the header a user needs; a malformed list is refused by line."""
from __future__ import annotations

import json
import math
import os
import re
from types import SimpleNamespace

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.compensation import load_errors
from fivecal.io import controllers as K, fanuc
from fivecal.procedures import sphere_check as sc

NAMES = ["19680", "19681", "19682", "19684", "19686", "19687", "19689",
         "rotary table position X", "rotary table position Y", "rotary table position Z",
         "19703", "19704", "19705"]


def _export(increment="IS-C", change=None):
    old = [12, 4, 1, 1, 5, 3, 1, 0.0, 0.0, -350.0, 0.0, 0.0, 100.0]
    change = change or [0] * 7 + [0.01234, -0.00456, 0.02, 0.0, 0.0151, -0.003]
    values = []
    for i, (n, o, c) in enumerate(zip(NAMES, old, change)):
        fixed = i < 7
        values.append({"name": n, "unit": "" if fixed else "mm", "old": float(o), "new": float(o + c),
                       "change": float(c), "sigma": math.nan if fixed else 0.0007 + 0.0001 * i,
                       "source": f"meaning of {n}; FANUC A-79348E, sheet 82/88", "fixed": fixed})
    ab = SimpleNamespace(model="table-table", rms=0.0021, max=0.0057)
    return SimpleNamespace(values=values, absorption=ab, options={"increment": increment, "path": "1"},
                           round_trip_max=3e-10, result="result.json")


MACHINE = SimpleNamespace(name="VMC-0656-like", topology="wCAfXYZSt")


def test_write_read_round_trip(tmp_path):
    exp = _export()
    files = fanuc.write(exp, MACHINE)
    assert list(files) == [".txt"]
    text = files[".txt"]
    p = tmp_path / "fanuc.txt"
    p.write_text(text)
    back = fanuc.read(str(p))
    assert list(back) == NAMES
    for v in exp.values:
        assert back[v["name"]] == pytest.approx(round(v["new"], 4), abs=1e-12)
    # Old beside new, the change with its 1σ, the codes never called a change.
    line = next(x for x in text.splitlines() if x.startswith("19704 |"))
    assert line.split(" | ")[:6] == ["19704", "1", "0.0151", "0.0000", "+0.0151 ± 0.001800", "mm"]
    assert next(x for x in text.splitlines() if x.startswith("19680 |")).split(" | ")[2:5] == ["12", "12", "(code)"]
    # The header: machine, result, date, model, what the controller cannot absorb.
    head = "\n".join(x for x in text.splitlines() if x.startswith("#"))
    assert "VMC-0656-like (wCAfXYZSt)" in head and "result: result.json" in head
    assert re.search(r"written: \d{4}-\d\d-\d\d \d\d:\d\d UTC", head)
    assert "model: table-table (No. 19680 = 12)" in head
    assert "rms 2.10 µm, max 5.70 µm" in head
    assert "increment: IS-C (0.0001 mm)" in head


def test_is_b_rounds_to_a_micrometre(tmp_path):
    p = tmp_path / "fanuc.txt"
    p.write_text(fanuc.write(_export("IS-B"), MACHINE)[".txt"])
    back = fanuc.read(str(p))
    assert back["rotary table position X"] == pytest.approx(0.012)
    assert back["19703"] == 0.0


def test_write_needs_the_increment():
    exp = _export()
    exp.options = {}
    with pytest.raises(ValueError, match="increment=None: expected IS-B or IS-C"):
        fanuc.write(exp, MACHINE)


@pytest.mark.parametrize("body, message", [
    ("19680 | 1 | 12\n19703 | 1\n", r":2: expected 'No. \| path \| value"),
    ("# c\n19703 | 1 | 0.01O\n", r":2: parameter 19703: value '0.01O' is not a number"),
    ("19703 | 1 | 0.01\n\n19703 | 1 | 0.02\n", r":3: parameter 19703 given twice"),
    ("19703 | 1 | nan\n", r":1: parameter 19703: value 'nan' is not finite"),
    ("# only comments\n", r"no parameter lines"),
])
def test_read_refuses_a_malformed_list(tmp_path, body, message):
    p = tmp_path / "old.txt"
    p.write_text(body)
    with pytest.raises(ValueError, match=message):
        fanuc.read(str(p))


# ---- end to end: simulate, identify, `fivecal export fanuc` -------------------------------------------

MACHINES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines")
BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
#: pivot errors only: everything the FANUC model can absorb (tens of µm)
PIVOTS = {"EY0A": 0.012, "EZ0A": -0.008, "EX0C": 0.015, "EY0C": -0.01}
SETS = ["--set", "increment=IS-C", "--set", "tool-length=100", "--set", "axis-order=XYZAC"]


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    """A sphere check of c600u with pivot errors and 0.2 µm noise, identified."""
    d = tmp_path_factory.mktemp("fanuc")
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    plan = sc.plan(m, BALL, tip_radius=3.0)
    ds = fivecal.simulate(m, plan, errors=PIVOTS, artefact={"spheres": [BALL]}, tip_radius=3.0, sigma=0.0002,
                          seed=11)
    fivecal.save_dataset(ds, str(d / "ds.json"))
    assert main(["sphere-check", str(d / "ds.json"), "--out", str(d / "check.json")]) == 0
    return d, m


def test_cli_export_reproduces_the_erroneous_machine(identified, capsys):
    d, m = identified
    out = d / "out"
    rc = main(["export", "fanuc", str(d / "check.json"), "--machine", os.path.join(MACHINES, "c600u.json"),
               "--out", str(out), *SETS])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert sorted(os.listdir(out)) == ["export.json", "fanuc.txt"]
    listed = fanuc.read(str(out / "fanuc.txt"))
    assert listed["19680"] == 12 and listed["19681"] == 4 and listed["19686"] == 5
    head = (out / "fanuc.txt").read_text()
    assert "c600u" in head.lower() or m.name in head
    assert "check.json" in head and "model: table-table" in head
    # The list's new values, through the manual's transformation (C++
    # FanucVendor::ToolPoints), put the tool where the erroneous machine does,
    # up to the work offset, over the working volume.
    names = [v["name"] for v in json.load(open(out / "export.json"))["values"]]
    opts = {"increment": "IS-C", "tool-length": "100", "axis-order": "XYZAC"}
    poses = K.pose_grid(m)
    pts = K.vendor_tool_points(m, "fanuc", [listed[n] for n in names], poses, opts)
    truth = m.tool_point(poses, PIVOTS)
    diff = truth - pts
    left = np.linalg.norm(diff - diff.mean(axis=0), axis=1).max()
    assert left < 1e-3, left
    # ... and the nominal values do not (the test can fail): the errors are tens of µm.
    nominal = K.vendor_tool_points(m, "fanuc", [json.load(open(out / "export.json"))["values"][k]["old"]
                                                for k in range(len(names))], poses, opts)
    diff0 = truth - nominal
    assert np.linalg.norm(diff0 - diff0.mean(axis=0), axis=1).max() > 0.01


@pytest.mark.parametrize("sets, machine, message", [
    (SETS[2:], "c600u", "option increment is required"),
    (SETS + ["--set", "increment=IS-A"], "c600u", "expected IS-B or IS-C"),
    (SETS[:4], "c600u", "option axis-order is required"),
    (SETS + ["--set", "sign=+"], "c600u", "unknown option 'sign'"),
    (SETS, "kx8", "inclined rotary axis"),
])
def test_cli_refusals_exit_2_with_the_reason(identified, capsys, sets, machine, message):
    d, _ = identified
    rc = main(["export", "fanuc", str(d / "check.json"), "--machine", os.path.join(MACHINES, f"{machine}.json"),
               "--out", str(d / f"refused-{len(sets)}-{machine}"), *sets])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert message in err


HEADS = {
    # C carries B in the head (19680 = 2): B 40 mm off the C axis, the spindle 15 mm off B
    "head-head": ({"name": "hh", "topology": "wXYfZCBSt", "axes": {
        "X": {"type": "linear", "direction": [-1, 0, 0]}, "Y": {"type": "linear", "direction": [0, -1, 0]},
        "Z": {"type": "linear", "direction": [0, 0, 1]},
        "C": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 300]},
        "B": {"type": "rotary", "direction": [0, 1, 0], "point": [40, 0, 260]},
        "S": {"type": "rotary", "direction": [0, 0, 1], "point": [15, 0, 0]}}, "tool": {"tip": [15, 0, 60]}},
        {"EX0B": 0.02, "EZ0B": -0.015, "EX0C": 0.01, "tip.z": 0.02}, "XYZCB", 2),
    # B tilts the head, C turns the table (19680 = 21)
    "table-head": ({"name": "th", "topology": "wCXYfZBSt", "axes": {
        "C": {"type": "rotary", "direction": [0, 0, -1], "point": [30, -20, 0]},
        "X": {"type": "linear", "direction": [-1, 0, 0]}, "Y": {"type": "linear", "direction": [0, -1, 0]},
        "Z": {"type": "linear", "direction": [0, 0, 1]},
        "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, 350]},
        "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [0, 0, 120]}},
        {"EX0C": 0.02, "EY0C": -0.015, "EX0B": 0.01, "EZ0B": 0.012, "tip.z": -0.01}, "XYZBC", 21),
}


@pytest.mark.parametrize("kind", sorted(HEADS))
def test_head_types_reproduce_the_erroneous_machine(tmp_path, kind):
    spec, errors, order, code = HEADS[kind]
    m = fivecal.Machine.from_dict(spec)
    opts = {"increment": "IS-C", "tool-length": "100", "holder-offset": "5", "axis-order": order}
    exp = K.vendor_export(m, "fanuc", errors, options=opts)
    assert exp.round_trip_max < 1e-9
    by = {v["name"]: v for v in exp.values}
    assert by["19680"]["new"] == code and by["19666"]["new"] == 5 and by["19666"]["change"] == 0
    assert max(abs(v["change"]) for v in exp.values if not v["fixed"]) > 0.005
    # the errors are all pivots and tool length: the manual's transformation
    # with the new values is the erroneous machine, up to the work offset
    poses = exp.absorption.poses
    pts = K.vendor_tool_points(m, "fanuc", [v["new"] for v in exp.values], poses, opts)
    diff = m.tool_point(poses, errors) - pts
    assert np.linalg.norm(diff - diff.mean(axis=0), axis=1).max() < 1e-6
    # the list of this export reads back to its new values at the increment
    p = tmp_path / "fanuc.txt"
    p.write_text(fanuc.write(exp, m)[".txt"])
    back = fanuc.read(str(p))
    assert all(back[v["name"]] == pytest.approx(v["new"], abs=5.1e-5) for v in exp.values)


def test_old_values_make_the_change_independent_of_tool_length_and_catch_a_wrong_one(identified, capsys):
    d, _ = identified
    base = ["export", "fanuc", str(d / "check.json"), "--machine", os.path.join(MACHINES, "c600u.json")]
    assert main([*base, "--out", str(d / "first"), *SETS]) == 0
    first = json.load(open(d / "first" / "export.json"))["values"]
    old = str(d / "first" / "fanuc.txt")
    # the same control, stated with a tool length 0.2 mm off: the change is the same
    sets = [s.replace("tool-length=100", "tool-length=100.2") for s in SETS]
    assert main([*base, "--out", str(d / "again"), "--old", old, *sets]) == 0
    again = json.load(open(d / "again" / "export.json"))["values"]
    for a, b in zip(first, again):
        assert b["change"] == pytest.approx(a["change"], abs=1e-12)
        assert b["new"] == pytest.approx(a["new"] + a["change"], abs=1e-4)
    capsys.readouterr()
    # 50 mm off: the control's rotary table position is not the machine file's
    sets = [s.replace("tool-length=100", "tool-length=150") for s in SETS]
    assert main([*base, "--out", str(d / "wrong"), "--old", old, *sets]) == 2
    assert "rotary table position Z" in capsys.readouterr().err


def test_a_wrong_sign_unit_or_doubled_value_is_seen_by_what_the_control_then_does(identified):
    """What verification after loading compares (docs/controllers.md): the
    errors a control running the keyed-in values compensates, against the
    export's predicted change within its uncertainty. The list as written
    agrees; a sign flipped, a change keyed in µm as mm, or a change applied
    twice does not."""
    d, m = identified
    doc = json.load(open(d / "check.json"))
    opts = {"increment": "IS-C", "tool-length": "100", "axis-order": "XYZAC"}
    exp = K.vendor_export(m, "fanuc", load_errors(doc, m), K.result_covariance(doc, m), options=opts)
    sigma = np.sqrt(np.diag(exp.absorbed["covariance"]))
    moved = [i for i in range(len(sigma)) if sigma[i] > 0]   # the tool length is held: no σ, no change
    assert len(moved) >= 4
    idx = [m.parameter_names().index(exp.absorbed["names"][i]) for i in moved]

    def worst(values):
        seen = K.vendor_to_theta(m, "fanuc", values, options=opts)["theta"][idx]
        return np.max(np.abs(seen - np.asarray(exp.absorbed["change"])[moved]) / sigma[moved])

    text = fanuc.write(exp, m)[".txt"]
    d.joinpath("keyed.txt").write_text(text)
    keyed = fanuc.read(str(d / "keyed.txt"))
    good = [keyed[v["name"]] for v in exp.values]
    assert worst(good) < 3
    k = int(np.argmax([0 if v["fixed"] else abs(v["change"]) for v in exp.values]))
    for what, value in [("sign", exp.values[k]["old"] - exp.values[k]["change"]),
                        ("µm keyed as mm", exp.values[k]["old"] + 1000 * exp.values[k]["change"]),
                        ("applied twice", exp.values[k]["new"] + exp.values[k]["change"])]:
        bad = list(good)
        bad[k] = value
        assert worst(bad) > 10, what
