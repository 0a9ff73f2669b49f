"""fivecal.io.tables and `fivecal import`: instrument tables to datasets, every
bad cell named by file, line and column, ids kept into the residual table."""
import csv
import json
import os

import numpy as np
import pytest

import fivecal
from fivecal import cli
from fivecal.demo import example_machine_path
from fivecal.io import import_dataset, read_table

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
EX = os.path.join(ROOT, "examples", "import")
C600U = example_machine_path("c600u")
TRUE = {"EY0A": 0.020, "EZ0A": -0.015, "EB0A": 30e-6, "EC0A": -25e-6,
        "EX0C": 0.030, "EY0C": -0.012, "EA0C": 40e-6, "EB0C": -20e-6}
ART = {"spheres": [{"id": "S1", "center": [60.0, 40.0, 30.0], "radius": 12.5}]}
PROBE_SIDE = {"probe": {"tip_radius": 3.0}, "artefact": ART}
BALL = (50.0, 0.0, 80.0)
RTEST_SIDE = {"setup": "R1", "tool_ball": [0, 0, 150.0], "table_ball": list(BALL)}


@pytest.fixture(scope="module")
def m():
    return fivecal.Machine.load(C600U)


def _sphere_plan(m, seed=0):
    rng = np.random.default_rng(seed)
    plan = []
    for a in (-60, -30, 0, 30, 60):
        for c in range(0, 360, 30):
            _, ax = m.tool_pose({"X": 0, "Y": 0, "Z": 0, "A": a, "C": c})
            for _ in range(5):
                v = ax[0] + 0.6 * rng.normal(size=3)
                plan.append({"type": "sphere", "target": "S1", "axes": {"A": a, "C": c},
                             "normal": (v / np.linalg.norm(v)).tolist()})
    return plan


def _rtest_plan(m):
    plan = []
    for a in np.arange(-90, 91, 15.0):
        for c in np.arange(0, 360, 20.0):
            e = {"type": "ball3d", "axes": {"X": 0.0, "Y": 0.0, "Z": 0.0, "A": float(a), "C": float(c)},
                 "tool_ball": [0, 0, 150.0], "table_ball": list(BALL), "setup": "R1"}
            cmd = m.inverse([list(BALL)], start=e["axes"])
            e["axes"] = {k: float(v[0]) for k, v in cmd.items()}
            plan.append(e)
    return plan


def _write(path, lines):
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return str(path)


# --------------------------------------------------------------------------
# Round trips: simulate, write as an instrument would, import, identify
# --------------------------------------------------------------------------
def test_probing_log_round_trip_recovers_the_same_errors(m, tmp_path):
    ds = fivecal.simulate(m, _sphere_plan(m), errors=TRUE, artefact=ART, tip_radius=3.0, sigma=0.0005, seed=3)
    lines = ["# controller probing log", "x,y,z,a,c,target,approach"]  # lower-case axis letters
    for o in ds.observations:
        a = o["axes"]
        appr = "".join(("+" if s > 0 else "-") + k for k, s in o.get("direction", {}).items() if s)
        lines.append(f"{a['X']:.6f},{a['Y']:.6f},{a['Z']:.6f},{a['A']:.6f},{a['C']:.6f},S1,{appr}")
    f = _write(tmp_path / "touches.csv", lines)
    got = import_dataset(f, "probing", m, sidecar={**PROBE_SIDE, "sigma": 0.0005})
    assert len(got) == len(ds)
    assert got.observations[0]["direction"] == ds.observations[0]["direction"]
    assert got.observations[0]["id"] == "touches.csv:3"
    r0, r1 = fivecal.identify(ds, "location"), fivecal.identify(got, "location")
    assert r1.estimated == r0.estimated
    for n in r0.estimated:
        assert abs(r1.values[n] - r0.values[n]) < 0.05 * r0.std[n], n
    for n in set(TRUE) & set(r1.estimated):
        assert abs(r1.values[n] - TRUE[n]) < 3 * r1.std[n], n


