"""fivecal.ball_dataset carries the declared noise of its samples into the
fit: one number, one per sample or one per ball3d component, exactly as
``"sigma"`` in a dataset file."""

import numpy as np
import pytest

import fivecal

TRUE = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
TABLE = [50.0, 0.0, 80.0]


@pytest.fixture(scope="module")
def samples(c600u):
    # An R-test: the nominal tool ball sits on the table ball at every pose;
    # the sensor reads where the erroneous machine puts it instead.
    n = 400
    rng = np.random.default_rng(7)
    tilt, turn = np.radians(rng.uniform(0, 60, n)), np.radians(rng.uniform(0, 360, n))
    tool_axes = np.column_stack([np.sin(tilt) * np.cos(turn), np.sin(tilt) * np.sin(turn), np.cos(tilt)])
    axes = c600u.inverse(np.tile(TABLE, (n, 1)), tool_axes)
    meas = c600u.tool_point(axes, TRUE) - np.array(TABLE) + rng.normal(0, 5e-4, (n, 3))
    return axes, meas


def fit(m, axes, meas, sigma=None):
    ds = fivecal.ball_dataset(m, "ball3d", axes, m.tip, TABLE, measured=meas, setup="R1", sigma=sigma)
    return ds, fivecal.identify(ds, list(TRUE), default_setup=False)


def test_sigma_reaches_the_dataset_and_the_chi_square(c600u, samples):
    axes, meas = samples
    ds1, r1 = fit(c600u, axes, meas, 0.0005)
    ds2, r2 = fit(c600u, axes, meas, 0.001)
    assert ds1.observations[0]["sigma"] == 0.0005 and ds2.observations[-1]["sigma"] == 0.001
    # The same residuals weighted by 1/sigma: chi-square scales with 1/sigma^2.
    assert r1.chi2 == pytest.approx(4 * r2.chi2, rel=1e-6)
    assert r1.verdict == "ok"  # the noise drawn is 0.5 µm: it agrees with sigma 0.0005
    # Without sigma the default of a 3D ball sensor (0.001 mm) applies.
    _, r0 = fit(c600u, axes, meas)
    assert r0.chi2 == pytest.approx(r2.chi2, rel=1e-6)


def test_per_sample_sigma_weights_the_fit(c600u, samples):
    axes, meas = samples
    bad = meas.copy()
    bad[:40] += 0.05  # 40 samples of a disturbed mounting
    sigma = np.full(len(bad), 0.0005)
    sigma[:40] = 5.0  # declared as nearly worthless
    _, weighted = fit(c600u, axes, bad, sigma)
    _, clean = fit(c600u, {a: v[40:] for a, v in axes.items()}, meas[40:], 0.0005)
    with pytest.warns(fivecal.FitWarning, match="declared instrument noise"):
        _, uniform = fit(c600u, axes, bad, 0.0005)  # the disturbed samples at full weight
    for k in TRUE:
        # the down-weighted samples no longer pull the estimate
        assert abs(weighted.values[k] - clean.values[k]) < 0.05 * clean.std[k], k
    assert max(abs(uniform.values[k] - clean.values[k]) / clean.std[k] for k in TRUE) > 3
    # one value per component: (N, 3)
    s3 = np.tile(sigma[:, None], (1, 3))
    ds3, per_component = fit(c600u, axes, bad, s3)
    assert ds3.observations[0]["sigma"] == 5.0
    assert per_component.values == pytest.approx(weighted.values, rel=1e-9, abs=1e-15)


def test_bad_sigma_is_refused_naming_the_sample(c600u, samples):
    axes, meas = samples
    sigma = np.full(len(meas), 0.001)
    sigma[17] = -1.0
    with pytest.raises(ValueError, match=r"observations\[17\]\.sigma"):
        fivecal.ball_dataset(c600u, "ball3d", axes, c600u.tip, TABLE, measured=meas, sigma=sigma)
    with pytest.raises(ValueError, match=r"sigma: 3 values for 400 samples"):
        fivecal.ball_dataset(c600u, "ball3d", axes, c600u.tip, TABLE, measured=meas, sigma=[0.001] * 3)
    with pytest.raises(ValueError, match=r"sigma must be 400 x 1 or 3"):
        fivecal.ball_dataset(c600u, "ball3d", axes, c600u.tip, TABLE, measured=meas, sigma=np.ones((400, 2)))
