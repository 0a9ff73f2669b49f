"""The distance kind (tracking interferometer, laser tracer): multilateration
of a reflector on the tool and one on the table of a machine with rotary
axes on both sides (C on the table, B on the head) from several stations.
The stations' positions, their dead lengths and the reflectors' offsets are
estimated with the machine errors."""
from __future__ import annotations

import json

import numpy as np
import pytest

import fivecal

from shared_machines import TABLE_HEAD as MACHINE  # noqa: E402
# Five stations around and above the machine, not in one plane; each
# station's dead length (the distance at reading 0) is roughly known.
STATIONS = {"L1": [900, -700, 150], "L2": [-800, -600, 650], "L3": [700, 800, 900], "L4": [-900, 700, 100],
            "L5": [50, -50, 1400]}
DEAD = {"L1": 200.0, "L2": 180.0, "L3": 220.0, "L4": 190.0, "L5": 210.0}
TRUTH = {"EA0B": 3e-5, "EC0B": -4e-5, "EX0C": 0.03, "EY0C": -0.02, "EA0C": 2e-5, "EB0C": -3e-5,
         "EB0Z": 5e-5, "EXX1": 2e-5}
SETUP = {"instrument.L1.x": 0.3, "instrument.L1.length": 0.05, "instrument.L2.y": -0.2, "instrument.L2.length": -0.03,
         "instrument.L3.z": 0.15, "instrument.L4.x": -0.1, "instrument.L4.length": 0.02, "instrument.L5.y": 0.1,
         "instrument.tracer.tool_z": 0.05, "instrument.tracer.tool_x": -0.02,
         "instrument.tracer.work_x": 0.04, "instrument.tracer.work_y": -0.03}
# As with a free tracker pose (the point kind): the tool reflector's y, along
# B, moves every tool point the way the stations' y do.
FIXED = ["instrument.tracer.tool_y"]
NOISE = {"distance": 0.001}


def _plan(rng, n=30, stations=STATIONS):
    plan = []
    for _ in range(n):
        axes = {"X": float(rng.uniform(-200, 200)), "Y": float(rng.uniform(-200, 200)),
                "Z": float(rng.uniform(-100, 100)), "B": float(rng.uniform(-60, 60)), "C": float(rng.uniform(0, 360))}
        for target, point in (("tool", [0, 0, 150]), ("work", [120, 40, 20])):
            for s in stations:
                plan.append({"type": "distance", "station": s, "target": target, "target_point": point,
                             "axes": axes, "station_position": STATIONS[s], "dead_length": DEAD[s]})
    return plan


@pytest.fixture(scope="module")
def machine():
    return fivecal.Machine.from_dict(MACHINE)


def _data(machine, seed, **kw):
    rng = np.random.default_rng(seed)
    return fivecal.simulate(machine, _plan(rng, **kw), errors=TRUTH, setup=SETUP, sigma=NOISE, seed=seed)


def _fit(machine, seed):
    ds = _data(machine, seed)
    return ds, fivecal.identify(ds, list(TRUTH), fix=FIXED)


def test_multilateration_recovers_machine_stations_and_dead_lengths_within_3_sigma(machine):
    ds, r = _fit(machine, 3)
    assert r.verdict == "ok", (r.verdict, r.adequacy)
    full = {**TRUTH, **SETUP}
    for n in r.estimated:
        assert abs(r.values[n] - full.get(n, 0.0)) < 3 * r.std[n], (n, r.values[n], full.get(n, 0.0), r.std[n])
    # Station positions, dead lengths and reflector offsets: the default setup.
    want = {f"instrument.{s}.{f}" for s in STATIONS for f in ("x", "y", "z", "length")}
    want |= {"instrument.tracer.tool_x", "instrument.tracer.tool_z"} | {f"instrument.tracer.work_{f}" for f in "xyz"}
    assert want <= set(r.estimated)


def test_coverage_of_the_distance_fit_over_100_simulations(machine):
    inside1 = inside2 = total = 0
    full = {**TRUTH, **SETUP}
    for seed in range(100):
        _, r = _fit(machine, 300 + seed)
        for n in list(TRUTH) + list(SETUP):
            z = abs(r.values[n] - full[n]) / r.std[n]
            total += 1
            inside1 += z < 1.0
            inside2 += z < 1.96
    assert 0.62 <= inside1 / total <= 0.74, inside1 / total
    assert 0.92 <= inside2 / total <= 0.98, inside2 / total


