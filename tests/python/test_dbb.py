"""Double ball bar module: end-to-end truth tests of the Jiang & Cripps
four-step test and the general engine, the limits of the four-step
approximations, the Wang et al. path / patterns / identification, planar
circular tests, CSV import, polar plots and the ``fivecal dbb`` CLI.

Every truth test simulates known errors with 0.1-0.5 µm reading noise.
"""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import fivecal
from fivecal.procedures import dbb
from fivecal.report import polar

HERE = os.path.dirname(os.path.abspath(__file__))
MACHINES = os.path.join(HERE, "..", "..", "examples", "machines")
ARCSEC = math.pi / (180 * 3600)
# Jiang & Cripps Tables 2-3: positions in mm, orientations read as arc-seconds.
PAPER = {"EY0A": 0.0342, "EZ0A": -0.0353, "EB0A": 6.62 * ARCSEC, "EC0A": 1.89 * ARCSEC,
         "EX0C": 0.0013, "EY0C": -0.0525, "EA0C": -22.32 * ARCSEC, "EB0C": -3.75 * ARCSEC}
# Larger orientation errors ("tens of µrad") for the noisy truth test.
TRUTH = dict(PAPER, EB0A=45e-6, EC0A=-30e-6, EA0C=-108e-6, EB0C=25e-6)


@pytest.fixture(scope="module")
def vmc():
    return fivecal.Machine.load(os.path.join(MACHINES, "vmc0656.json"))


@pytest.fixture(scope="module")
def four_step_plan(c600u):
    return dbb.four_step_plan(c600u)


def _sim(machine, plan, errors, sigma=0.0, seed=1, setup=None):
    return fivecal.simulate(machine, plan, errors=errors, sigma={"dbb": sigma}, seed=seed, setup=setup or {})


# ---- Jiang & Cripps ----------------------------------------------------------

@pytest.mark.parametrize("sigma,seed", [(0.0001, 11), (0.0003, 12), (0.0005, 13)])
def test_four_step_and_engine_recover_the_truth(c600u, four_step_plan, sigma, seed):
    ds = _sim(c600u, four_step_plan, TRUTH, sigma, seed)
    res = dbb.jiang_cripps(ds)
    assert res.engine is not None and res.engine.converged
    for n, v in TRUTH.items():
        assert abs(res.values[n] - v) < 3 * res.std[n], ("four-step", n, res.values[n], v, res.std[n])
        assert abs(res.engine.values[n] - v) < 3 * res.engine.std[n], ("engine", n)
        # Same readings: the two methods agree far inside their uncertainty.
        assert abs(res.values[n] - res.engine.values[n]) < 0.5 * res.std[n]
    assert res.engine.rank == res.engine.n_parameters == 12  # 8 PIGEs + 4 bar lengths
    text = res.report()
    for n in TRUTH:
        assert n in text
    d = res.to_dict()
    assert set(d["parameters"]) == set(TRUTH) and "engine" in d


def test_four_step_approximation_error_table(c600u, four_step_plan):
    """The numbers of docs/dbb.md, "Four-step approximations": noise-free
    error of the four-step method against the exact model."""
    def worst(truth, kind, **kw):
        res = dbb.jiang_cripps(_sim(c600u, four_step_plan, truth), engine=False, **kw)
        angular = kind == "angular"
        return max(abs(res.values[n] - truth[n]) for n in truth if (n[1] in "ABC") == angular)

    # Paper-sized errors: below 0.05 µm and 0.05 µrad.
    assert worst(PAPER, "linear") < 0.05e-3 and worst(PAPER, "angular") < 0.05e-6
    # Orientation errors near 1 mrad: still below 1 µrad; 10 mrad: tens of µrad.
    big = {n: (v * 10 if n[1] in "ABC" else v) for n, v in PAPER.items()}
    huge = {n: (v * 100 if n[1] in "ABC" else v) for n, v in PAPER.items()}
    assert worst(big, "angular") < 1e-6
    assert worst(huge, "angular") > 10e-6
    # Position errors of 0.3-0.5 mm: the circle fit's ovalisation, ~e^2/R.
    far = {n: (v * 10 if n[1] in "XYZ" else v) for n, v in PAPER.items()}
    assert 1e-3 < worst(far, "linear") < 4e-3