@pytest.mark.parametrize("style", ["comma", "decimal_comma"])
def test_rtest_round_trip_in_um_recovers_the_same_errors(m, tmp_path, style):
    ds = fivecal.simulate(m, _rtest_plan(m), errors=TRUE, sigma={"ball3d": 0.0005}, seed=5)
    sep = "," if style == "comma" else ";"
    lines = [sep.join(["X_mm", "Y_mm", "Z_mm", "A_deg", "C_deg", "dx_um", "dy_um", "dz_um"])]
    for o in ds.observations:
        a = o["axes"]
        cells = [f"{a[k]:.6f}" for k in "XYZAC"] + [f"{v * 1e3:.4f}" for v in o["measured"]]
        if style == "decimal_comma":
            cells = [c.replace(".", ",") for c in cells]
        lines.append(sep.join(cells))
    f = _write(tmp_path / "rtest.csv", lines)
    got = import_dataset(f, "rtest", m, sidecar={**RTEST_SIDE, "sigma": 0.0005})
    assert got.observations[0]["measured"] == pytest.approx(ds.observations[0]["measured"], abs=1e-7)
    names = list(TRUE)
    r0 = fivecal.identify(ds, names, default_setup=False)
    r1 = fivecal.identify(got, names, default_setup=False)
    for n in names:
        assert abs(r1.values[n] - r0.values[n]) < 0.05 * r0.std[n], n
        assert abs(r1.values[n] - TRUE[n]) < 3 * r1.std[n], n


def test_dbb_trace_in_um_with_renamed_column_and_options(m, tmp_path):
    plan = [e for e in fivecal.procedures.dbb.four_step_plan(m, step=10.0) if e["setup"] == "C1"]
    ds = fivecal.simulate(m, plan, errors=TRUE, sigma={"dbb": 0.0002}, seed=4)
    lines = ["time\tX\tY\tZ\tA\tC\tdL"]
    for k, o in enumerate(ds.observations):
        a = o["axes"]
        lines.append("\t".join([str(k)] + [f"{a[x]:.6f}".replace(".", ",") for x in "XYZAC"]
                               + [f"{o['reading'] * 1e3:.4f}".replace(".", ",")]))
    f = _write(tmp_path / "trace.txt", lines)
    e = plan[0]
    got = import_dataset(f, "dbb", m, columns={"reading": "dL"}, units="um", ignore=["time"], setup="C1",
                         length=e["length"], tool_ball=e["tool_ball"], table_ball=e["table_ball"])
    assert [o["reading"] for o in got.observations] == pytest.approx([o["reading"] for o in ds.observations],
                                                                     abs=1e-7)
    assert {o["setup"] for o in got.observations} == {"C1"}
    # the same through the command line
    out = tmp_path / "ds.json"
    rc = cli.main(["import", "dbb", f, "--machine", C600U, "--column", "reading=dL", "--units", "um",
                   "--ignore", "time", "--setup", "C1", "--length", str(e["length"]),
                   "--tool-ball", ",".join(map(str, e["tool_ball"])),
                   "--table-ball", ",".join(map(str, e["table_ball"])), "--out", str(out)])
    assert rc == 0
    assert fivecal.load_dataset(out).observations == got.observations


# --------------------------------------------------------------------------
# The examples: one file per kind, each imported
# --------------------------------------------------------------------------
EXAMPLES = [("probing", "probing.csv", "probing.json", {"sphere": 12, "facet": 2}),
            ("dbb", "dbb_trace.csv", "dbb_trace.json", {"dbb": 12}),
            ("rtest", "rtest.txt", "rtest.json", {"ball3d": 12}),
            ("fivecal", "mixed.csv", "mixed.json", {"sphere": 4, "dbb": 3, "ball3d": 3})]


@pytest.mark.parametrize("kind,name,side,counts", EXAMPLES)
def test_examples_import_through_the_cli(tmp_path, capsys, kind, name, side, counts):
    out = tmp_path / "ds.json"
    rc = cli.main(["import", kind, os.path.join(EX, name), "--machine", C600U,
                   "--sidecar", os.path.join(EX, side), "--out", str(out)])
    assert rc == 0, capsys.readouterr().err
    ds = fivecal.load_dataset(out)
    got = {}
    for t in ds.observation_types:
        got[t] = got.get(t, 0) + 1
    assert got == counts
    ids = [o["id"] for o in ds.observations]
    assert len(set(ids)) == len(ids)


def test_example_dbb_trace_reads_decimal_comma_and_um():
    ds = read_table(os.path.join(EX, "dbb_trace.csv"), "dbb", C600U, sidecar=os.path.join(EX, "dbb_trace.json"))
    first = ds["observations"][0]
    assert first["reading"] == pytest.approx(0.02995)
    assert first["axes"]["Z"] == -150.0
    assert first["id"] == "dbb_trace.csv:3"


