"""Readings checked against their plan (issue 28, item 4): a probe log or
R-test readings that do not line up with the plan the program was written
from (another order, lines missing, another plan) are refused naming the
line, from the command line (exit 2) and from Python (ValueError); the
right readings pass and the check recovers the errors."""
import json

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.io import linuxcnc as L
from fivecal.io import nc_programs as N
from fivecal.io import plan_readings as P
from fivecal.procedures.sphere_check import spindle_names

from test_linuxcnc import MACHINES, TRUE_LOCATION

KINS = "xyzac-trt"
ERRORS = dict(TRUE_LOCATION, ECCb=3e-5)


def run(capsys, *argv):
    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def _plan(tmp_path, capsys, name, a="-60,-15,30", c="-120,0,120"):
    mf = tmp_path / "machine.json"
    mf.write_text(json.dumps(MACHINES[KINS]))
    plan_file = tmp_path / f"{name}.json"
    rc, _, err = run(capsys, "plan", "sphere-check", mf, "--sphere-centre", "60,30,40", "--radius", "12.5",
                     "--tip-radius", "3", "--positions", f"A={a}", "--positions", f"C={c}", "--out", plan_file)
    assert rc == 0, err
    return plan_file


def _log_rows(plan_file, seed=3):
    """The log of the plan's program on the machine with ERRORS: fivecal's
    trigger model plus 0.5 um of probing noise along each touch direction."""
    m = fivecal.Machine.from_dict(MACHINES[KINS])
    spec = json.loads(plan_file.read_text())
    plan, art = spec["plan"], spec["artefact"]
    model = N.sphere_trigger_model(m, KINS, plan, art, 3.0, L.nominal_pins(m, KINS), errors=ERRORS)
    rng = np.random.default_rng(seed)
    rows = []
    for e, t in zip(plan, model):
        w = np.asarray(t["world"]) + rng.normal(0, 0.0005) * np.asarray(e["normal"])
        rows.append(" ".join(f"{x:.6f}" for x in (*w, t["rot"][0], 0.0, t["rot"][1], 0.0, 0.0, 0.0)))
    return rows


@pytest.fixture
def setup(tmp_path, capsys):
    plan_file = _plan(tmp_path, capsys, "plan")
    return plan_file, _log_rows(plan_file)


def _import(capsys, tmp_path, plan_file, rows):
    log = tmp_path / "probe-log.txt"
    log.write_text("\n".join(rows) + "\n")
    return run(capsys, "import", "probe-log", log, "--plan", plan_file, "--kins", KINS,
               "--out", tmp_path / "ds.json")


def _refused(capsys, tmp_path, plan_file, rows, line, words):
    rc, _, err = _import(capsys, tmp_path, plan_file, rows)
    assert rc == 2, err
    assert f"probe-log.txt:{line}:" in err and all(w in err for w in words), err
    with pytest.raises(ValueError, match=f"probe-log.txt:{line}:"):
        P.probe_log_dataset(tmp_path / "probe-log.txt", plan_file, KINS)
    return err


def test_the_right_log_passes_and_the_check_recovers_the_errors(tmp_path, capsys, setup):
    plan_file, rows = setup
    rc, out, err = _import(capsys, tmp_path, plan_file, rows)
    assert rc == 0, err
    rc, out, err = run(capsys, "sphere-check", tmp_path / "ds.json", "--out", tmp_path / "check.json")
    assert rc == 0, err
    got = json.loads((tmp_path / "check.json").read_text())["parameters"]
    # under the names every command reports (a rotary offset that is the spindle's: EX0S = -EX0C)
    for name, truth in spindle_names(fivecal.Machine.from_dict(MACHINES[KINS]), ERRORS).items():
        assert abs(got[name]["value"] - truth) < 3 * got[name]["std"], (name, got[name], truth)


def test_a_reversed_log_is_refused_naming_its_first_line(tmp_path, capsys, setup):
    plan_file, rows = setup
    # the case: imported reversed, the check said ok with ECCb -0.1 urad for 30
    err = _refused(capsys, tmp_path, plan_file, rows[::-1], 1, ["reverse"])
    assert f"touch {len(rows)} of the plan, not touch 1" in err


def test_a_log_with_a_missing_line_is_refused_naming_the_line(tmp_path, capsys, setup):
    plan_file, rows = setup
    # touch 6 is the first of the second rotary position: line 6 is then touch 7
    _refused(capsys, tmp_path, plan_file, rows[:5] + rows[6:], 6, ["not touch 6", "missing"])
    # the last line missing: the log ends one line early
    _refused(capsys, tmp_path, plan_file, rows[:-1], len(rows) - 1, ["ends here", f"touch {len(rows)}"])
    # one line too many (two runs appended)
    _refused(capsys, tmp_path, plan_file, rows + rows[:1], len(rows) + 1, ["more probed positions"])


def test_two_touches_of_one_position_swapped_are_refused(tmp_path, capsys, setup):
    """Same rotary position, another touch direction: only the probe line tells them apart."""
    plan_file, rows = setup
    swapped = [rows[1], rows[0]] + rows[2:]
    _refused(capsys, tmp_path, plan_file, swapped, 1, ["touch 2 of the plan, not touch 1", "order"])


