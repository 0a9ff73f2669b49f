"""Property-based tests of every loader (issue 12, "What to build" 2): random
valid documents load; random mutations (a wrong type, NaN, a missing key, an
unknown key, a huge number) either load or raise one ValueError line naming
where the problem is, never another exception; simulate -> save_dataset ->
load_dataset keeps the observations."""
import copy
import json
import math
import os
import warnings

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fivecal
from fivecal import schema
from fivecal.compensation import load_errors

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
MACHINES = [os.path.join(ROOT, "examples", "machines", f"{n}.json") for n in ("hu40t", "c600u", "kx8", "vmc0656")]
SPHERES = os.path.join(ROOT, "examples", "specs", "hu40t_spheres.json")

SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def load(path):
    with open(path) as f:
        return json.load(f)


BASE_SPEC = load(SPHERES)
BASE_SPEC["machine"] = load(MACHINES[0])


def _simulate(spec, plan, seed=1, sigma=0.0006):
    return fivecal.simulate(spec["machine"], plan, errors=spec["errors"], artefact=spec["artefact"],
                            tip_radius=spec["probe"]["tip_radius"], sigma=sigma, seed=seed, setup=spec["setup"])


BASE_DATASET = _simulate(BASE_SPEC, BASE_SPEC["plan"][:30]).to_dict()
BASE_DATASET["observations"].append(
    {"type": "dbb", "setup": "A1", "axes": {a: 0.0 for a in "XYZBC"}, "direction": {"X": 1}, "reading": 0.001,
     "length": 100.0, "tool_ball": [0, 0, 100], "table_ball": [0, 0, 0]})
with warnings.catch_warnings():  # the loaders take any result file, usable or not: only its shape matters
    warnings.simplefilter("ignore", fivecal.FitWarning)
    BASE_RESULT = json.loads(fivecal.identify(BASE_DATASET, estimate=["EX0C", "EY0C"], fix=["tip.z"]).to_json())


# ---- mutations -------------------------------------------------------------------
def _paths(node, prefix=()):
    """Every (path, value) in a document, the root included."""
    out = [(prefix, node)]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, prefix + (i,))
    return out


BAD_VALUES = [float("nan"), float("inf"), -float("inf"), 1e308, -1e308, 2 ** 70, -2 ** 63, 0, -1, 1.5, "",
              "x", True, None, [], {}, [1, 2], {"a": 1}]


# Objects whose keys are names, not fixed keys (a misspelt name there is the
# C++ loader's or the fit's business, not the schema's).
FREE_MAPS = {"errors", "setup", "priors", "parameters"}
NEVER_KEYS = ["dirction", "artifact", "Q", "priors ", "_x"]


@st.composite
def mutated(draw, doc):
    """A copy of ``doc`` with one random change, the path it touched, and
    whether the change must be refused (an unknown or misspelt key)."""
    d = copy.deepcopy(doc)
    paths = _paths(d)
    path, value = draw(st.sampled_from(paths[1:]))
    parent = d
    for p in path[:-1]:
        parent = parent[p]
    key = path[-1]
    kind = draw(st.sampled_from(["value", "delete", "unknown", "rename"]))
    must_fail = False
    if kind == "value" or (kind in ("unknown", "rename") and not isinstance(parent, dict)):
        parent[key] = draw(st.sampled_from(BAD_VALUES))
    elif kind == "delete":
        del parent[key]
    elif kind == "unknown":
        new = draw(st.sampled_from(NEVER_KEYS + ["sigma", "id", "tip"]))
        parent[new] = draw(st.sampled_from([1, "a", [0, 0, 1], {}]))
        must_fail = new in NEVER_KEYS and not (len(path) > 1 and path[-2] in FREE_MAPS)
        path = path[:-1] + (new,)
    else:  # a misspelt key
        new = str(key)[:-1] + "_"
        parent[new] = parent.pop(key)
        must_fail = not (len(path) > 1 and path[-2] in FREE_MAPS)
        path = path[:-1] + (new,)
    return d, path, must_fail


def _named(message: str, path) -> bool:
    """The message names the place: one of the keys or indices on the mutated path."""
    words = {str(p) for p in path if isinstance(p, str)} | {f"[{p}]" for p in path if isinstance(p, int)}
    return any(w and w in message for w in words)


def _check_refusal(call, doc, path, must_fail=False):
    try:
        call(doc)
    except ValueError as e:
        msg = str(e)
        assert "\n" not in msg.strip(), msg
        assert _named(msg, path), (path, msg)
        assert "Traceback" not in msg and "jsonschema" not in msg, msg
        return False
    assert not must_fail, f"an unknown key at {path} was accepted"
    return True


# ---- machine ---------------------------------------------------------------------
@st.composite
def machines(draw):
    m = load(draw(st.sampled_from(MACHINES)))
    coord = st.floats(-500, 500, allow_nan=False)
    m["tool"] = {"tip": [draw(coord), draw(coord), draw(st.floats(0, 400))]}
    m["name"] = draw(st.text(min_size=1, max_size=10))
    for a in m["axes"].values():
        if a.get("type", "rotary") == "rotary" and "point" in a:
            a["point"] = [draw(coord) for _ in range(3)]
    if draw(st.booleans()):
        m["priors"] = {"EX0C": draw(st.floats(1e-6, 1.0)), "class:location_angle": 1e-4}
    return m


@SETTINGS
@given(machines())
def test_random_valid_machines_load(m):
    machine = fivecal.Machine.from_dict(m)
    assert machine.topology == m["topology"]


@SETTINGS
@given(st.data())
def test_mutated_machines_load_or_raise_a_named_value_error(data):
    d, path, must_fail = data.draw(mutated(load(data.draw(st.sampled_from(MACHINES)))))
    _check_refusal(fivecal.Machine.from_dict, d, path, must_fail)