# --------------------------------------------------------------------------
# ids through load, save, the residual table and the report
# --------------------------------------------------------------------------
@pytest.mark.filterwarnings("ignore::fivecal.guards.FitWarning")  # a two-parameter fit: only the ids matter
def test_ids_survive_save_load_residual_table_and_report(tmp_path):
    ds = import_dataset(os.path.join(EX, "probing.csv"), "probing", C600U, sidecar=os.path.join(EX, "probing.json"))
    fivecal.save_dataset(ds, tmp_path / "ds.json")
    back = fivecal.load_dataset(tmp_path / "ds.json")
    assert [o["id"] for o in back.observations] == [f"T{k}" for k in range(1, 15)]
    r = fivecal.identify(back, ["EX0C", "EY0C"], default_setup=False)
    table = r.residual_table()
    assert [t["id"] for t in table] == [f"T{k}" for k in range(1, 15)]
    assert table[13]["type"] == "facet" and table[13]["target"] == "F1"
    assert [t["residual"] for t in table] == pytest.approx(list(r.residuals))
    r.save(tmp_path / "result.json")
    saved = fivecal.schema.validate(json.loads((tmp_path / "result.json").read_text()), "result")
    assert saved["residual_ids"] == [f"T{k}" for k in range(1, 15)]
    assert saved["residuals"] == pytest.approx(list(r.residuals))
    fivecal.write_report(r, tmp_path / "rep")
    rows = list(csv.DictReader(open(tmp_path / "rep" / "residuals.csv", encoding="utf-8")))
    assert [x["id"] for x in rows] == [f"T{k}" for k in range(1, 15)]
    worst = max(table, key=lambda t: abs(t["residual"]))
    html = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    assert f"<td>{worst['id']}</td>" in html and "residuals.csv" in html


@pytest.mark.filterwarnings("ignore::fivecal.guards.FitWarning")
def test_residual_table_names_ball3d_components(m):
    ds = fivecal.simulate(m, _rtest_plan(m)[:20], errors=TRUE, sigma={"ball3d": 0.0005}, seed=5)
    d = ds.to_dict()
    for k, o in enumerate(d["observations"]):
        o["id"] = f"r{k}"
    r = fivecal.identify(d, ["EX0C", "EY0C"], default_setup=False)
    t = r.residual_table()
    assert [(x["id"], x["component"]) for x in t[:4]] == [("r0", "x"), ("r0", "y"), ("r0", "z"), ("r1", "x")]


def test_outlier_rows_are_named_by_id_in_the_text_report(m):
    ds = fivecal.simulate(m, _sphere_plan(m), errors=TRUE, artefact=ART, tip_radius=3.0, sigma=0.0005, seed=4)
    d = ds.to_dict()
    for k, o in enumerate(d["observations"]):
        o["id"] = f"touch{k}"
    bad = 17
    axes = {k: [v] for k, v in d["observations"][bad]["axes"].items()}
    p = m.tool_point(axes)[0]
    u = (p - np.array(ART["spheres"][0]["center"])) / np.linalg.norm(p - ART["spheres"][0]["center"])
    moved = m.inverse([p + 0.05 * u], start={k: v[0] for k, v in axes.items()})
    d["observations"][bad]["axes"] = {k: float(v[0]) for k, v in moved.items()}
    r = fivecal.identify(d, "location", robust="huber")
    assert bad in r.outliers
    assert f"{bad} (touch{bad})" in r.report()


# --------------------------------------------------------------------------
# Bad input: file, line and column named; CLI exit code 2
# --------------------------------------------------------------------------
HEAD = "X,Y,Z,A,C,dx_um,dy_um,dz_um"
GOOD = "50,-40,-80.718,-30,0,-29.6,7.2,23.0"


@pytest.mark.parametrize("row,match", [
    ("50,-40,nan,-30,0,-29.6,7.2,23.0", r"r\.csv:3: column 'Z': 'nan' is not a finite number"),
    ("50,-40,,-30,0,-29.6,7.2,23.0", r"r\.csv:3: column 'Z': empty cell"),
    ("50,-40,-80.7,-30,0,abc,7.2,23.0", r"r\.csv:3: column 'dx_um': 'abc' is not a number"),
    ("50,-40,-80.7,-30,0,7.2,23.0", r"r\.csv:3: 7 cells, the header \(line 1\) has 8 columns"),
    ("50,-40,-80.7,-30,0,-29600,7.2,23.0", r"r\.csv:3: column 'dx_um': -29\.6 mm is beyond an R-test"),
    ("50e6,-40,-80.7,-30,0,-29.6,7.2,23.0", r"r\.csv:3: column 'X': 5e\+07 mm is beyond any machine tool"),
])
def test_bad_cells_name_file_line_and_column(tmp_path, row, match):
    f = _write(tmp_path / "r.csv", [HEAD, GOOD, row])
    with pytest.raises(ValueError, match=match):
        read_table(f, "ball3d", C600U, sidecar=RTEST_SIDE)


