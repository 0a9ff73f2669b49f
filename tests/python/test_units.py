"""Units at the boundary (issue 12, units and radians item).

Must show: rotary values in radians warn once per axis in datasets, plans and
CSV traces; magnitudes that fit the wrong unit are refused when the evidence
does not depend on the nominal model, and warned about when a rough nominal
could explain them; units named in CSV headers are honoured.
"""
import copy
import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import fivecal
from fivecal.procedures import dbb, tango
from fivecal.units import column_unit, looks_like_radians

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
MACHINES = os.path.join(ROOT, "examples", "machines")


@pytest.fixture(scope="module")
def probe_dict():
    return tango.hu40t_dataset(seed=2).to_dict()


@pytest.fixture(scope="module")
def hu40t():
    return fivecal.Machine.load(os.path.join(MACHINES, "hu40t.json"))


def caught(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    return out, [x for x in w if issubclass(x.category, (fivecal.RadiansWarning, fivecal.UnitsWarning))]


# ---------------------------------------------------------------- heuristic
@pytest.mark.parametrize("values,expected", [
    (np.linspace(0, 2 * np.pi, 37), True),        # a sweep in radians
    ([0, np.pi / 2, np.pi], True),                 # indexations in radians
    ([1.5708], True),                              # pi/2 written out, even alone
    ([0, 0.5, 1], False),                          # ambiguous: could be degrees
    ([0, 0.001, 0.002], False),                    # tiny legitimate motions
    ([0.2], False), ([0, 30, 90], False), ([0, 1.25, 2.5], False),
    ([-90, 0, 1.5708], False),                     # beyond 2 pi: degrees
])
def test_radians_heuristic(values, expected):
    assert looks_like_radians(values) is expected


# ---------------------------------------------------------------- datasets
def test_dataset_rotary_radians_warn_once_per_axis(probe_dict, tmp_path):
    d = copy.deepcopy(probe_dict)
    for o in d["observations"]:
        for a in "BC":
            o["axes"][a] = float(np.radians(o["axes"][a]))
    p = tmp_path / "rad.json"
    p.write_text(json.dumps(d))
    _, w = caught(fivecal.load_dataset, p)
    rad = [x for x in w if issubclass(x.category, fivecal.RadiansWarning)]
    assert len([x for x in rad if ".B" in str(x.message)]) == 1
    assert len([x for x in rad if ".C" in str(x.message)]) == 1
    assert all(str(p) in str(x.message) for x in rad)
    # degrees: no warning of any kind
    _, w = caught(fivecal.Dataset.from_dict, probe_dict)
    assert w == []


def test_dataset_in_um_is_refused(probe_dict):
    d = copy.deepcopy(probe_dict)
    for o in d["observations"]:
        for a in "XYZ":
            o["axes"][a] *= 1000
    for s in d["artefact"]["spheres"]:
        s["center"] = [c * 1000 for c in s["center"]]
        s["radius"] *= 1000
    for f in d["artefact"]["facets"]:
        f["point"] = [c * 1000 for c in f["point"]]
    d["probe"]["tip_radius"] *= 1000
    with pytest.raises(ValueError, match=r"look like µm: divide by 1000"):
        fivecal.Dataset.from_dict(d)


def test_sphere_radius_given_as_diameter_is_refused(probe_dict):
    d = copy.deepcopy(probe_dict)
    d["artefact"]["spheres"][0]["radius"] *= 2
    with pytest.raises(ValueError, match=r"spheres\[0\] \('S1'\).*looks like the diameter; give radius 12.7"):
        fivecal.Dataset.from_dict(d)


def test_rough_nominal_is_not_refused(probe_dict):
    # a rotary centre 50 mm off in the machine file: a rough nominal, not a unit
    # error; the identification is what finds it, so at most a warning
    d = copy.deepcopy(probe_dict)
    d["machine"]["axes"]["B"]["point"] = [p + o for p, o in zip(d["machine"]["axes"]["B"].get(
        "point", [0, 0, 0]), [50.0, 0, 0])]
    ds, w = caught(fivecal.Dataset.from_dict, d)
    assert len(ds) == len(probe_dict["observations"])
    assert all(issubclass(x.category, fivecal.UnitsWarning) for x in w)


def test_facet_far_from_its_touches_warns(probe_dict):
    d = copy.deepcopy(probe_dict)
    f = d["artefact"]["facets"][0]
    f["point"] = [p + 20 * n for p, n in zip(f["point"], f["normal"])]
    _, w = caught(fivecal.Dataset.from_dict, d)
    assert any(f"'{f['id']}'" in str(x.message) and issubclass(x.category, fivecal.UnitsWarning) for x in w)


@pytest.fixture(scope="module")
def c600u():
    return fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))