def test_four_step_breaks_with_spindle_ball_placement_and_the_engine_sees_it_too(c600u, four_step_plan):
    # 2 µm lateral error of the spindle ball in A2 -> 2 µm / 111.8 mm = 17.9 µrad on EC0A.
    ds = _sim(c600u, four_step_plan, TRUTH, 0.0002, 3, setup={"dbb.A2.tool.y": 0.002})
    res = dbb.jiang_cripps(ds)
    arm = math.sqrt(150 ** 2 - 100 ** 2)
    assert res.values["EC0A"] - TRUTH["EC0A"] == pytest.approx(0.002 / arm, abs=3 * res.std["EC0A"])
    # The general engine with the nominal spindle ball is fooled the same way:
    # a ball placement error is indistinguishable from an axis error here.
    assert abs(res.engine.values["EC0A"] - res.values["EC0A"]) < res.std["EC0A"]
    with pytest.raises(ValueError, match="confounded"):
        fivecal.identify(ds, list(TRUTH) + ["dbb.A1.tool.y", "dbb.A1.tool.z"])


def test_four_step_pivot_offset_correction_eq1(c600u, four_step_plan):
    ds = _sim(c600u, four_step_plan, PAPER, setup={"dbb.C1.table.y": 1.0, "dbb.C2.table.y": 1.0})
    raw = dbb.jiang_cripps(ds, engine=False)
    fixed = dbb.jiang_cripps(ds, c_pivot_offset=(0.0, 1.0))
    assert abs(raw.values["EB0C"] - PAPER["EB0C"]) > 0.5e-6
    assert fixed.values["EB0C"] == pytest.approx(PAPER["EB0C"], abs=0.05e-6)
    # The engine, told the pivot offset, also recovers the truth.
    assert fixed.engine.values["EB0C"] == pytest.approx(PAPER["EB0C"], abs=1e-9)
    assert fixed.step("C1").start_angle_error == pytest.approx(math.atan(1 / 100), rel=1e-12)


def test_four_step_from_csv_traces(c600u, four_step_plan, tmp_path):
    ds = _sim(c600u, four_step_plan, PAPER, 0.0002, 5)
    traces = {}
    for sid, axis in (("A1", "A"), ("A2", "A"), ("C1", "C"), ("C2", "C")):
        obs = [o for o in ds.observations if o["setup"] == sid]
        t = dbb.Trace([o["axes"][axis] for o in obs], [o["reading"] for o in obs], label=sid)
        dbb.write_trace_csv(t, tmp_path / f"{sid}.csv")
        traces[sid] = dbb.read_trace_csv(tmp_path / f"{sid}.csv")
    rebuilt = dbb.four_step_dataset(c600u, traces)
    a = dbb.jiang_cripps(ds, engine=False)
    b = dbb.jiang_cripps(rebuilt, engine=False)
    for n in PAPER:
        assert b.values[n] == pytest.approx(a.values[n], abs=1e-9)


def test_four_step_errors_name_the_problem(c600u, four_step_plan, vmc):
    ds = _sim(c600u, four_step_plan, PAPER)
    with pytest.raises(ValueError, match="'A9'"):
        dbb.jiang_cripps(ds, setups=("A9", "A2", "C1", "C2"))
    with pytest.raises(ValueError, match="a_removal"):
        dbb.jiang_cripps(ds, a_removal="some")
    # The KX8's nutating A axis (45 deg) has no plane basis of the method
    # (other pairs: test_four_step_pairs.py).
    kx8 = fivecal.Machine.load(os.path.join(MACHINES, "kx8.json"))
    with pytest.raises(ValueError, match="not along X, Y or Z"):
        dbb.four_step_plan(kx8)


# ---- Wang et al. ---------------------------------------------------------------

def test_wang_path_keeps_the_ball_on_the_circle_and_lists_table1(vmc):
    p = dbb.wang_path(vmc)
    assert p.max_circle_error < 1e-9
    # Independent check through the simulator: on the nominal machine the
    # bar length never changes along the path.
    plan = dbb.wang_plan(vmc, path=p)
    ds = _sim(vmc, [{k: v for k, v in e.items() if k != "tracking"} for e in plan], {})
    assert max(abs(o["reading"]) for o in ds.observations) < 1e-9
    rows = p.table(45)
    assert [r[0] for r in rows] == [45.0 * k for k in range(13)]
    # Table 1's reversals: A changes direction at 90 and 270, C at 180 and 360.
    dirs = {r[0]: (r[5], r[6]) for r in rows}
    assert dirs[45][0] != dirs[135][0] and dirs[225][0] != dirs[315][0]
    assert dirs[135][1] != dirs[225][1] and dirs[315][1] != dirs[405][1]
    assert "smallest-move branch" in p.format_table()


