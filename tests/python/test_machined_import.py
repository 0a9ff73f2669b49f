"""`fivecal import machined`: a CMM report of a machined test part (Zhang &
Zhang machining tests; the `machined` observation kind) read into a dataset.
End to end: a machine with known rotary-axis location errors cuts the faces,
the CMM report is written as a CMM would (semicolons, decimal commas,
deviations in µm, the feature ids), imported through the command line and
identified: every estimate within 3 sigma. Bad reports are refused naming
the line and the column."""
from __future__ import annotations

import json
import pathlib

import numpy as np
import pytest

import fivecal
from fivecal import cli
from fivecal.io import tables

from test_machining_kind import DATUM, LOCATION, TRUTH, faces_plan

ROOT = pathlib.Path(__file__).resolve().parents[2]
C600U = ROOT / "examples" / "machines" / "c600u.json"
AXES = ["X", "Y", "Z", "A", "C"]


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.load(C600U)


def _plan(m):
    """The faces of test_machining_kind (3 points x 12 table poses x 3
    sensitive directions) and three of Zhang & Zhang's steps (one face cut at
    C = 0 and again at C = -180, -90, -270: the datum drops out)."""
    plan = faces_plan(m)
    for i, c in enumerate((-180.0, -90.0, -270.0)):
        plan.append({"type": "machined", "part": "P1", "feature": "step", "axes": {"A": -90.0, "C": c},
                     "point": [0.0, 150.0, 60.0], "normal": [0.0, 0.0, 1.0],
                     "reference_axes": {"A": -90.0, "C": 0.0}})
    for i, e in enumerate(plan):
        e["id"] = f"F{i + 1:03d}"
    return plan


def cmm_report(ds, path, decimal_comma=True):
    """The CMM's report: one line per measured feature, the programme's axis
    commands of the cut, the nominal point and normal, the deviation in µm."""
    head = ["feature_id", "part", "feature"] + AXES + [f"ref_{a}" for a in AXES] + \
        ["point_x", "point_y", "point_z", "normal_x", "normal_y", "normal_z", "deviation_um"]
    rows = []
    num = (lambda v: f"{v:.6f}".replace(".", ",")) if decimal_comma else (lambda v: f"{v:.6f}")
    for o in ds.to_dict()["observations"]:
        ref = o.get("reference_axes")
        rows.append([o["id"], o["part"], o["feature"]] + [num(o["axes"][a]) for a in AXES]
                    + [num(ref[a]) if ref else "" for a in AXES]
                    + [num(v) for v in o["point"]] + [num(v) for v in o["normal"]] + [num(o["measured"] * 1e3)])
    sep = ";" if decimal_comma else ","
    text = "# CMM report, test part P1: deviation of each machined face along its normal\n"
    text += sep.join(head) + "\n" + "\n".join(sep.join(r) for r in rows) + "\n"
    pathlib.Path(path).write_text(text)