@pytest.fixture(scope="module")
def dbb_dict(c600u):
    plan = dbb.four_step_plan(c600u, step=10.0)
    return fivecal.simulate(c600u, plan, sigma=0.0005, seed=1).to_dict()


def test_dbb_readings_in_um_are_refused(dbb_dict):
    d = copy.deepcopy(dbb_dict)
    for o in d["observations"]:
        o["reading"] = o["reading"] * 1000 + 5.0
    with pytest.raises(ValueError, match=r"observations\[\d+\]\.reading .* look like µm: divide by 1000"):
        fivecal.Dataset.from_dict(d)
    fivecal.Dataset.from_dict(dbb_dict)  # mm: accepted


def test_ball_arrays_in_um_are_refused(hu40t):
    axes = {a: np.zeros(5) for a in "XYZBC"}
    with pytest.raises(ValueError, match=r"readings\[\d\] .* divide by 1000"):
        fivecal.ball_dataset(hu40t, "dbb", axes, [0, 0, 100], [0, 0, 0], length=100,
                             readings=np.full(5, 12.0))
    with pytest.raises(ValueError, match=r"measured\[\d\] .* divide by 1000"):
        fivecal.ball_dataset(hu40t, "ball3d", axes, [0, 0, 100], [0, 0, 0], measured=np.full((5, 3), 30.0))
    fivecal.ball_dataset(hu40t, "ball3d", axes, [0, 0, 100], [0, 0, 0], measured=np.full((5, 3), 0.03))


def test_ball3d_observations_in_um_are_refused(hu40t):
    axes = {a: np.linspace(0, 40, 6) for a in "XYZBC"}
    ds = fivecal.ball_dataset(hu40t, "ball3d", axes, [0, 0, 100], [0, 0, 0], measured=np.full((6, 3), 0.02),
                              setup="R1")
    d = copy.deepcopy(ds.to_dict())
    d["observations"][3]["measured"] = [20.0, 15.0, -3.0]
    with pytest.raises(ValueError, match=r"observations\[3\]\.measured .* look like µm"):
        fivecal.Dataset.from_dict(d)


def test_plan_rotary_radians_warn(c600u):
    plan = dbb.four_step_plan(c600u, step=10.0)
    for p in plan:
        for a in ("A", "C"):
            p["axes"][a] = float(np.radians(p["axes"][a]))
    _, w = caught(fivecal.simulate, c600u, plan)
    msgs = [str(x.message) for x in w if issubclass(x.category, fivecal.RadiansWarning)]
    assert len(msgs) >= 1 and all(m.startswith("plan[*].axes.") for m in msgs)
    assert len(msgs) == len(set(msgs))


def test_plan_in_um_is_refused(hu40t):
    plan = [{"type": "dbb", "setup": "P", "axes": {"X": 150000.0, "Y": 0, "Z": 0, "B": 0, "C": 0},
             "length": 100000.0, "tool_ball": [0, 0, 100], "table_ball": [0, 0, 0]}]
    with pytest.raises(ValueError, match=r"plan\[0\]\.(axes\.X|length) .* divide by 1000"):
        fivecal.simulate(hu40t, plan)


def test_plan_beyond_10_m_warns(hu40t):
    # a 20 m position: µm, or a very large machine; warned, not refused. The
    # table ball travels with X, so it sits 20 m out too: a 100 mm bar at 20 m
    # (with the table ball at the origin the bar would be 20 m long, which the
    # simulator rightly refuses as beyond a ball bar's range)
    plan = [{"type": "dbb", "setup": "P", "axes": {"X": 20000.0, "Y": 0, "Z": 0, "B": 0, "C": 0},
             "length": 100.0, "tool_ball": [0, 0, 100], "table_ball": [20000, 0, 0]}]
    _, w = caught(fivecal.simulate, hu40t, plan)
    assert any("plan[0].axes.X = 20000 mm is beyond 10 m" in str(x.message) for x in w)
    assert all(x.filename == __file__ for x in w)  # points at the caller's line


# ---------------------------------------------------------------- CSV traces
def write(tmp_path, name, header, angles, readings):
    p = tmp_path / name
    lines = ([header] if header else []) + [f"{a:.6f},{r:.6f}" for a, r in zip(angles, readings)]
    p.write_text("\n".join(lines) + "\n")
    return p


ANG = np.arange(0.0, 360.0, 5.0)
RD = 0.01 * np.cos(np.radians(ANG))


