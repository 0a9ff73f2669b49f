"""A small bad-input campaign run on every test: every leaf of a real
dataset, machine and simulation spec is replaced in turn by hostile values
(NaN, infinity, a huge number, a string, null, a nested object, a negative
number) and every object gets an unknown key. Loading or simulating must
either accept the value (when it is a legitimate one) or refuse it with a
ValueError, never another exception, and at least 97% of the refusals must
name the field (its key or its index path)."""
from __future__ import annotations

import copy
import json
import math
import os
import random

import pytest

import fivecal
from fivecal.procedures import tango

HOSTILE = [math.nan, math.inf, 1e308, "x", None, {"a": 1}, -1.0, [1, 2]]


def _leaves(doc, path=()):
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _leaves(v, path + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _leaves(v, path + (i,))
    else:
        yield path


def _objects(doc, path=()):
    if isinstance(doc, dict):
        yield path
        for k, v in doc.items():
            yield from _objects(v, path + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _objects(v, path + (i,))


def _set(doc, path, value):
    d = doc
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value


def _names_field(msg: str, path) -> bool:
    """The message names the field: its last key, or its index with the key above it."""
    keys = [str(k) for k in path if isinstance(k, str)]
    idx = [k for k in path if isinstance(k, int)]
    if keys and keys[-1] in msg:
        return True
    return bool(idx) and f"[{idx[-1]}]" in msg


def _campaign(doc, load, sample, seed):
    rng = random.Random(seed)
    leaves = list(_leaves(doc))
    cases = [(p, v) for p in rng.sample(leaves, min(sample, len(leaves))) for v in HOSTILE]
    objs = list(_objects(doc))
    cases += [(p + ("dirction",), 1) for p in rng.sample(objs, min(sample // 4, len(objs)))]
    refused = named = 0
    unnamed = []
    for path, value in cases:
        bad = copy.deepcopy(doc)
        _set(bad, path, value)
        try:
            load(bad)
        except ValueError as e:
            refused += 1
            if _names_field(str(e), path):
                named += 1
            else:
                unnamed.append((path, value, str(e)[:160]))
        # Any other exception type propagates and fails the test.
    return refused, named, unnamed


def _check(refused, named, unnamed):
    assert refused > 0
    assert named / refused >= 0.97, (named, refused, unnamed[:10])


def test_dataset_campaign():
    ds = tango.hu40t_dataset(sigma=0.0006)
    doc = ds.to_dict()
    doc["observations"] = doc["observations"][:40] + doc["observations"][-4:]
    _check(*_campaign(doc, fivecal.Dataset.from_dict, sample=120, seed=1))


def test_machine_campaign():
    doc = json.loads(json.dumps(tango.HU40T_MACHINE))
    _check(*_campaign(doc, fivecal.Machine.from_dict, sample=60, seed=2))


def test_spec_campaign():
    with open(os.path.join(os.path.dirname(__file__), "..", "data", "tango_thin_spec.json")) as f:
        doc = json.load(f)
    if isinstance(doc.get("machine"), str):
        pytest.skip("spec refers to a machine file")
    doc["plan"] = doc["plan"][:20]

    def run(d):
        fivecal.simulate(d["machine"], d["plan"], errors=d.get("errors"), artefact=d.get("artefact"),
                         tip_radius=d.get("probe", {}).get("tip_radius", 3.0), sigma=d.get("sigma", 0.0),
                         seed=d.get("seed", 0), setup=d.get("setup"))

    _check(*_campaign(doc, run, sample=80, seed=3))