def _sym_about_y(h):
    """Harmonics of a pattern symmetric about the Y axis: r(pi - phi) = r(phi)
    keeps sin of odd and cos of even orders only."""
    return max(abs(h[1, 0]), abs(h[2, 1]), abs(h[3, 0]))


def test_wang_patterns_have_the_shapes_of_section4(vmc):
    pats = dbb.wang_patterns(vmc, {"EX0C": 0.01, "EY0C": 0.01, "EZ0C": 0.01, "EA0C": 50e-6})
    h = {n: p.harmonics for n, p in pats.items()}
    # (2) EX0C > 0: still a circle, shifted along +X.
    x = h["EX0C"]
    assert x[1, 0] > 0.007 and abs(x[1, 1]) < 1e-9
    assert max(abs(x[0, 0]), np.abs(x[2:]).max()) < 1e-4 * x[1, 0]
    # (3) EY0C > 0: shifted along +Y, symmetric about the Y axis.
    y = h["EY0C"]
    assert y[1, 1] > 0.005 and _sym_about_y(y) < 1e-3 * y[1, 1]
    # (4) EZ0C > 0: smaller than the standard circle, centre along -Y, pear
    # shaped: elongated along Y (cos 2phi < 0) on top of the shift, so the
    # small end is at the top (+Y) and the big end at the bottom.
    z = h["EZ0C"]
    assert z[0, 0] < -0.002 and z[1, 1] < -0.005 and z[2, 0] < -0.1 * abs(z[1, 1])
    assert _sym_about_y(z) < 1e-3 * abs(z[1, 1])
    # (1) the angular error EA0C > 0: the same pear family, shift along -Y.
    a = h["EA0C"]
    assert a[1, 1] < -0.005 and a[2, 0] < -0.05 * abs(a[1, 1]) and a[0, 0] < 0
    assert _sym_about_y(a) < 1e-3 * abs(a[1, 1])
    # Linear in the error: doubling EA0C doubles every harmonic.
    a2 = dbb.wang_patterns(vmc, {"EA0C": 100e-6})["EA0C"].harmonics
    np.testing.assert_allclose(a2, 2 * a, atol=2e-6)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_wang_identification_recovers_the_four_errors(vmc, seed):
    truth = {"EX0C": 0.007, "EY0C": -0.005, "EZ0C": 0.006, "EA0C": 30e-6}
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in dbb.wang_plan(vmc)]
    ds = _sim(vmc, plan, truth, 0.0003, seed)
    ident = dbb.wang_identify(ds)
    r = ident.result
    for n, v in truth.items():
        assert abs(r.values[n] - v) < 3 * r.std[n], (n, r.values[n], v, r.std[n])
    # What this path cannot separate: EB0A and a spindle-ball X offset look
    # exactly like EX0C; the table ball's height exactly like EZ0C; EC0A has
    # no effect; EZ0A is the bar length.
    c = ident.confounded
    assert c["EB0A"] == ["EX0C"] and c["dbb.W1.tool.x"] == ["EX0C"]
    assert c["dbb.W1.table.z"] == ["EZ0C"]
    assert c["EC0A"] == []
    assert c["EZ0A"] == ["dbb.W1.length"]
    assert "EB0C" in ident.separable and "EC0C" in ident.separable
    text = ident.report()
    assert "cannot be separated" in text and "no effect on this path" in text


def test_wang_path_errors(vmc):
    with pytest.raises(ValueError, match="radius"):
        dbb.wang_path(vmc, radius=400)
    d = vmc.to_dict()
    d["axes"]["C"]["point"] = [0, 5, 100]
    with pytest.raises(ValueError, match="miss each other"):
        dbb.wang_path(fivecal.Machine.from_dict(d))


# ---- planar circular tests --------------------------------------------------------

