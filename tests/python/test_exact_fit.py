"""A fit with exactly as many residual rows as estimated parameters has no
redundancy: its residuals are zero and say nothing about the noise. The
uncertainty then comes from the declared noise, not from the (zero)
residuals: an exactly determined fit is not an exact one."""
from __future__ import annotations

import warnings

import numpy as np

import fivecal

from test_registered_kinds import FIXED, MACHINE, _point_plan


def test_exactly_determined_fit_keeps_the_declared_noise():
    m = fivecal.Machine.from_dict(MACHINE)
    ds = fivecal.simulate(m, _point_plan(1), errors={"EX0C": 0.01, "EY0C": -0.02}, sigma={"point": 0.004}, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exact = fivecal.identify(ds, ["EX0C", "EY0C", "EZ0C"], fix=FIXED)
    assert exact.dof == 0
    # One tracker point, 3 rows of sigma 4 um, moves by exactly the three
    # C-axis offsets: each one's sigma is the tracker's.
    for n in ("EX0C", "EY0C", "EZ0C"):
        assert np.isclose(exact.std[n], 0.004, rtol=1e-6), (n, exact.std[n])
