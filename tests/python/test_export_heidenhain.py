"""The Heidenhain kinematics rows: the writer's text reads back to the values
it wrote, the reader refuses a malformed line by its number, and the values
written for a machine with known pivot errors, read back from the file and
run through the TNC's own kinematics (the core's, from the manual), put the
tool where the erroneous machine puts it, up to the work offset."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

import fivecal
from fivecal import Machine, _core
from fivecal.cli import main
from fivecal.procedures import sphere_check as sc
from fivecal.io import controllers as K, heidenhain as H

OPTIONS = {"table-axis-sign": "iso", "tool-length": "100"}


def _export(machine: Machine, errors=None, cov_scale=1e-6, options=OPTIONS, seed=1):
    """The Python export path (what ``fivecal export heidenhain`` writes)."""
    rng = np.random.default_rng(seed)
    poses = {}
    for a in machine.axis_names:
        lo, hi = {"C": (-180, 180), "A": (-100, 100), "B": (-100, 100), "S": (0, 0)}.get(a, (-200, 200))
        poses[a] = rng.uniform(lo, hi, 80)
    names = machine.parameter_names()
    # the identification's uncertainty on the errors it estimated only
    cov = np.diag([cov_scale if n in (errors or {}) else 0.0 for n in names])
    exp = K.vendor_export(machine, "heidenhain", errors or {}, cov, poses=poses, options=options)
    exp.result = "result.json"
    return exp, machine.axes_matrix(poses)


def test_the_vendor_is_registered():
    assert "heidenhain" in K.vendors()
    info = K.vendor_info("heidenhain")
    assert set(info["options"]) == {"table-axis-sign", "tool-length"}


def test_written_rows_read_back(tmp_path):
    m = Machine.load("examples/machines/hu40t.json")
    exp, _ = _export(m, {"EX0C": 0.012, "EY0B": -0.02, "EA0B": 3e-5})
    texts = H.write(exp, m)
    assert set(texts) == {".tab", ".csv"}
    tab = texts[".tab"]
    # The header says what it is and what is left; the table has its layout.
    assert "VALUES TO ENTER" in tab and f"machine {m.name} ({m.topology})" in tab
    assert "left after these values" in tab and "absorption model table-table" in tab
    lines = tab.splitlines()
    begin = next(i for i, ln in enumerate(lines) if ln.startswith("BEGIN "))
    assert lines[begin] == "BEGIN FIVECAL_KINEMATICS.TAB MM"
    assert lines[begin + 1].split()[:4] == ["NR", "KEY", "AXIS", "COORD"]
    assert lines[-1] == "[END]"
    assert all(ln.startswith(";") for ln in lines[:begin])
    for suffix, text in texts.items():
        path = tmp_path / f"k{suffix}"
        path.write_text(text)
        back = H.read(str(path))
        want = {v["name"]: v["new"] for v in exp.values if " Trans " in v["name"]}
        assert set(back) == set(want), suffix
        for name, v in want.items():
            tol = 1e-6 if "Trans X" in name or "Trans Y" in name or "Trans Z" in name else 1e-9
            assert back[name] == pytest.approx(v, abs=tol), (suffix, name)
    # Old beside new, the change and its 1 sigma on the row that moved.
    row = next(ln for ln in lines if ln.split()[:3] == ["18", "Trans", "X"])  # C's pivot x
    cells = row.split()
    assert float(cells[3]) == pytest.approx(float(cells[4]) + float(cells[5]), abs=2e-6)
    assert abs(float(cells[5])) > 0.005 and float(cells[6]) > 0


@pytest.mark.parametrize("bad, msg", [
    ("12  Trans  X  1.2.3", "line 9 COORD: expected a number, got '1.2.3'"),
    ("12  Trans  Q  1.0", "line 9: AXIS 'Q'"),
    ("x1  Trans  X  1.0", "line 9: NR 'x1'"),
    ("12  Trans", "line 9: expected NR KEY AXIS COORD"),
    ("12  Foo  X  1.0", "line 9: KEY 'Foo'"),
    ("12  Trans  X  nan", "line 9 COORD: expected a finite number"),
])
def test_reader_refuses_a_malformed_line_by_number(tmp_path, bad, msg):
    text = "\n".join(["; fivecal", "; header", "BEGIN FIVECAL_KINEMATICS.TAB MM", "NR KEY AXIS COORD",
                      "0 ToolAxis Z -", "1 Trans B 0", "2 Trans A 0", "3 MachAxis Y -", bad, "[END]"]) + "\n"
    p = tmp_path / "k.tab"
    p.write_text(text)
    with pytest.raises(ValueError, match=msg.replace("(", r"\(").replace(".", r"\.")):
        H.read(str(p))


@pytest.mark.parametrize("text, msg", [
    ("NR KEY AXIS COORD\n[END]\n", "line 1: expected 'BEGIN <name>.TAB MM'"),
    ("BEGIN K.TAB INCH\nNR KEY AXIS COORD\n[END]\n", "in inch"),
    ("BEGIN K.TAB MM\nNR KEY AXIS\n[END]\n", "line 2: the column line has no COORD column"),
    ("BEGIN K.TAB MM\nNR KEY AXIS COORD\n1 Trans X 1\n", "no \\[END\\] line"),
    ("BEGIN K.TAB MM\nNR KEY AXIS COORD\n1 Trans X 1\n1 Trans X 2\n[END]\n", "line 4: row 1 given twice"),
])
def test_reader_refuses_a_malformed_table(tmp_path, text, msg):
    p = tmp_path / "k.tab"
    p.write_text(text)
    with pytest.raises(ValueError, match=msg):
        H.read(str(p))


def test_csv_reader_refuses_by_line(tmp_path):
    p = tmp_path / "k.csv"
    p.write_text("# h\nnr,key,axis,coord\n1,Trans,X,1\n2,Trans,Y,abc\n")
    with pytest.raises(ValueError, match="line 4 coord: expected a number"):
        H.read(str(p))


@pytest.mark.parametrize("path, table_sense", [
    ("examples/machines/c600u.json", "iso"),
    ("examples/machines/hu40t.json", "carriage"),
    ("examples/machines/kx8.json", "iso"),
])
def test_file_values_through_the_tnc_kinematics_reproduce_the_machine(tmp_path, path, table_sense):
    """Known pivot errors -> export -> .tab -> read -> the TNC's kinematics
    with those rows == the erroneous machine's tool points up to the work
    offset (1 um); the nominal rows leave tens of um."""
    m = Machine.load(path)
    rot = [a for a in m.axis_names if m.is_rotary(a) and a != "S"]
    errors = {f"EX0{rot[0]}": 0.025, f"EY0{rot[0]}": -0.018, f"EY0{rot[1]}": 0.02, f"EX0{rot[1]}": -0.03}
    errors = {k: v for k, v in errors.items() if k in m.parameter_names()}
    options = {"table-axis-sign": table_sense, "tool-length": "80"}
    exp, poses = _export(m, errors, options=options)
    p = tmp_path / "k.tab"
    p.write_text(H.write(exp, m)[".tab"])
    back = H.read(str(p))
    values = np.array([back.get(v["name"], v["new"]) for v in exp.values])
    assert sum(v["name"] in back for v in exp.values) >= 20
    tnc = K.vendor_tool_points(m, "heidenhain", values, m.axes_dict(poses), options)
    nominal = K.vendor_tool_points(m, "heidenhain", np.array([v["old"] for v in exp.values]), m.axes_dict(poses),
                                   options)
    # The erroneous machine in the controller's workpiece frame (machine frame at the zero pose).
    theta = m.theta(errors)
    table = K.kinematics_table(m, theta)
    truth = (m.tool_point(m.axes_dict(poses), errors) @ np.asarray(table["part_rotation"]).T
             + np.asarray(table["part_origin"]))
    d = tnc - truth
    d -= d.mean(axis=0)
    assert np.abs(np.linalg.norm(d, axis=1)).max() < 1e-3
    d0 = nominal - truth
    d0 -= d0.mean(axis=0)
    assert np.linalg.norm(d0, axis=1).max() > 0.02


def test_options_are_required_and_checked():
    m = Machine.load("examples/machines/c600u.json")
    theta = m.theta({})
    with pytest.raises(ValueError, match="--set table-axis-sign=iso"):
        _core.vendor_values("heidenhain", m._core, theta, {"tool-length": "100"})
    with pytest.raises(ValueError, match="--set tool-length=<mm>"):
        _core.vendor_values("heidenhain", m._core, theta, {"table-axis-sign": "iso"})
    with pytest.raises(ValueError, match='unknown option "sign"'):
        _core.vendor_values("heidenhain", m._core, theta, dict(OPTIONS, sign="iso"))


BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
PIVOTS = {"EY0A": 0.012, "EZ0A": -0.008, "EX0C": 0.015, "EY0C": -0.01}
C600U = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines", "c600u.json")
SETS = ["--set", "table-axis-sign=iso", "--set", "tool-length=100"]


@pytest.fixture(scope="module")
def sphere_check(tmp_path_factory):
    """A simulated sphere check of c600u with known pivot errors, identified."""
    d = tmp_path_factory.mktemp("heidenhain")
    m = Machine.load(C600U)
    plan = sc.plan(m, BALL, tip_radius=3.0)
    ds = fivecal.simulate(m, plan, errors=PIVOTS, artefact={"spheres": [BALL]}, tip_radius=3.0, sigma=1e-5,
                          seed=11)
    fivecal.save_dataset(ds, str(d / "ds.json"))
    assert main(["sphere-check", str(d / "ds.json"), "--out", str(d / "check.json")]) == 0
    return d, m


def test_cli_export_on_an_identification_reproduces_the_machine(sphere_check, capsys):
    """fivecal export heidenhain on the identification exits 0; the .tab's
    new values, through the TNC's kinematics, put the tool where the
    erroneous machine puts it, up to the work offset, within 1 um."""
    d, m = sphere_check
    out = d / "out"
    rc = main(["export", "heidenhain", str(d / "check.json"), "--machine", C600U, "--out", str(out), *SETS])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert sorted(os.listdir(out)) == ["export.json", "heidenhain.csv", "heidenhain.tab"]
    rec = json.load(open(out / "export.json"))
    back = H.read(str(out / "heidenhain.tab"))
    assert "check.json" in (out / "heidenhain.tab").read_text().splitlines()[3]
    values = np.array([back[v["name"]] if v["name"] in back else v["new"] for v in rec["values"]])
    assert all(v["name"] in back for v in rec["values"] if not v["fixed"])
    rng = np.random.default_rng(3)
    poses = {"C": rng.uniform(-180, 180, 60), "A": rng.uniform(-100, 100, 60), "X": rng.uniform(-200, 200, 60),
             "Y": rng.uniform(-200, 200, 60), "Z": rng.uniform(-200, 200, 60), "S": np.zeros(60)}
    options = {"table-axis-sign": "iso", "tool-length": "100"}
    tnc = K.vendor_tool_points(m, "heidenhain", values, poses, options)
    nominal = K.vendor_tool_points(m, "heidenhain", [v["old"] for v in rec["values"]], poses, options)
    table = K.kinematics_table(m, PIVOTS)
    truth = m.tool_point(poses, PIVOTS) @ table["part_rotation"].T + table["part_origin"]
    for pts, ok in ((tnc, True), (nominal, False)):
        dev = pts - truth
        dev -= dev.mean(axis=0)
        worst = np.linalg.norm(dev, axis=1).max()
        assert (worst < 1e-3) if ok else (worst > 0.02), worst


def test_cli_refuses_a_wrong_option_and_a_missing_one(sphere_check, capsys):
    d, _ = sphere_check
    base = ["export", "heidenhain", str(d / "check.json"), "--machine", C600U]
    assert main([*base, "--out", str(d / "w1"), "--set", "table-axis-sign=ISO", "--set", "tool-length=100"]) == 2
    assert 'expected iso or carriage, got "ISO"' in capsys.readouterr().err
    assert main([*base, "--out", str(d / "w2"), "--set", "tool-length=100"]) == 2
    assert "--set table-axis-sign=iso" in capsys.readouterr().err
    assert main([*base, "--out", str(d / "w3"), "--set", "table-axis-sign=iso"]) == 2
    assert "--set tool-length=<mm>" in capsys.readouterr().err
    assert not any(os.path.exists(d / w) for w in ("w1", "w2", "w3"))


def test_an_unsupported_topology_is_refused():
    m = Machine.from_dict({"name": "4ax", "topology": "wCfXYZSt", "axes": {
        "C": {"type": "rotary", "direction": [0, 0, -1]}, "X": {"type": "linear", "direction": [1, 0, 0]},
        "Y": {"type": "linear", "direction": [0, 1, 0]}, "Z": {"type": "linear", "direction": [0, 0, 1]},
        "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [0, 0, 100]}})
    with pytest.raises(ValueError, match=r"two rotary axes .*4ax \(wCfXYZSt\) has 1"):
        K.vendor_export(m, "heidenhain", {}, options=OPTIONS)


def test_cli_refuses_an_unsupported_topology(sphere_check, capsys):
    """Three rotary axes (C on B on A): the TNC rows written here cover two."""
    d, _ = sphere_check
    three = {"name": "cba", "topology": "wCBAfXYZSt", "axes": {
        "C": {"type": "rotary", "direction": [0, 0, -1]}, "B": {"type": "rotary", "direction": [0, -1, 0]},
        "A": {"type": "rotary", "direction": [-1, 0, 0]}, "X": {"type": "linear", "direction": [1, 0, 0]},
        "Y": {"type": "linear", "direction": [0, 1, 0]}, "Z": {"type": "linear", "direction": [0, 0, 1]},
        "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [0, 0, 150]}}
    (d / "cba.json").write_text(json.dumps(three))
    rc = main(["export", "heidenhain", str(d / "check.json"), "--machine", str(d / "cba.json"), "--out",
               str(d / "w4"), *SETS])
    assert rc == 2
    assert "two rotary axes" in capsys.readouterr().err and not os.path.exists(d / "w4")
