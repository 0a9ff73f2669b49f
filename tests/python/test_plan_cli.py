"""From a machine file to a test's program and back (issue 16, NC programs
for the tests): `fivecal plan` writes the plan, `fivecal export program` its
G-code, the readings of the run (simulated here the way the instrument would
record them on a machine with known errors) come back through `fivecal
import`, and the evaluation recovers the errors within 3 sigma."""
import json
import re

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal import gcode
from fivecal.io import linuxcnc as L
from fivecal.io import nc_programs as N
from fivecal.procedures.sphere_check import spindle_names

from test_linuxcnc import MACHINES, TRUE_LOCATION

KINS = "xyzac-trt"


@pytest.fixture
def machine_file(tmp_path):
    p = tmp_path / "machine.json"
    p.write_text(json.dumps(MACHINES[KINS]))
    return p


def run(capsys, *argv):
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


# ---- fivecal plan -----------------------------------------------------------

def test_plan_commands_write_specs_export_program_accepts(tmp_path, machine_file, capsys):
    m = fivecal.Machine.from_dict(MACHINES[KINS])
    cases = {
        "chk": ["sphere-check", "--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3",
                "--positions", "A=-60,-15,30", "--positions", "C=-120,0,120"],
        "st": ["sphere-test", "--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3",
               "--at", "A=0,C=0", "--at", "A=-30,C=90", "--rings", "0:8,45:4,90:1"],
        "rt": ["rtest", "--tests", "K1,K2", "--table-ball", "60,20,30", "--step", "30"],
        "fs": ["four-step", "--step", "5"],
    }
    for name, argv in cases.items():
        out = tmp_path / f"{name}.json"
        rc, text, err = run(capsys, "plan", argv[0], machine_file, *argv[1:], "--out", out)
        assert rc == 0, err
        spec = json.loads(out.read_text())
        assert spec["plan"] and fivecal.Machine.from_dict(spec["machine"]).name == m.name
        rc, text, err = run(capsys, "export", "program", out, "--kins", KINS, "--out", tmp_path / f"{name}.ngc")
        assert rc == 0, (name, err)
    # Wang's path needs intersecting A and C axes
    d = dict(MACHINES[KINS])
    d["axes"] = {**d["axes"], "C": {**d["axes"]["C"], "point": [12, 20, 0]}}
    wm = tmp_path / "wang_machine.json"
    wm.write_text(json.dumps(d))
    assert run(capsys, "plan", "wang", wm, "--step", "5", "--out", tmp_path / "w.json")[0] == 0
    w = json.loads((tmp_path / "w.json").read_text())["plan"]
    assert w and all(e["type"] == "dbb" and "tracking" not in e for e in w)
    rc, _, err = run(capsys, "export", "program", tmp_path / "w.json", "--kins", KINS, "--out", tmp_path / "w.ngc")
    assert rc == 0, err
    rc, _, err = run(capsys, "plan", "wang", machine_file, "--out", tmp_path / "w2.json")
    assert rc == 2 and "miss each other" in err
    # the sphere check plan is the one the Python call makes, both sides of each position
    from fivecal.procedures import sphere_check
    spec = json.loads((tmp_path / "chk.json").read_text())
    want = sphere_check.plan(m, {"id": "S1", "center": [60, 30, 40], "radius": 12.5}, tip_radius=3.0,
                             axis_positions={"A": [-60, -15, 30], "C": [-120, 0, 120]})
    assert spec["plan"] == json.loads(json.dumps(want))
    assert spec["probe"] == {"tip_radius": 3.0} and spec["artefact"]["spheres"][0]["radius"] == 12.5
    rt = json.loads((tmp_path / "rt.json").read_text())["plan"]
    assert {e["setup"] for e in rt} == {"K1", "K2"} and rt[0]["id"] == "K1-0"
    # the spec runs through fivecal simulate (with --errors in it)
    out = tmp_path / "rt_err.json"
    assert run(capsys, "plan", "rtest", machine_file, "--table-ball", "60,20,30", "--tests", "K1",
               "--errors", "EX0C=0.01", "--out", out)[0] == 0
    assert json.loads(out.read_text())["errors"] == {"EX0C": 0.01}
    assert run(capsys, "simulate", out, "--out", tmp_path / "ds.json")[0] == 0


