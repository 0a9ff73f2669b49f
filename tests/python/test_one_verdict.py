"""One verdict (issue 28, item 2): values far outside their prior make a fit
not usable, whichever command fitted it and however its parameters were
chosen, and the message names the machine file as the likely cause.

The quick sphere check fits its own explicit set of pivot parameters; with a
machine file whose A pivot is 100 mm off it used to say "verdict ok", exit 0
and report EZ0A = 99,980 µm. The same data with the right machine file still
passes. And the report's banner carries the grade: OK, NOT USABLE, FAIL.
"""
from __future__ import annotations

import json
import os
import re

import numpy as np
import pytest

import fivecal
from fivecal import guards
from fivecal.cli import main
from fivecal.history import fleetsim
from fivecal.identification import INFORMED_THRESHOLD
from fivecal.procedures import sphere_check as sc
from fivecal.report.history import History

MACHINES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines")
BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
TIP = 3.0
SIGMA = 0.001
PIVOTS = "EY0A,EZ0A,EB0A,EC0A,EAAb,EX0C,EY0C,EA0C,EB0C,ECCb"
TRUTH = {"EY0A": 0.012, "EZ0A": -0.008, "EB0A": 2e-5, "EX0C": 0.015, "EY0C": -0.01, "EAAb": 1e-5, "ECCb": 1.5e-5}


def _machine_file(tmp_path, pivot_off: float = 0.0) -> str:
    """c600u's machine file, its A pivot moved ``pivot_off`` mm in Z (a typo in
    the file, another machine's file)."""
    d = json.load(open(os.path.join(MACHINES, "c600u.json")))
    p = d["axes"]["A"].get("point", [0, 0, 0])
    d["axes"]["A"]["point"] = [p[0], p[1], p[2] + pivot_off]
    path = tmp_path / f"c600u_{pivot_off:g}.json"
    path.write_text(json.dumps(d))
    return str(path)


@pytest.fixture(scope="module")
def touches(tmp_path_factory):
    """A sphere check of the real machine (the right file), and the same
    touches evaluated against a machine file whose A pivot is 100 mm off."""
    d = tmp_path_factory.mktemp("one_verdict")
    right = _machine_file(d)
    m = fivecal.Machine.load(right)
    plan = sc.plan(m, BALL, tip_radius=TIP)
    ds = fivecal.simulate(m, plan, errors=TRUTH, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=SIGMA,
                          seed=5)
    good = d / "right.json"
    fivecal.save_dataset(ds, str(good))
    doc = ds.to_dict()
    doc["machine"] = fivecal.Machine.load(_machine_file(d, 100.0)).to_dict()
    bad = d / "pivot_off.json"
    bad.write_text(json.dumps(doc))
    return d, good, bad


def _machine_file_message(err: str, command: str) -> None:
    # one line says it (a procedure's fit may also have warned, in one line of its own)
    assert "Traceback" not in err, err
    lines = [ln for ln in err.strip().splitlines() if ": warning: " not in ln]
    assert len(lines) == 1 and lines[0].startswith(f"fivecal {command}: not usable: "), err
    assert "far outside their plausible size" in lines[0] and "EZ0A" in lines[0], err
    assert re.search(r"likely cause: the machine file \(machine \"C600U-like\"\): its nominal geometry of "
                     r"axis A", lines[0]), err


def test_sphere_check_with_the_right_machine_file_passes(touches, capsys):
    _, good, _ = touches
    assert main(["sphere-check", str(good)]) == 0
    out = capsys.readouterr()
    assert "verdict ok" in out.out and "not usable" not in out.err


