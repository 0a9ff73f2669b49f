"""The generic ``fivecal`` table: its columns come from the registered
observation kinds' file keys, so every kind, a new one included, is written
and read back without an edit of the importer. Every registered kind round
trips dataset -> table -> dataset unchanged, and a key the registry does not
list is refused as a column."""
from __future__ import annotations

import pathlib

import pytest

import fivecal
from fivecal import _core
from fivecal.io import tables

ROOT = pathlib.Path(__file__).resolve().parents[2]
C600U = ROOT / "examples" / "machines" / "c600u.json"
ART = {"spheres": [{"id": "S1", "center": [60.0, 40.0, 30.0], "radius": 12.5}],
       "facets": [{"id": "F1", "point": [0.0, 0.0, 0.0], "normal": [0, 0, 1]}],
       "cylinders": [{"id": "K1", "point": [0, 0, 0], "axis": [0, 0, 1], "radius": 80.0}]}
POSE = {"A": -30.0, "C": 45.0, "S": 0.0}


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.load(C600U)


def _at(m, point):
    """Axis commands putting the tool tip on `point` (workpiece frame) at POSE."""
    q = m.inverse([point], start={"X": 0, "Y": 0, "Z": 0, **POSE})
    return {k: float(v[0]) for k, v in q.items()}


def every_kind_dataset(m):
    """One or two observations of each registered kind, with every optional
    key of its file format (ids, directions, per-row sigmas, a step's
    reference cut), as fivecal.simulate writes them."""
    full = _at(m, [100.0, 0.0, 0.0])
    plan = [
        {"type": "sphere", "target": "S1", "axes": {"A": 0, "C": 0, "S": 0}, "normal": [0, 0, 1],
         "direction": {"Z": -1}, "id": "s1"},
        {"type": "facet", "target": "F1", "axes": {"A": 0, "C": 0, "S": 0}, "point": [10, 5, 0], "id": "f1"},
        {"type": "cylinder", "target": "K1", "axes": {"A": 0, "C": 0, "S": 0}, "point": [80, 0, 10], "id": "k1"},
        {"type": "dbb", "setup": "D1", "axes": full, "length": 150.0, "tool_ball": [0, 0, 150],
         "table_ball": [100, 0, 150], "direction": {"X": 1, "C": -1}, "id": "d1"},
        {"type": "ball3d", "setup": "R1", "axes": full, "tool_ball": [0, 0, 150], "table_ball": [100, 0, 0],
         "id": "r1"},
        {"type": "point", "instrument": "T1", "target": "work", "target_point": [100, 0, 20], "axes": full,
         "instrument_origin": [1500, -800, 300], "instrument_angles": [0.5, -1, 30], "id": "p1"},
        {"type": "pose", "instrument": "CAM", "target": "work", "target_point": [100, 0, 20],
         "target_rotation": [0.1, 0, 0], "axes": full, "instrument_origin": [0, -900, 300],
         "instrument_angles": [0, 0, 90], "id": "q1"},
        {"type": "distance", "station": "L1", "instrument": "LT2", "target": "tool", "target_point": [0, 0, 150],
         "axes": full, "station_position": [900, -700, 150], "dead_length": 200.0, "id": "t1"},
        {"type": "machined", "part": "P1", "feature": "face", "axes": {"A": -90, "C": 0, "S": 0},
         "point": [0, 150, 60], "normal": [0, 0, 1], "id": "m1"},
        {"type": "machined", "part": "P1", "feature": "step", "axes": {"A": -90, "C": -180, "S": 0},
         "point": [0, 150, 60], "normal": [0, 0, 1], "reference_axes": {"A": -90, "C": 0, "S": 0},
         "reference_point": [0, 140, 60], "reference_normal": [0, 0, 1], "id": "m2"},
    ]
    sigma = {c: 0.001 for c in _core.noise_classes()}
    sigma["pose_angle"] = 1e-5
    ds = fivecal.simulate(m, plan, errors={"EX0C": 0.01, "EA0C": 2e-5}, artefact=ART, tip_radius=3.0,
                          sigma=sigma, seed=1)
    d = ds.to_dict()
    for o in d["observations"]:
        if o["type"] == "ball3d":
            o["sigma"] = [0.001, 0.001, 0.002]  # anisotropic: sigma_x|y|z columns
        if o["type"] == "machined" and o["feature"] == "face":
            o["sigma"] = 0.003
        o.setdefault("direction", {"Y": -1, "A": 1})  # backlash directions: the dir_<axis> columns
    return d


