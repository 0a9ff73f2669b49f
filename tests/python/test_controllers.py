"""Controller models (fivecal.io.controllers): what a table-table, head-head,
table-head pivot model and LinuxCNC's trt / 5axiskins modules absorb of
identified errors, what they leave, and the neutral kinematics table."""
import json
import subprocess
import sys

import numpy as np
import pytest

import fivecal
from fivecal.io import controllers as K
from fivecal.io import linuxcnc as L


def _axes(topology, rot, tip=(0, 0, 150)):
    d = {"X": {"type": "linear", "direction": [1, 0, 0]},
         "Y": {"type": "linear", "direction": [0, 1, 0]},
         "Z": {"type": "linear", "direction": [0, 0, 1]},
         "S": {"type": "rotary", "direction": [0, 0, 1]}}
    d.update(rot)
    return fivecal.Machine.from_dict({"name": topology, "topology": topology, "axes": d,
                                      "tool": {"tip": list(tip)}})


HEAD_HEAD = lambda: _axes("wXYfZCBSt", {  # noqa: E731  B on C in the spindle head, 5axiskins-like
    "C": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 300]},
    "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, 300]}}, tip=(0, 0, 50))
TABLE_HEAD = lambda: _axes("wCXYfZBSt", {  # noqa: E731  C table, B head
    "C": {"type": "rotary", "direction": [0, 0, -1], "point": [5, -3, 0]},
    "B": {"type": "rotary", "direction": [0, 1, 0], "point": [0, 0, 250]}})

MACHINES = {
    "hu40t": (lambda: fivecal.Machine.load("examples/machines/hu40t.json"), "table-table"),
    "c600u": (lambda: fivecal.Machine.load("examples/machines/c600u.json"), "table-table"),
    "kx8": (lambda: fivecal.Machine.load("examples/machines/kx8.json"), "table-table"),
    "vmc0656": (lambda: fivecal.Machine.load("examples/machines/vmc0656.json"), "table-table"),
    "head-head": (HEAD_HEAD, "head-head"),
    "table-head": (TABLE_HEAD, "table-head"),
}


def _inject(m, model, rng, directions):
    """Errors the model represents: random pivot (and direction) offsets."""
    th = m.theta(None).copy()
    for p in K.parameters(m, model, directions=directions, tool_length=False):
        th = th + p.column * (rng.uniform(0.01, 0.04) if p.unit == "mm" else rng.uniform(1e-5, 4e-5)) \
            * rng.choice([-1, 1])
    names = m.parameter_names()
    return {n: float(v) for n, v in zip(names, th - m.theta(None)) if v != 0}


@pytest.mark.parametrize("name", list(MACHINES))
@pytest.mark.parametrize("directions", [False, True])
def test_represented_errors_are_absorbed(name, directions):
    make, model = MACHINES[name]
    m = make()
    errors = _inject(m, model, np.random.default_rng(3), directions)
    ab = K.absorb(m, model, errors, directions=directions)
    assert ab.max_old > 5e-3           # tens of um before
    assert ab.max < 1e-6, (name, ab.max)
    # the table of the absorbed model reproduces the tool points (not just printed)
    tab = K.kinematics_table(m, ab.theta)
    truth = m.tool_point(ab.poses, errors=errors)
    assert np.abs(K.table_tool_points(tab, ab.poses) + ab.workpiece_shift - truth).max() < 1e-6


@pytest.mark.parametrize("name", list(MACHINES))
def test_tilts_are_left_by_pivot_models_with_the_predicted_map(name):
    make, model = MACHINES[name]
    m = make()
    tilts = {}
    for a in [x for x in m.axes if x["type"] == "rotary" and x["name"] != "S"]:
        tilts.update({f"EA0{a['name']}": 3e-5, f"EB0{a['name']}": -2e-5, f"EC0{a['name']}": 2.5e-5})
    # a linear axis squareness: no pivot model represents it
    tilts["EC0Y"] = 4e-5
    ab = K.absorb(m, model, tilts, compensation=True)
    assert ab.max > 1e-3 and ab.rms < ab.rms_old
    # the residual map is the true tool point minus the absorbed model's, the
    # latter computed from the neutral table by independent screw kinematics
    tab = K.kinematics_table(m, ab.theta)
    predicted = m.tool_point(ab.poses, errors=tilts) - K.table_tool_points(tab, ab.poses) - ab.workpiece_shift
    assert np.abs(ab.residual - predicted).max() < 1e-9
    # fivecal's G-code compensation on top removes what the model leaves
    assert ab.max_compensated < 1e-5 < ab.max
    # direction-capable models take the rotary tilts, not the squareness
    ab2 = K.absorb(m, model, tilts, directions=True)
    assert ab2.rms < ab.rms
    assert ab2.max > 1e-4


