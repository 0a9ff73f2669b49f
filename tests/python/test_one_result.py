"""One result (issue 28, item 1): every procedure writes the same result
document (the result schema, its own values in the ``procedure`` section),
every consumer takes it (``export linuxcnc|kinematics``, ``compensate``,
``history add|compare|trend`` on a real SQLite store) and machine errors
carry the same ISO 230-1 names whichever command fitted them.

Each procedure is a runner registered with :func:`procedure`: it simulates
a machine with known errors and noise, runs the procedure's command with
``--out`` and returns a :class:`Run`. The ball-bar procedures (four-step,
Wang, circular, Jiang-Cripps) register theirs the same way, and every test
here is parametrised over the registry.

Units: mm, rad (axes in degrees)."""
from __future__ import annotations

import json
import os
import sqlite3
import time
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Optional

import numpy as np
import pytest

import fivecal
from fivecal import schema
from fivecal.cli import main
from fivecal.identification import PROCEDURES
from fivecal.procedures import dbb, machining, rtest, sphere_check, tango
from fivecal.procedures.sphere_check import spindle_equivalent, spindle_names

from test_machining_kind import DATUM as MACHINED_DATUM
from test_machining_kind import faces_plan

HERE = os.path.dirname(__file__)
MACHINES = os.path.join(HERE, "..", "..", "examples", "machines")
VMC = os.path.join(MACHINES, "vmc0656.json")      # the A/C trunnion example (VMC0656-like)
HU40T = os.path.join(MACHINES, "hu40t.json")

#: location errors of both rotary axes of the A/C trunnion, of the size the papers report
AC_TRUTH = {"EX0C": 0.010, "EY0C": -0.008, "EA0C": 2e-5, "EB0C": -1.5e-5,
            "EY0A": 0.012, "EZ0A": -0.006, "EB0A": 1e-5, "EC0A": -1.2e-5}
BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
TIP = 3.0
A_LIMITS = (-90.0, 30.0)       # the trunnion's tilt range
TABLE_BALL = [150.0, 0.0, 100.0]


def seen(machine, truth: Dict[str, float]) -> Dict[str, float]:
    """The truth under the names every command reports."""
    return spindle_names(machine, truth)


@dataclass
class Run:
    """One run of a procedure's command: its exit status, the result document
    it wrote, the machine and LinuxCNC kinematics that fit it, and the truth
    (under the reported names) its machine errors must recover."""
    rc: int
    result: str
    machine: str
    kins: str
    truth: Dict[str, float]
    seconds: float = 0.0
    doc: dict = field(default_factory=dict)


#: procedure name -> runner(folder, seed) -> Run
RUNNERS: Dict[str, Callable[[str, int], Run]] = {}


def procedure(name: str):
    """Register the runner of procedure ``name`` (one of the result schema's names)."""
    assert name in PROCEDURES, name

    def deco(f):
        RUNNERS[name] = f
        return f
    return deco


def _cli(*args) -> int:
    return main([str(a) for a in args])


def _timed(f, *args):
    t = time.time()
    rc = f(*args)
    return rc, time.time() - t


def _save(ds, path) -> str:
    fivecal.save_dataset(ds, str(path))
    return str(path)


@procedure("sphere-check")
def _sphere_check(d: str, seed: int) -> Run:
    m = fivecal.Machine.load(VMC)
    plan = sphere_check.plan(m, BALL, tip_radius=TIP, n=4, limits={"A": A_LIMITS})
    ds = fivecal.simulate(m, plan, errors=AC_TRUTH, artefact={"spheres": [BALL]}, tip_radius=TIP,
                          sigma=0.001, seed=seed)
    out = os.path.join(d, "sphere_check.json")
    rc, s = _timed(_cli, "sphere-check", _save(ds, os.path.join(d, "touches.json")), "--out", out)
    return Run(rc, out, VMC, "xyzac-trt", seen(m, AC_TRUTH), s)