@pytest.mark.parametrize("argv, option", [
    (["sphere-check", "--sphere", "60,30", "--radius", "12.5", "--tip-radius", "3"], "--sphere"),
    (["sphere-check", "--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3",
      "--positions", "B=1,2,3"], "--positions"),
    (["sphere-check", "--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3",
      "--positions", "A=1,2"], "--positions A"),
    (["sphere-check", "--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3",
      "--limits", "A=30:-90"], "--limits A"),
    (["sphere-check", "--sphere", "60,30,40", "--radius", "-1", "--tip-radius", "3"], "--radius"),
    (["sphere-test", "--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3"], "--at"),
    (["sphere-test", "--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3", "--at", "A=0",
      "--rings", "0:x"], "--rings"),
    (["rtest", "--tests", "K9", "--table-ball", "60,20,30"], "--tests"),
    (["rtest", "--table-ball", "60,20"], "--table-ball"),
    (["rtest", "--table-ball", "60,20,30", "--tilt-range", "90:-90"], "--tilt-range"),
    (["rtest", "--table-ball", "60,20,30", "--step", "0"], "--step"),
    (["four-step", "--setups", "a,b,c"], "--setups"),
    (["four-step", "--extended-length", "50"], "--extended-length"),
    (["wang", "--setup", "W.1"], "--setup"),
    (["four-step", "--errors", "EX0C"], "--errors"),
])
def test_plan_errors_name_the_option(tmp_path, machine_file, capsys, argv, option):
    try:
        rc, _, err = run(capsys, "plan", argv[0], machine_file, *argv[1:], "--out", tmp_path / "x.json")
    except SystemExit as e:  # argparse's own refusal of an option's value
        rc, err = e.code, capsys.readouterr().err
    assert rc == 2 and option in err, err
    assert not (tmp_path / "x.json").exists()


SPHERE = ["--sphere", "60,30,40", "--radius", "12.5", "--tip-radius", "3"]


@pytest.mark.parametrize("argv, option", [
    (["sphere-check", *SPHERE, "-n", "1000000000"], "-n"),
    (["sphere-check", *SPHERE, "-n", "361"], "-n"),
    (["sphere-check", *SPHERE, "--positions", "A=" + ",".join(str(i / 10) for i in range(400))], "--positions A"),
    (["sphere-test", *SPHERE, "--at", "A=0", "--rings", "0:1000000000"], "--rings"),
    (["sphere-test", *SPHERE, "--at", "A=0", "--rings", "0:99999,10:99999"], "--rings"),
    (["rtest", "--table-ball", "60,20,30", "--step", "1e-6"], "--step"),
    (["rtest", "--table-ball", "60,20,30", "--tests", "K2", "--step", "0.01", "--tilt-range=-90000:90000"], "--step"),
    (["four-step", "--step", "1e-6"], "--step"),
    (["four-step", "--step", "0.01", "--carrier-range=-50000:50000"], "--step"),
    (["wang", "--step", "1e-7"], "--step"),
    (["sphere-check", "--sphere", "1e308,1e308,0", "--radius", "12.5", "--tip-radius", "3"], "--sphere"),
    (["rtest", "--table-ball", "1e308,1e308,0"], "--table-ball"),
    (["four-step", "--tool-ball", "-1e308,-1e308,0"], "--tool-ball"),
])
def test_plan_counts_and_steps_are_bounded_naming_the_option(tmp_path, machine_file, capsys, argv, option):
    """Issue #27: `plan sphere-check -n 1000000000` and `plan rtest --step 1e-6`
    ended in `internal error (MemoryError)`; now a one-line refusal, exit 2."""
    try:
        rc, _, err = run(capsys, "plan", argv[0], machine_file, *argv[1:], "--out", tmp_path / "x.json")
    except SystemExit as e:  # argparse's own refusal of an option's value
        rc, err = e.code, capsys.readouterr().err
    assert rc == 2, err
    assert re.search(rf"(^|argument |: ){re.escape(option)}[ :]", err), err
    assert "internal error" not in err and "MemoryError" not in err
    assert not (tmp_path / "x.json").exists()