def test_a_log_of_another_plan_is_refused_naming_the_line(tmp_path, capsys, setup):
    plan_file, rows = setup
    other = _plan(tmp_path, capsys, "other", a="-45,0,45", c="-90,30,150")
    foreign = _log_rows(other)[:len(rows)]  # as many lines: the count alone cannot tell
    assert len(foreign) == len(rows)
    _refused(capsys, tmp_path, plan_file, foreign, 1, ["another plan"])


def test_the_python_reader_checks_rotary_positions_without_the_probe_lines(tmp_path, capsys, setup):
    """read_probe_log without touches still checks each line's rotary command."""
    plan_file, rows = setup
    m, plan, _, _ = P.read_plan(plan_file)
    pins = L.nominal_pins(m, KINS)
    assert len(L.read_probe_log("\n".join(rows) + "\n", m, KINS, plan, pins)) == len(rows)
    with pytest.raises(ValueError, match=r"probe log:1: .*reverse"):
        L.read_probe_log("\n".join(rows[::-1]) + "\n", m, KINS, plan, pins)


def test_rtest_readings_reversed_short_or_partial_are_refused_naming_the_line(tmp_path, capsys):
    mf = tmp_path / "machine.json"
    mf.write_text(json.dumps(MACHINES[KINS]))
    plan_file = tmp_path / "p.json"
    assert run(capsys, "plan", "rtest", mf, "--tests", "K1", "--table-ball", "60,20,30", "--step", "90",
               "--out", plan_file)[0] == 0
    plan = json.loads(plan_file.read_text())["plan"]
    rows = [f"{e['axes']['A']:g},{e['axes']['C']:g},1,2,3" for e in plan]
    f = tmp_path / "r.csv"

    def imp(lines):
        f.write_text("A,C,dx_um,dy_um,dz_um\n" + "\n".join(lines) + "\n")
        return run(capsys, "import", "rtest", f, "--plan", plan_file, "--out", tmp_path / "ds.json")

    assert imp(rows)[0] == 0
    rc, _, err = imp(rows[::-1])  # the logger's axis columns tell the order
    assert rc == 2 and "r.csv:2:" in err and "not the plan's command" in err, err
    rc, _, err = imp(rows[:1] + rows[2:])
    assert rc == 2 and "r.csv:3:" in err and "not the plan's command" in err, err
    rc, _, err = imp(rows[:-1])
    assert rc == 2 and f"r.csv:{len(rows)}: the readings end here" in err, err
    with pytest.raises(ValueError, match=f"r.csv:{len(rows)}: the readings end here"):
        P.rtest_readings(f, plan_file)


# ---- ball bar traces of the four-step test -------------------------------------

def _four_step_traces(tmp_path):
    from fivecal.procedures import dbb
    m = fivecal.Machine.load(str(__import__("pathlib").Path(__file__).parents[2] / "examples/machines/c600u.json"))
    plan = dbb.four_step_plan(m, step=10.0)
    ds = fivecal.simulate(m, plan, errors={"EX0C": 0.01, "EY0A": -0.02}, sigma={"dbb": 0.0002}, seed=2)
    files = {}
    for sid, axis in (("A1", "A"), ("A2", "A"), ("C1", "C"), ("C2", "C")):
        obs = [o for o in ds.observations if o["setup"] == sid]
        rows = [f"{o['axes'][axis]:.6f},{o['reading']:.7f}" for o in obs]
        files[sid] = rows
    return m, plan, files


def test_four_step_traces_are_checked_against_the_plan(tmp_path, capsys):
    from fivecal.procedures import dbb
    m, plan, rows = _four_step_traces(tmp_path)

    def traces(**override):
        out = {}
        for sid, r in {**rows, **override}.items():
            p = tmp_path / f"{sid}.csv"
            p.write_text("angle_deg,reading_mm\n" + "\n".join(r) + "\n")
            out[sid] = dbb.read_trace_csv(p)
        return out

    assert len(dbb.four_step_dataset(m, traces(), plan).observations) == len(plan)
    with pytest.raises(ValueError, match=r"trace A1 \(A1.csv\): row 1: the trace runs -A .* plan's A1 runs \+A"):
        dbb.four_step_dataset(m, traces(A1=rows["A1"][::-1]), plan)
    swapped = rows["C1"][:4] + [rows["C1"][5], rows["C1"][4]] + rows["C1"][6:]
    with pytest.raises(ValueError, match=r"trace C1 \(C1.csv\): row 6: angle 40 deg goes back from 50 deg"):
        dbb.four_step_dataset(m, traces(C1=swapped), plan)
    with pytest.raises(ValueError, match=r"trace A2 \(A2.csv\): row \d+: angle .* outside the plan's A range"):
        dbb.four_step_dataset(m, traces(A2=rows["C2"]), plan)      # the C file given for A2
    # from the command line: exit 2 naming the trace and the row
    mf = tmp_path / "m.json"
    mf.write_text(json.dumps(m.to_dict()))
    traces(A1=rows["A1"][::-1])
    csv = ",".join(f"{s}={tmp_path / (s + '.csv')}" for s in rows)
    rc, _, err = run(capsys, "dbb", "jiang", "--machine", mf, "--csv", csv, "--step", "10")
    assert rc == 2 and "trace A1" in err and "row 1" in err and "runs -A" in err, err