@pytest.mark.parametrize("lines,kind,side,match", [
    (["50,-40,-80.7,-30,0,1,2,3"], "ball3d", RTEST_SIDE, r"x\.csv:1: no header row .*X Y Z A C dx_um dy_um dz_um"),
    (["X,Y,Z,A,U,dx,dy,dz", GOOD], "ball3d", RTEST_SIDE, r"x\.csv:1: column 'U': unknown axis letter 'U' "
                                                          r"\(the machine's axes: X Y Z A C S\)"),
    (["X,Y,Z,A,dx,dy,dz", "1,2,3,4,5,6,7"], "ball3d", RTEST_SIDE, r"x\.csv:1: no column for axis C"),
    (["X,Y,Z,A,C,dx,dy,dz,temp", GOOD + ",20"], "ball3d", RTEST_SIDE, r"column 'temp'.*--ignore"),
    (["X,Y,Z,A,C,readng", "0,0,-150,0,0,0.01"], "dbb", RTEST_SIDE, r"column 'readng'.*did you mean 'reading'"),
    (["X,Y,Z,A,C,dx_deg,dy,dz", GOOD], "ball3d", RTEST_SIDE, r"column 'dx_deg': unknown unit 'deg' for a length"),
    ([HEAD, GOOD], "ball3d", {}, r"x\.csv:2: no tool_ball .*--tool-ball"),
    (["X,Y,Z,A,C,reading", "0,0,-150,0,0,25"], "dbb", {**RTEST_SIDE, "length": 100},
     r"x\.csv:2: column 'reading': reading 25 mm is beyond a ballbar's range .*reading_um"),
    (["X,Y,Z,A,C,reading", "0,0,-150,0,0,0.01"], "dbb", RTEST_SIDE, r"x\.csv:2: no bar length"),
    (["X,Y,Z,A,C,target", "1,2,3,0,0,S9"], "probing", PROBE_SIDE, r"x\.csv:2: column 'target': 'S9' is not a facet"),
    (["X,Y,Z,A,C,target,approach", "1,2,3,0,0,S1,-Q"], "probing", PROBE_SIDE,
     r"x\.csv:2: column 'approach': approach '-Q': unknown axis letter 'Q'"),
    (["X,Y,Z,A,C,target,dir_x", "1,2,3,0,0,S1,2"], "probing", PROBE_SIDE, r"x\.csv:2: column 'dir_x': direction 2"),
    (["X,Y,Z,A,C,target", "1,2,3,0,0,S1"], "probing", {"artefact": ART}, r"probe tip radius"),
    (["id,X,Y,Z,A,C,target", "a,1,2,3,0,0,S1", "a,1,2,3,0,0,S1"], "probing", PROBE_SIDE,
     r"x\.csv:3: id 'a' already used on line 2"),
    (["type,X,Y,Z,A,C,reading,dx,dy,dz", "ball3d,0,0,0,0,0,0.1,,,"], "fivecal", RTEST_SIDE,
     r"x\.csv:2: column 'reading': a ball3d row has no reading"),
    (["type,X,Y,Z,A,C,reading,dx,dy,dz", "ball3d,0,0,0,0,0,,0.1,,0.1"], "fivecal", RTEST_SIDE,
     r"x\.csv:2: column 'dy': empty cell"),
    (["X;Y;Z;A;C;dx;dy;dz", "1;2;3;0;0;0,1;0,2;0,3"], "ball3d", RTEST_SIDE, None),  # decimal comma is fine
])
def test_bad_tables_are_refused_naming_what_is_expected(tmp_path, lines, kind, side, match):
    f = _write(tmp_path / "x.csv", lines)
    if match is None:
        assert read_table(f, kind, C600U, sidecar=side)["observations"][0]["measured"] == [0.1, 0.2, 0.3]
        return
    with pytest.raises(ValueError, match=match):
        read_table(f, kind, C600U, sidecar=side)


def test_core_validation_errors_are_mapped_to_the_line(tmp_path):
    # a negative bar length passes the table reader and is refused by the dataset loader
    f = _write(tmp_path / "t.csv", ["X,Y,Z,A,C,reading,length", "0,0,-150,0,0,0.01,100", "0,0,-150,0,30,0.01,-5"])
    with pytest.raises(ValueError, match=r"t\.csv:3 \(observations\[1\]\).*length"):
        import_dataset(f, "dbb", C600U, sidecar=RTEST_SIDE)


