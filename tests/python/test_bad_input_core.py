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


# ---------------------------------------------------------------------------
# directions of any finite scale; every path (dict, file) the same (issue #27)
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("axis, direction, unit", [
    ("X", [-1e308, -1e308, 0], [-2 ** -0.5, -2 ** -0.5, 0.0]),  # the squared norm overflows
    ("X", [1.7e308, 1.7e308, 1.7e308], [3 ** -0.5] * 3),       # so does the norm itself
    ("X", [5e-324, 0, 0], [1.0, 0.0, 0.0]),                     # subnormal: its square is 0
    ("B", [0, -1e-200, 0], [0.0, -1.0, 0.0]),
    ("B", [0, -1e308, -1e308], [0.0, -2 ** -0.5, -2 ** -0.5]),
    ("S", [1e308, 0, 1e308], [2 ** -0.5, 0.0, 2 ** -0.5]),
])
def test_axis_direction_of_any_finite_scale_is_a_unit_vector_on_every_path(tmp_path, axis, direction, unit):
    m = copy.deepcopy(HU40T)
    m["axes"][axis]["direction"] = direction
    p = tmp_path / "m.json"
    p.write_text(json.dumps(m))
    for machine in (fivecal.Machine.from_dict(m), fivecal.Machine.load(p)):
        got = next(a["direction"] for a in machine.axes if a["name"] == axis)
        assert np.allclose(got, unit, atol=1e-15), (got, unit)


@pytest.mark.parametrize("direction, message", [
    ([0, 0, 0], r"machine\.axes\.Z\.direction: zero vector"),
    ([0, float("nan"), 1], r"machine\.axes\.Z\.direction\[1\]: .*not finite"),
])
def test_a_zero_or_non_finite_axis_direction_is_refused_naming_it(direction, message):
    m = copy.deepcopy(HU40T)
    m["axes"]["Z"]["direction"] = direction
    with pytest.raises(ValueError, match=message):
        fivecal.Machine.from_dict(m)


def test_inverse_tool_axes_of_any_scale_and_points_out_of_range():
    m = fivecal.Machine.from_dict(HU40T)
    p = m.tool_point({"X": [10.0], "Y": [20.0], "Z": [-5.0], "B": [30.0], "C": [40.0]})
    _, a = m.tool_pose({"X": [10.0], "Y": [20.0], "Z": [-5.0], "B": [30.0], "C": [40.0]})
    # the tool axis scaled past the square root of the largest double: still that axis
    q = m.inverse(p, tool_axes=a * 1e308, start={"X": 0, "Y": 0, "Z": 0, "B": 20, "C": 30})
    assert q["B"][0] == pytest.approx(30.0) and q["C"][0] == pytest.approx(40.0)
    with pytest.raises(ValueError, match=r"tool_axes\[0\]: zero vector"):
        m.inverse(p, tool_axes=[[0, 0, 0]])
    with pytest.raises(ValueError, match=r"points\[0\]\[0\].*implausible"):
        m.inverse([[1e308, 0, 0]])


# ---------------------------------------------------------------------------
# errors= names: only set-up parameter names are skipped (issue #27)
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("name, hint", [
    ("EX0C.x", '"EX0C"'),        # a machine parameter with a stray component
    ("EX0c", '"EX0C"'),
    ("tip.q", '"tip.x"'),
    ("sphere.S1.q", None),       # a set-up kind, but no such field
    ("facet", None),
    ("foo.bar", None),
])
def test_an_unknown_error_name_is_refused_naming_it(name, hint):
    m = fivecal.Machine.from_dict(HU40T)
    with pytest.raises(ValueError) as e:
        m.tool_point(AXES, errors={name: 1e-3})
    assert str(e.value).startswith(f"errors.{name}: unknown parameter")
    if hint:
        assert f"did you mean {hint}" in str(e.value)


def test_set_up_parameters_of_a_result_are_skipped():
    m = fivecal.Machine.from_dict(HU40T)
    base = m.tool_point(AXES, errors={"EX0C": 1e-3})
    setup = {"facet.F3": 0.01, "sphere.S1.x": 0.02, "sphere.S1.r": 0.01, "dbb.length": 0.1,
             "dbb.A1.tool.x": 0.1, "ball3d.R1.table.z": 0.1, "instrument.T1.a": 0.001}
    assert np.array_equal(m.tool_point(AXES, errors={"EX0C": 1e-3, **setup}), base)


