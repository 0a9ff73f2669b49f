"""Which simulator noise levels are in rad is said once, by the kinds' rows
(each row's unit and noise class): the C++ simulator and the Python
uncertainty layer both ask the registry instead of each reading it from a
"*_angle" name."""
from __future__ import annotations

import pytest

from fivecal import _core, uncertainty


def test_the_registry_gives_each_noise_class_the_unit_of_its_rows():
    units = _core.noise_class_units()
    assert set(units) == set(_core.noise_classes())
    seen = {}
    for k in _core.observation_kinds():
        assert len(k["row_units"]) == len(k["row_noise_classes"]) == k["rows"]
        assert list(dict.fromkeys(k["row_noise_classes"])) == list(k["noise_classes"])
        for u, c in zip(k["row_units"], k["row_noise_classes"]):
            assert seen.setdefault(c, u) == u, (k["name"], c)  # one unit per class
    assert seen == units
    assert units["pose_angle"] == "rad" and units["pose"] == "mm" and units["probe"] == "mm"


def test_uncertainty_takes_the_rad_classes_from_the_registry(monkeypatch):
    # A class in rad whatever its name: the Python layer follows the registry.
    fake = dict(_core.noise_class_units(), distance="rad")
    monkeypatch.setattr(_core, "noise_class_units", lambda: fake)
    levels = uncertainty._noise_levels(None, 0.001, 5e-5)
    assert levels["distance"] == 5e-5 and levels["pose_angle"] == 5e-5 and levels["probe"] == 0.001
    # a number (mm) leaves the rad classes at their default
    assert uncertainty._noise_levels(0.002, 0.001, 5e-5)["distance"] == 5e-5
    with pytest.raises(ValueError, match="sigma.distance: must be a finite number >= 0 rad"):
        uncertainty._noise_levels({"distance": -1.0}, 0.001, 5e-5)