# ---- R-test: plan -> program -> nest readings -> import -> K-test analysis --

def _dwells(prog, machine, kins=None, tcp=False):
    """What an R-test logger sees of the program: per G4 dwell, the commanded
    axis position (fivecal's command names; joint values with ``kins``
    converted back, world coordinates with ``tcp`` through LinuxCNC's inverse
    kinematics with the nominal pins), the sample id of the dwell's comment
    and the balls of the setup comment."""
    pos, balls, out = {}, None, []
    for ln, line in enumerate(gcode.split_lines(prog), 1):
        m = re.match(r"\(setup (\S+): \d+ samples, table ball (\S+) (\S+) (\S+), tool ball (\S+) (\S+) (\S+)\)",
                     line.strip())
        if m:
            balls = (m.group(1), [float(x) for x in m.group(2, 3, 4)], [float(x) for x in m.group(5, 6, 7)])
        words = gcode.tokenize(line.rstrip("\n"), "prog", ln)
        if 4.0 in gcode.g_codes(words):
            sid = re.search(r"\(sample \d+: (\S+)\)", line).group(1)
            if kins:
                j = np.array([[pos[a] for a in ("X", "Y", "Z", L.TILT[kins], "C")]])
                if tcp:
                    j = L.inverse(kins, L.nominal_pins(machine, kins), j)
                axes = {a: float(v[0]) for a, v in L.commands(machine, kins, j).items()}
            else:
                axes = dict(pos)
            out.append({"axes": axes, "id": sid, "setup": balls[0], "table_ball": balls[1], "tool_ball": balls[2]})
            continue
        pos.update({w.letter: w.value for w in words if w.letter in "XYZABC"})
    return out


def _nest_readings(machine, dwells, errors, sigma, seed):
    """The nest's dx dy dz at each dwell on the machine with ``errors``:
    fivecal's model at the commanded pose, plus reading noise."""
    entries = [{"type": "ball3d", "axes": d["axes"], "setup": d["setup"], "tool_ball": d["tool_ball"],
                "table_ball": d["table_ball"]} for d in dwells]
    ds = fivecal.simulate(machine, entries, errors=errors, sigma={"ball3d": sigma}, seed=seed)
    return np.array([o["measured"] for o in ds.to_dict()["observations"]])


R_ERRORS = {k: v for k, v in TRUE_LOCATION.items()}