def test_linuxcnc_trt_model_equals_linuxcnc_absorption():
    """The generic pivot model restricted to LinuxCNC's pins leaves the same
    map as the fit through LinuxCNC's own trtfuncs.c kinematics."""
    from test_linuxcnc import FULL_ERRORS, MACHINES as LM
    for kins in ("xyzac-trt", "xyzbc-trt"):
        m = fivecal.Machine.from_dict(LM[kins])
        errors = {k.replace("A", L.TILT[kins]): v for k, v in FULL_ERRORS.items()}
        poses = L.pose_grid(m, kins)
        lab = L.absorb(m, kins, errors, poses=poses)
        ab = K.absorb(m, kins, errors, poses=poses)
        assert abs(ab.rms - lab.rms) < 1e-9 and abs(ab.max - lab.max) < 1e-9
        assert np.abs(ab.residual - lab.residual).max() < 1e-8
        # (the workpiece shifts differ: fivecal's part frame moves with the
        # C pivot, LinuxCNC's world does not; the maps are the same)
    with pytest.raises(ValueError, match="no joint in LinuxCNC's xyzac-trt"):
        K.absorb(fivecal.Machine.load("examples/machines/hu40t.json"), "xyzac-trt", {})


def test_5axiskins_conventions_and_pivot_length():
    m = HEAD_HEAD()
    rng = np.random.default_rng(1)
    q = {"X": rng.uniform(-50, 50, 40), "Y": rng.uniform(-50, 50, 40), "Z": rng.uniform(-50, 50, 40),
         "C": rng.uniform(-180, 180, 40), "B": rng.uniform(-90, 90, 40), "S": np.zeros(40)}
    mp = K._match_5axis(m)
    assert mp["pivot_length"] == 250.0
    j = K.fiveaxis_joints(m, q)
    # 5axiskins.c forward (B turns the tool about -y, C about +z) = fivecal's nominal machine
    world = K.fiveaxis_forward(mp["pivot_length"], j)
    assert np.abs(world + mp["origin"] - m.tool_point(q)).max() < 1e-9
    assert np.abs(K.fiveaxis_inverse(250.0, np.column_stack([world, j[:, 3:]])) - j).max() < 1e-9
    # the spindle 20 um lower on the B carriage is a pivot-length change
    ab = K.absorb(m, "5axiskins", {"EZ0S": -0.02})
    assert ab.max < 1e-6 and ab.max_old > 0.01
    dl = ab.value("tool length")
    assert abs(dl - 0.02) < 1e-9
    left = m.tool_point(ab.poses, errors={"EZ0S": -0.02}) - mp["origin"] - ab.workpiece_shift \
        - K.fiveaxis_forward(250.0 + dl, K.fiveaxis_joints(m, ab.poses))
    # up to a constant: 5axiskins's world zero stays at the tool tip at B = 0
    assert np.abs(left - left.mean(axis=0)).max() < 1e-6
    # B (and the spindle) off the C axis is nothing 5axiskins can hold
    ab = K.absorb(m, "5axiskins", {"EX0B": 0.02})
    assert ab.max > 0.01
    with pytest.raises(ValueError, match="5axiskins"):
        K.absorb(TABLE_HEAD(), "5axiskins", {})


def test_topology_must_fit_the_model():
    with pytest.raises(ValueError, match="is table-table"):
        K.parameters(fivecal.Machine.load("examples/machines/hu40t.json"), "head-head")
    with pytest.raises(ValueError, match="is table-head"):
        K.parameters(TABLE_HEAD(), "table-table")
    with pytest.raises(ValueError, match="model: 'fanuc'"):
        K.parameters(TABLE_HEAD(), "fanuc")


def test_table_values_are_the_pivots_and_directions():
    m = fivecal.Machine.load("examples/machines/hu40t.json")
    old = K.kinematics_table(m)
    # nominal: the machine file's own pivots and directions
    b = next(r for r in old["axes"] if r["axis"] == "B")
    assert np.allclose(b["point"], [0, 0, -120]) and np.allclose(b["direction"], [0, -1, 0])
    assert np.allclose(old["tool_tip"], m.tip)
    # a C pivot offset and tilt show up as such in the table (B carries C)
    new = K.kinematics_table(m, {"EX0C": 0.03, "EY0C": -0.02, "EA0C": 5e-5})
    c = next(r for r in new["axes"] if r["axis"] == "C")
    assert np.allclose(c["point"][:2], [0.03, -0.02], atol=1e-9)
    assert np.allclose(c["direction"], [0, 5e-5, -1], atol=1e-8)
    rows = K.table_rows(old, new)
    cx = next(r for r in rows if r["axis"] == "C" and r["value"] == "point.x")
    assert cx["old"] == 0 and abs(cx["new"] - 0.03) < 1e-12


