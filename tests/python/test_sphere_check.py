"""Quick sphere check (issue 17, item 2): a calibrated stylus, one sphere, a
few positions per rotary axis approached from both sides, on the four
example machines. Injected pivot errors and rotary reversal errors are
recovered within 3σ, σ is right (coverage), the dispersion of the sphere
positions drops to the noise, and the change since the previous check is
reported with its uncertainty."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

import fivecal
from fivecal.procedures import sphere_check as sc

MACHINES = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "machines")
BALL = {"id": "S1", "center": [80.0, 50.0, 60.0], "radius": 12.5}
TIP = 3.0
SIGMA = 0.001


def _truth(m, rng):
    out = {}
    for a in sc._rotary_axes(m):
        for n in sc.pivot_parameters(m, a):
            out[n] = float(rng.normal(0, 2e-5) if n[1] in "ABC" or n.endswith("b") else rng.normal(0, 0.015))
    return out


def _check(name, seed, previous=None, truth=None):
    m = fivecal.Machine.load(os.path.join(MACHINES, f"{name}.json"))
    rng = np.random.default_rng(seed)
    truth = truth or _truth(m, rng)
    plan = sc.plan(m, BALL, tip_radius=TIP)
    # the stylus is calibrated: its true offsets are zero, and the check fixes them
    ds = fivecal.simulate(m, plan, errors=truth, artefact={"spheres": [BALL]}, tip_radius=TIP,
                          sigma=SIGMA, seed=seed)
    return m, truth, sc.evaluate(ds, previous=previous)


@pytest.mark.parametrize("name", ["c600u", "hu40t", "kx8", "vmc0656"])
def test_pivots_and_backlash_recovered_on_the_four_example_machines(name):
    m, truth, c = _check(name, 11)
    assert c.result.converged and c.result.verdict == "ok"
    assert set(c.axes) == set(sc._rotary_axes(m))
    for a in c.axes:
        for n, (v, s) in c.pivots[a].items():
            assert abs(v - truth[n]) < 3 * s, (name, n, v, truth[n], s)
        v, s = c.backlash[a]
        assert abs(v - truth[f"E{a}{a}b"]) < 3 * s and s < 5e-6, (name, a, v, s)
    # dispersion of the per-position sphere centres: tens of µm before, noise after
    assert c.dispersion_before > 10 * SIGMA
    assert c.dispersion_after < SIGMA
    text = c.report()
    assert "dispersion of the sphere positions" in text and "reversal" in text and "condition number" in text


def test_sigma_is_right_over_many_checks():
    """Coverage: over 60 simulated checks of one machine, the fraction of
    pivot values within 1σ and 2σ of the truth is what σ claims."""
    z = []
    for seed in range(60):
        m, truth, c = _check("c600u", 100 + seed)
        z += [(v - truth[n]) / s for a in c.axes for n, (v, s) in c.pivots[a].items()]
    z = np.abs(np.array(z))
    assert 0.62 <= np.mean(z < 1) <= 0.75, np.mean(z < 1)
    assert 0.92 <= np.mean(z < 2) <= 0.98, np.mean(z < 2)


def test_change_since_the_previous_check(tmp_path):
    m, truth, first = _check("c600u", 21)
    path = tmp_path / "last.json"
    path.write_text(sc.to_json(first))
    moved = dict(truth, EY0C=truth["EY0C"] + 0.010)  # the C pivot moved 10 µm (a crash)
    _, _, second = _check("c600u", 22, previous=str(path), truth=moved)
    dx, s = second.change["EY0C"]
    assert abs(dx - 0.010) < 3 * s and s < 0.001
    for n, (d, s) in second.change.items():
        if n != "EY0C":
            assert abs(d) < 4 * s, (n, d, s)
    assert "change" in second.report()
    # a Result or a SphereCheck works as previous too
    assert sc.evaluate(second.result.dataset, previous=first).change.keys() == second.change.keys()


def test_one_sided_approach_does_not_claim_backlash_and_bad_requests_are_refused():
    m = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    plan = sc.plan(m, BALL, tip_radius=TIP, both_sides=False)
    ds = fivecal.simulate(m, plan, errors={"EX0C": 0.01}, artefact={"spheres": [BALL]}, tip_radius=TIP,
                          sigma=SIGMA, seed=1)
    c = sc.evaluate(ds, backlash=False)
    assert c.backlash == {} and "ECCb" not in c.result.estimated
    # every position reached from one side but the first (the move from 0
    # down to the lowest position): the reversal is seen once, so it is still
    # estimated, with a larger sigma than from both sides
    one = sc.evaluate(ds).backlash["C"][1]
    both = _check("c600u", 1)[2].backlash["C"][1]
    assert one > both
    with pytest.raises(ValueError, match="at least 3"):
        sc.plan(m, BALL, tip_radius=TIP, axis_positions={"C": [0, 90]})
    with pytest.raises(ValueError, match="no rotary axis 'B'"):
        sc.plan(m, BALL, tip_radius=TIP, axis_positions={"B": [0, 30, 60]})
    with pytest.raises(ValueError, match="limits.A"):
        sc.positions(m, 5, {"A": (30, -30)})
    # only C moved: the A pivot is not claimed
    only_c = sc.plan(m, BALL, tip_radius=TIP, axis_positions={"C": [0, 90, 180, 270]})
    ds = fivecal.simulate(m, only_c, errors={}, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=SIGMA, seed=2)
    c = sc.evaluate(ds)
    assert c.axes == ["C"] and "EY0A" not in c.result.estimated
    # no rotary motion at all: nothing to check
    still = [dict(e, axes={**e["axes"], "C": 0.0, "A": 0.0}) for e in only_c]
    ds = fivecal.simulate(m, still, errors={}, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=SIGMA, seed=2)
    with pytest.raises(ValueError, match="no rotary axis moved"):
        sc.evaluate(ds)
    assert json.loads(sc.to_json(c))["procedure"]["name"] == "sphere-check"


def test_cli_sphere_check(tmp_path, capsys):
    from fivecal.cli import main

    m = fivecal.Machine.load(os.path.join(MACHINES, "hu40t.json"))
    plan = sc.plan(m, BALL, tip_radius=TIP, n=4)
    truth = {"EX0C": 0.012, "EA0B": 2e-5, "ECCb": 1.5e-5}
    ds = fivecal.simulate(m, plan, errors=truth, artefact={"spheres": [BALL]}, tip_radius=TIP, sigma=SIGMA, seed=4)
    data = tmp_path / "touches.json"
    fivecal.save_dataset(ds, str(data))
    out = tmp_path / "check.json"
    assert main(["sphere-check", str(data), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "axis C: pivot" in text and "axis B: pivot" in text and "dispersion" in text
    saved = json.loads(out.read_text())
    assert abs(saved["parameters"]["EX0C"]["value"] - 0.012) < 3 * saved["parameters"]["EX0C"]["std"]
    assert main(["sphere-check", str(data), "--previous", str(out)]) == 0
    assert "change" in capsys.readouterr().out
    bad = tmp_path / "missing.json"
    assert main(["sphere-check", str(bad)]) == 2
