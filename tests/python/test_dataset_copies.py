"""Dataset.to_dict() hands out the caller's own copy: editing it never
changes the dataset (whose core, what the fit sees, would not follow), and
the shared views observations / artefact refuse edits."""
from __future__ import annotations

import copy
import json
import pickle

import pytest

import fivecal

MACHINE = {"name": "xyzbc", "topology": "wCBfXYZt",
           "axes": {"C": {"type": "rotary", "direction": [0, 0, 1]},
                    "B": {"type": "rotary", "direction": [0, 1, 0]},
                    "X": {"type": "linear", "direction": [1, 0, 0]},
                    "Y": {"type": "linear", "direction": [0, 1, 0]},
                    "Z": {"type": "linear", "direction": [0, 0, 1]}},
           "tool": {"tip": [0, 0, 100]}}


@pytest.fixture()
def ds():
    plan = [{"type": "sphere", "target": "S1", "axes": {"B": b, "C": c}, "normal": n}
            for b in (0.0, 30.0) for c in (0.0, 90.0) for n in ([0, 0, 1], [1, 0, 0], [0, 1, 0])]
    return fivecal.simulate(MACHINE, plan, artefact={"spheres": [{"id": "S1", "center": [0, 0, 50],
                                                                    "radius": 10.0}]},
                            tip_radius=2.0, seed=1)


def test_editing_to_dict_leaves_the_dataset_alone(ds, tmp_path):
    before = json.dumps(ds.to_dict(), sort_keys=True)
    d = ds.to_dict()
    d["observations"][0]["axes"]["X"] += 5.0
    d["observations"].pop()
    d["artefact"]["spheres"][0]["radius"] = 99.0
    d["probe"]["tip_radius"] = 7.0
    assert json.dumps(ds.to_dict(), sort_keys=True) == before
    assert ds.observations[0]["axes"]["X"] == json.loads(before)["observations"][0]["axes"]["X"]
    assert ds.artefact["spheres"][0]["radius"] == 10.0
    # what is saved is the dataset, not the caller's edits
    fivecal.save_dataset(ds, tmp_path / "d.json")
    assert json.dumps(fivecal.load_dataset(tmp_path / "d.json").to_dict(), sort_keys=True) == before
    # the edited copy is a dataset of its own (its new radius no longer fits the touches)
    with pytest.warns(fivecal.UnitsWarning):
        assert len(fivecal.Dataset.from_dict(d)) == len(ds) - 1


def test_shared_views_refuse_edits_and_copy_to_plain_data(ds):
    with pytest.raises(TypeError, match="read-only.*to_dict"):
        ds.observations[0]["axes"]["X"] = 1.0
    with pytest.raises(TypeError, match="read-only"):
        ds.observations.append({})
    with pytest.raises(TypeError, match="read-only"):
        ds.artefact["spheres"][0].update(radius=1.0)
    # they read, compare and serialise as plain dicts and lists
    o = ds.observations[0]
    assert isinstance(o, dict) and o == ds.to_dict()["observations"][0]
    assert json.loads(json.dumps(ds.observations)) == ds.to_dict()["observations"]
    # a copy is the caller's to edit
    c = copy.deepcopy(ds.observations)
    c[0]["axes"]["X"] = 1.0
    p = pickle.loads(pickle.dumps(ds.artefact))
    p["spheres"][0]["radius"] = 1.0
    assert ds.artefact["spheres"][0]["radius"] == 10.0