def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys):
    f = _write(tmp_path / "r.csv", [HEAD, GOOD, "50,-40,-80.7,-30,0,x,7.2,23.0"])
    out = tmp_path / "ds.json"
    rc = cli.main(["import", "rtest", f, "--machine", C600U, "--setup", "R1", "--tool-ball", "0,0,150",
                   "--table-ball", "50,0,80", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2
    assert "r.csv:3: column 'dx_um': 'x' is not a number" in err and err.count("\n") == 1
    assert not out.exists()
    side = tmp_path / "side.json"
    side.write_text(json.dumps({"tool_bal": [0, 0, 1]}))
    rc = cli.main(["import", "rtest", f, "--machine", C600U, "--sidecar", str(side), "--out", str(out)])
    assert rc == 2 and "did you mean 'tool_ball'" in capsys.readouterr().err


def test_sidecar_and_option_values_are_named_where_given(tmp_path):
    f = _write(tmp_path / "r.csv", [HEAD, GOOD])
    side = tmp_path / "side.json"
    side.write_text(json.dumps({**RTEST_SIDE, "table_ball": [1, 2]}))
    with pytest.raises(ValueError, match=r"side\.json: sidecar\.table_ball: expected 3 values, got 2"):
        read_table(f, "ball3d", C600U, sidecar=side)
    with pytest.raises(ValueError, match=r"--sigma: expected a finite number > 0"):
        read_table(f, "ball3d", C600U, sidecar=RTEST_SIDE, sigma=float("nan"))
    # a sidecar given as a dict: the dataset checks name it
    t = _write(tmp_path / "t.csv", ["X,Y,Z,A,C,target", "1,2,3,0,0,S1"])
    bad = {"probe": {"tip_radius": 3.0}, "artefact": {"spheres": [{"id": "S1", "center": [0, 0, 0], "radius": -2}]}}
    with pytest.raises(ValueError, match=r"^sidecar: artefact\.spheres\[0\]\.radius: must be > 0"):
        import_dataset(t, "probing", C600U, sidecar=bad)
    probe = tmp_path / "probe.json"
    probe.write_text(json.dumps({"probe": {"tip_radius": 3.0},
                                 "artefact": {"spheres": [{"id": "S1", "center": [0, 0, 0], "radius": -2}]}}))
    with pytest.raises(ValueError, match=r"probe\.json: sidecar\.artefact\.spheres\[0\]\.radius: must be > 0"):
        import_dataset(t, "probing", C600U, sidecar=probe)


def test_rotary_columns_in_radians_warn_naming_the_column_and_the_option(tmp_path):
    # a sweep off the quarter turns: radian indexations (0.5236, 1.0472, ...) are refused (below)
    sweep = np.linspace(0, 2 * np.pi, 13)[:-1] + 0.01
    lines = ["X,Y,Z,A,C,dx,dy,dz"] + [f"0,0,0,0,{c:.5f},0.001,0,0" for c in sweep]
    f = _write(tmp_path / "r.csv", lines)
    with pytest.warns(fivecal.RadiansWarning, match=r"r\.csv: axis column C: .*C_rad or give --angle-units rad"):
        import_dataset(f, "ball3d", C600U, sidecar=RTEST_SIDE)
    ds = import_dataset(f, "ball3d", C600U, sidecar=RTEST_SIDE, angle_units="rad")
    assert ds.observations[3]["axes"]["C"] == pytest.approx(90.0 + np.degrees(0.01), abs=1e-3)


def test_renamed_columns_keep_the_unit_of_their_header(tmp_path):
    f = _write(tmp_path / "r.csv", ["# R-test export", "Xpos,Y,Z,a,c,dev [um],dy_um,DZ", "1,2,3,0,0,10,20,0.03"])
    d = read_table(f, "rtest", C600U, sidecar=RTEST_SIDE, columns={"X": "Xpos", "dx": "dev [um]"})
    o = d["observations"][0]
    assert o["axes"]["X"] == 1.0 and o["measured"] == pytest.approx([0.01, 0.02, 0.03])
    assert o["id"] == "r.csv:3"
    with pytest.raises(ValueError, match=r"no column 'nope' in the header"):
        read_table(f, "rtest", C600U, sidecar=RTEST_SIDE, columns={"X": "nope"})


# --------------------------------------------------------------------------
# Units, encodings and broken files (issue #27)
# --------------------------------------------------------------------------
@pytest.mark.parametrize("a,c,angle_units", [
    ("A [°]", "C°", None), ("A_degrees", "C (degree)", None), ("A (deg)", "C_°", None),
    ("A", "C", "°"), ("A", "C", "degrees"), ("A [µrad]", "C [μrad]", None)])
def test_every_spelling_of_an_angle_unit_is_read(tmp_path, capsys, a, c, angle_units):
    f = _write(tmp_path / "r.csv", [f"X,Y,Z,{a},{c},dx_um,dy_um,dz_um", GOOD])
    o = read_table(f, "ball3d", C600U, sidecar=RTEST_SIDE, angle_units=angle_units)["observations"][0]
    want = -30.0 * (1.8e-4 / np.pi if "rad" in a else 1.0)
    assert o["axes"]["A"] == pytest.approx(want)
    args = ["--angle-units", angle_units] if angle_units else []
    rc = cli.main(["import", "rtest", f, "--machine", C600U, "--sidecar", _side(tmp_path), *args,
                   "--out", str(tmp_path / "ds.json")])
    assert rc == 0, capsys.readouterr().err


def _side(tmp_path, side=RTEST_SIDE):
    p = tmp_path / "side.json"
    p.write_text(json.dumps(side))
    return str(p)


def test_an_unknown_angle_unit_names_the_column_and_the_units(tmp_path, capsys):
    f = _write(tmp_path / "r.csv", ["X,Y,Z,A [grad],C,dx_um,dy_um,dz_um", GOOD])
    with pytest.raises(ValueError, match=r"r\.csv:1: column 'A \[grad\]': unknown unit 'grad' for an angle "
                                         r"\(units: deg, °, .*rad"):
        read_table(f, "ball3d", C600U, sidecar=RTEST_SIDE)
    rc = cli.main(["import", "rtest", f, "--machine", C600U, "--sidecar", _side(tmp_path),
                   "--angle-units", "grad", "--out", str(tmp_path / "ds.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "--angle-units 'grad': expected deg or rad" in err and "°" in err, err


def test_a_table_in_latin1_is_refused_naming_the_file_line_and_the_fix(tmp_path, capsys):
    f = tmp_path / "r.csv"
    f.write_bytes("# R-test\nX,Y,Z,A [°],C,dx_um,dy_um,dz_um\n".encode("latin-1") + GOOD.encode() + b"\n")
    with pytest.raises(ValueError, match=r"r\.csv: not UTF-8 text \(byte 0xb0 at byte offset 18\) on line 2, "
                                         r"'°' in Latin-1.*save the file as UTF-8"):
        read_table(str(f), "ball3d", C600U, sidecar=RTEST_SIDE)
    side = tmp_path / "s.json"
    side.write_bytes(json.dumps({"setup": "R1"}).encode()[:-1] + ', "_comment": "\xb5m"}'.encode("latin-1"))
    rc = cli.main(["import", "rtest", _write(tmp_path / "g.csv", [HEAD, GOOD]), "--machine", C600U,
                   "--sidecar", str(side), "--out", str(tmp_path / "ds.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "s.json: not UTF-8 text" in err and "on line 1" in err and err.count("\n") == 1, err


def test_a_probe_log_in_latin1_is_refused_naming_the_file(tmp_path, m):
    from fivecal.io import linuxcnc

    log = tmp_path / "probe.log"
    log.write_bytes(b"1 2 3 0 0 0 0 0 0\n# \xb0\n")
    with pytest.raises(ValueError, match=r"probe\.log: not UTF-8 text .* on line 2"):
        linuxcnc.read_probe_log(str(log), m, "xyzac-trt", [], {})


@pytest.mark.parametrize("sep,quote", [(",", ""), (",", '"'), (";", ""), (" ", "")])
def test_a_huge_cell_is_refused_naming_the_line(tmp_path, capsys, sep, quote):
    big = quote + "1" * 2_000_000 + quote
    f = _write(tmp_path / "r.csv", [HEAD.replace(",", sep), GOOD.replace(",", sep),
                                    sep.join(GOOD.split(",")[:5] + [big] + GOOD.split(",")[6:])])
    with pytest.raises(ValueError, match=r"r\.csv:3: .*characters \(at most 4096 are read\)"):
        read_table(f, "ball3d", C600U, sidecar=RTEST_SIDE)
    rc = cli.main(["import", "rtest", f, "--machine", C600U, "--sidecar",
                   _side(tmp_path), "--out", str(tmp_path / "ds.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "r.csv:3:" in err and len(err) < 400 and "internal error" not in err, err[:400]


@pytest.mark.parametrize("head", ["X,Y,Z,A,C,dx,dy,dz,X", "X Y Z A C dx dy dz DZ", "x,Y,Z,A,C,dx,dy,dz,temp,X"])
def test_a_column_named_twice_is_refused(tmp_path, head):
    n = len(head.replace(" ", ",").split(","))
    f = _write(tmp_path / "r.csv", [head, ",".join(["0.1"] * n) if "," in head else " ".join(["0.1"] * n)])
    with pytest.raises(ValueError, match=r"r\.csv:1: column '.*' appears twice in the header \(columns \d+ and "
                                         rf"{n}\)"):
        read_table(f, "ball3d", C600U, sidecar=RTEST_SIDE, ignore=["temp"] if "temp" in head else ())


# --------------------------------------------------------------------------
# Rotary columns in another unit than declared (issue #27)
# --------------------------------------------------------------------------
DBB_SIDE = {"setup": "C1", "length": 100.0, "tool_ball": [0, 0, 150.0], "table_ball": [100.0, 0.0, 0.0]}


def _dbb(tmp_path, c_header, cs, name="d.csv"):
    return _write(tmp_path / name, [f"X,Y,Z,A,{c_header},reading_um"] + [f"0,0,-150,0,{c},5" for c in cs])


@pytest.mark.parametrize("header,values,angle_units,match", [
    ("C_rad", [0, 30, 60, 90], None,
     r"d\.csv:3: column 'C_rad': 30 rad is 1718\.87 degrees, more than a turn and a quarter \(7\.854 rad\); "
     r"the values look like degrees: name the column C_deg$"),
    ("C [rad]", [0, -5, -10, 15], None, r"d\.csv:4: column 'C \[rad\]': -10 rad .*name the column C_deg"),
    ("C_rad", [0, 1, 2, 3, 4, 5], None, r"d\.csv:3: column 'C_rad': 1 rad, and every value of the column is a "
                                        r"whole number \(1, 2, 3, 4, \.\.\.\), as degrees are written"),
    ("C", [0, 30, 60], "rad", r"d\.csv:3: column 'C': 30 rad .*drop --angle-units rad \(degrees are the default\)"),
    ("C", [0, -2, 2, 4], "RAD", r"d\.csv:3: column 'C': -2 rad, .*whole number.*drop --angle-units rad"),
    ("C (mrad)", [0, 9000], None, r"d\.csv:3: column 'C \(mrad\)': 9000 mrad is 515\.662 degrees"),
    ("C", [0, 0.7854, 1.5708, 3.1416], None,
     r"d\.csv:3: column 'C': 0\.7854 degrees, and every value of the column is a multiple of π/12 written in "
     r"decimals \(0\.7854 = 3π/12\), as radians are written; .*name the column C_rad or give --angle-units rad"),
    ("C_deg", [0, 0.5236, -1.0472], None, r"d\.csv:3: column 'C_deg': .*π/12.*name the column C_rad$"),
])
def test_rotary_values_plainly_in_another_unit_than_declared_are_refused(tmp_path, header, values, angle_units,
                                                                         match):
    f = _dbb(tmp_path, header, values)
    with pytest.raises(ValueError, match=match):
        import_dataset(f, "dbb", C600U, sidecar=DBB_SIDE, angle_units=angle_units)


@pytest.mark.parametrize("header,values,angle_units,want", [
    ("C_rad", [f"{c:.5f}" for c in np.linspace(-2 * np.pi, 2 * np.pi, 9)], None, -360.0),
    ("C_rad", [0, 7], None, 0.0),  # one whole value: 7 rad (401 degrees) may be meant
    ("C", [0, 0.5, 1, 1.5], None, 0.0),  # small rotations in degrees
    ("C", [0, 0.25, 0.5], "deg", 0.0),
    ("C", ["0.52360", "1.04720"], "rad", 30.0),
    ("C (mrad)", [0, 15, 30], None, 0.0),  # whole mrad are usual
])
def test_rotary_values_that_fit_their_unit_are_read(tmp_path, header, values, angle_units, want):
    f = _dbb(tmp_path, header, values)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fivecal.RadiansWarning)
        ds = import_dataset(f, "dbb", C600U, sidecar=DBB_SIDE, angle_units=angle_units)
    assert ds.observations[0]["axes"]["C"] == pytest.approx(want, abs=1e-3)


def test_angle_units_rad_over_degrees_is_refused_by_the_cli_for_every_kind(tmp_path, capsys):
    out = str(tmp_path / "ds.json")
    rc = cli.main(["import", "rtest", os.path.join(EX, "rtest.txt"), "--machine", C600U, "--sidecar",
                   os.path.join(EX, "rtest.json"), "--angle-units", "rad", "--out", out])
    err = capsys.readouterr().err
    assert rc == 2 and "rtest.txt:3: column 'A': -30 rad is -1718.87 degrees" in err and \
        "drop --angle-units rad" in err and err.count("\n") == 1, err
    with pytest.raises(ValueError, match=r"rtest\.txt:3: column 'A': -30 rad"):
        import_dataset(os.path.join(EX, "rtest.txt"), "rtest", C600U, sidecar=os.path.join(EX, "rtest.json"),
                       angle_units="rad")
    trace = open(os.path.join(EX, "dbb_trace.csv"), encoding="utf-8").read()
    for header, extra, needle in (("C_rad", [], "column 'C_rad': 30 rad"),
                                  ("C", ["--angle-units", "rad"], "column 'C': 30 rad")):
        f = tmp_path / "t.csv"
        f.write_text(trace.replace("C_deg", header), encoding="utf-8")
        rc = cli.main(["import", "dbb", str(f), "--machine", C600U, "--sidecar", os.path.join(EX, "dbb_trace.json"),
                       *extra, "--out", out])
        err = capsys.readouterr().err
        assert rc == 2 and f"t.csv:4: {needle}" in err, err
        assert not os.path.exists(out)
    # the generic table and a joint layout: the same check
    f = _write(tmp_path / "g.csv", ["type,X,Y,Z,A,C_rad,dx,dy,dz"] +
               [f"ball3d,0,0,0,0,{c},0.001,0,0" for c in (0, 45, 90)])
    with pytest.raises(ValueError, match=r"g\.csv:3: column 'C_rad': 45 rad"):
        import_dataset(f, "fivecal", C600U, sidecar=RTEST_SIDE)
    f = _write(tmp_path / "j.csv", ["joint,position,measured_x,measured_y,measured_z"] +
               [f"C,{c},{c},0,0" for c in (0, 30, 60)])
    with pytest.raises(ValueError, match=r"j\.csv:3: column 'position' \(joint C\): 30 rad .*drop --angle-units"):
        import_dataset(f, "point", C600U, target="work", target_point=[100, 0, 0], angle_units="rad")


# --------------------------------------------------------------------------
# Lengths of the set-up typed in µm (issue #27)
# --------------------------------------------------------------------------
@pytest.mark.parametrize("side,options,match", [
    ({**DBB_SIDE, "length": 100000}, {}, r"side\.json: length: 100000 mm: no ball bar is that long \(refused "
                                         r"beyond 2000 mm\); it looks like µm: give 100 \(mm\)"),
    ({**DBB_SIDE, "length": 50000.0}, {}, r"side\.json: length: 50000 mm"),
    (DBB_SIDE, {"length": 100000}, r"^--length: 100000 mm: no ball bar"),
    ({**DBB_SIDE, "table_ball": [100000, 0, 0]}, {}, r"side\.json: table_ball\[0\]: 100000 mm"),
    (DBB_SIDE, {"tool_ball": "0,0,150000"}, r"--tool-ball\[2\]: 150000 mm"),
    ({**DBB_SIDE, "probe": {"tip_radius": 3000}}, {}, r"side\.json: probe\.tip_radius: 3000 mm: no probe tip"),
    ({**DBB_SIDE, "artefact": {"spheres": [{"id": "S1", "center": [0, 0, 0], "radius": 12500}]}}, {},
     r"side\.json: artefact\.spheres\[0\]\.radius: 12500 mm: no reference sphere"),
])
def test_set_up_lengths_in_um_are_refused_naming_the_field(tmp_path, side, options, match):
    f = _dbb(tmp_path, "C", [0, 30, 60])
    with pytest.raises(ValueError, match=match):
        import_dataset(f, "dbb", C600U, sidecar=_side(tmp_path, side), **options)


def test_set_up_lengths_in_um_are_refused_in_columns_and_by_the_cli(tmp_path, capsys):
    f = _write(tmp_path / "l.csv", ["X,Y,Z,A,C,reading_um,length", "0,0,-150,0,0,5,100", "0,0,-150,0,30,5,100000"])
    with pytest.raises(ValueError, match=r"l\.csv:3: column 'length': 100000 mm: no ball bar"):
        import_dataset(f, "dbb", C600U, sidecar=DBB_SIDE)
    f = _write(tmp_path / "g.csv", ["type,X,Y,Z,A,C,reading,length,tool_ball_x,tool_ball_y,tool_ball_z",
                                    "dbb,0,0,-150,0,0,0.005,100,0,0,150", "dbb,0,0,-150,0,30,0.005,100,0,0,150000"])
    with pytest.raises(ValueError, match=r"g\.csv:3: column 'tool_ball_z': 150000 mm"):
        import_dataset(f, "fivecal", C600U, sidecar=DBB_SIDE)
    side = tmp_path / "s.json"
    side.write_text(json.dumps({**DBB_SIDE, "length": 100000}))
    out = tmp_path / "ds.json"
    rc = cli.main(["import", "dbb", os.path.join(EX, "dbb_trace.csv"), "--machine", C600U, "--sidecar", str(side),
                   "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "s.json: length: 100000 mm" in err and not out.exists(), err
    rc = cli.main(["import", "dbb", os.path.join(EX, "dbb_trace.csv"), "--machine", C600U, "--sidecar",
                   os.path.join(EX, "dbb_trace.json"), "--length", "100000", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "--length: 100000 mm" in err, err