@pytest.mark.parametrize("layout", ["program-order", "ids", "tcp"])
def test_rtest_plan_program_readings_import_and_ktests(tmp_path, machine_file, capsys, layout):
    m = fivecal.Machine.from_dict(MACHINES[KINS])
    plan_file = tmp_path / "rtest_plan.json"
    rc, _, err = run(capsys, "plan", "rtest", machine_file, "--tests", "K1,K2,K3,K4", "--table-ball", "60,20,30",
                     "--tool-ball", "0,0,140", "--step", "15", "--tilt=-40", "--tilt-range=-90:60",
                     "--out", plan_file)
    assert rc == 0, err
    prog_file = tmp_path / "rtest.ngc"
    # axis commands, LinuxCNC joint values, LinuxCNC world moves with TCP on
    kins = KINS if layout in ("ids", "tcp") else None
    assert run(capsys, "export", "program", plan_file, *(["--kins", kins] if kins else []),
               *(["--mode", "tcp"] if layout == "tcp" else []), "--out", prog_file)[0] == 0
    dwells = _dwells(prog_file.read_text(), m, kins, tcp=layout == "tcp")
    plan = json.loads(plan_file.read_text())["plan"]
    assert len(dwells) == len(plan)
    sigma = 0.0005
    d = _nest_readings(m, dwells, R_ERRORS, sigma, seed=5) * 1e3  # the logger writes µm
    readings = tmp_path / "nest.csv"
    if layout != "program-order":  # a CSV with the dwell's plan id per row, in any order
        rows = [f"{w['id']},{x:.4f},{y:.4f},{z:.4f}" for w, (x, y, z) in zip(dwells, d)][::-1]
        readings.write_text("id,dx_um,dy_um,dz_um\n" + "\n".join(rows) + "\n")
    else:  # a plain log, one line per dwell in program order
        readings.write_text("# R-test nest log\ndx dy dz\n"
                            + "".join(f"{x:.4f} {y:.4f} {z:.4f}\n" for x, y, z in d))
    ds_file = tmp_path / "rtest_ds.json"
    argv = ["import", "rtest", readings, "--plan", plan_file, "--out", ds_file]
    rc, out, err = run(capsys, *argv, *(["--units", "um"] if layout == "program-order" else []))
    assert rc == 0, err
    ds = fivecal.load_dataset(str(ds_file))
    obs = ds.to_dict()["observations"]
    assert len(obs) == len(plan)
    by_id = {o["id"]: o for o in obs}
    for e in plan:  # each reading sits on its plan sample: axes, balls, mounting
        o = by_id[e["id"]]
        assert o["setup"] == e["setup"] and o["table_ball"] == e["table_ball"]
        assert all(abs(o["axes"][a] - e["axes"][a]) < 1e-9 for a in e["axes"])
    rc, out, err = run(capsys, "rtest", ds_file)
    assert rc == 0, err
    from fivecal.procedures import rtest
    res = rtest.evaluate(ds)
    r = res.result
    checked = 0
    # under the names every command reports (EX0C of this A/C table is EX0S, EY0A is EY0S)
    seen = spindle_names(ds.machine, R_ERRORS)
    for n in res.estimated:
        if n in (r.undetermined or []):
            continue
        s = r.std[n]
        assert abs(r.values[n] - seen.get(n, 0.0)) < 3 * s + 1e-12, (n, r.values[n], seen.get(n), s)
        checked += 1
    assert checked >= 6
    # the pivot position errors come out well above their uncertainty
    assert all(abs(seen[n]) > 10 * r.std[n] for n in ("EX0S", "EY0C", "EY0S", "EZ0A"))