@procedure("rtest")
def _rtest(d: str, seed: int) -> Run:
    m = fivecal.Machine.load(VMC)
    plan = [e for t in rtest.TESTS for e in rtest.plan(m, t, table_ball=TABLE_BALL, tilt_range=A_LIMITS)]
    ds = fivecal.simulate(m, plan, errors=AC_TRUTH, sigma={"ball3d": 0.0005}, seed=seed)
    out = os.path.join(d, "rtest.json")
    rc, s = _timed(_cli, "rtest", _save(ds, os.path.join(d, "rtest_data.json")), "--out", out)
    return Run(rc, out, VMC, "xyzac-trt", seen(m, AC_TRUTH), s)


@procedure("identify")
def _identify(d: str, seed: int) -> Run:
    # the R-test data fitted by identify's own location selection: the same
    # names as `fivecal rtest` gives (item 4)
    m = fivecal.Machine.load(VMC)
    plan = [e for t in rtest.TESTS for e in rtest.plan(m, t, table_ball=TABLE_BALL, tilt_range=A_LIMITS)]
    ds = fivecal.simulate(m, plan, errors=AC_TRUTH, sigma={"ball3d": 0.0005}, seed=seed)
    out = os.path.join(d, "identify.json")
    rc, s = _timed(_cli, "identify", _save(ds, os.path.join(d, "data.json")), "--estimate", "location",
                   "--out", out)
    return Run(rc, out, VMC, "xyzac-trt", seen(m, AC_TRUTH), s)


@procedure("sphere-test")
def _sphere_test(d: str, seed: int) -> Run:
    # the machine as a CMM with the model of a sphere check of the same touches
    chk = _sphere_check(d, seed)
    assert chk.rc == 0
    out = os.path.join(d, "sphere_test.json")
    rc, s = _timed(_cli, "sphere", os.path.join(d, "touches.json"), "--values", chk.result, "--out", out)
    return Run(rc, out, VMC, "xyzac-trt", chk.truth, s)


@procedure("machining")
def _machining(d: str, seed: int) -> Run:
    # faces of a test part cut at 12 table poses, measured on a CMM (the
    # `machined` kind), fitted by `fivecal identify`: its result names the
    # procedure machining
    m = fivecal.Machine.load(VMC)
    ds = fivecal.simulate(m, faces_plan(m), errors=AC_TRUTH, setup=MACHINED_DATUM, sigma={"machined": 0.003},
                          seed=seed)
    names = list(seen(m, AC_TRUTH))
    out = os.path.join(d, "machining.json")
    rc, s = _timed(_cli, "identify", _save(ds, os.path.join(d, "faces.json")), "--estimate", ",".join(names),
                   "--out", out)
    return Run(rc, out, VMC, "xyzac-trt", seen(m, AC_TRUTH), s)


@procedure("tango")
def _tango(d: str, seed: int) -> Run:
    # Rahman's TANGO on the HU40T-like B/C machine: facets of the table and a scale bar
    m = fivecal.Machine.load(HU40T)
    truth = tango.thesis_s3_errors()
    ds = tango.hu40t_dataset(seed=seed)
    out = os.path.join(d, "tango.json")
    rc, s = _timed(_cli, "identify", _save(ds, os.path.join(d, "tango_data.json")), "--estimate", "S3",
                   "--out", out)
    names = set(m.parameter_names())
    return Run(rc, out, HU40T, "xyzbc-trt", {n: v for n, v in truth.items() if n in names}, s)


# ---- the ball-bar procedures (`fivecal dbb ...`) on the same A/C trunnion ----
#: the Wang path's four errors (C relative to A), of the paper's size
WANG_TRUTH = {"EX0C": 0.007, "EY0C": -0.005, "EZ0C": 0.006, "EA0C": 2e-5}
#: what a planar circle determines on its own: each plane axis' backlash
CIRCULAR_TRUTH = {"EXXb": 0.002, "EYYb": -0.0015}