def test_cli_export_kinematics(tmp_path):
    res = tmp_path / "errors.json"
    res.write_text(json.dumps({"EX0C": 0.03, "EY0C": -0.02, "EX0B": 0.01, "EA0C": 3e-5}))
    base = [sys.executable, "-m", "fivecal", "export", "kinematics", str(res), "--machine",
            "examples/machines/hu40t.json", "--model", "table-table", "--force"]
    r = subprocess.run(base, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "after absorption + fivecal G-code compensation" in r.stdout
    assert "C pivot x" in r.stdout and "I2 = point" in r.stdout and "V1" in r.stdout  # the vendor-name column
    r = subprocess.run(base + ["--format", "json", "--out", str(tmp_path / "k.json")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    d = json.loads((tmp_path / "k.json").read_text())
    ab = K.absorb(fivecal.Machine.load("examples/machines/hu40t.json"), "table-table",
                  {"EX0C": 0.03, "EY0C": -0.02, "EX0B": 0.01, "EA0C": 3e-5})
    assert abs(d["residual"]["max_mm"] - ab.max) < 1e-9
    assert np.abs(np.array(d["map"]["residual_mm"]) - ab.residual).max() < 1e-12
    assert len(d["map"]["axes"]["C"]) == len(ab.residual)
    assert d["residual"]["max_compensated_mm"] < 1e-5 < d["residual"]["max_mm"]
    cx = next(r for r in d["table"] if r["axis"] == "C" and r["value"] == "point.x")
    assert abs(cx["new"] - 0.04) < 2e-3  # B carries C: EX0B + EX0C
    r = subprocess.run(base + ["--format", "csv"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.splitlines()[0].startswith("axis,chain,value,old,new")
    r = subprocess.run(base[:-1] + ["--model", "head-head", "--force"], capture_output=True, text=True)
    assert r.returncode == 2 and "is table-table" in r.stderr


@pytest.mark.skipif(__import__("linuxcnc_harness").unavailable_reason() is not None,
                    reason="needs LinuxCNC")
def test_5axiskins_round_trip_in_linuxcnc():
    """Debian's 5axiskins, headless: the joints LinuxCNC commands for world
    moves equal fivecal's inverse kinematics of the head-head machine (its B
    along -y is LinuxCNC's +B); with a pivot-length error the absorbed
    pivot-length makes LinuxCNC put the erroneous machine's tool on the
    target, up to the constant work offset."""
    import linuxcnc_harness as harness
    m = HEAD_HEAD()
    mp = K._match_5axis(m)
    err = {"EZ0S": -0.02}
    ab = K.absorb(m, "5axiskins", err)
    rng = np.random.default_rng(4)
    n = 50
    w = rng.uniform(-60, 60, (n, 3))
    b = rng.uniform(-90, 90, n)
    c = rng.uniform(-180, 180, n)
    b[:3] = [-90, 90, 45]
    moves = [f"G1 X{x!r} Y{y!r} Z{z!r} B{bb!r} C{cc!r} F100000" for (x, y, z), bb, cc in
             zip(w.tolist(), b.tolist(), c.tolist())]
    L_new = mp["pivot_length"] + ab.value("tool length")
    for L, errors in ((mp["pivot_length"], None), (L_new, err)):
        with harness.Sim("5axiskins", hal=f"setp 5axiskins.pivot-length {L!r}\n") as sim:
            out = sim.run(moves, setup=[])
        j = np.array(out["joints"])[:, :5]
        assert np.abs(j - K.fiveaxis_inverse(L, np.column_stack([w, b, c]))).max() < 1e-6
        q = {"X": j[:, 0] * mp["sign"]["X"], "Y": j[:, 1] * mp["sign"]["Y"], "Z": j[:, 2] * mp["sign"]["Z"],
             "B": j[:, 3] * mp["sign"]["B"], "C": j[:, 4] * mp["sign"]["C"], "S": np.zeros(n)}
        if errors is None:
            # fivecal's nominal tool point at LinuxCNC's joints is the world target
            assert np.abs(m.tool_point(q) - mp["origin"] - w).max() < 1e-6
            # and fivecal's inverse gives LinuxCNC's joints
            for i in range(5):
                start = {"X": 0.0, "Y": 0.0, "Z": 0.0, "B": b[i] * mp["sign"]["B"], "C": c[i] * mp["sign"]["C"],
                         "S": 0.0}
                _, axis = m.tool_pose(start)
                qi = m.inverse((w[i] + mp["origin"])[None, :], tool_axes=axis, start=start)
                assert np.abs(K.fiveaxis_joints(m, qi)[0] - j[i]).max() < 1e-6
        else:
            left = m.tool_point(q, errors=errors) - mp["origin"] - w
            assert np.abs(left - left.mean(axis=0)).max() < 1e-6
            # the nominal pivot-length leaves the error
            j0 = K.fiveaxis_inverse(mp["pivot_length"], np.column_stack([w, b, c]))
            q0 = {a: j0[:, k] * mp["sign"][a] for k, a in enumerate("XYZBC")}
            q0["S"] = np.zeros(n)
            l0 = m.tool_point(q0, errors=errors) - mp["origin"] - w
            assert np.abs(l0 - l0.mean(axis=0)).max() > 0.01


def test_cli_export_kinematics_5axiskins_pin(tmp_path):
    m = HEAD_HEAD()
    mf = tmp_path / "m.json"
    mf.write_text(json.dumps(m.to_dict()))
    res = tmp_path / "errors.json"
    res.write_text(json.dumps({"EZ0S": -0.02, "EX0B": 0.005}))
    r = subprocess.run([sys.executable, "-m", "fivecal", "export", "kinematics", str(res), "--machine",
                        str(mf), "--model", "5axiskins", "--force"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    line = next(x for x in r.stdout.splitlines() if x.startswith("setp 5axiskins.pivot-length"))
    assert abs(float(line.split()[2]) - 250.02) < 1e-6
    # B off the C axis (EX0B) is left: the error after absorption is reported
    assert "after absorption rms" in r.stdout
    ab = K.absorb(m, "5axiskins", {"EZ0S": -0.02, "EX0B": 0.005})
    assert ab.max > 4e-3


# ---- export kinematics: the plausibility guard and the file format (issue 27) ----

def _kinematics(tmp_path, errors, *extra):
    from fivecal.cli import main
    res = tmp_path / "errors.json"
    res.write_text(json.dumps(errors))
    return main(["export", "kinematics", str(res), "--machine", "examples/machines/hu40t.json", "--model",
                 "table-table", *extra])


@pytest.mark.parametrize("errors,extra,fragment", [
    ({"EX0C": 50.0}, [], "C pivot x would change by 50 mm, more than the plausibility limit of 0.5 mm"),
    ({"EX0C": 0.03, "EA0C": 0.01}, ["--directions"], "C direction about x would change by 0.01 rad"),
    ({"EX0C": 0.8}, ["--max-change", "0.5,0.01"], "C pivot x"),
])
def test_cli_export_kinematics_refuses_an_implausible_change(tmp_path, capsys, errors, extra, fragment):
    # before: a 50 mm pivot change was exported as if it were the machine
    assert _kinematics(tmp_path, errors, *extra) == 2
    err = capsys.readouterr().err
    assert fragment in err and "--max-change" in err and len(err.strip().splitlines()) == 1, err


def test_cli_export_kinematics_max_change_lifts_the_guard(tmp_path, capsys):
    assert _kinematics(tmp_path, {"EX0C": 50.0}, "--max-change", "60") == 0
    assert _kinematics(tmp_path, {"EX0C": 50.0}, "--max-change", "off") == 0
    assert _kinematics(tmp_path, {"EX0C": 0.03, "EA0C": 0.01}, "--directions", "--max-change", "0.5,0.02") == 0
    capsys.readouterr()
    for bad in ("x", "0", "-1", "nan", "1,2,3"):
        assert _kinematics(tmp_path, {"EX0C": 0.03}, "--max-change", bad) == 2
        assert "--max-change" in capsys.readouterr().err


def test_cli_export_kinematics_writes_the_format_its_extension_says(tmp_path, capsys):
    # before: --out k.json without --format wrote the text report into it
    errors = {"EX0C": 0.03, "EY0C": -0.02}
    assert _kinematics(tmp_path, errors, "--out", str(tmp_path / "k.json")) == 0
    assert json.loads((tmp_path / "k.json").read_text())["model"] == "table-table"
    assert _kinematics(tmp_path, errors, "--out", str(tmp_path / "k.csv")) == 0
    assert (tmp_path / "k.csv").read_text().startswith("axis,chain,value,old,new")
    assert _kinematics(tmp_path, errors, "--out", str(tmp_path / "k.txt")) == 0
    assert (tmp_path / "k.txt").read_text().startswith("controller model table-table")
    capsys.readouterr()
    for name, extra, fragment in (("t.json", ["--format", "text"], "--format text"),
                                  ("t.csv", ["--format", "json"], "--format json"),
                                  ("t.xlsx", [], "'.xlsx' names no format"), ("t", ["--format", "json"], "(none)")):
        assert _kinematics(tmp_path, errors, "--out", str(tmp_path / name), *extra) == 2
        err = capsys.readouterr().err
        assert f"--out {tmp_path / name}:" in err and fragment in err, err
        assert not (tmp_path / name).exists()