@SETTINGS
@given(st.data())
def test_mutated_machine_files_load_or_raise_a_named_value_error(tmp_path_factory, data):
    d, path, must_fail = data.draw(mutated(load(MACHINES[0])))
    p = tmp_path_factory.mktemp("m") / "m.json"
    p.write_text(json.dumps(d))  # NaN and inf as Python writes them
    _check_refusal(lambda _: fivecal.Machine.load(p), d, path, must_fail)


# ---- dataset ---------------------------------------------------------------------
@st.composite
def datasets(draw):
    plan = draw(st.lists(st.sampled_from(BASE_SPEC["plan"]), min_size=1, max_size=25))
    ds = _simulate(BASE_SPEC, plan, seed=draw(st.integers(0, 2 ** 64 - 1)),
                   sigma=draw(st.sampled_from([0.0, 0.0006, 0.002])))
    return ds.to_dict()


@SETTINGS
@given(datasets())
def test_random_valid_datasets_load_and_round_trip(tmp_path_factory, d):
    p = tmp_path_factory.mktemp("ds") / "ds.json"
    fivecal.save_dataset(d, p)
    back = fivecal.load_dataset(p)
    assert back.observations == d["observations"]
    assert back.artefact == fivecal.Dataset.from_dict(d).artefact


@SETTINGS
@given(st.data())
def test_mutated_datasets_load_or_raise_a_named_value_error(tmp_path_factory, data):
    d, path, must_fail = data.draw(mutated(BASE_DATASET))
    _check_refusal(fivecal.Dataset.from_dict, d, path, must_fail)
    p = tmp_path_factory.mktemp("ds") / "ds.json"
    p.write_text(json.dumps(d))
    _check_refusal(lambda _: fivecal.load_dataset(p), d, path, must_fail)


def test_simulate_save_load_keeps_observation_ids_and_sigma(tmp_path):
    d = copy.deepcopy(BASE_DATASET)
    for i, o in enumerate(d["observations"]):
        o["id"] = f"touch-{i}"
        o["sigma"] = 0.0006 * (1 + i % 3)
    ds = fivecal.Dataset.from_dict(d)
    if "id" not in ds.observations[0]:
        pytest.xfail("the C++ core does not keep observation 'id' and 'sigma' yet (the loaders work adds them)")
    p = tmp_path / "ds.json"
    fivecal.save_dataset(ds, p)
    back = fivecal.load_dataset(p).observations
    assert [o["id"] for o in back] == [o["id"] for o in d["observations"]]
    assert [o["sigma"] for o in back] == [o["sigma"] for o in d["observations"]]


# ---- simulation spec / plan ------------------------------------------------------
def _simulate_spec(spec):
    """What `fivecal simulate` does with a spec document (the file kind first)."""
    schema.validate(spec, "spec")
    if not isinstance(spec.get("probe", {}), dict):
        raise AssertionError("schema let a non-object probe through")
    return fivecal.simulate(spec["machine"], spec["plan"], errors=spec.get("errors"), artefact=spec.get("artefact"),
                            tip_radius=spec.get("probe", {}).get("tip_radius", 0.0), sigma=spec.get("sigma", 0.0),
                            seed=spec.get("seed", 0), setup=spec.get("setup"))


SMALL_SPEC = copy.deepcopy(BASE_SPEC)
SMALL_SPEC["plan"] = SMALL_SPEC["plan"][:12]


@SETTINGS
@given(st.data())
def test_random_valid_specs_simulate(data):
    s = copy.deepcopy(SMALL_SPEC)
    s["plan"] = data.draw(st.lists(st.sampled_from(BASE_SPEC["plan"]), min_size=1, max_size=12))
    s["seed"] = data.draw(st.integers(0, 2 ** 64 - 1) | st.integers(0, 1000).map(float))
    s["sigma"] = data.draw(st.sampled_from([0.0, 0.001, {"probe": 0.001}]))
    assert len(_simulate_spec(s)) == len(s["plan"])


@SETTINGS
@given(st.data())
def test_mutated_specs_simulate_or_raise_a_named_value_error(data):
    d, path, must_fail = data.draw(mutated(SMALL_SPEC))
    _check_refusal(_simulate_spec, d, path, must_fail)


# ---- result ----------------------------------------------------------------------
MACHINE = fivecal.Machine.load(MACHINES[0])


@SETTINGS
@given(st.dictionaries(st.sampled_from(["EX0C", "EY0C", "EB0C", "EX0S", "tip.x", "sphere.S1.x"]),
                       st.floats(-0.1, 0.1, allow_nan=False), min_size=1))
def test_random_valid_results_load(tmp_path_factory, values):
    r = copy.deepcopy(BASE_RESULT)
    r["parameters"] = {k: {"value": v, "std": abs(v) / 10} for k, v in values.items()}
    p = tmp_path_factory.mktemp("r") / "result.json"
    p.write_text(json.dumps(r))
    errors = load_errors(str(p), MACHINE)
    assert errors == {k: v for k, v in values.items() if "." not in k}


@SETTINGS
@given(st.data())
def test_mutated_results_load_or_raise_a_named_value_error(tmp_path_factory, data):
    d, path, must_fail = data.draw(mutated(BASE_RESULT))
    p = tmp_path_factory.mktemp("r") / "result.json"
    p.write_text(json.dumps(d))
    ok = _check_refusal(lambda _: load_errors(str(p), MACHINE), d, path, must_fail)
    if ok:
        assert all(math.isfinite(v) for v in load_errors(str(p), MACHINE).values())
