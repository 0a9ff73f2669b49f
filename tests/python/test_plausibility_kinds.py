"""The magnitude checks know every registered kind: their type codes come
from the registry, and the positions of the kinds beyond the probe touches
and ball samples (a station of a laser tracer, a tracker's pose, a target
point) get the same µm check as the machine axes."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import fivecal
from fivecal import _core, plausibility
import test_distance_kind as D


def test_every_key_of_every_registered_kind_is_classified():
    known = set(plausibility.POSITION_KEYS) | set(plausibility.LENGTH_KEYS) | set(plausibility.OTHER_KEYS)
    for k in _core.observation_kinds():
        missing = (set(k["json_keys"]) | set(k["plan_keys"])) - known
        assert not missing, (k["name"], missing)


def _distance_doc(station_scale: float) -> dict:
    # The dataset of the distance kind's test, its stations' positions scaled
    # (x 1000: given in µm).
    m = fivecal.Machine.from_dict(D.MACHINE)
    d = D._data(m, 4, n=4).to_dict()
    for o in d["observations"]:
        o["station_position"] = [x * station_scale for x in o["station_position"]]
    return d


def test_a_station_position_in_um_is_flagged_on_load_and_in_a_plan():
    # Stations up to 18 m away: beyond the 10 m at which an axis position
    # already draws the warning (a position in the wrong unit).
    d = _distance_doc(13.0)
    with pytest.warns(fivecal.UnitsWarning, match=r"observations\[\d+\]\.station_position\[\d\] = .* mm is beyond 10 m"):
        fivecal.Dataset.from_dict(d)
    plan = [{k: v for k, v in o.items() if k not in ("reading", "id")} for o in d["observations"]]
    with pytest.warns(fivecal.UnitsWarning, match=r"plan\[\d+\]\.station_position\[\d\]"):
        plausibility.check_plan(fivecal.Machine.from_dict(D.MACHINE), plan)


def test_plausible_stations_pass_quietly():
    d = _distance_doc(1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = fivecal.Dataset.from_dict(d)
    assert len(ds) == len(d["observations"])


def test_dict_and_loaded_columns_agree_on_every_kind_code():
    # a dict dataset's observations get the core's type codes, whatever the kind
    d = _distance_doc(1.0)
    ds = fivecal.Dataset.from_dict(d)
    m = ds.machine
    cols = plausibility._dict_columns(m, d["observations"], d["artefact"])
    assert np.array_equal(cols["type"], ds._core.columns()["type"])
    assert (cols["type"] == plausibility._code("distance")).all()