@pytest.mark.parametrize("sigma,seed", [(0.0001, 1), (0.0005, 2)])
def test_planar_diagnosis_recovers_scale_squareness_backlash(c600u, sigma, seed):
    truth = {"EXX1": 25e-6, "EYY1": -8e-6, "EC0Y": 35e-6, "EXXb": 0.003, "EYYb": -0.002}
    plan = dbb.planar_plan(c600u, "XY", 100.0)
    ds = _sim(c600u, plan, truth, sigma, seed)
    cw, ccw = dbb.trace_from_dataset(ds, "P-"), dbb.trace_from_dataset(ds, "P+")
    assert (cw.direction, ccw.direction, ccw.plane) == (-1, 1, "XY")
    res = dbb.circular_test([cw, ccw], 100.0, "XY", feed=1000)
    expect = {"scale_mismatch": truth["EXX1"] - truth["EYY1"],  # mm/mm
              "squareness": truth["EC0Y"],  # angle between +X and +Y = 90 deg + EC0Y
              "backlash.1": truth["EXXb"], "backlash.2": truth["EYYb"], "servo_mismatch": 0.0}
    for n, v in expect.items():
        assert abs(res.diagnosis[n] - v) < 3 * res.diagnosis_std[n] + 1e-3 * abs(v), (n, res.diagnosis[n], v)
    assert res.diagnosis_rms < 1.3 * sigma + 1e-5
    # ISO 230-4 values: scale mismatch and squareness make an ellipse of
    # radial amplitude R/2 |(m, psi)| = 2.4 µm (4.8 µm peak to peak); the
    # backlash steps add 2 b per axis at the reversals: G of about 10-13 µm.
    for run in res.runs:
        assert 0.008 < run.circular_deviation < 0.016
        assert run.radial_deviation_max > 0 > run.radial_deviation_min
    assert res.hysteresis > 0.004  # the backlash steps differ between CW and CCW
    text = res.report()
    assert "circular deviation G" in text and "squareness" in text


def test_planar_diagnosis_single_run_leaves_servo_out(c600u):
    plan = dbb.planar_plan(c600u, "YZ", 100.0, directions=(1,))
    ds = _sim(c600u, plan, {"EYY1": 20e-6}, 0.0002, 4)
    t = dbb.trace_from_dataset(ds, "P+")
    assert t.plane == "YZ"
    res = dbb.circular_test([t], 100.0, "YZ")
    assert "servo_mismatch" not in res.diagnosis
    assert any("servo" in s for s in res.not_fitted)
    assert res.diagnosis["scale_mismatch"] == pytest.approx(20e-6, abs=3 * res.diagnosis_std["scale_mismatch"])


# ---- CSV import and plots ----------------------------------------------------------

def test_csv_import(tmp_path):
    p = tmp_path / "run.csv"
    p.write_text("# CCW run\nangle;reading\n0;0.001\n1;0.002\n2;0.0015\n3;0.001\n")
    t = dbb.read_trace_csv(p)
    assert t.direction == 1 and t.angles.tolist() == [0, 1, 2, 3]
    one = tmp_path / "readings.csv"
    one.write_text("0.001\n0.002\n0.003\n0.004\n0.005\n")
    t = dbb.read_trace_csv(one, sweep=90.0, start=-20.0)  # eq. 2
    np.testing.assert_allclose(t.angles, [-20, 2.5, 25, 47.5, 70])
    with pytest.raises(ValueError, match="sweep"):
        dbb.read_trace_csv(one)
    bad = tmp_path / "bad.csv"
    bad.write_text("0,0.001\n1,0.002\n2,x\n")
    with pytest.raises(ValueError, match=r"bad.csv:3"):
        dbb.read_trace_csv(bad)


def test_polar_plots_are_written(c600u, vmc, four_step_plan, tmp_path):
    ds = _sim(c600u, four_step_plan, PAPER, 0.0003, 2)
    res = dbb.jiang_cripps(ds)
    files = [polar.plot_four_step(res, str(tmp_path / "jiang.png"))]
    pats = dbb.wang_patterns(vmc, {"EX0C": 0.01, "EA0C": 50e-6})
    files.append(polar.plot_wang_patterns(pats, str(tmp_path / "wang.png"), dbb.wang_path(vmc)))
    plan = dbb.planar_plan(c600u, "XY", 100.0, step=2.0)
    pds = _sim(c600u, plan, {"EXXb": 0.002}, 0.0003, 1)
    cres = dbb.circular_test([dbb.trace_from_dataset(pds, "P-"), dbb.trace_from_dataset(pds, "P+")], 100.0)
    files.append(polar.plot_circular_test(cres, str(tmp_path / "circ.png")))
    for f in files:
        assert os.path.getsize(f) > 20000
        with open(f, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert polar.magnification(100.0, 5.0) == pytest.approx(100000 / 15)
    assert polar.nice_scale(9.0) == 5.0


# ---- CLI -------------------------------------------------------------------------

def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fivecal", "dbb", *args], capture_output=True, text=True,
                          cwd=cwd)


