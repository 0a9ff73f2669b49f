"""R-test K tests (issue 17, item 3) on a simulated table-table machine:
the plan keeps the ball centred on the nominal machine, the deviation ranges
per direction are those the true machine produces, and the location errors
of both rotary axes come out of the same data within 3σ, with σ right."""
from __future__ import annotations

import os

import numpy as np
import pytest

import fivecal
from fivecal.procedures import rtest
from fivecal.procedures.sphere_check import spindle_names

MACHINES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines")
TRUTH = {"EX0C": 0.007, "EY0C": 0.016, "EA0C": 1e-5, "EB0C": -4e-5, "EY0A": 0.009, "EZ0A": -0.011,
         "EB0A": 1.7e-5, "EC0A": 1.1e-5}
BALL = [120.0, -40.0, 80.0]


def _seen(m, truth):
    """The truth under the names every command reports: on this A/C table EX0C
    (C moved along A's line) and EY0A are constant tool-part offsets, the
    spindle's EX0S and EY0S (minus the table axis' value)."""
    return spindle_names(m, truth)


@pytest.fixture(scope="module")
def c600u():
    return fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))


def _plan(m):
    return [e for t in rtest.TESTS for e in rtest.plan(m, t, table_ball=BALL)]


def test_plan_keeps_the_ball_centred_on_the_nominal_machine(c600u):
    for t in rtest.TESTS:
        p = rtest.plan(c600u, t, table_ball=BALL, step=10)
        ds = fivecal.simulate(c600u, p, errors={}, sigma={"ball3d": 0.0})
        assert max(np.abs(o["measured"]).max() for o in ds.observations) < 1e-9
    k1 = rtest.plan(c600u, "K1", table_ball=BALL, step=30)
    assert [e["axes"]["C"] for e in k1] == [30.0 * k for k in range(13)] and all(e["axes"]["A"] == 0 for e in k1)
    k4 = rtest.plan(c600u, "K4", table_ball=BALL, tilt=-30)
    assert min(e["axes"]["A"] for e in k4) == pytest.approx(-30) and max(e["axes"]["A"] for e in k4) == pytest.approx(30)


def test_ranges_and_location_errors_recovered(c600u):
    plan = _plan(c600u)
    ds = fivecal.simulate(c600u, plan, errors=TRUTH, sigma={"ball3d": 0.0005}, seed=2)
    clean = fivecal.simulate(c600u, plan, errors=TRUTH, sigma={"ball3d": 0.0})
    out = rtest.evaluate(ds)
    ref = rtest.evaluate(clean, identify=False)
    assert set(out.tests) == set(rtest.TESTS)
    for t in rtest.TESTS:
        # the range is the true machine's, up to the noise of two samples
        assert np.abs(out.tests[t].ranges - ref.tests[t].ranges).max() < 6 * 0.0005
        assert out.tests[t].ranges.max() > 0.005  # the errors show: several µm
    r = out.result
    assert r.verdict == "ok"
    assert {"EX0S", "EY0S"} <= set(r.estimated) and not {"EX0C", "EY0A"} & set(r.estimated)
    for n, v in _seen(c600u, TRUTH).items():
        assert abs(r.values[n] - v) < 3 * r.std[n], (n, r.values[n], v, r.std[n])
    text = out.report(tolerance=0.02)
    assert "FAIL" in text and "K1" in text and "EX0S" in text


def test_sigma_is_right_over_many_simulations(c600u):
    plan = _plan(c600u)
    z = []
    for seed in range(40):
        ds = fivecal.simulate(c600u, plan, errors=TRUTH, sigma={"ball3d": 0.0005}, seed=100 + seed)
        r = rtest.evaluate(ds).result
        z += [(r.values[n] - v) / r.std[n] for n, v in _seen(c600u, TRUTH).items()]
    z = np.abs(np.array(z))
    assert 0.60 <= np.mean(z < 1) <= 0.76 and 0.91 <= np.mean(z < 2) <= 0.99