def _ball_bar(d: str, seed: int, name: str, plan, truth: Dict[str, float], *args) -> Run:
    m = fivecal.Machine.load(VMC)
    ds = fivecal.simulate(m, plan, errors=truth, sigma={"dbb": 0.0003}, seed=seed)
    data = _save(ds, os.path.join(d, f"{name}_data.json"))
    out = os.path.join(d, f"{name}.json")
    rc, s = _timed(_cli, "dbb", *args, data, "--out", out)
    return Run(rc, out, VMC, "xyzac-trt", seen(m, truth), s)


@procedure("four-step")
def _four_step(d: str, seed: int) -> Run:
    m = fivecal.Machine.load(VMC)
    return _ball_bar(d, seed, "four_step", dbb.four_step_plan(m, step=3.0), AC_TRUTH, "four-step")


@procedure("jiang-cripps")
def _jiang(d: str, seed: int) -> Run:
    m = fivecal.Machine.load(VMC)
    return _ball_bar(d, seed, "jiang", dbb.four_step_plan(m, step=3.0), AC_TRUTH, "jiang")


@procedure("wang")
def _wang(d: str, seed: int) -> Run:
    m = fivecal.Machine.load(VMC)
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in dbb.wang_plan(m)]
    return _ball_bar(d, seed, "wang", plan, WANG_TRUTH, "wang")


@procedure("circular")
def _circular(d: str, seed: int) -> Run:
    m = fivecal.Machine.load(VMC)
    r = _ball_bar(d, seed, "circular", dbb.planar_plan(m, "XY", 100.0, step=3.0), CIRCULAR_TRUTH,
                  "circular", "--radius", "100", "--dataset")
    return r


_CACHE: Dict[tuple, Run] = {}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """run(name, seed) -> Run, each command run once per module."""
    def get(name: str, seed: int = 1) -> Run:
        key = (name, seed)
        if key not in _CACHE:
            d = str(tmp_path_factory.mktemp(f"{name}-{seed}"))
            r = RUNNERS[name](d, seed)
            with open(r.result) as f:
                r.doc = json.load(f)
            _CACHE[key] = r
        return _CACHE[key]
    return get


NAMES = sorted(RUNNERS)


# ---------------------------------------------------------------------------
# the document
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_result_validates_and_names_its_procedure(run, name):
    r = run(name)
    assert r.rc == 0, (name, r.rc)
    schema.validate(r.doc, "result", r.result)
    assert r.doc["procedure"]["name"] == name
    m = fivecal.Machine.load(r.machine)
    machine_names = set(m.parameter_names())
    errors = [n for n in r.doc["parameters"] if n in machine_names]
    assert errors, f"{name}: no machine error in the result"
    # the names every command gives: a rotary offset that is the spindle's is named as the spindle's
    assert all(spindle_equivalent(m, n) == n for n in errors), (name, errors)


def test_procedure_values_per_procedure(run):
    """Each procedure's own values sit in its section, not at the top level."""
    sc = run("sphere-check").doc
    v = sc["procedure"]["values"]
    assert v["dispersion_before"] > 0.010 and v["dispersion_after"] < 0.002
    assert set(v["pivots"]) == {"A", "C"} and set(v["reversal"]) == {"A", "C"}
    assert "dispersion_before" not in sc
    rt = run("rtest").doc["procedure"]["values"]
    assert set(rt["tests"]) == set(rtest.TESTS)
    assert all(set(t["range"]) == {"x", "y", "z"} and t["samples"] > 0 for t in rt["tests"].values())
    st = run("sphere-test").doc["procedure"]["values"]
    assert set(st["models"]) == {"nominal model", "identified model"}
    assert st["models"]["identified model"]["out_of_sphericity"] < st["models"]["nominal model"]["out_of_sphericity"]
    mc = run("machining").doc["procedure"]["values"]
    assert len(mc["features"]) == len(run("machining").doc["residuals"])
    tg = run("tango").doc["procedure"]["values"]
    assert tg["facets"] == 26 and tg["scale_bars"] == 1


