"""What follows the C++ registry of observation kinds instead of naming the
kinds: the simulator's noise classes (a spec's sigma, a plan around recorded
data) and the kinds the dataset and spec schemas accept. A new kind then
needs no edit outside its own files."""
from __future__ import annotations

import copy

import numpy as np
import pytest

import fivecal
from fivecal import _core, schema
from fivecal.uncertainty import simulation_plan

from shared_machines import TABLE_HEAD as MACHINE  # noqa: E402


# The tracker pose and target offsets are known here: the test is about the noise.
FIXED = [f"instrument.T1.{f}" for f in ("x", "y", "z", "a", "b", "c", "work_x", "work_y", "work_z")]


def _point_plan(n=12):
    rng = np.random.default_rng(0)
    return [{"type": "point", "instrument": "T1", "target": "work", "target_point": [120, 40, 20],
             "axes": {"X": float(rng.uniform(-100, 100)), "Y": float(rng.uniform(-100, 100)),
                      "Z": float(rng.uniform(-50, 50)), "B": float(rng.uniform(-40, 40)),
                      "C": float(rng.uniform(0, 360))},
             "instrument_origin": [1500.0, -200.0, 300.0]} for _ in range(n)]


def test_noise_classes_are_the_kinds_with_probe_touches_shared():
    kinds = _core.observation_kinds()
    classes = _core.noise_classes()
    assert classes[0] == "probe"
    assert set(classes) == {c for k in kinds for c in k["noise_classes"]}
    assert all(k["noise_class"] == k["noise_classes"][0] for k in kinds)
    assert {c for k in kinds if k["name"] == "pose" for c in k["noise_classes"]} == {"pose", "pose_angle"}
    assert {k["name"] for k in kinds if k["noise_class"] == "probe"} >= {"facet", "sphere"}


def test_a_plan_around_recorded_point_data_draws_the_point_noise():
    # The plan around a dataset used to know probe, dbb and ball3d levels
    # only: tracker rows got no noise at all.
    m = fivecal.Machine.from_dict(MACHINE)
    ds = fivecal.simulate(m, _point_plan(), errors={"EX0C": 0.01}, sigma={"point": 0.004}, seed=1)
    plan, _ = simulation_plan(ds, estimate=["EX0C"], fix=FIXED, sigma={"point": 0.004})
    assert plan.num_inputs == 36
    assert np.allclose(plan.input_sigma, 0.004)
    plan, fit = simulation_plan(ds, estimate=["EX0C"], fix=FIXED)  # the fit's residual sigma, for every class
    assert np.allclose(plan.input_sigma, fit.sigma) and fit.sigma > 0
    with pytest.raises(ValueError, match=r"sigma\.pint: unknown key \(probe, .*point"):
        simulation_plan(ds, estimate=["EX0C"], fix=FIXED, sigma={"pint": 0.004})


def test_every_noise_class_is_a_key_of_a_spec_sigma():
    s = schema.load_schema("spec")
    assert set(s["properties"]["sigma"]["then"]["properties"]) == set(_core.noise_classes())
    m = fivecal.Machine.from_dict(MACHINE)
    with pytest.raises(ValueError, match=r"sigma.*pint"):
        fivecal.simulate(m, _point_plan(), sigma={"pint": 0.004})


def test_the_schemas_list_every_registered_kind():
    names = [k["name"] for k in _core.observation_kinds()]
    for kind, item in (("dataset", "observation"), ("spec", "plan_item")):
        s = schema.load_schema(kind)["$defs"][item]
        assert s["properties"]["type"]["enum"] == names
        described = {b["if"]["properties"]["type"]["const"] for b in s["allOf"]}
        assert described == set(names)


def test_a_kind_no_schema_file_describes_gets_its_keys_from_the_registry():
    # The shipped file minus its point block stands for a kind added after
    # the file was written.
    raw = copy.deepcopy(schema.load_schema.__wrapped__("dataset"))
    obs = raw["$defs"]["observation"]
    obs["properties"]["type"]["enum"].remove("point")
    obs["allOf"] = [b for b in obs["allOf"] if b["if"]["properties"]["type"]["const"] != "point"]
    out = schema._with_registered_kinds("dataset", raw)
    block = [b for b in out["$defs"]["observation"]["allOf"] if b["if"]["properties"]["type"]["const"] == "point"]
    assert len(block) == 1
    then = block[0]["then"]
    point = [k for k in _core.observation_kinds() if k["name"] == "point"][0]
    assert then["additionalProperties"] is False
    assert set(then["properties"]) == set(point["json_keys"])
    assert "point" in out["$defs"]["observation"]["properties"]["type"]["enum"]


def test_setup_angles_are_shown_in_microradians():
    # Every setup parameter used to be shown in µm, the tracker's angles too.
    from fivecal.units import display_scale

    assert display_scale("instrument.T1.a") == (1e6, "µrad")
    assert display_scale("instrument.T1.x") == (1e3, "µm")
    assert display_scale("instrument.T1.work_x") == (1e3, "µm")
    assert display_scale("sphere.S1.x") == (1e3, "µm")
    assert display_scale("tip.z") == (1e3, "µm")