def test_csv_header_units_are_honoured(tmp_path):
    t = dbb.read_trace_csv(write(tmp_path, "a.csv", "angle_rad,reading_um", np.radians(ANG), RD * 1000))
    assert np.allclose(t.angles, ANG, atol=1e-4) and np.allclose(t.readings, RD, atol=1e-8)
    t = dbb.read_trace_csv(write(tmp_path, "b.csv", "angle [deg]; reading [mm]", ANG, RD))
    assert np.allclose(t.readings, RD, atol=1e-6)
    with pytest.raises(ValueError, match=r"column 'reading_inches': unknown unit 'inches'"):
        dbb.read_trace_csv(write(tmp_path, "c.csv", "angle_deg,reading_inches", ANG, RD))
    with pytest.raises(ValueError, match=r"column 'reading_deg'"):
        dbb.read_trace_csv(write(tmp_path, "d.csv", "angle_deg,reading_deg", ANG, RD))


def test_csv_readings_in_um_are_refused(tmp_path):
    p = write(tmp_path, "um.csv", "angle,reading", ANG, RD * 1000)
    with pytest.raises(ValueError, match=r"um\.csv: column 'reading'.*divide by 1000 or name the column "
                                         r"reading_um"):
        dbb.read_trace_csv(p)


def test_csv_angles_in_radians_warn_once(tmp_path):
    p = write(tmp_path, "rad.csv", None, np.radians(ANG), RD)
    t, w = caught(dbb.read_trace_csv, p)
    assert len(w) == 1 and "rad.csv" in str(w[0].message) and "angle_rad" in str(w[0].message)
    # and a circular test of that 'circle' is refused
    with pytest.raises(ValueError, match=r"sweep 6\.\d+ degrees.*full circle.*radians"):
        dbb.circular_test([t], 100)


def test_circular_test_needs_a_sweep_of_10_degrees():
    a = np.linspace(0, 8, 40)
    with pytest.raises(ValueError, match=r"run 1 .*sweep 8 degrees"):
        dbb.circular_test([dbb.Trace(a, 0.001 * np.cos(np.radians(a)), label="short")], 100)


def test_cli_refuses_um_trace_with_exit_2(tmp_path):
    p = write(tmp_path, "um.csv", "angle,reading", ANG, RD * 1000)
    r = subprocess.run([sys.executable, "-m", "fivecal", "dbb", "circular", str(p), "--radius", "100"],
                       capture_output=True, text=True, env={**os.environ})
    assert r.returncode == 2 and "divide by 1000" in r.stderr


def test_column_unit():
    assert column_unit("reading_um", "length") == (1e-3, "um")
    assert column_unit("reading (µm)", "length") == (1e-3, "µm")
    assert column_unit("angle", "angle") == (1.0, None)
    assert abs(column_unit("angle_rad", "angle")[0] - 180 / np.pi) < 1e-12


def test_large_dataset_checked_on_every_observation(c600u, tmp_path):
    n = 25000
    rng = np.random.default_rng(0)
    axes = {a: rng.uniform(-50, 50, n) for a in "XYZ"}
    axes.update({"A": rng.uniform(-20, 70, n), "C": rng.uniform(0, 359, n)})
    r = rng.normal(0, 0.01, n)
    ds = fivecal.ball_dataset(c600u, "dbb", axes, [0, 0, 100], [0, 0, 0], length=100, readings=r)
    d = copy.deepcopy(ds.to_dict())
    for o in d["observations"]:
        o["reading"] *= 1000
    d["observations"][-1]["reading"] = 99.0
    with pytest.raises(ValueError, match=rf"observations\[{n - 1}\]\.reading = 99 mm \(\d+ of the {n} "):
        fivecal.Dataset.from_dict(d)
    # One reading in µm among 25000 is found, also where a sample of 20000
    # evenly spaced observations would not look (a unit slip in one file of a
    # merged trace), and named by its index.
    grid = set(np.linspace(0, n - 1, 20000).round().astype(int).tolist())
    k = next(i for i in range(n // 2, n) if i not in grid)
    d = copy.deepcopy(ds.to_dict())
    d["observations"][k]["reading"] = 12.5
    with pytest.raises(ValueError, match=rf"observations\[{k}\]\.reading = 12.5 mm \(1 of the {n} "):
        fivecal.Dataset.from_dict(d)
    p = tmp_path / "one_bad_row.json"
    p.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=rf"one_bad_row.json: observations\[{k}\]\.reading = 12.5 mm"):
        fivecal.load_dataset(p)