def test_rtest_and_identify_give_the_same_names(run):
    """Item 4: the same R-test data gave EX0C/EY0A through `fivecal rtest` and
    EX0S/EY0S through `identify --estimate location`. On the A/C trunnion the
    C line's X offset (along A) and A's Y offset are constant tool-part
    offsets: both commands now name them EX0S, EY0S."""
    rt, ident = run("rtest").doc["parameters"], run("identify").doc["parameters"]
    m = fivecal.Machine.load(VMC)
    rt_names = {n for n in rt if n in set(m.parameter_names())}
    assert {"EX0S", "EY0S"} <= rt_names and not {"EX0C", "EY0A"} & rt_names
    assert rt_names <= set(ident)
    for n in rt_names:
        a, b = rt[n], ident[n]
        assert abs(a["value"] - b["value"]) < 3 * max(a["std"], b["std"]), (n, a, b)


# ---------------------------------------------------------------------------
# every consumer
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_result_goes_through_every_consumer(run, name, tmp_path, capsys):
    r = run(name)
    assert r.rc == 0
    assert _cli("export", "linuxcnc", r.result, "--machine", r.machine, "--kins", r.kins,
                "--out", tmp_path / "lcnc") == 0
    assert os.path.exists(tmp_path / "lcnc" / "fivecal-kins.hal")
    assert _cli("export", "kinematics", r.result, "--machine", r.machine, "--model", "table-table",
                "--out", tmp_path / "kin.json") == 0
    assert _cli("compensate", r.result, r.machine, "--table", tmp_path / "table.csv") == 0
    prog = tmp_path / "p.ngc"
    prog.write_text("G90 G21\nG0 X10 Y10 Z50 A0 C0\nG1 X20 Y-5 Z40 A-10 C30 F500\nM2\n" if r.kins == "xyzac-trt"
                    else "G90 G21\nG0 X10 Y10 Z50 B0 C0\nG1 X20 Y-5 Z40 B-10 C30 F500\nM2\n")
    assert _cli("compensate", r.result, r.machine, prog, "--out", tmp_path / "c.ngc") == 0
    # history on a real SQLite store: two calibrations of this procedure
    other = run(name, 2)
    store = tmp_path / "shop.fcdb"
    for i, res in enumerate((r, other)):
        assert _cli("history", "add", "--store", store, "--machine-id", "M1", "--machine", r.machine,
                    "--time", f"2026-11-0{i + 1}T08:00:00Z", res.result) == 0
    with sqlite3.connect(store) as db:
        labels = [row[0] for row in db.execute("SELECT procedure FROM calibrations")]
    assert labels == [name, name]        # the document's procedure, without --procedure
    capsys.readouterr()
    assert _cli("history", "compare", "--store", store, "1", "2") == 0
    assert _cli("history", "compare", r.result, other.result) == 0
    assert _cli("history", "trend", "--store", store, "--machine-id", "M1", "--procedure", name) == 0
    out = capsys.readouterr().out
    assert "CUSUM" in out


def test_a_foreign_procedure_section_is_refused_naming_the_field(run, tmp_path, capsys):
    d = dict(run("sphere-check").doc)
    d["procedure"] = {"name": "sphere_check"}
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    capsys.readouterr()
    assert _cli("export", "linuxcnc", bad, "--machine", VMC, "--kins", "xyzac-trt", "--out", tmp_path / "l") == 2
    assert _cli("history", "add", "--store", tmp_path / "s.fcdb", "--machine-id", "M1", bad) == 2
    err = capsys.readouterr().err
    assert "procedure.name" in err and "Traceback" not in err


def test_previous_takes_any_result_document(run, tmp_path, capsys):
    """sphere-check --previous: the result of any procedure (here rtest's), and a
    check written before the spindle names (EX0C on this trunnion)."""
    d = os.path.dirname(run("sphere-check").result)
    touches = os.path.join(d, "touches.json")
    assert _cli("sphere-check", touches, "--previous", run("rtest").result) == 0
    out = capsys.readouterr().out
    assert "change" in out
    old = {"parameters": {"EX0C": {"value": 0.010, "std": 0.0005}}, "dispersion_before": 0.03,
           "dispersion_after": 0.001}
    (tmp_path / "old.json").write_text(json.dumps(old))
    c = sphere_check.evaluate(fivecal.load_dataset(touches), previous=str(tmp_path / "old.json"))
    # EX0S = -EX0C: the change is the measured EX0S minus -0.010
    v, _ = c.pivots["C"]["EX0S"]
    assert c.change["EX0S"][0] == pytest.approx(v + 0.010)