def test_sphere_check_with_the_pivot_100_mm_off_is_not_usable_and_names_the_machine_file(touches, capsys):
    d, _, bad = touches
    assert main(["sphere-check", str(bad), "--out", str(d / "check.json")]) == 1
    out = capsys.readouterr()
    assert "verdict ok" not in out.out and "verdict implausible" in out.out
    _machine_file_message(out.err, "sphere-check")
    # the value the check used to pass: about 100 mm, far beyond the 0.1 mm prior
    check = sc.evaluate(fivecal.load_dataset(str(bad)))
    r = check.result
    assert abs(abs(r.values["EZ0A"]) - 100.0) < 1.0 and "EZ0A" in r.implausible
    assert r.verdict == "implausible" and not r.plausible and not r.usable
    # consumers refuse it: it is no measurement of the machine
    with pytest.raises(fivecal.UnusableResultError, match="machine file"):
        r.machine_errors()
    # --force accepts it (to read the offset off and correct the file): exit 0, a warning
    assert main(["sphere-check", str(bad), "--force"]) == 0
    assert "warning: not usable" in capsys.readouterr().err


def test_identify_with_explicit_names_refuses_the_same_data(touches, tmp_path, capsys):
    _, good, bad = touches
    names = PIVOTS
    assert main(["identify", str(good), "--estimate", names, "--fix", "tip.x,tip.y,tip.z"]) == 0
    capsys.readouterr()
    out = tmp_path / "r.json"
    assert main(["identify", str(bad), "--estimate", names, "--fix", "tip.x,tip.y,tip.z", "--out", str(out)]) == 1
    _machine_file_message(capsys.readouterr().err, "identify")
    # the result file carries the verdict and its cause; read back, it is judged the same
    doc = json.loads(out.read_text())
    assert doc["verdict"] == "implausible" and doc["plausible"] is False and "machine file" in doc["plausibility"]
    a = guards.assess(str(out))
    assert a.verdict == "implausible" and "machine file" in a.reason
    # compensation refuses it (bad input: exit 2), naming the cause
    p = main(["compensate", str(out), _machine_file(tmp_path, 100.0), "--table", str(tmp_path / "t.csv")])
    assert p == 2 and "machine file" in capsys.readouterr().err
    # and the default fit is not usable either (whatever it finds first)
    assert main(["identify", str(bad)]) == 1


def test_undetermined_and_set_up_values_far_off_do_not_make_the_verdict():
    """Only machine errors the data determined: an undetermined value is
    arbitrary (its own verdict says so), and a set-up value (a sphere placed
    100 mm from its nominal spot) is the person's, not the machine file's."""
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    plan = sc.plan(m, BALL, tip_radius=TIP)
    moved = dict(BALL, center=[80.0, 50.0, 160.0])
    ds = fivecal.simulate(m, plan, errors=TRUTH, artefact={"spheres": [moved]}, tip_radius=TIP, sigma=SIGMA,
                          seed=6)
    doc = ds.to_dict()
    doc["artefact"]["spheres"][0]["center"] = BALL["center"]   # the file says where it was meant to be
    r = fivecal.identify(doc, PIVOTS, fix="tip.x,tip.y,tip.z")
    assert r.plausible and r.verdict == "ok", (r.verdict, r.plausibility)
    assert abs(r.values["sphere.S1.z"] - 100.0) < 0.01 and "sphere.S1.z" in r.implausible
    # an undetermined machine error's value is arbitrary: its verdict is "undetermined", not the machine file
    und = fivecal.identify(ds, PIVOTS + ",EZ0C", fix="tip.x,tip.y,tip.z", allow_unidentifiable=True,
                           initial={"EZ0C": 50.0})
    assert "EZ0C" in und.undetermined and und.plausible and und.verdict == "undetermined", und.verdict


