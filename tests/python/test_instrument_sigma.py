"""Per-instrument declared noise ("instruments" in a dataset): an
observation without its own sigma takes its instrument's, then its kind's
default. An anisotropic camera (depth noise five times the lateral one)
fits adequately only with its own per-row sigma."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal

from shared_machines import TABLE_HEAD as MACHINE  # noqa: E402
ORIGIN, ANGLES = [2000.0, -500.0, 400.0], [0.5, -1.0, 155.0]
TRUTH = {"EA0B": 3e-5, "EC0B": -4e-5, "EX0C": 0.03, "EY0C": -0.02, "EA0C": 2e-5, "EB0C": -3e-5,
         "EB0Z": 5e-5, "EXX1": 2e-5}
SETUP = {"instrument.C1.x": 0.3, "instrument.C1.y": -0.2, "instrument.C1.c": 2e-3,
         "instrument.C1.tool_z": 0.05, "instrument.C1.work_x": 0.04}
FIXED = ["instrument.C1.tool_y"]
ROW_SIGMA = np.array([0.002, 0.002, 0.01])  # lateral, lateral, depth (mm)


@pytest.fixture(scope="module")
def camera_doc():
    """Noise-free simulated camera data with the camera's own anisotropic
    noise added, and no sigma declared on any observation."""
    rng = np.random.default_rng(11)
    plan = []
    for _ in range(60):
        axes = {"X": float(rng.uniform(-200, 200)), "Y": float(rng.uniform(-200, 200)),
                "Z": float(rng.uniform(-100, 100)), "B": float(rng.uniform(-60, 60)), "C": float(rng.uniform(0, 360))}
        for target, point in (("tool", [0, 0, 150]), ("work", [120, 40, 20])):
            plan.append({"type": "point", "instrument": "C1", "target": target, "target_point": point,
                         "axes": axes, "instrument_origin": ORIGIN, "instrument_angles": ANGLES})
    doc = fivecal.simulate(MACHINE, plan, errors=TRUTH, setup=SETUP, sigma=0.0).to_dict()
    for o in doc["observations"]:
        assert "sigma" not in o
        o["measured"] = [m + s * rng.standard_normal() for m, s in zip(o["measured"], ROW_SIGMA)]
    return doc


def _fit(doc, instruments):
    d = json.loads(json.dumps(doc))
    if instruments is not None:
        d["instruments"] = instruments
    return fivecal.identify(fivecal.Dataset.from_dict(d), list(TRUTH), fix=FIXED)


def test_the_instrument_sigma_weighs_the_depth_row_and_fits(camera_doc):
    r = _fit(camera_doc, {"C1": {"sigma": ROW_SIGMA.tolist()}})
    assert r.verdict == "ok", (r.verdict, r.adequacy)
    full = {**TRUTH, **SETUP}
    for n in TRUTH:
        assert abs(r.values[n] - full[n]) < 3 * r.std[n], n


def test_a_wrong_isotropic_sigma_is_inadequate(camera_doc):
    # The lateral sigma for every row: the depth rows are 5x their declaration.
    with pytest.warns(Warning, match="not usable"):
        r = _fit(camera_doc, {"C1": {"sigma": 0.002}})
    assert r.verdict == "inadequate", (r.verdict, r.adequacy)
    # One isotropic sigma between the two passes the chi-square, but the
    # lateral rows lose their weight to the noisy depth rows and the errors
    # come out less certain (on the whole) than the same data determine them.
    loose = _fit(camera_doc, {"C1": {"sigma": 0.006}})
    assert loose.verdict == "ok"
    good = _fit(camera_doc, {"C1": {"sigma": ROW_SIGMA.tolist()}})
    ratio = np.exp(np.mean([np.log(loose.std[n] / good.std[n]) for n in TRUTH]))
    assert ratio > 1.5, ratio


def test_the_instrument_sigma_is_what_the_problem_weighs(camera_doc):
    # The same data, once with the sigma on every observation and once on the
    # instrument: the same fit.
    d = json.loads(json.dumps(camera_doc))
    for o in d["observations"]:
        o["sigma"] = ROW_SIGMA.tolist()
    a = fivecal.identify(fivecal.Dataset.from_dict(d), list(TRUTH), fix=FIXED)
    b = _fit(camera_doc, {"C1": {"sigma": ROW_SIGMA.tolist()}})
    for n in TRUTH:
        assert a.values[n] == pytest.approx(b.values[n], rel=1e-8, abs=1e-12)
        assert a.std[n] == pytest.approx(b.std[n], rel=1e-8)
    # An observation's own sigma wins over its instrument's.
    d = json.loads(json.dumps(camera_doc))
    d["instruments"] = {"C1": {"sigma": 0.001}}
    for o in d["observations"]:
        o["sigma"] = ROW_SIGMA.tolist()
    c = fivecal.identify(fivecal.Dataset.from_dict(d), list(TRUTH), fix=FIXED)
    assert c.std["EX0C"] == pytest.approx(a.std["EX0C"], rel=1e-8)


def test_instruments_round_trip(camera_doc):
    d = json.loads(json.dumps(camera_doc))
    d["instruments"] = {"C1": {"sigma": ROW_SIGMA.tolist()}}
    out = fivecal.Dataset.from_dict(d).to_dict()
    assert out["instruments"] == {"C1": {"sigma": ROW_SIGMA.tolist()}}
    again = fivecal.Dataset.from_dict(json.loads(json.dumps(out))).to_dict()
    assert again == out
    d["instruments"] = {"C1": {"sigma": 0.02}}
    assert fivecal.Dataset.from_dict(d).to_dict()["instruments"] == {"C1": {"sigma": 0.02}}


@pytest.mark.parametrize("instruments,words", [
    ({"C2": {"sigma": 0.002}}, r"instruments\.C2: no observation names this instrument.*C1"),
    ({"C1": {"sigma": [0.01, 0.01]}}, r"instruments\.C1\.sigma: 2 values for a point instrument"),
    ({"C1": {"sigma": [0.01, 0.01, 0.0]}}, r"instruments\.C1\.sigma"),
    ({"C1": {"sigma": -1}}, r"instruments\.C1\.sigma"),
    ({"C1": {"sigma": "x"}}, r"instruments\.C1\.sigma"),
    ({"C1": {"sigm": 0.01}}, r"instruments\.C1"),
    ({"C1": 0.01}, r"instruments\.C1"),
])
def test_bad_instruments_are_named(camera_doc, instruments, words):
    d = json.loads(json.dumps(camera_doc))
    d["instruments"] = instruments
    with pytest.raises(ValueError, match=words):
        fivecal.Dataset.from_dict(d)