def test_rtest_without_a_fit_writes_a_result_no_consumer_takes_for_errors(tmp_path, capsys):
    m = fivecal.Machine.load(VMC)
    ds = fivecal.simulate(m, rtest.plan(m, "K1", table_ball=TABLE_BALL), errors=AC_TRUTH,
                          sigma={"ball3d": 0.0005}, seed=4)
    data, out = _save(ds, tmp_path / "k1.json"), tmp_path / "k1_result.json"
    assert _cli("rtest", data, "--no-identify", "--tolerance", "5um", "--out", out) == 1   # K1 exceeds 5 µm
    doc = json.loads(out.read_text())
    schema.validate(doc, "result")
    assert doc["procedure"]["values"]["tests"]["K1"]["passes"] is False and doc["parameters"] == {}
    capsys.readouterr()
    assert _cli("export", "linuxcnc", out, "--machine", VMC, "--kins", "xyzac-trt", "--out", tmp_path / "l") == 2
    assert "refusing" in capsys.readouterr().err


def test_an_unusable_fit_exits_1_writes_its_document_and_consumers_refuse_it(tmp_path, capsys):
    """Exit codes as identify's: readings 20x noisier than declared make the
    R-test fit inadequate: exit 1, the document is written (verdict
    inadequate, to inspect) and export / compensate refuse it (exit 2)."""
    m = fivecal.Machine.load(VMC)
    plan = [e for t in rtest.TESTS for e in rtest.plan(m, t, table_ball=TABLE_BALL, tilt_range=A_LIMITS, step=30)]
    d = fivecal.simulate(m, plan, errors=AC_TRUTH, sigma={"ball3d": 0.0005}, seed=9).to_dict()
    rng = np.random.default_rng(9)
    for o in d["observations"]:
        o["measured"] = [x + rng.normal(0, 0.01) for x in o["measured"]]
    data, out = tmp_path / "noisy.json", tmp_path / "noisy_result.json"
    data.write_text(json.dumps(d))
    capsys.readouterr()
    assert _cli("rtest", data, "--out", out) == 1
    assert "not usable" in capsys.readouterr().err
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "inadequate" and doc["procedure"]["name"] == "rtest"
    assert _cli("export", "linuxcnc", out, "--machine", VMC, "--kins", "xyzac-trt", "--out", tmp_path / "l") == 2
    assert _cli("compensate", out, VMC, "--table", tmp_path / "t.csv") == 2
    assert _cli("rtest", data, "--out", out, "--force") == 0


def test_standalone_machining_procedure_writes_the_result_document():
    m = fivecal.Machine.load(VMC)
    tests = machining.zhang_tests(m, L=150.0, H=60.0)
    truth = {"EA0C": 3e-5, "EY0C": 0.02}
    rng = np.random.default_rng(3)
    for t, v in zip(tests, machining.predict(m, tests, errors=truth)):
        t["measured"] = float(v + rng.normal(0, 0.001))
    doc = machining.identify(m, tests, sigma=0.001).to_dict()
    schema.validate(doc, "result")
    assert doc["procedure"]["name"] == "machining" and set(doc["procedure"]["values"]["tests"]) == {"T1", "T2", "T3"}
    for n, v in truth.items():
        p = doc["parameters"][n]
        assert abs(p["value"] - v) < 3 * p["std"], (n, p, v)


# ---------------------------------------------------------------------------
# truth
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_values_within_3_sigma_of_the_truth(run, name):
    r = run(name)
    p = r.doc["parameters"]
    und = set(r.doc.get("undetermined") or [])
    checked = 0
    for n, v in r.truth.items():
        if n not in p or n in und or p[n].get("fixed"):
            continue
        assert abs(p[n]["value"] - v) < 3 * p[n]["std"], (name, n, p[n], v)
        checked += 1
    assert checked >= min(4, len(r.truth)), (name, checked)