@pytest.mark.parametrize("seed", [31, 32])
def test_cmm_report_imports_and_identifies_within_3_sigma(machine, tmp_path, seed, capsys):
    truth_ds = fivecal.simulate(machine, _plan(machine), errors=TRUTH, setup=DATUM, sigma={"machined": 0.003},
                                seed=seed)
    report = tmp_path / "cmm.csv"
    cmm_report(truth_ds, report)
    out = tmp_path / "ds.json"
    rc = cli.main(["import", "machined", str(report), "--machine", str(C600U), "--column", "id=feature_id",
                   "--sigma", "0.003", "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    ds = fivecal.load_dataset(out)
    obs = ds.to_dict()["observations"]
    assert [o["id"] for o in obs] == [o["id"] for o in truth_ds.to_dict()["observations"]]
    assert sum(o["feature"] == "step" for o in obs) == 3
    got = np.array([o["measured"] for o in obs])
    want = np.array([o["measured"] for o in truth_ds.to_dict()["observations"]])
    assert np.max(np.abs(got - want)) < 1e-9  # µm with six decimals
    r = fivecal.identify(ds, LOCATION)
    assert r.verdict == "ok", (r.verdict, r.adequacy)
    full = {**TRUTH, **DATUM}
    for n in r.estimated:
        assert abs(r.values[n] - full[n]) < 3 * r.std[n], (n, r.values[n], full[n], r.std[n])
    # the ids reach the residual table
    assert {row["id"] for row in r.residual_table()} >= {"F001", "F111"}


def _report(tmp_path, lines, name="r.csv"):
    f = tmp_path / name
    f.write_text("\n".join(lines) + "\n")
    return f


HEAD = "id,X,Y,Z,A,C,point_x,point_y,point_z,normal_x,normal_y,normal_z,measured_um"
GOOD = "f1,0,-60,0,-90,0,0,150,60,0,0,1,-8.5"


@pytest.mark.parametrize("lines,match", [
    ([HEAD, GOOD, "f2,0,-60,0,-90,0,0,150,60,0,0,1,nan"],
     r"r\.csv:3: column 'measured_um': 'nan' is not a finite number"),
    ([HEAD + ",temp", GOOD + ",20.5"], r"r\.csv:1: column 'temp': unknown column 'temp' for a machined import"),
    ([HEAD.replace("normal_z", "normal_zz"), GOOD], r"column 'normal_zz': unknown column .*did you mean"),
    ([HEAD.replace("measured_um", "measured"), GOOD.replace("-8.5", "-8.5")],
     r"r\.csv:2: column 'measured': deviation -8\.5 mm: .*look like µm: name the column measured_um"),
    ([HEAD, "f1,0,-60,0,-90,0,0,150e6,60,0,0,1,-8.5"], r"r\.csv:2: column 'point_y': 1\.5e\+08 mm .*point_y_um"),
    ([HEAD, "f1,0,-60,0,-90,0,0,150,60,0,0,0,-8.5"], r"r\.csv:2: column 'normal_x': the face normal .* is zero"),
    ([HEAD.replace("normal_x", "normal_x_mm"), GOOD], r"column 'normal_x_mm': a face normal .* has no unit"),
    ([HEAD, "f1,0,-60,0,-90,,0,150,60,0,0,1,-8.5"], r"r\.csv:2: column 'C': empty cell"),
    ([HEAD + ",feature", GOOD + ",fase"], r"r\.csv:2: column 'feature': 'fase' is neither face nor step; "
                                          r"did you mean 'face'"),
    ([HEAD + ",feature", GOOD + ",step"], r"r\.csv:2: a step needs the axes of its reference cut"),
    ([HEAD + ",ref_X,ref_Y,ref_Z,ref_A,ref_C", GOOD + ",0,-60,0,-90,"],
     r"r\.csv:2: column 'ref_C': empty cell \(reference_axes needs every axis"),
    ([HEAD + ",feature,ref_X,ref_Y,ref_Z,ref_A,ref_C", GOOD + ",face,0,-60,0,-90,0"],
     r"r\.csv:2: column 'ref_X': a face has no reference cut"),
    ([HEAD.replace(",C,", ",C_rad,"), "f1,0,-60,0,-90,180,0,150,60,0,0,1,-8.5"],
     r"r\.csv:2: column 'C_rad': 180 rad is .* degrees, more than a turn and a quarter .*C_deg"),
    ([HEAD + ",part", GOOD + ",P.1"], r"r\.csv:2: column 'part': part 'P\.1': a part name has no '\.'"),
    ([HEAD, GOOD, GOOD], r"r\.csv:3: id 'f1' already used on line 2"),
])
def test_bad_reports_name_line_and_column(machine, tmp_path, lines, match):
    with pytest.raises(ValueError, match=match):
        tables.import_dataset(_report(tmp_path, lines), "machined", machine)


def test_a_good_report_and_its_defaults(machine, tmp_path):
    """Part from --setup (else P1), a face unless the row has a reference cut,
    the deviation in µm from the header, ids kept."""
    lines = [HEAD + ",ref_X,ref_Y,ref_Z,ref_A,ref_C", GOOD + ",,,,,",
             "f2,0,-60,-300,-90,-180,0,150,60,0,0,1,9.0,0,-60,0,-90,0"]
    d = tables.read_table(_report(tmp_path, lines), "machined", machine)
    a, b = d["observations"]
    assert (a["id"], a["part"], a["feature"], a["measured"]) == ("f1", "P1", "face", pytest.approx(-0.0085))
    assert b["feature"] == "step" and b["reference_axes"] == {"X": 0, "Y": -60, "Z": 0, "A": -90, "C": 0}
    d = tables.read_table(_report(tmp_path, lines), "machined", machine, setup="Block7", units="um")
    assert {o["part"] for o in d["observations"]} == {"Block7"}
    fivecal.Dataset.from_dict(d)


def test_rotary_columns_in_radians_warn_naming_the_column(machine, tmp_path):
    # not quarter turns: radian indexations (-1.570796, -3.141593) are refused (test_import.py)
    rad = [0.01, 0.01 - np.pi / 2, 0.01 - np.pi, 0.01 - 1.5 * np.pi]
    lines = ["id,X,Y,Z,A,C,ref_X,ref_Y,ref_Z,ref_A,ref_C,point_x,point_y,point_z,normal_x,normal_y,normal_z,"
             "measured_um"]
    for i, c in enumerate(rad):
        lines.append(f"s{i},0,-60,-300,-90,-180,0,-60,0,-1.5708,{c:.6f},0,150,60,0,0,1,9.0")
    with pytest.warns(fivecal.RadiansWarning, match=r"r\.csv: column 'ref_C': rotary values look like radians"):
        tables.import_dataset(_report(tmp_path, lines), "machined", machine)


def test_cli_refuses_a_bad_report_with_status_2(machine, tmp_path, capsys):
    f = _report(tmp_path, [HEAD, GOOD, "f2,0,-60,0,-90,0,0,150,60,0,0,1,abc"])
    rc = cli.main(["import", "machined", str(f), "--machine", str(C600U), "--out", str(tmp_path / "o.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "r.csv:3: column 'measured_um': 'abc' is not a number" in err
    assert not (tmp_path / "o.json").exists()


def test_a_type_column_must_say_machined(machine, tmp_path):
    ok = tables.read_table(_report(tmp_path, [HEAD + ",type", GOOD + ",machined"]), "machined", machine)
    assert ok["observations"][0]["type"] == "machined"
    with pytest.raises(ValueError, match=r"r\.csv:2: column 'type': 'face' in a machined import"):
        tables.read_table(_report(tmp_path, [HEAD + ",type", GOOD + ",face"]), "machined", machine)