def test_rtest_readings_that_do_not_line_up_are_refused(tmp_path, machine_file, capsys):
    plan_file = tmp_path / "p.json"
    run(capsys, "plan", "rtest", machine_file, "--tests", "K1", "--table-ball", "60,20,30", "--step", "90",
        "--out", plan_file)
    n = len(json.loads(plan_file.read_text())["plan"])  # 5 samples

    def imp(text, *extra):
        f = tmp_path / "r.csv"
        f.write_text(text)
        return run(capsys, "import", "rtest", f, "--plan", plan_file, "--out", tmp_path / "ds.json", *extra)

    rc, _, err = imp("dx_um,dy_um,dz_um\n" + "1,2,3\n" * (n - 1))
    assert rc == 2 and "4 readings for the 5 dwells" in err
    rc, _, err = imp("dx_um,dy_um,dz_um\n" + "1,2,3\n" * (n + 1))
    assert rc == 2 and "more readings than the 5 dwells" in err and ":7:" in err
    rc, _, err = imp("id,dx_um,dy_um,dz_um\nK1-0,1,2,3\nK9-0,1,2,3\n")
    assert rc == 2 and "'K9-0' is not a sample id" in err and ":3:" in err
    rc, _, err = imp("id,dx_um,dy_um,dz_um\nK1-0,1,2,3\nK1-0,1,2,3\n")
    assert rc == 2 and "already read on line 2" in err
    rc, _, err = imp("id,dx,dy,dz\nK1-0,12,2,3\n")
    assert rc == 2 and "look like µm" in err
    rc, _, err = imp("id,C,dx_um,dy_um,dz_um\nK1-1,45,1,2,3\n")  # K1-1 is at C 90
    assert rc == 2 and "not the plan's command" in err
    rc, _, err = imp("id,dx_um,dy_um\nK1-0,1,2\n")
    assert rc == 2 and "no 'dz' column" in err
    rc, _, err = imp("dx_um,dy_um,dz_um\n" + "1,2,3\n" * n, "--machine", str(machine_file))
    assert rc == 2 and "--machine: not used with --plan" in err
    rc, _, err = run(capsys, "import", "rtest", tmp_path / "r.csv", "--out", tmp_path / "ds.json")
    assert rc == 2 and "--machine" in err
    rc, _, err = run(capsys, "import", "probe-log", tmp_path / "r.csv", "--out", tmp_path / "ds.json")
    assert rc == 2 and "--plan" in err
    # an id column may give a subset: the samples read are imported
    rc, out, err = imp("id,dx_um,dy_um,dz_um\nK1-2,1,2,3\nK1-0,1,2,3\n")
    assert rc == 0 and "2 ball3d observations of the 5 planned" in out


def test_rtest_readings_read_rotary_columns_in_the_declared_unit(tmp_path, machine_file, capsys):
    plan_file = tmp_path / "p.json"
    run(capsys, "plan", "rtest", machine_file, "--tests", "K1", "--table-ball", "60,20,30", "--step", "90",
        "--out", plan_file)

    def imp(text, *extra):
        f = tmp_path / "r.csv"
        f.write_text(text)
        return run(capsys, "import", "rtest", f, "--plan", plan_file, "--out", tmp_path / "ds.json", *extra)

    # K1-1 is at C 90, K1-2 at C 180: --angle-units was ignored, now it reads the C column
    rc, _, err = imp("id,C,dx_um,dy_um,dz_um\nK1-1,1.570796,1,2,3\nK1-2,3.141593,1,2,3\n", "--angle-units", "rad")
    assert rc == 0, err
    rc, _, err = imp("id,C,dx_um,dy_um,dz_um\nK1-1,90,1,2,3\nK1-2,180,1,2,3\n", "--angle-units", "rad")
    assert rc == 2 and "r.csv:2: column 'C': 90 rad is 5156.62 degrees" in err and "--angle-units" in err, err
    rc, _, err = imp("id,C_rad,dx_um,dy_um,dz_um\nK1-1,90,1,2,3\nK1-2,180,1,2,3\n")
    assert rc == 2 and "column 'C_rad': 90 rad" in err and "C_deg" in err, err
    rc, _, err = imp("id,C,dx_um,dy_um,dz_um\nK1-1,90,1,2,3\n", "--angle-units", "grad")
    assert rc == 2 and "--angle-units 'grad'" in err, err
    rc, _, err = run(capsys, "import", "probe-log", tmp_path / "r.csv", "--plan", plan_file, "--kins", "xyzac-trt",
                     "--angle-units", "rad", "--out", tmp_path / "ds.json")
    assert rc == 2 and "--angle-units: not used by a probe-log import" in err, err


# ---- sphere check: plan -> program -> probe log -> import -> sphere-check ---

