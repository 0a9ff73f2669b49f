"""The probe-touch kinds (facet, sphere, cylinder) share one reading of their
target (ProbeTouchKind): an unknown target is named the same way, with the
artefact list it is missing from, whether a file is read or a plan simulated."""
from __future__ import annotations

import pytest

import fivecal

MACHINE = {"name": "xyz", "topology": "wfXYZt",
           "axes": {"X": {"type": "linear", "direction": [1, 0, 0]},
                    "Y": {"type": "linear", "direction": [0, 1, 0]},
                    "Z": {"type": "linear", "direction": [0, 0, 1]}},
           "tool": {"tip": [0, 0, 100]}}
ARTEFACT = {"facets": [{"id": "F1", "point": [0, 0, 0], "normal": [0, 0, 1]}],
            "spheres": [{"id": "S1", "center": [0, 0, 50], "radius": 10.0}],
            "cylinders": [{"id": "C1", "point": [0, 0, 0], "axis": [0, 0, 1], "radius": 20.0}]}
TARGET = {"facet": "F1", "sphere": "S1", "cylinder": "C1"}
WHERE = {"facet": ("point", [0, 0, 0]), "sphere": ("normal", [0, 0, 1]), "cylinder": ("point", [20, 0, 5])}


@pytest.mark.parametrize("kind", ["facet", "sphere", "cylinder"])
def test_an_unknown_target_is_named_with_its_artefact_list(kind):
    key, value = WHERE[kind]
    words = rf"target: unknown {kind} 'Z9' \(not among the artefact's {kind}s\)"
    with pytest.raises(ValueError, match=r"plan\[0\]\." + words):
        fivecal.simulate(MACHINE, [{"type": kind, "target": "Z9", "axes": {}, key: value}],
                         artefact=ARTEFACT, tip_radius=2.0)
    good = fivecal.simulate(MACHINE, [{"type": kind, "target": TARGET[kind], "axes": {}, key: value}],
                            artefact=ARTEFACT, tip_radius=2.0)
    d = good.to_dict()
    d["observations"][0]["target"] = "Z9"
    with pytest.raises(ValueError, match=r"observations\[0\]\." + words):
        fivecal.Dataset.from_dict(d)