# ---------------------------------------------------------------------------
# every array argument names its field and index (issue #27)
# ---------------------------------------------------------------------------
AX3 = {"X": [0.0, 1.0], "Y": [0.0, 0.0], "Z": [0.0, 0.0], "B": [0.0, 0.0], "C": [0.0, 0.0]}


@pytest.mark.parametrize("call, message", [
    (lambda m: m.tool_point({**AX3, "X": ["a", 0]}), r"^axes\.X\[0\]: expected a number, got 'a'"),
    (lambda m: m.tool_point({**AX3, "Y": [0, None]}), r"^axes\.Y\[1\]: expected a number, got None"),
    (lambda m: m.tool_point({**AX3, "Z": "10"}), r"^axes\.Z: expected a number"),
    (lambda m: m.tool_point({**AX3, "B": [True, False]}), r"^axes\.B\[0\]: expected a number, got True"),
    (lambda m: m.tool_point({**AX3, "C": [0, 1j]}), r"^axes\.C\[1\]: expected a number"),
    (lambda m: m.tool_point({**AX3, "X": [[0, 1], [2]]}), r"^axes\.X: rows of different lengths"),
    (lambda m: m.tool_point({**AX3, "X": [0, float("nan")]}), r"^axes\.X\[1\]: value is not finite"),
    (lambda m: m.tool_point({**AX3, "X": [0, 10 ** 400]}), r"^axes\.X\[1\]: .*out of the range"),
    (lambda m: m.tool_point(AX3, directions={"X": [1, "+"]}), r"^directions\.X\[1\]: expected a number"),
    (lambda m: m.tool_point(AX3, directions={"X": [1, 2]}), r"^directions\.X\[1\]: values must be -1, 0 or \+1"),
    (lambda m: m.tool_point(AX3, errors={"EX0C": "1e-3"}), r"^errors\.EX0C: expected a number"),
    (lambda m: m.tool_point(AX3, errors={"EX0C": [1e-3]}), r"^errors\.EX0C: expected a number"),
    (lambda m: m.tool_point(AX3, errors={"EX0C": float("inf")}), r"^errors\.EX0C: value is not finite"),
    (lambda m: m.tool_point(AX3, tip=[0, 0]), r"^tip: expected 3 numbers"),
    (lambda m: m.tool_point(AX3, tip=[0, "z", 0]), r"^tip\[1\]: expected a number"),
    (lambda m: m.inverse([[0, 0, "a"]]), r"^points\[0\]\[2\]: expected a number"),
    (lambda m: m.inverse([[0, 0, 0], [0, 0]]), r"^points: rows of different lengths"),
    (lambda m: m.inverse([[0, 0, 0]], tool_axes=[[0, float("nan"), 1]]), r"^tool_axes\[0\]\[1\]: value is not finite"),
    (lambda m: m.inverse([[0, 0, 0]], tool_axes=[[0, 1]]), r"^tool_axes: expected shape"),
    (lambda m: m.inverse([[0, 0, 0]], start={**ZERO, "B": "x"}), r"^start\.B: expected a number"),
])
def test_bad_array_values_name_their_field_and_index(call, message):
    m = fivecal.Machine.from_dict(HU40T)
    with pytest.raises(ValueError, match=message):
        call(m)


def test_ball_bar_geometry_past_the_machine_size_is_refused_naming_it():
    """Norms of 1e308 mm overflow: the four-step plan said the machine could
    not place the ball, the Wang path reached inverse kinematics as inf."""
    from fivecal.demo import example_machine_path
    from fivecal.procedures import dbb

    c600u = fivecal.Machine.load(example_machine_path("c600u"))
    with pytest.raises(ValueError, match=r"four-step plan\.tool_ball\[0\]: .*implausible"):
        dbb.four_step_plan(c600u, tool_ball=[-1e308, -1e308, 0])
    with pytest.raises(ValueError, match=r"four-step plan\.extended_length: .*implausible"):
        dbb.four_step_plan(c600u, extended_length=1e308)
    vmc = fivecal.Machine.load(example_machine_path("vmc0656"))
    with pytest.raises(ValueError, match=r"wang path\.table_ball\[0\]: .*implausible"):
        dbb.wang_path(vmc, table_ball=[1e308, 1e308, 0])
