"""identify's fit path for long data (fit_path): the normal equations
accumulated in chunks give the dense fit's result, the option is checked, and
long data take that path by themselves."""
import os

import numpy as np
import pytest

import fivecal

HERE = os.path.dirname(os.path.abspath(__file__))
TRUE = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
TABLE = [50.0, 0.0, 80.0]


@pytest.fixture(scope="module")
def c600u():
    return fivecal.Machine.load(os.path.join(HERE, "..", "..", "examples", "machines", "c600u.json"))


def rtest(m, n, seed=3):
    # An R-test: the nominal tool ball on the table ball at every pose.
    rng = np.random.default_rng(seed)
    tilt, turn = np.radians(rng.uniform(0, 60, n)), np.radians(rng.uniform(0, 360, n))
    tool_axes = np.column_stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), np.cos(tilt)])
    axes = m.inverse(np.tile(TABLE, (n, 1)), tool_axes)
    meas = m.tool_point(axes, TRUE) - np.array(TABLE) + rng.normal(0, 5e-4, (n, 3))
    return fivecal.ball_dataset(m, "ball3d", axes, m.tip, TABLE, measured=meas, setup="R1")


def test_both_paths_give_the_same_fit(c600u):
    ds = rtest(c600u, 3000)
    d = fivecal.identify(ds, list(TRUE), fit_path="dense")
    s = fivecal.identify(ds, list(TRUE), fit_path="normal_equations", num_threads=2)
    assert (d.fit_path, s.fit_path) == ("dense", "normal_equations")
    assert d.estimated == s.estimated and s.verdict == d.verdict == "ok"
    for k in d.estimated:
        assert abs(d.values[k] - s.values[k]) < 1e-9 * d.std[k], k
        assert s.std[k] == pytest.approx(d.std[k], rel=1e-8), k
    assert s.chi2 == pytest.approx(d.chi2, rel=1e-9)
    assert s.rms == pytest.approx(d.rms, rel=1e-9)
    np.testing.assert_allclose(s.residuals, d.residuals, atol=1e-9 * d.rms)


def test_long_data_take_the_normal_equations_and_bad_requests_are_refused(c600u):
    assert fivecal.identify(rtest(c600u, 2000), list(TRUE)).fit_path == "dense"
    assert fivecal.identify(rtest(c600u, 200_000), list(TRUE)).fit_path == "normal_equations"
    ds = rtest(c600u, 500)
    with pytest.raises(ValueError, match="fit_path"):
        fivecal.identify(ds, list(TRUE), fit_path="sparse")
    with pytest.raises(ValueError, match="robust"):
        fivecal.identify(ds, list(TRUE), fit_path="normal_equations", robust="huber")
