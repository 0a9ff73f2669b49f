"""σ coverage of every procedure's command (issue 28, "What it must show"):
simulate a machine with known errors and noise N times (new seeds), run the
procedure's command with ``--out`` and check that the σ it writes covers the
scatter of its values about the truth.

The runners are the ones of test_one_result (one per procedure, each
simulating and running the real command through ``fivecal.cli.main``); the
truth is under the names every command reports
(:func:`fivecal.procedures.sphere_check.spindle_names`).

Already covered elsewhere, not repeated here:

* sphere-check, rtest: test_one_result (through the documents);
* four-step: test_dbb_result (``dbb.jiang_cripps``, 60 runs);
* TANGO: test_tango.test_monte_carlo_coverage_of_2_sigma_intervals, 100 runs
  of ``fivecal.identify(ds, "S3")``, the fit ``fivecal identify --estimate
  S3`` runs.

Units: mm, rad."""
from __future__ import annotations

import json
import os
from typing import List

import numpy as np
import pytest

import fivecal
from fivecal.cli import main
from fivecal.procedures import dbb
from fivecal.procedures.sphere_check import spindle_names

from test_one_result import RUNNERS, VMC, WANG_TRUTH


def _z_scores(name: str, seeds, tmp_path) -> List[float]:
    z: List[float] = []
    for seed in seeds:
        d = tmp_path / f"{name}-{seed}"
        d.mkdir()
        r = RUNNERS[name](str(d), seed)
        assert r.rc == 0, (name, seed, r.rc)
        with open(r.result) as f:
            doc = json.load(f)
        p, und = doc["parameters"], set(doc.get("undetermined") or [])
        for n, v in r.truth.items():
            if n in p and n not in und and not p[n].get("fixed"):
                z.append((p[n]["value"] - v) / p[n]["std"])
    return z


def _assert_coverage(z: List[float], minimum: int) -> None:
    """A right σ gives z ~ N(0, 1): 95 % of |z| below 2, rms 1.

    Bounds: fraction |z| < 2 in [0.85, 1] and rms(z) in [0.6, 1.5]. With
    >= 60 z-scores (correlated within a run, say 20 independent), a right σ
    gives rms 1 ± 0.16 and fraction 0.95 ± 0.05: both bounds are > 2.5 of
    their spreads away. A σ half the true scatter gives rms 2 and fraction
    0.68 (fails both); a σ twice the scatter gives rms 0.5 (fails the rms)."""
    z = np.asarray(z)
    assert len(z) >= minimum, len(z)
    frac, rms = float(np.mean(np.abs(z) < 2)), float(np.sqrt(np.mean(z ** 2)))
    assert 0.85 <= frac <= 1.0 and 0.6 <= rms <= 1.5, (f"n={len(z)} frac|z|<2={frac:.3f} rms={rms:.3f}",
                                                       np.round(np.sort(np.abs(z))[-5:], 2))


# Each run takes 0.1-0.5 s; N keeps a test well under 20 s on a loaded 2-core machine.

def test_jiang_cripps_sigma_coverage(tmp_path):
    """`fivecal dbb jiang`: 15 runs x 8 location errors of the A/C trunnion."""
    _assert_coverage(_z_scores("jiang-cripps", range(900, 915), tmp_path), 100)


def test_sphere_test_sigma_coverage(tmp_path):
    """`fivecal sphere --values`: 15 runs x 8 location errors."""
    _assert_coverage(_z_scores("sphere-test", range(900, 915), tmp_path), 100)


def test_machining_sigma_coverage(tmp_path):
    """Machined faces through `fivecal identify`: 15 runs x 8 location errors."""
    _assert_coverage(_z_scores("machining", range(900, 915), tmp_path), 100)


def test_circular_sigma_coverage(tmp_path):
    """`fivecal dbb circular`: 24 runs x the two backlashes a circle determines."""
    _assert_coverage(_z_scores("circular", range(900, 924), tmp_path), 48)


@pytest.mark.parametrize("scale,passes", [(1.0, True), (2.0, False), (0.5, False)])
def test_the_coverage_bounds_fail_a_sigma_off_by_two(scale, passes):
    """The bounds can fail: z of a σ half (scale 2) or twice (scale 0.5) the
    scatter, 100 per draw as above, are refused in 200 draws out of 200."""
    rng = np.random.default_rng(11)
    ok = 0
    for _ in range(200):
        try:
            _assert_coverage(list(rng.normal(0, scale, 100)), 48)
            ok += 1
        except AssertionError:
            pass
    assert ok == (200 if passes else 0), ok


def _wang_run(d, seed: int, placed: bool):
    """`fivecal dbb wang` on the trunnion; with ``placed`` the balls are put
    where a real set-up puts them: drawn from the placement uncertainty the
    fit assumes (docs/setup_uncertainty.md: table ball 30 µm, cup 5/5/20 µm)."""
    m = fivecal.Machine.load(VMC)
    rng = np.random.default_rng(seed)
    setup = {}
    if placed:
        setup = {f"dbb.W1.table.{c}": float(rng.normal(0, 0.030)) for c in "xyz"}
        setup.update({f"dbb.W1.tool.{c}": float(rng.normal(0, u)) for c, u in zip("xyz", (0.005, 0.005, 0.020))})
    plan = [{k: v for k, v in e.items() if k != "tracking"} for e in dbb.wang_plan(m)]
    ds = fivecal.simulate(m, plan, errors=WANG_TRUTH, sigma={"dbb": 0.0003}, seed=seed, setup=setup)
    data, out = os.path.join(d, "wang_data.json"), os.path.join(d, "wang.json")
    fivecal.save_dataset(ds, data)
    assert main(["dbb", "wang", data, "--out", out]) == 0
    with open(out) as f:
        p = json.load(f)["parameters"]
    return [(p[n]["value"] - v) / p[n]["std"] for n, v in spindle_names(m, WANG_TRUTH).items()]


def test_wang_sigma_coverage_with_the_balls_placed_as_assumed(tmp_path):
    """`fivecal dbb wang`: 20 runs x the four Wang errors, each run with its
    own ball placement and noise. The σ holds the placement uncertainty (a
    confounded error gets the σ the placement allows), so the truth test
    draws the placement as well as the noise."""
    z = []
    for seed in range(900, 920):
        z += _wang_run(str(tmp_path), seed, placed=True)
    _assert_coverage(z, 80)
