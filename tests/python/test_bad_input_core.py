"""Bad input at the core's boundary, seen from Python: every refusal is a
ValueError naming the field, every message decodes, and nothing implausible
reaches a fit. (The C++ side of the same checks is tests/cpp/test_loaders.cc.)"""
import copy
import json

import numpy as np
import pytest

import fivecal
from fivecal import _core

HU40T = {"name": "HU40T-like", "topology": "wCBXfZYSt",
         "axes": {"X": {"type": "linear", "direction": [-1, 0, 0]},
                  "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, -120]},
                  "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
                  "Z": {"type": "linear", "direction": [0, 0, 1]},
                  "Y": {"type": "linear", "direction": [0, 1, 0]},
                  "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]}},
         "tool": {"tip": [0, 0, 100]}}

AXES = {"X": 10.0, "Y": 20.0, "Z": -5.0, "B": 30.0, "C": 0.0, "S": 0.0}
ZERO = {"X": 0.0, "Y": 0.0, "Z": 0.0, "B": 0.0, "C": 0.0, "S": 0.0}  # the tool ball at its nominal place


def dataset():
    return {"machine": copy.deepcopy(HU40T), "probe": {"tip_radius": 3.0},
            "artefact": {"facets": [{"id": "F1", "point": [0, 0, 10], "normal": [0, 0, 1]}],
                         "spheres": [{"id": "S1", "center": [0, 0, 50], "radius": 12.7},
                                     {"id": "S2", "center": [100, 0, 50], "radius": 12.7}],
                         "scale_bars": [{"spheres": ["S1", "S2"], "length": 100.0}]},
            "observations": [
                {"type": "facet", "target": "F1", "axes": dict(AXES), "direction": {"X": 1, "Y": -1}},
                {"type": "sphere", "target": "S1", "axes": dict(AXES)},
                {"type": "dbb", "setup": "A1", "axes": dict(AXES), "reading": 0.001, "length": 100.0,
                 "tool_ball": [0, 0, 0], "table_ball": [0, 0, 100]}]}


def load_text(tmp_path, text, name="ds.json"):
    p = tmp_path / name
    p.write_text(text) if isinstance(text, str) else p.write_bytes(text)
    return fivecal.load_dataset(p)


def load(tmp_path, d):
    return load_text(tmp_path, json.dumps(d))


def test_sigma_and_id_survive_save_and_load(tmp_path):
    d = dataset()
    d["observations"][0]["sigma"] = 0.002
    d["observations"][0]["id"] = "first touch"
    d["observations"][2]["sigma"] = [0.0004]
    ds = load(tmp_path, d)
    fivecal.save_dataset(ds, tmp_path / "out.json")
    back = json.loads((tmp_path / "out.json").read_text())
    assert back["observations"][0]["sigma"] == 0.002
    assert back["observations"][0]["id"] == "first touch"
    assert back["observations"][2]["sigma"] == 0.0004
    assert "sigma" not in back["observations"][1]


@pytest.mark.parametrize("bad", [-2147483648, 2**32 + 1, 2**64 - 1, 0.5, 2])
def test_backlash_direction_outside_range_is_refused(tmp_path, bad):
    d = dataset()
    d["observations"][0]["direction"]["X"] = bad
    # the schema refuses first; the C++ loader (read directly) must refuse as well
    with pytest.raises(ValueError, match=r"observations\[0\]\.direction\.X: must be -1, 0 or \+1"):
        load(tmp_path, d)
    with pytest.raises(ValueError, match=r"observations\[0\]\.direction\.X: must be -1, 0 or \+1"):
        _core.Dataset.from_json(json.dumps(d))


def test_backlash_direction_integral_floats_are_accepted(tmp_path):
    d = dataset()
    d["observations"][0]["direction"] = {"X": 1.0, "Y": -1.0, "Z": 0.0}
    out = json.loads(load(tmp_path, d)._core.to_json())
    assert out["observations"][0]["direction"] == {"X": 1, "Y": -1}


def test_unknown_keys_get_did_you_mean(tmp_path):
    d = dataset()
    d["observations"][1]["dirction"] = {"X": 1}
    # what the user gets: the schema's message (path and did-you-mean) ...
    with pytest.raises(ValueError, match=r"dataset\.observations\[1\]\.dirction: unknown key; "
                                         r"did you mean 'direction'\?"):
        load(tmp_path, d)
    # ... and the C++ loader's own check behind it, read directly
    with pytest.raises(ValueError, match=r'dataset\.observations\[1\]: unknown key "dirction" '
                                         r'\(did you mean "direction"\?\)'):
        _core.Dataset.from_json(json.dumps(d))
    d = dataset()
    d["artifact"] = d.pop("artefact")
    with pytest.raises(ValueError, match=r"dataset\.artifact: unknown key; did you mean 'artefact'\?"):
        load(tmp_path, d)
    with pytest.raises(ValueError, match=r'unknown key "artifact" \(did you mean "artefact"\?\)'):
        _core.Dataset.from_json(json.dumps(d))


def test_simulate_unknown_plan_type_and_loader_checks():
    plan = [{"type": "dbbb", "setup": "A1"}]
    with pytest.raises(ValueError, match=r"plan\[0\]\.type: \"dbbb\" is not one of .*did you mean 'dbb'"):
        fivecal.simulate(HU40T, plan)  # the schema's message
    with pytest.raises(ValueError, match=r"plan\[0\]\.type: unknown type 'dbbb'.*did you mean \"dbb\""):
        _core.simulate(json.dumps({"machine": HU40T, "plan": plan}))  # the C++ check behind it
    dbb = {"type": "dbb", "setup": "A1", "axes": dict(ZERO), "length": 0.0,
           "tool_ball": [0, 0, 0], "table_ball": [0, 0, 100]}
    with pytest.raises(ValueError, match=r"plan\[0\]\.length"):
        fivecal.simulate(HU40T, [dbb])
    with pytest.raises(ValueError, match=r"plan\[0\]\.setup.*'\.'"):
        fivecal.simulate(HU40T, [dict(dbb, length=100.0, setup="A.1")])
    with pytest.raises(ValueError, match=r"plan\[0\]\.setup"):
        fivecal.simulate(HU40T, [dict(dbb, length=100.0, setup=3)])
    with pytest.raises(ValueError, match=r"sigma\.probe"):
        fivecal.simulate(HU40T, [dict(dbb, length=100.0)], sigma={"probe": "x"})


def test_simulated_noise_is_declared_in_the_dataset():
    dbb = {"type": "dbb", "setup": "A1", "axes": dict(ZERO), "length": 100.0,
           "tool_ball": [0, 0, 0], "table_ball": [0, 0, 100]}
    ds = fivecal.simulate(HU40T, [dbb], sigma={"dbb": 0.0003}, seed=1)
    assert json.loads(ds._core.to_json())["observations"][0]["sigma"] == 0.0003
    ds = fivecal.simulate(HU40T, [dbb], seed=1)
    assert "sigma" not in json.loads(ds._core.to_json())["observations"][0]


def test_parallel_linear_axes_and_no_axes_are_refused():
    m = copy.deepcopy(HU40T)
    m["axes"]["Y"]["direction"] = [1, 0, 0]
    with pytest.raises(ValueError, match=r"machine\.axes\.Y\.direction: parallel to linear axis X"):
        fivecal.Machine.from_dict(m)
    with pytest.raises(ValueError, match=r"machine\.topology.*no axes"):
        fivecal.Machine.from_dict({"topology": "wft", "axes": {}})


def test_overflowing_axis_direction_is_normalised():
    m = copy.deepcopy(HU40T)
    m["axes"]["Z"]["direction"] = [0, 0, 1.35e154]
    mm = fivecal.Machine.from_dict(m)
    p = mm.tool_point({"X": [0.0], "Y": [0.0], "Z": [10.0], "B": [0.0], "C": [0.0]})
    assert p[0, 2] == pytest.approx(110.0)  # Z moved the tool by 10 mm


def test_spindle_and_alias_together_are_refused(tmp_path):
    d = dataset()
    d["observations"][1]["axes"]["C1"] = 0.0
    with pytest.raises(ValueError, match=r"observations\[1\]\.axes: .*both 'S' and its alias 'C1'"):
        load(tmp_path, d)  # the schema's message
    with pytest.raises(ValueError, match=r'observations\[1\]\.axes: both "S" and its alias "C1"'):
        _core.Dataset.from_json(json.dumps(d))


@pytest.mark.parametrize("edit, field", [
    (lambda d: d["artefact"]["spheres"][0].update(radius=1e308), r"artefact\.spheres\[0\]\.radius"),
    (lambda d: d["observations"][2].update(length=1e308), r"observations\[2\]\.length"),
    (lambda d: d["observations"][2].update(reading=1e308), r"observations\[2\]\.reading"),
    (lambda d: d["observations"][0]["axes"].update(X=1e308), r"observations\[0\]\.axes\.X"),
    (lambda d: d["observations"][0]["axes"].update(B=1e308), r"observations\[0\]\.axes\.B"),
    (lambda d: d["artefact"]["facets"][0].update(point=[0, 1e308, 0]), r"artefact\.facets\[0\]\.point\[1\]"),
])
def test_implausible_magnitudes_are_refused(tmp_path, edit, field):
    d = dataset()
    edit(d)
    with pytest.raises(ValueError, match=field + r".*implausible"):
        load(tmp_path, d)


def test_tool_point_refuses_implausible_axis_values():
    m = fivecal.Machine.from_dict(HU40T)
    ax = {"X": [0.0], "Y": [0.0], "Z": [1e308], "B": [0.0], "C": [0.0]}
    with pytest.raises(ValueError, match=r"axes\.Z\[0\].*implausible"):
        m.tool_point(ax)


def test_scale_bar_from_a_sphere_to_itself(tmp_path):
    d = dataset()
    d["artefact"]["scale_bars"][0]["spheres"] = ["S1", "S1"]
    with pytest.raises(ValueError, match=r"scale_bars\[0\]\.spheres: joins sphere 'S1' to itself"):
        load(tmp_path, d)
    d["artefact"]["scale_bars"][0]["spheres"] = ["S1", 5]
    with pytest.raises(ValueError, match=r"scale_bars\[0\]\.spheres\[1\]"):
        load(tmp_path, d)


def test_malformed_and_mistyped_parameter_names():
    ds = fivecal.Dataset.from_dict(dataset())
    with pytest.raises(ValueError, match=r"did you mean \"EX0C\"\?"):
        fivecal.identify(ds, estimate=["EX0c"])
    with pytest.raises(ValueError, match=r"'EX0C\.x'"):
        fivecal.identify(ds, estimate=["EX0C.x"])


def test_deep_nesting_gives_a_short_named_message():
    with pytest.raises(ValueError) as e:
        _core.Dataset.from_json('{"machine": ' + "[" * 100000)
    assert len(str(e.value)) < 1000
    assert "nested deeper than" in str(e.value)
    text = '{"machine": ' + '{"a": ' * 5000 + "1" + "}" * 5001
    with pytest.raises(ValueError, match="nested deeper than"):
        _core.Dataset.from_json(text)


def test_messages_decode_for_non_utf8_input():
    m = copy.deepcopy(HU40T)
    m["topology"] = "wCéBXfZYSt"
    with pytest.raises(ValueError, match="unknown axis letter 'é'"):
        fivecal.Machine.from_dict(m)
    # Invalid UTF-8 bytes (an embedder passing raw file bytes): the message
    # escapes them instead of raising UnicodeDecodeError.
    raw_bytes = json.dumps(HU40T).encode().replace(b"wCBXfZYSt", b"wC\xffBXfZYSt")
    with pytest.raises(ValueError) as e:
        _core.Machine.from_json(raw_bytes)
    assert "\\xFF" in str(e.value)


@pytest.mark.parametrize("dirs", [{"X": [[1, 1, 1]]}, {"X": np.ones((3, 1))}, {"X": [1, 1]}])
def test_directions_of_the_wrong_shape_are_not_broadcast(dirs):
    m = fivecal.Machine.from_dict(HU40T)
    ax = {"X": [0.0, 1.0, 2.0], "Y": [0.0] * 3, "Z": [0.0] * 3, "B": [0.0] * 3, "C": [0.0] * 3}
    with pytest.raises(ValueError, match=r"directions\.X"):
        m.tool_point(ax, directions=dirs)
    with pytest.raises(ValueError, match=r"directions: expected a dict"):
        m.tool_point(ax, directions=[1, 1, 1])