def test_sphere_check_plan_program_log_import_and_check(tmp_path, machine_file, capsys):
    m = fivecal.Machine.from_dict(MACHINES[KINS])
    plan_file = tmp_path / "check_plan.json"
    rc, _, err = run(capsys, "plan", "sphere-check", machine_file, "--sphere", "60,30,40", "--radius", "12.5",
                     "--tip-radius", "3", "--positions", "A=-60,-15,30", "--positions", "C=-120,0,120",
                     "--out", plan_file)
    assert rc == 0, err
    prog_file = tmp_path / "check.ngc"
    assert run(capsys, "export", "program", plan_file, "--kins", KINS, "--clearance", "1", "--overtravel", "1",
               "--out", prog_file)[0] == 0
    prog = prog_file.read_text()
    spec = json.loads(plan_file.read_text())
    plan, art = spec["plan"], spec["artefact"]
    assert prog.count("G38.2") == len(plan) and "(PROBEOPEN probe-log.txt)" in prog
    # the offline trigger simulation of test_nc_programs: where each probe move
    # of this program trips on the machine with errors, plus probing noise
    # along the touch direction
    errors = dict(TRUE_LOCATION, ECCb=3e-5)
    pins = L.nominal_pins(m, KINS)
    model = N.sphere_trigger_model(m, KINS, plan, art, 3.0, pins, errors=errors)
    rng = np.random.default_rng(3)
    sigma = 0.0005
    rows = []
    for e, t in zip(plan, model):
        w = np.asarray(t["world"]) + rng.normal(0, sigma) * np.asarray(e["normal"])
        r = [*w, t["rot"][0], 0.0, t["rot"][1], 0.0, 0.0, 0.0]
        rows.append(" ".join(f"{x:.6f}" for x in r))
    log = tmp_path / "probe-log.txt"
    log.write_text("\n".join(rows) + "\n")
    # each modelled trip lies on the probe move the program commands, between
    # its start (the G0 before it) and its end, at the position's rotary pose
    lines = prog.splitlines()
    xyz = lambda ln: np.array([float(re.search(a + r"(-?[\d.]+)", ln).group(1)) for a in "XYZ"])  # noqa: E731
    g38 = [i for i, ln in enumerate(lines) if ln.startswith("G38.2")]
    assert len(g38) == len(model)
    for i, t in zip(g38, model):
        a, b, w = xyz(lines[i - 1]), xyz(lines[i]), np.asarray(t["world"])
        s = (w - a) @ (b - a) / ((b - a) @ (b - a))
        assert 0 < s < 1 and np.linalg.norm(a + s * (b - a) - w) < 1e-6, (lines[i], t["world"])
    ds_file = tmp_path / "check_ds.json"
    rc, out, err = run(capsys, "import", "probe-log", log, "--plan", plan_file, "--kins", KINS, "--out", ds_file)
    assert rc == 0, err
    assert f"{len(plan)} sphere observations" in out
    # the pins the controller ran with, as a HAL file: here the nominal ones, the same dataset
    hal = tmp_path / "kins.hal"
    hal.write_text(L.hal_text(KINS, pins))
    rc, _, err = run(capsys, "import", "probe-log", log, "--plan", plan_file, "--kins", KINS, "--pins", hal,
                     "--out", tmp_path / "check_ds2.json")
    assert rc == 0, err
    assert json.loads((tmp_path / "check_ds2.json").read_text()) == json.loads(ds_file.read_text())
    check_file = tmp_path / "check.json"
    rc, out, err = run(capsys, "sphere-check", ds_file, "--out", check_file)
    assert rc == 0, err
    got = json.loads(check_file.read_text())["parameters"]
    seen = spindle_names(m, errors)   # EX0C of this A/C table is reported as EX0S, EY0A as EY0S
    for name, p in got.items():
        truth = seen.get(name, 0.0)
        assert abs(p["value"] - truth) < 3 * p["std"], (name, p, truth)
    assert set(spindle_names(m, TRUE_LOCATION)) <= set(got) and "ECCb" in got
    # a log of another plan does not line up
    log.write_text("\n".join(rows[:-1]) + "\n")
    rc, _, err = run(capsys, "import", "probe-log", log, "--plan", plan_file, "--kins", KINS, "--out", ds_file)
    assert rc == 2 and "planned touches" in err
    rc, _, err = run(capsys, "import", "probe-log", log, "--plan", plan_file, "--out", ds_file)
    assert rc == 2 and "--kins" in err


