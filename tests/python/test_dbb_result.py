"""Every ball-bar procedure (``fivecal dbb four-step | jiang | wang |
circular``) writes the one result document, judged by identify's verdict,
and that document goes through every consumer: ``export linuxcnc``,
``compensate`` and ``history add | compare | trend`` (the command line, a
real SQLite store). Truth tests run the commands on simulated machines with
known errors and reading noise; run directions come from the data.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import fivecal
from fivecal import schema
from fivecal.procedures import dbb
from fivecal.procedures.sphere_check import spindle_names

HERE = os.path.dirname(os.path.abspath(__file__))
MACHINES = os.path.join(HERE, "..", "..", "examples", "machines")
C600U = os.path.join(MACHINES, "c600u.json")
VMC = os.path.join(MACHINES, "vmc0656.json")

#: location errors of a four-step test (C on A), tens of µm and µrad
FOUR_STEP_TRUTH = {"EY0A": 0.0342, "EZ0A": -0.0353, "EB0A": 45e-6, "EC0A": -30e-6,
                   "EX0C": 0.0013, "EY0C": -0.0525, "EA0C": -108e-6, "EB0C": 25e-6}
WANG_TRUTH = {"EX0C": 0.007, "EY0C": -0.005, "EZ0C": 0.006, "EA0C": 20e-6}
#: a planar test sees each plane axis' backlash on its own
CIRCULAR_TRUTH = {"EXXb": 0.002, "EYYb": -0.0015, "EXX1": 2e-5}


def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fivecal", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd)


def _ok(r):
    assert r.returncode == 0, (r.args, r.returncode, r.stdout[-2000:], r.stderr)
    return r


def _errors_file(tmp_path, errors, name="errors.json"):
    p = tmp_path / name
    p.write_text(json.dumps(errors))
    return p


def _command(procedure, tmp_path, out, seed=1, errors=None):
    """The command line of one ball-bar procedure on a simulated machine."""
    if procedure in ("four-step", "jiang"):
        e = _errors_file(tmp_path, errors or FOUR_STEP_TRUTH)
        return ["dbb", procedure, "--machine", C600U, "--simulate", e, "--sigma", "0.0003", "--seed", seed,
                "--step", "3", "--out", out]
    if procedure == "wang":
        e = _errors_file(tmp_path, errors or WANG_TRUTH)
        return ["dbb", "wang", "--machine", VMC, "--simulate", e, "--sigma", "0.0003", "--seed", seed, "--out", out]
    e = ",".join(f"{k}={v}" for k, v in (errors or CIRCULAR_TRUTH).items())
    return ["dbb", "circular", "--machine", C600U, "--simulate", e, "--radius", "100", "--sigma", "0.0003",
            "--seed", seed, "--step", "2", "--out", out]


PROCEDURE_NAME = {"four-step": "four-step", "jiang": "jiang-cripps", "wang": "wang", "circular": "circular"}
MACHINE_OF = {"four-step": C600U, "jiang": C600U, "wang": VMC, "circular": C600U}


@pytest.mark.parametrize("procedure", ["four-step", "jiang", "wang", "circular"])
def test_ball_bar_result_goes_through_every_consumer(procedure, tmp_path):
    docs = []
    for seed in (1, 2):
        out = tmp_path / f"r{seed}.json"
        _ok(_run(*_command(procedure, tmp_path, out, seed)))
        doc = json.loads(out.read_text())
        schema.validate(doc, "result", str(out))
        assert doc["procedure"]["name"] == PROCEDURE_NAME[procedure]
        assert doc["verdict"] == "ok" and doc["converged"]
        # machine errors under their ISO 230-1 names, the procedure's own values beside them
        assert any(n in doc["parameters"] for n in ("EX0S", "EY0C", "EXXb"))
        assert doc["procedure"]["values"]
        docs.append(out)
    machine = MACHINE_OF[procedure]
    _ok(_run("export", "linuxcnc", docs[0], "--machine", machine, "--kins", "xyzac-trt",
             "--out", tmp_path / "hal"))
    assert (tmp_path / "hal" / "fivecal-kins.hal").exists()
    _ok(_run("compensate", docs[0], machine, "--table", tmp_path / "errors.csv"))
    assert (tmp_path / "errors.csv").read_text().strip()
    store = tmp_path / "store.sqlite"
    for d in docs:
        _ok(_run("history", "add", d, "--store", store, "--machine-id", "M1", "--procedure", procedure))
    r = _ok(_run("history", "compare", "1", "2", "--store", store))
    assert "changed beyond" in r.stdout
    _ok(_run("history", "trend", "--store", store, "--machine-id", "M1"))


def _z(doc, truth, machine):
    """z of each true error under the names every command reports (an offset
    that is the spindle's, EX0C on these A/C machines, as EX0S = -EX0C)."""
    p = doc["parameters"]
    seen = spindle_names(fivecal.Machine.load(machine), truth)
    return {n: (p[n]["value"] - v) / p[n]["std"] for n, v in seen.items()}


@pytest.mark.parametrize("procedure,truth", [("four-step", FOUR_STEP_TRUTH), ("jiang", FOUR_STEP_TRUTH),
                                             ("wang", WANG_TRUTH), ("circular", CIRCULAR_TRUTH)])
def test_ball_bar_command_recovers_the_truth(procedure, truth, tmp_path):
    out = tmp_path / "r.json"
    _ok(_run(*_command(procedure, tmp_path, out, seed=7)))
    doc = json.loads(out.read_text())
    if procedure == "circular":
        # EXX1 alone is not determined by a circle (the mean scale goes into the
        # bar length): the result says so, or gives it the sigma the bar length's
        # placement prior allows (2 um on 100 mm: 2e-5); the backlashes are measured
        assert "EXX1" in doc["undetermined"] or doc["parameters"]["EXX1"]["std"] >= 1.5e-5, doc["parameters"]["EXX1"]
        truth = {n: v for n, v in truth.items() if n != "EXX1"}
        diag = doc["procedure"]["values"]["diagnosis"]
        # scale mismatch X-Y: EXX1 - EYY1 (mm/mm), within 3 sigma of the diagnosis
        sm = diag["scale_mismatch"]
        assert abs(sm["value"] - CIRCULAR_TRUTH["EXX1"]) < 3 * sm["std"], sm
    for n, z in _z(doc, truth, MACHINE_OF[procedure]).items():
        assert abs(z) < 3, (procedure, n, z)
        assert n not in doc["undetermined"]
    if procedure == "jiang":
        # the method's own values, in procedure.values, recover the truth as well
        mv = doc["procedure"]["values"]["method_values"]
        for n, v in truth.items():
            assert abs(mv[n]["value"] - v) < 3 * mv[n]["std"], (n, mv[n], v)
    # iterations: the number the solver made from the nominal start (never 0 after moving tens of µm)
    assert doc["iterations"] >= 1


def test_four_step_sigma_covers_the_scatter_over_repeated_simulations(c600u):
    plan = dbb.four_step_plan(c600u, step=3.0)
    z = []
    for seed in range(60):
        ds = fivecal.simulate(c600u, plan, errors=FOUR_STEP_TRUTH, sigma={"dbb": 0.0003}, seed=100 + seed)
        res = dbb.jiang_cripps(ds)
        eng = res.engine
        assert eng.assessment().usable
        z += [(eng.values[n] - v) / eng.std[n] for n, v in FOUR_STEP_TRUTH.items()]
    z = np.abs(np.array(z))
    # 480 z-scores: 68 % within 1 sigma, 95 % within 2 (binomial spread about +-4 %, +-2 %)
    assert 0.58 < np.mean(z < 1) < 0.78, np.mean(z < 1)
    assert np.mean(z < 2) > 0.91, np.mean(z < 2)
    assert z.max() < 4.5


def test_ac_trunnion_plan_simulate_four_step_export_and_history(tmp_path):
    """The VMC0656-like A/C trunnion: plan -> simulate -> four-step -> export linuxcnc, history add."""
    plan = tmp_path / "plan.json"
    _ok(_run("plan", "four-step", VMC, "--out", plan))
    spec = json.loads(plan.read_text())
    truth = {"EY0A": 0.012, "EZ0A": -0.020, "EX0C": 0.008, "EY0C": -0.015, "EA0C": 40e-6, "EB0C": -30e-6}
    spec.update({"errors": truth, "sigma": 0.0003, "seed": 5})
    plan.write_text(json.dumps(spec))
    ds = tmp_path / "ds.json"
    _ok(_run("simulate", plan, "--out", ds))
    out = tmp_path / "result.json"
    r = _ok(_run("dbb", "four-step", ds, "--out", out))
    assert "OK (usable)" in r.stdout or "Usable" in r.stdout, r.stdout[-1500:]
    doc = json.loads(out.read_text())
    schema.validate(doc, "result", "four-step result")
    for n, z in _z(doc, truth, VMC).items():
        assert abs(z) < 3, (n, z)
    _ok(_run("export", "linuxcnc", out, "--machine", VMC, "--kins", "xyzac-trt", "--out", tmp_path / "hal"))
    _ok(_run("history", "add", out, "--store", tmp_path / "h.sqlite", "--machine-id", "VMC0656",
             "--procedure", "four-step", "--dataset", ds))


# ---- one verdict -----------------------------------------------------------

def test_wang_speaks_identify_verdict_and_exits_1_when_not_usable(tmp_path):
    """An error the path sees but the fit leaves out (EB0C, 200 µrad): the
    residuals are too large for the noise. identify's verdict words, exit 1,
    the document still written and marked."""
    out = tmp_path / "w.json"
    r = _run(*_command("wang", tmp_path, out, errors=dict(WANG_TRUTH, EB0C=200e-6)))
    assert r.returncode == 1, (r.stdout[-1500:], r.stderr)
    assert "NOT USABLE" in r.stdout and "Usable:" not in r.stdout
    assert "not usable" in r.stderr
    doc = json.loads(out.read_text())
    assert doc["verdict"] != "ok"
    # and the consumers refuse it
    r = _run("export", "linuxcnc", out, "--machine", VMC, "--kins", "xyzac-trt", "--out", tmp_path / "hal")
    assert r.returncode == 2 and "refusing to use" in r.stderr


def test_circular_grades_its_tolerances_fail_exits_1(tmp_path):
    base = _command("circular", tmp_path, tmp_path / "c.json")
    r = _run(*base, "--tolerance", "G=3um")
    assert r.returncode == 1, (r.stdout[-800:], r.stderr)
    assert "FAIL against the tolerances" in r.stderr
    doc = json.loads((tmp_path / "c.json").read_text())
    assert doc["procedure"]["values"]["grade"]["grade"] == "FAIL"
    r = _ok(_run(*base, "--tolerance", "G=50um,H=20um"))
    assert "grade against the tolerances: PASS" in r.stdout
    # a bare 15 is 15 mm: refused as µm written without its unit
    r = _run(*base, "--tolerance", "G=15")
    assert r.returncode == 2 and "--tolerance G" in r.stderr
    r = _run(*base, "--tolerance", "X=15um")
    assert r.returncode == 2 and "--tolerance X" in r.stderr


def test_circular_without_machine_writes_iso_values_only(tmp_path):
    angles = np.arange(0.0, 360.0, 2.0)
    p = tmp_path / "run1.csv"
    p.write_text("angle_deg,reading_mm\n" + "".join(f"{a},{0.001 * np.cos(np.radians(2 * a)):.6f}\n"
                                                    for a in angles))
    out = tmp_path / "c.json"
    _ok(_run("dbb", "circular", p, "--radius", "100", "--out", out))
    doc = json.loads(out.read_text())
    schema.validate(doc, "result", "circular result")
    assert doc["parameters"] == {} and doc["procedure"]["values"]["runs"][0]["direction"] == "CCW"
    # no machine errors were fitted: no consumer takes that for a measured zero
    assert doc["verdict"] != "ok"
    r = _run("export", "linuxcnc", out, "--machine", C600U, "--kins", "xyzac-trt", "--out", tmp_path / "hal")
    assert r.returncode == 2 and "refusing to use" in r.stderr


def test_four_step_no_engine_refuses_out(tmp_path):
    r = _run("dbb", "jiang", "--machine", C600U, "--simulate", "paper", "--step", "3", "--no-engine",
             "--out", tmp_path / "r.json")
    assert r.returncode == 2 and "--out" in r.stderr and not (tmp_path / "r.json").exists()


# ---- run directions from the data -------------------------------------------

def _write_run(path, angles, readings):
    path.write_text("angle_deg,reading_mm\n" + "".join(f"{a:.4f},{r:.6f}\n" for a, r in zip(angles, readings)))


def test_run_direction_comes_from_the_angles_not_the_file_order():
    # a CW turn printed modulo 360: its last angle is larger than its first
    cw = np.mod(-np.arange(0.0, 360.0, 1.0), 360.0)
    assert cw[1] > cw[0] and dbb.run_direction(cw) == -1
    assert dbb.Trace(cw, np.zeros_like(cw)).direction == -1
    assert dbb.run_direction(np.arange(0.0, 360.0, 1.0)) == 1
    assert dbb.run_direction(np.arange(90.0, -270.0, -1.0)) == -1
    assert dbb.claimed_direction("xy_ccw.csv") == 1 and dbb.claimed_direction("xy-cw.csv") == -1
    assert dbb.claimed_direction("P+") == 1 and dbb.claimed_direction("P-") == -1
    assert dbb.claimed_direction("run1.csv") == 0


def test_circular_labels_runs_by_their_data_and_refuses_a_contradicting_name(c600u, tmp_path):
    plan = dbb.planar_plan(c600u, "XY", 100.0, step=2.0)
    ds = fivecal.simulate(c600u, plan, errors={"EXXb": 0.002}, sigma={"dbb": 0.0003}, seed=3)
    cw, ccw = dbb.trace_from_dataset(ds, "P-"), dbb.trace_from_dataset(ds, "P+")
    # the CW run written modulo 360 (0, 358, 356 ... rises at the first step), the CCW one as is
    a = tmp_path / "first.csv"
    b = tmp_path / "second.csv"
    _write_run(a, np.mod(cw.angles, 360.0), cw.readings)
    _write_run(b, ccw.angles, ccw.readings)
    r = _ok(_run("dbb", "circular", b, a, "--radius", "100", "--machine", C600U, "--out", tmp_path / "c.json"))
    assert "CW  circular deviation" in r.stdout and "CCW circular deviation" in r.stdout
    doc = json.loads((tmp_path / "c.json").read_text())
    runs = {x["label"]: x["direction"] for x in doc["procedure"]["values"]["runs"]}
    assert runs == {"CCW (second.csv)": "CCW", "CW (first.csv)": "CW"}
    # the data-placed CSV runs give the machine errors too: X backlash within 3 sigma
    p = doc["parameters"]["EXXb"]
    assert abs(p["value"] - 0.002) < 3 * p["std"]
    # a file named ccw whose angles turn clockwise is refused, naming the file
    bad = tmp_path / "xy_ccw.csv"
    _write_run(bad, cw.angles, cw.readings)
    r = _run("dbb", "circular", bad, "--radius", "100")
    assert r.returncode == 2 and "xy_ccw.csv" in r.stderr and "clockwise" in r.stderr


def test_dataset_setup_named_against_its_data_is_refused(c600u, tmp_path):
    plan = dbb.planar_plan(c600u, "XY", 100.0, step=2.0)
    for e in plan:  # the P- run relabelled P+ and the other way round
        e["setup"] = {"P+": "P-", "P-": "P+"}[e["setup"]]
    ds = fivecal.simulate(c600u, plan, errors={}, sigma={"dbb": 0.0003}, seed=3)
    path = tmp_path / "ds.json"
    fivecal.save_dataset(ds, str(path))
    r = _run("dbb", "circular", "--dataset", path, "--radius", "100")
    assert r.returncode == 2 and "ds.json" in r.stderr and "setup P-" in r.stderr


def test_four_step_csv_named_against_its_data_is_refused(c600u, tmp_path):
    plan = dbb.four_step_plan(c600u, step=3.0)
    ds = fivecal.simulate(c600u, plan, errors=FOUR_STEP_TRUTH, sigma={"dbb": 0.0003}, seed=2)
    names = {}
    for sid in ("A1", "A2", "C1", "C2"):
        idx = [i for i, o in enumerate(ds.observations) if o["setup"] == sid]
        axis = sid[0]
        ang = np.array([ds.observations[i]["axes"][axis] for i in idx])
        rd = np.array([ds.observations[i]["reading"] for i in idx])
        # C1 is recorded as a CCW turn; its file says cw
        name = f"{sid.lower()}_cw.csv" if sid == "C1" else f"{sid.lower()}.csv"
        _write_run(tmp_path / name, ang, rd)
        names[sid] = name
    csv = ",".join(f"{s}={tmp_path / n}" for s, n in names.items())
    r = _run("dbb", "four-step", "--machine", C600U, "--csv", csv, "--step", "3")
    assert dbb.run_direction(np.arange(0, 360, 3.0)) == 1
    assert r.returncode == 2 and "c1_cw.csv" in r.stderr, (r.stdout[-500:], r.stderr)