@pytest.mark.parametrize("sub", ["jiang", "wang", "circular", "plot"])
def test_cli_help_has_an_example(sub):
    r = _cli(sub, "--help")
    assert r.returncode == 0 and "example" in r.stdout and f"fivecal dbb {sub}" in r.stdout


def test_cli_runs_every_subcommand(tmp_path):
    c600u = os.path.join(MACHINES, "c600u.json")
    vmc = os.path.join(MACHINES, "vmc0656.json")
    r = _cli("jiang", "--machine", c600u, "--simulate", "paper", "--sigma", "0.0003", "--plot",
             str(tmp_path / "j.png"), "--out", str(tmp_path / "j.json"), "--save-dataset", str(tmp_path / "ds.json"))
    assert r.returncode == 0, r.stderr
    assert "EB0C" in r.stdout and os.path.exists(tmp_path / "j.png")
    # EY0A is the spindle's offset on this A/C table: the result names it EY0S = -EY0A
    assert json.load(open(tmp_path / "j.json"))["parameters"]["EY0S"]["value"] == pytest.approx(-0.0342, abs=0.002)
    r = _cli("jiang", str(tmp_path / "ds.json"), "--no-engine")
    assert r.returncode == 0, r.stderr
    r = _cli("wang", "--machine", vmc, "--every", "45", "--simulate", "paper", "--patterns",
             str(tmp_path / "wp.png"), "--plot", str(tmp_path / "w.png"))
    assert r.returncode == 0, r.stderr
    assert "540" in r.stdout and "cannot be separated" in r.stdout and os.path.exists(tmp_path / "wp.png")
    r = _cli("circular", "--machine", c600u, "--simulate", "EXX1=2e-5,EXXb=0.002", "--radius", "100",
             "--plot", str(tmp_path / "c.png"), "--out", str(tmp_path / "c.json"))
    assert r.returncode == 0, r.stderr
    assert "squareness" in r.stdout
    t = dbb.Trace(np.arange(0, 360, 2.0), 0.001 * np.cos(np.radians(np.arange(0, 360, 2.0))))
    dbb.write_trace_csv(t, tmp_path / "ccw.csv")
    r = _cli("circular", str(tmp_path / "ccw.csv"), "--radius", "100")
    assert r.returncode == 0, r.stderr
    r = _cli("plot", str(tmp_path / "ccw.csv"), str(tmp_path / "ds.json"), "--setup", "C1", "--radius", "100",
             "--out", str(tmp_path / "p.png"))
    assert r.returncode == 0, r.stderr and os.path.exists(tmp_path / "p.png")


def test_cli_errors_are_one_line(tmp_path):
    r = _cli("circular", "--radius", "100")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "error" in r.stderr
    r = _cli("jiang", "--machine", os.path.join(MACHINES, "kx8.json"), "--simulate", "paper")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "not along X, Y or Z" in r.stderr
    r = _cli("wang", "--machine", os.path.join(MACHINES, "vmc0656.json"), "--simulate", "EX0C")
    assert r.returncode == 2 and r.stderr.count("\n") == 1