def test_one_test_alone_reports_what_it_cannot_see(c600u):
    """K1 turns only C: the A axis' location is not in its data, and asking
    for it is refused rather than answered."""
    ds = fivecal.simulate(c600u, rtest.plan(c600u, "K1", table_ball=BALL), errors=TRUTH,
                          sigma={"ball3d": 0.0005}, seed=3)
    with pytest.raises(ValueError, match="EZ0A|EY0A|EB0A|EC0A"):
        rtest.evaluate(ds)
    # Asked for the C pivot only, K1 measures the C axis line in the machine
    # frame: at A = 0 the A axis' Y position and tilt about Y move that line
    # exactly as EY0C and EB0C do, so what comes out is their sum. The docs
    # say so; run K2-K4 too to separate them (test above).
    only_c = rtest.evaluate(ds, estimate=["EX0C", "EY0C", "EA0C", "EB0C"])
    r = only_c.result
    seen = {"EX0C": TRUTH["EX0C"], "EY0C": TRUTH["EY0C"] + TRUTH["EY0A"], "EA0C": TRUTH["EA0C"],
            "EB0C": TRUTH["EB0C"] + TRUTH["EB0A"]}
    for n, v in seen.items():
        assert abs(r.values[n] - v) < 3 * r.std[n], (n, r.values[n], v, r.std[n])
    assert "K1" in only_c.report()
    # the same request as one string, as identify takes it: the names, not their letters
    as_text = rtest.evaluate(ds, estimate="EX0C, EY0C,EA0C EB0C")
    assert as_text.result.values == pytest.approx(r.values)


def test_bad_requests(c600u):
    with pytest.raises(ValueError, match="K5"):
        rtest.plan(c600u, "K5", table_ball=BALL)
    with pytest.raises(ValueError, match="table_ball"):
        rtest.plan(c600u, "K1", table_ball=[1, 2])
    with pytest.raises(ValueError, match="step"):
        rtest.plan(c600u, "K1", table_ball=BALL, step=0)
    three = fivecal.Machine.from_dict({"name": "3ax", "topology": "wfXYZt",
                                       "axes": {"X": {"type": "linear", "direction": [1, 0, 0]},
                                                "Y": {"type": "linear", "direction": [0, 1, 0]},
                                                "Z": {"type": "linear", "direction": [0, 0, 1]}},
                                       "tool": {"tip": [0, 0, 100]}})
    with pytest.raises(ValueError, match="two"):
        rtest.plan(three, "K1", table_ball=BALL)


def test_cli_rtest(c600u, tmp_path, capsys):
    from fivecal.cli import main

    ds = fivecal.simulate(c600u, _plan(c600u), errors=TRUTH, sigma={"ball3d": 0.0005}, seed=5)
    path = tmp_path / "rtest.json"
    fivecal.save_dataset(ds, str(path))
    assert main(["rtest", str(path)]) == 0
    text = capsys.readouterr().out
    assert "K4" in text and "EZ0A" in text
    assert main(["rtest", str(path), "--tolerance", "20um"]) == 1  # K1 ranges ~50 µm
    assert "FAIL" in capsys.readouterr().out
    assert main(["rtest", str(path), "--tolerance", "0.1", "--no-identify"]) == 0   # bare: mm, as everywhere
    capsys.readouterr()
    # the old bare µm habit: 20 mm would pass any machine; refused, naming the unit to write
    assert main(["rtest", str(path), "--tolerance", "20", "--no-identify"]) == 2
    err = capsys.readouterr().err
    assert "--tolerance" in err and "implausibly large" in err and "20um" in err, err
    capsys.readouterr()
    assert main(["rtest", str(path), "--tolerance", "-3"]) == 2
    assert "--tolerance" in capsys.readouterr().err
    assert main(["rtest", str(path), "--tolerance", "0.1mm", "--no-identify"]) == 0     # 100 µm, with its unit