def test_the_sample_covers_every_registered_kind_and_key(machine):
    """So that the round trip below checks every key: a kind registered later
    without a sample here fails this test."""
    d = every_kind_dataset(machine)
    used = {}
    for o in d["observations"]:
        used.setdefault(o["type"], set()).update(o)
    for k in _core.observation_kinds():
        assert k["name"] in used, f"add an observation of kind {k['name']} to every_kind_dataset"
        assert set(k["json_keys"]) == used[k["name"]], (k["name"], set(k["json_keys"]) ^ used[k["name"]])


def test_every_registered_kind_round_trips_through_the_generic_table(machine, tmp_path):
    d = every_kind_dataset(machine)
    ds = fivecal.Dataset.from_dict(d)
    side = tables.write_table(ds, tmp_path / "all.csv")
    back = tables.import_dataset(tmp_path / "all.csv", "fivecal", machine, sidecar=side)
    assert back.to_dict()["observations"] == d["observations"]
    assert back.to_dict() == ds.to_dict()
    # the same through the command line and a semicolon table
    tables.write_table(ds, tmp_path / "all_sc.csv", delimiter=";")
    import json
    (tmp_path / "side.json").write_text(json.dumps(side))
    from fivecal import cli
    rc = cli.main(["import", "fivecal", str(tmp_path / "all_sc.csv"), "--machine", str(C600U), "--sidecar",
                   str(tmp_path / "side.json"), "--out", str(tmp_path / "ds.json")])
    assert rc == 0
    assert fivecal.load_dataset(tmp_path / "ds.json").to_dict() == ds.to_dict()


def test_the_columns_are_the_registrys_keys(machine, tmp_path, monkeypatch):
    """A kind's key the registry does not list is no column of the generic
    table: with `station_position` taken out of the registry's distance keys
    (and no kind listing it), its columns are refused by name."""
    d = every_kind_dataset(machine)
    tables.write_table(fivecal.Dataset.from_dict(d), tmp_path / "all.csv")
    real = tables._registered

    def without_station_position():
        reg = real()
        reg["distance"] = {**reg["distance"],
                           "json_keys": [k for k in reg["distance"]["json_keys"] if k != "station_position"]}
        return reg

    monkeypatch.setattr(tables, "_registered", without_station_position)
    with pytest.raises(ValueError, match=r"all\.csv:1: column 'station_position_x': unknown column"):
        tables.read_table(tmp_path / "all.csv", "fivecal", machine, sidecar={"probe": {"tip_radius": 3.0},
                                                                             "artefact": ART})


@pytest.mark.parametrize("lines,match", [
    (["type,id,X,Y,Z,A,C,reading", "dbbb,a,0,0,0,0,0,0.01"], r"x\.csv:2: column 'type': 'dbbb' is not an "
                                                            r"observation type .*did you mean 'dbb'"),
    (["type,X,Y,Z,A,C,reading,part", "dbb,0,0,0,0,0,0.01,P1"], r"x\.csv:2: column 'part': a dbb row has no part"),
    (["type,X,Y,Z,A,C,measured_x,measured_y,measured_z", "point,0,0,0,0,0,1,,3"],
     r"x\.csv:2: column 'measured_y': empty cell \(a number is expected for a point row\)"),
    (["type,X,Y,Z,A,C,reading,reading_x", "dbb,0,0,0,0,0,0.01,"], None),
    (["type,X,Y,Z,A,C,measurd_x", "point,0,0,0,0,0,1"], r"column 'measurd_x': unknown column .*a fivecal table"),
    (["type,X,Y,Z,A,C,station_position_x_deg", "distance,0,0,0,0,0,1"], r"only axis columns take an angle unit"),
    (["type,X,Y,Z,A,C,reading", "distance,0,0,0,0,0,nan"], r"x\.csv:2: column 'reading': 'nan' is not a finite"),
])
def test_bad_generic_rows_name_line_and_column(machine, tmp_path, lines, match):
    f = tmp_path / "x.csv"
    f.write_text("\n".join(lines) + "\n")
    if match is None:
        assert tables.read_table(f, "fivecal", machine)["observations"][0]["reading"] == 0.01
        return
    with pytest.raises(ValueError, match=match):
        tables.read_table(f, "fivecal", machine)


def test_units_in_the_header_of_a_generic_table(machine, tmp_path):
    f = tmp_path / "u.csv"
    f.write_text("type,id,X,Y,Z,A_rad,C,reading_um,sigma_um,length,tool_ball_x,tool_ball_y,tool_ball_z,"
                 "table_ball_x,table_ball_y,table_ball_z\n"
                 "dbb,d,0,0,-150,0.5,0,12.5,0.2,100,0,0,150,100,0,0\n")
    o = tables.read_table(f, "fivecal", machine)["observations"][0]
    assert o["reading"] == pytest.approx(0.0125) and o["sigma"] == pytest.approx(0.0002)
    assert o["axes"]["A"] == pytest.approx(28.64788975654116)