def test_wang_four_point_extraction_is_singular_and_says_what_it_cannot_see(vmc):
    """The paper extracts its four errors from the readings at the four
    diagonal angles. EY0C, EZ0C and EA0C give patterns symmetric about the Y
    axis, so each reads the same at 135° and 405° (45°) and at 225° and 315°:
    three unknowns in two equations. The analysis finds rank 3, the invisible
    combination, that only EX0C is determined, and gives no values."""
    a = dbb.wang_four_point(vmc)
    assert a.rank == 3 and a.singular_values[-1] < 1e-9
    assert a.estimable == ["EX0C"]
    null = a.null_space[:, 0]
    assert abs(null[0]) < 1e-9 and min(abs(null[1:])) > 0.05  # EY0C, EZ0C, EA0C all in it
    # the symmetry itself: equal readings at the mirrored diagonal points
    S = a.sensitivity
    np.testing.assert_allclose(S[0, 1:], S[3, 1:], rtol=1e-6)
    np.testing.assert_allclose(S[1, 1:], S[2, 1:], rtol=1e-6)
    truth = {"EX0C": 0.007, "EY0C": -0.005, "EZ0C": 0.006, "EA0C": 30e-6}
    plan = dbb.wang_plan(vmc)
    ds = _sim(vmc, [{k: v for k, v in e.items() if k != "tracking"} for e in plan], truth)
    readings = {e["tracking"]: o["reading"] for e, o in zip(plan, ds.observations)}
    solved = dbb.wang_four_point(vmc, readings)
    assert solved.values is None and "singular" in solved.report()
    # Three of the errors are regular in the four points: right when the
    # fourth is truly zero, aliased when it is not (EA0C leaks into EY0C and
    # EZ0C along the invisible combination).
    three = ("EX0C", "EY0C", "EZ0C")
    assert dbb.wang_four_point(vmc, errors=three).rank == 3
    no_ea = _sim(vmc, [{k: v for k, v in e.items() if k != "tracking"} for e in plan],
                 {n: truth[n] for n in three})
    clean = dbb.wang_four_point(vmc, {e["tracking"]: o["reading"] for e, o in zip(plan, no_ea.observations)},
                                errors=three)
    assert all(abs(clean.values[n] - truth[n]) < 1e-6 for n in three)  # linearised: nm
    aliased = dbb.wang_four_point(vmc, readings, errors=three)
    assert abs(aliased.values["EZ0C"] - truth["EZ0C"]) > 0.002
    # The whole-trace fit (wang_identify) separates all four: the second and
    # third harmonics it sees break the symmetry's tie.
    r = dbb.wang_identify(ds).result
    assert all(abs(r.values[n] - v) < 1e-6 for n, v in truth.items())


def test_wang_origin_shift_compensation_flattens_the_trace(vmc):
    """Section 5.2: the paper compensates by shifting the work origin with the
    rotary commands as programmed. Replayed on the erroneous machine, the
    origin-shifted path reads the nominal bar length everywhere (the DBB sees
    only the tool point), while the rotary commands are untouched; the tool
    axis keeps the A-C angular error, which pose-by-pose compensation removes."""
    from fivecal.compensation import compensate_poses, origin_shift

    truth = {"EX0C": 0.007, "EY0C": -0.005, "EZ0C": 0.006, "EA0C": 30e-6}
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in dbb.wang_plan(vmc)]
    before = _sim(vmc, plan, truth)
    axes = {a: np.array([e["axes"][a] for e in plan]) for a in plan[0]["axes"]}
    dirs = {a: np.array([e["direction"].get(a, 0) for e in plan]) for a in plan[0]["direction"]}
    shifted = origin_shift(vmc, truth, axes, dirs)
    for a in "AC":
        np.testing.assert_array_equal(shifted.axes[a], axes[a])
    moved = [dict(e, axes={a: float(shifted.axes[a][i]) for a in e["axes"]}) for i, e in enumerate(plan)]
    after = _sim(vmc, moved, truth)
    r0 = np.array([o["reading"] for o in before.observations])
    r1 = np.array([o["reading"] for o in after.observations])
    assert np.abs(r0).max() > 0.005 and np.abs(r1).max() < 1e-6
    assert shifted.axis_error_remaining.max() > 20e-6  # EA0C stays in the tool axis
    full = compensate_poses(vmc, truth, axes, dirs)
    assert full.axis_error_remaining.max() < 1e-9 and full.max_remaining() < 1e-9


def test_four_step_trace_redraws_the_measured_points_about_the_fitted_centre(c600u, four_step_plan):
    # Pivots 50-100 um off the nominal ones (PAPER): about the nominal pivot the
    # angles of the points are off by |centre| / radius.
    res = dbb.jiang_cripps(_sim(c600u, four_step_plan, PAPER), engine=False)
    for s in res.steps:
        t = res.step_trace(s.setup)
        a = np.radians(t.angles)
        redrawn = np.asarray(s.centre) + (s.radius + t.readings)[:, None] * np.c_[np.cos(a), np.sin(a)]
        assert np.abs(redrawn - np.asarray(s.points)).max() < 1e-9, s.setup
        assert abs(t.angles[0] - np.degrees(s.angles[0])) < 1.0  # the same turn as the step's angles