def test_a_data_only_confounded_parameter_at_its_prior_is_never_reported_as_measured():
    """Under priors (estimate "auto") a parameter the data alone cannot
    separate from others is undetermined unless the data, with the others'
    priors, narrowed it: one that sits at its prior (posterior σ near the
    prior σ) is undetermined, left out of the machine errors and out of the
    plots; one reported determined has a σ that covers its truth."""
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    plan = sc.plan(m, BALL, tip_radius=TIP)
    z = []
    for seed in range(8):
        ds = fivecal.simulate(m, plan, errors=TRUTH, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=SIGMA,
                              seed=40 + seed)
        r = fivecal.identify(ds, "auto")
        assert r.map_fit
        a = r.assessment()
        grouped = {n for g in r.unidentifiable for n in g}
        assert grouped, "the sphere check's auto fit has data-only confounded groups"
        for n in grouped:
            # posterior σ / prior σ at the declared noise (informed is inflated by χ²/dof beyond 1)
            ratio = r.informed[n] / np.sqrt(max(1.0, r.chi2 / r.dof))
            if ratio > INFORMED_THRESHOLD * (1 + 1e-9):  # the data did not narrow its prior
                assert n in a.undetermined and n in r.undetermined, n
                assert n not in r.machine_errors(force=True), n
            elif n in m.parameter_names() and n not in r.held:
                z.append((r.values[n] - TRUTH.get(n, 0.0)) / r.std[n])
    # what the data (with the others' priors) did narrow is honest: 3σ covers the truth
    assert z and np.max(np.abs(z)) < 3.5, z


# -- the report's banner carries the grade -----------------------------------

def _nights(tmp_path, n=6):
    m = fleetsim.machine()
    plan = fleetsim.sphere_check_plan(m)
    store = str(tmp_path / "s.fcdb")
    results = []
    with fivecal.history.Store(store) as s:
        for night in range(n):
            ds = fivecal.simulate(m, plan, errors={"EX0C": 0.010}, artefact={"spheres": [fleetsim.SPHERE]},
                                  tip_radius=3.0, sigma=0.0006, seed=night)
            r = fivecal.identify(ds, "location")
            results.append(r)
            if night < n - 1:
                s.add(r, machine_id="HU-1", procedure="sphere", time=fleetsim.night_time(night))
    return store, results


def _banner(path):
    doc = open(path, encoding="utf-8").read()
    m = re.search(r"<div class='box (\w+)' id='verdict'><b>([A-Z ]+)(?: — [^.<]*)?\.</b>", doc)
    assert m and doc.index("id='verdict'") < doc.index("id='findings'"), doc[:3000]
    return m.group(1), m.group(2), doc


def test_report_banner_shows_ok_fail_and_not_usable(tmp_path):
    store, results = _nights(tmp_path)
    r = results[-1]
    assert r.usable
    cls, grade, _ = _banner(fivecal.write_report(r, tmp_path / "plain"))
    assert grade in ("OK", "OK WITH RESERVATIONS") and cls in ("ok", "warn")
    cls, grade, _ = _banner(fivecal.write_report(r, tmp_path / "pass", history=History(
        store, "HU-1", tolerances={"EX0C": 0.05})))
    assert grade.startswith("OK") and cls != "bad"
    # the same usable fit out of tolerance: red FAIL at the top, not only 7,000 px lower
    cls, grade, doc = _banner(fivecal.write_report(r, tmp_path / "fail", history=History(
        store, "HU-1", tolerances={"EX0C": 0.005})))
    assert (cls, grade) == ("bad", "FAIL"), (cls, grade)
    assert "out of tolerance: EX0C" in doc[:doc.index("id='findings'")]
    assert "<title>" in doc and "— FAIL</title>" in doc and "box ok" not in doc[:doc.index("id='findings'")]
    # a fit that is not usable stays NOT USABLE whatever its grade
    doc = r.dataset.to_dict()
    c = doc["machine"]["axes"]["C"]
    c["point"] = [float(x) + d for x, d in zip(c.get("point", [0, 0, 0]), (100.0, 0.0, 0.0))]
    bad = fivecal.identify(doc, "location")
    assert bad.verdict == "implausible"
    cls, grade, doc = _banner(fivecal.write_report(bad, tmp_path / "bad", history=History(
        store, "HU-1", tolerances={"EX0C": 0.005})))
    assert (cls, grade) == ("bad", "NOT USABLE") and "machine file" in doc[:doc.index("id='findings'")]