# ---- a designed TANGO plan: facet and sphere touches in one program ------------

TANGO_SPEC = __import__("os").path.join(__import__("os").path.dirname(__file__), "..", "..", "examples", "design",
                                        "hu40t_table_4_2.json")


def test_designed_mixed_plan_program_log_import_and_identify(tmp_path, capsys):
    """`fivecal design` picks visits of the TANGO pool with facets and the
    scale bar's balls; `fivecal export program` (kind auto) writes them as one
    probing program; the log of a run on a machine with location errors
    (fivecal's trigger model of that program plus 0.6 um noise) comes back
    through `fivecal import probe-log --plan` as facet and sphere touches, and
    `fivecal identify` recovers the errors within 3 sigma."""
    from fivecal.procedures import tango
    from test_nc_programs import TANGO_ERRORS, check_touch_program

    kins = "xyzbc-trt"
    errors = {k: v for k, v in TANGO_ERRORS.items() if k != "ECCb"}
    plan_file = tmp_path / "plan.json"
    # visit 16 is the B = C = 0 row with the balls (Table 4-2 row 17)
    rc, out, err = run(capsys, "design", TANGO_SPEC, "-k", "8", "--require", "16", "--estimate", ",".join(errors),
                       "--no-progress", "--out", plan_file)
    assert rc == 0, err
    spec = json.loads(plan_file.read_text())
    plan, art = spec["plan"], spec["artefact"]
    assert {e["type"] for e in plan} == {"facet", "sphere"}
    m = tango.hu40t_machine()
    prog_file = tmp_path / "tango.ngc"
    rc, out, err = run(capsys, "export", "program", plan_file, "--kins", kins, "--clearance", "1",
                       "--overtravel", "1", "--out", prog_file)
    assert rc == 0, err
    assert f"probing program, {len(plan)} plan entries" in out
    prog = prog_file.read_text()
    kinds = check_touch_program(m, kins, plan, art, prog, 3.0, 1.0, 1.0)
    assert kinds["facet"] > 0 and kinds["sphere"] == 10
    pins = L.nominal_pins(m, kins)
    model = N.touch_trigger_model(m, kins, plan, art, 3.0, pins, errors=errors)
    rng = np.random.default_rng(7)
    rows = []
    for t in model:
        w = np.asarray(t["world"]) + rng.normal(0, 0.0006, 3)
        rows.append(" ".join(f"{x:.6f}" for x in (w[0], w[1], w[2], 0.0, t["rot"][0], t["rot"][1], 0, 0, 0)))
    log = tmp_path / "probe-log.txt"
    log.write_text("\n".join(rows) + "\n")
    ds_file = tmp_path / "ds.json"
    rc, out, err = run(capsys, "import", "probe-log", log, "--plan", plan_file, "--kins", kins, "--out", ds_file)
    assert rc == 0, err
    assert f"{kinds['facet']} facet and 10 sphere observations of the {len(plan)} planned" in out
    obs = json.loads(ds_file.read_text())["observations"]
    assert [(o["type"], o["target"]) for o in obs] == [(e["type"], e["target"]) for e in plan]
    res_file = tmp_path / "result.json"
    rc, out, err = run(capsys, "identify", ds_file, "--estimate", ",".join(errors), "--fix", "tip.x,tip.y,tip.z",
                       "--out", res_file)
    assert rc == 0, err
    got = json.loads(res_file.read_text())["parameters"]
    for name, truth in errors.items():
        p = got[name]
        assert abs(p["value"] - truth) < 3 * p["std"], (name, p, truth)