@pytest.mark.parametrize("stations", [["L1"], ["L1", "L2"]])
def test_too_few_stations_are_reported_undetermined_not_a_confident_number(machine, stations):
    rng = np.random.default_rng(5)
    setup = {k: v for k, v in SETUP.items()
             if not k.startswith(tuple(f"instrument.{s}." for s in STATIONS if s not in stations))}
    ds = fivecal.simulate(machine, _plan(rng, stations=stations), errors=TRUTH, setup=setup, sigma=NOISE, seed=5)
    with pytest.raises(ValueError, match=r"not determined.*confounded with the setup"):
        fivecal.identify(ds, list(TRUTH), fix=FIXED)
    with pytest.warns(Warning, match="did not determine"):
        r = fivecal.identify(ds, list(TRUTH), fix=FIXED, allow_unidentifiable=True)
    assert r.unidentifiable, "too few stations cannot fix the table side's errors"
    assert any(n.startswith("instrument.tracer.work_") for g in r.unidentifiable for n in g), r.unidentifiable


def test_file_round_trip_and_bad_fields(machine):
    doc = _data(machine, 1, n=2).to_dict()
    o = doc["observations"][0]
    assert o["type"] == "distance" and o["station"] == "L1" and "setup" not in o
    assert o["station_position"] == STATIONS["L1"] and o["dead_length"] == DEAD["L1"]
    assert "instrument" not in o  # the default tracer
    again = fivecal.Dataset.from_dict(json.loads(json.dumps(doc)))
    assert again.to_dict()["observations"] == doc["observations"]
    for field, value, words in (("station", "L.1", "station"), ("reading", "x", "reading"),
                                ("station_position", [0, 0], "station_position"),
                                ("dead_length", float("nan"), "dead_length"),
                                ("instrument", "", "instrument"), ("stations", "L1", "stations"),
                                ("sigma", [0.001, 0.001], "sigma")):
        bad = json.loads(json.dumps(doc))
        bad["observations"][1][field] = value
        with pytest.raises(ValueError, match=words):
            fivecal.Dataset.from_dict(bad)
    for missing in ("reading", "station_position", "station"):
        bad = json.loads(json.dumps(doc))
        del bad["observations"][1][missing]
        with pytest.raises(ValueError, match=r"observations\[1\]\." + missing):
            fivecal.Dataset.from_dict(bad)


def test_a_station_named_like_a_tracker_is_refused(machine):
    # Its parameters instrument.L1.x|y|z would be a station's position and a
    # tracker's origin at once.
    doc = _data(machine, 1, n=2).to_dict()
    n = len(doc["observations"])
    doc["observations"].append({"type": "point", "instrument": "L1", "target": "tool", "target_point": [0, 0, 150],
                                "axes": doc["observations"][0]["axes"], "measured": [0, 0, 0]})
    with pytest.raises(ValueError, match=rf"observations\[{n}\]\.instrument: .L1. is also the station of "
                                         r"observations\[0\]"):
        fivecal.Dataset.from_dict(doc)


def test_bad_input_campaign_on_pose_distance_and_instruments(machine):
    # Every leaf of a dataset of pose and distance observations with an
    # "instruments" declaration replaced in turn by hostile values: refused
    # with a ValueError naming the field, or accepted.
    from test_bad_input_campaign import _campaign, _check

    from test_pose_kind import _plan as pose_plan, NOISE as POSE_NOISE, SETUP as POSE_SETUP

    rng = np.random.default_rng(4)
    plan = _plan(rng, n=1) + pose_plan(rng, n=1)
    doc = fivecal.simulate(machine, plan, errors=TRUTH, setup={**SETUP, **POSE_SETUP},
                           sigma={**NOISE, **POSE_NOISE}, seed=4).to_dict()
    for o in doc["observations"][:3]:
        del o["sigma"]
    doc["instruments"] = {"L1": {"sigma": 0.002}, "T1": {"sigma": [0.01, 0.01, 0.02, 1e-4, 1e-4, 2e-4]}}
    fivecal.Dataset.from_dict(doc)
    _check(*_campaign(doc, fivecal.Dataset.from_dict, sample=60, seed=5))