def _coverage(z: List[float]) -> None:
    z = np.abs(np.asarray(z))
    assert 0.55 <= np.mean(z < 1) <= 0.80 and 0.90 <= np.mean(z < 2) <= 1.0, (np.mean(z < 1), np.mean(z < 2))


def test_sphere_check_sigma_coverage_from_its_documents():
    """σ in the written document covers the truth as claimed: 12 checks of
    the trunnion, 8 pivot values each."""
    m = fivecal.Machine.load(VMC)
    plan = sphere_check.plan(m, BALL, tip_radius=TIP, n=4, limits={"A": A_LIMITS})
    truth = seen(m, AC_TRUTH)
    z = []
    for seed in range(12):
        ds = fivecal.simulate(m, plan, errors=AC_TRUTH, artefact={"spheres": [BALL]}, tip_radius=TIP,
                              sigma=0.001, seed=500 + seed)
        p = sphere_check.evaluate(ds).to_dict()["parameters"]
        z += [(p[n]["value"] - v) / p[n]["std"] for n, v in truth.items()]
    _coverage(z)


def test_rtest_sigma_coverage_from_its_documents():
    m = fivecal.Machine.load(VMC)
    plan = [e for t in rtest.TESTS for e in rtest.plan(m, t, table_ball=TABLE_BALL, tilt_range=A_LIMITS, step=30)]
    truth = seen(m, AC_TRUTH)
    z = []
    for seed in range(14):
        ds = fivecal.simulate(m, plan, errors=AC_TRUTH, sigma={"ball3d": 0.0005}, seed=700 + seed)
        p = rtest.evaluate(ds).to_dict()["parameters"]
        z += [(p[n]["value"] - v) / p[n]["std"] for n, v in truth.items()]
    _coverage(z)


# ---------------------------------------------------------------------------
# end to end on the A/C trunnion, through the commands a user runs
# ---------------------------------------------------------------------------
def test_ac_trunnion_plan_simulate_check_export_and_record(tmp_path, capsys):
    """plan -> simulate with known errors and noise -> sphere check and R-test
    -> export linuxcnc and history add, every step the CLI."""
    errors = tmp_path / "errors.json"
    errors.write_text(json.dumps(AC_TRUTH))
    d = str(tmp_path)
    assert _cli("plan", "sphere-check", VMC, "--sphere", "80,50,60", "--radius", "12.5", "--tip-radius", "3",
                "--limits", "A=-90:30,C=-180:180", "-n", "4", "--errors", errors, "--out", f"{d}/sc_plan.json") == 0
    assert _cli("plan", "rtest", VMC, "--table-ball", "150,0,100", "--tilt-range=-90:30", "--errors", errors,
                "--out", f"{d}/rt_plan.json") == 0
    assert _cli("simulate", f"{d}/sc_plan.json", "--sigma", "0.001", "--seed", "3", "--out", f"{d}/sc.json") == 0
    assert _cli("simulate", f"{d}/rt_plan.json", "--sigma", "0.0005", "--seed", "3", "--out", f"{d}/rt.json") == 0
    assert _cli("sphere-check", f"{d}/sc.json", "--out", f"{d}/sc_result.json") == 0
    assert _cli("rtest", f"{d}/rt.json", "--out", f"{d}/rt_result.json") == 0
    m = fivecal.Machine.load(VMC)
    for res in ("sc_result", "rt_result"):
        doc = json.loads(open(f"{d}/{res}.json").read())
        for n, v in seen(m, AC_TRUTH).items():
            assert abs(doc["parameters"][n]["value"] - v) < 3 * doc["parameters"][n]["std"], (res, n)
        assert _cli("export", "linuxcnc", f"{d}/{res}.json", "--machine", VMC, "--kins", "xyzac-trt",
                    "--out", f"{d}/lcnc_{res}") == 0
        assert _cli("history", "add", "--store", f"{d}/shop.fcdb", "--machine-id", "VMC-1", "--machine", VMC,
                    f"{d}/{res}.json") == 0
    assert "recorded" in capsys.readouterr().out