def test_export_program_refuses_a_mix_that_is_not_one_program(tmp_path, capsys):
    from fivecal.procedures import rtest
    m = fivecal.Machine.from_dict(MACHINES[KINS])
    art = {"facets": [{"id": "TOP", "point": [0, 0, 60], "normal": [0, 0, 1]}],
           "spheres": [{"id": "S1", "center": [60.0, 30.0, 40.0], "radius": 12.5}]}
    facet = {"type": "facet", "target": "TOP", "axes": {"A": 0, "C": 0}, "point": [10.0, 0.0, 60.0]}
    sphere = {"type": "sphere", "target": "S1", "axes": {"A": 0, "C": 0}, "normal": [0, 0, 1]}
    ball3d = rtest.plan(m, "K1", table_ball=[60, 20, 30], step=60)[0]
    for entries, named in (([facet, ball3d], "ball3d, facet"), ([facet, sphere, ball3d], "ball3d, facet, sphere")):
        spec = tmp_path / "mix.json"
        spec.write_text(json.dumps({"machine": MACHINES[KINS], "plan": entries, "artefact": art,
                                    "probe": {"tip_radius": 3.0}}))
        rc, _, err = run(capsys, "export", "program", spec, "--kins", KINS)
        assert rc == 2, err
        assert f"plan entries of type {named}" in err and "--kind" in err
    # facet and sphere together are one program (to standard output)
    spec.write_text(json.dumps({"machine": MACHINES[KINS], "plan": [facet, sphere, facet], "artefact": art,
                                "probe": {"tip_radius": 3.0}}))
    rc, out, err = run(capsys, "export", "program", spec, "--kins", KINS)
    assert rc == 0, err
    assert out == N.touch_program(m, KINS, [facet, sphere, facet], art, 3.0, retract=5.0, safe=100.0)
    # --kind sphere still takes sphere touches only
    rc, _, err = run(capsys, "export", "program", spec, "--kins", KINS, "--kind", "sphere")
    assert rc == 2 and "type 'facet'" in err


def test_facet_plan_beside_balls_keeps_out_of_them(tmp_path, capsys):
    """A facet-only plan on an artefact that also carries balls (TANGO's
    octagonal table with its scale bar): the program's moves keep out of the
    balls (the per-touch lift of the facet-only program went up to 4 mm
    through them)."""
    from fivecal.procedures import tango
    from test_nc_programs import check_touch_program
    kins = "xyzbc-trt"
    m, art = tango.hu40t_machine(), tango.octagonal_table()
    plan = [e for e in tango.hu40t_plan(art, m) if e["type"] == "facet"]
    spec = tmp_path / "facets.json"
    spec.write_text(json.dumps({"machine": m.to_dict(), "plan": plan, "artefact": art,
                                "probe": {"tip_radius": 3.0}}))
    rc, out, err = run(capsys, "export", "program", spec, "--kins", kins, "--out", tmp_path / "f.ngc")
    assert rc == 0, err
    kinds = check_touch_program(m, kins, plan, art, (tmp_path / "f.ngc").read_text(), 3.0, 1.0, 1.0)
    assert kinds == {"facet": len(plan), "sphere": 0}


def test_export_program_bounds_its_counts_naming_the_option(tmp_path, machine_file, capsys):
    """--subdivide and a ball bar path's --tolerance set how many points the
    program gets: bounded like the plans' counts and steps (issue #27)."""
    rc, _, err = run(capsys, "plan", "four-step", machine_file, "--out", tmp_path / "p.json")
    assert rc == 0, err
    for opt, value in (("--tolerance", "1e-12"), ("--subdivide", "1000000000")):
        try:
            rc, _, err = run(capsys, "export", "program", tmp_path / "p.json", opt, value)
        except SystemExit as e:
            rc, err = e.code, capsys.readouterr().err
        assert rc == 2 and opt in err and "MemoryError" not in err, err
