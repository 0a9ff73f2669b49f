"""The Jiang & Cripps four-step test on rotary pairs other than the paper's
C-on-A table: a B/C trunnion (C on B, with the X axis under the table), an
A/C table with the other order (A carried by C), a head-head pair, the
refusals of what the geometry cannot do, and the CLI with its plot.

Truths are the paper-sized PIGEs of test_dbb.py, given to each pair by role
(the carrier gets A's values, the carried axis C's), with 0.3 µm noise.
"""
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import fivecal
from fivecal.procedures import dbb
from fivecal.procedures.sphere_check import spindle_names

HERE = os.path.dirname(os.path.abspath(__file__))
MACHINES = os.path.join(HERE, "..", "..", "examples", "machines")
# test_dbb.TRUTH: Jiang & Cripps Tables 2-3 positions, tens of µrad orientations.
ROLE_TRUTH = (0.0342, -0.0353, 45e-6, -30e-6, 0.0013, -0.0525, -108e-6, 25e-6)

LIN = {"X": [1, 0, 0], "Y": [0, 1, 0], "Z": [0, 0, 1]}


def _machine(name, topology, rotaries, tip=(0, 0, 150)):
    axes = {a: {"type": "linear", "direction": LIN[a]} for a in "XYZ"}
    axes["S"] = {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]}
    for a, (d, p) in rotaries.items():
        axes[a] = {"type": "rotary", "direction": list(d), "point": list(p)}
    return fivecal.Machine.from_dict({"name": name, "topology": topology, "axes": axes,
                                      "tool": {"tip": list(tip)}})


def hu40t():
    return fivecal.Machine.load(os.path.join(MACHINES, "hu40t.json"))


def a_on_c():
    # A tilting table mounted on a C rotary table: C nearer the foundation.
    return _machine("A-on-C", "wACfXYZSt", {"C": ((0, 0, 1), (0, 0, 0)), "A": ((1, 0, 0), (0, 0, 80))})


def b_on_c():
    return _machine("B-on-C", "wBCfXYZSt", {"C": ((0, 0, -1), (0, 0, 0)), "B": ((0, 1, 0), (0, 0, 60))})


def head_cb():
    # Fork head: B (about Y) carried by C (about Z); the table moves in X, Y.
    d = {"name": "head C/B", "topology": "wXYfZCBSt",
         "axes": {a: {"type": "linear", "direction": v} for a, v in LIN.items()},
         "tool": {"tip": [0, 0, 100]}}
    d["axes"]["C"] = {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 300]}
    d["axes"]["B"] = {"type": "rotary", "direction": [0, 1, 0], "point": [0, 0, 250]}
    d["axes"]["S"] = {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 250]}
    return fivecal.Machine.from_dict(d)


def head_bc():
    # Head with a C axis carried by a tilting B axis, off the B pivot.
    d = {"name": "head B/C", "topology": "wXYfZBCSt",
         "axes": {a: {"type": "linear", "direction": v} for a, v in LIN.items()},
         "tool": {"tip": [0, 0, 100]}}
    d["axes"]["B"] = {"type": "rotary", "direction": [0, 1, 0], "point": [0, 0, 300]}
    d["axes"]["C"] = {"type": "rotary", "direction": [0, 0, 1], "point": [30, 0, 250]}
    d["axes"]["S"] = {"type": "rotary", "direction": [0, 0, 1], "point": [30, 0, 250]}
    return fivecal.Machine.from_dict(d)


def _truth(m):
    return dict(zip(dbb.four_step_pair(m)["names"], ROLE_TRUTH))


def test_the_pair_names_and_setups_follow_the_axes_and_the_chain_order():
    c600u = fivecal.Machine.load(os.path.join(MACHINES, "c600u.json"))
    p = dbb.four_step_pair(c600u)
    assert (p["carrier"], p["carried"], p["tool_side"]) == ("A", "C", False)
    assert p["names"] == list(dbb.FOUR_STEP_PARAMETERS) and p["setups"] == list(dbb.FOUR_STEP_SETUPS)
    p = dbb.four_step_pair(hu40t())
    assert (p["carrier"], p["carried"]) == ("B", "C")
    assert p["names"] == ["EZ0B", "EX0B", "EC0B", "EA0B", "EX0C", "EY0C", "EA0C", "EB0C"]
    assert p["setups"] == ["B1", "B2", "C1", "C2"]
    p = dbb.four_step_pair(a_on_c())
    assert (p["carrier"], p["carried"]) == ("C", "A")
    assert p["names"] == ["EX0C", "EY0C", "EA0C", "EB0C", "EY0A", "EZ0A", "EB0A", "EC0A"]
    p = dbb.four_step_pair(head_cb())
    assert (p["carrier"], p["carried"], p["tool_side"]) == ("C", "B", True)


def test_plans_sweep_the_tilting_axis_a_quarter_turn_and_the_table_a_full_turn():
    plan = dbb.four_step_plan(hu40t())
    by = {}
    for e in plan:
        by.setdefault(e["setup"], []).append(e)
    assert sorted(by) == ["B1", "B2", "C1", "C2"]
    b = [e["axes"]["B"] for e in by["B1"]]
    c = [e["axes"]["C"] for e in by["C1"]]
    assert (min(b), max(b), len(b)) == (-20.0, 70.0, 91) and (min(c), max(c), len(c)) == (0.0, 359.0, 360)
    # hu40t's X moves the table: the plan uses it to put the spindle ball on
    # the B axis, and holds it during a step.
    assert len({e["axes"]["X"] for e in by["B1"]}) == 1
    # On the nominal machine the bar length never changes.
    ds = fivecal.simulate(hu40t(), plan, errors={})
    assert max(abs(o["reading"]) for o in ds.observations) < 1e-9


MACHINE_CASES = [("hu40t C on B", hu40t), ("A on C", a_on_c), ("B on C", b_on_c), ("head B on C", head_cb),
                 ("head C on B", head_bc)]


@pytest.mark.parametrize("label,make", MACHINE_CASES, ids=[c[0] for c in MACHINE_CASES])
@pytest.mark.parametrize("seed", [21, 22])
def test_four_step_and_engine_recover_the_truth_on_other_pairs(label, make, seed):
    m = make()
    truth = _truth(m)
    plan = dbb.four_step_plan(m)
    ds = fivecal.simulate(m, plan, errors=truth, sigma={"dbb": 0.0003}, seed=seed)
    res = dbb.jiang_cripps(ds)
    assert res.names == list(truth)
    assert res.engine is not None and res.engine.converged, res.engine_error
    for n, v in truth.items():
        assert abs(res.values[n] - v) < 3 * res.std[n], (label, "four-step", n, res.values[n], v, res.std[n])
        assert abs(res.engine.values[n] - v) < 3 * res.engine.std[n], (label, "engine", n)
        # Same readings: the two methods agree inside the four-step uncertainty
        # (they differ by the four-step approximation, <= 0.5 µrad here,
        # docs/dbb.md "Four-step approximations").
        assert abs(res.values[n] - res.engine.values[n]) < res.std[n], (label, n)
    assert res.engine.rank == res.engine.n_parameters == 12  # 8 PIGEs + 4 bar lengths
    text = res.report()
    assert f"{res.carried} carried by {res.carrier}" in text
    for n in truth:
        assert n in text
    d = res.to_dict()
    assert set(d["parameters"]) == set(truth) and set(d["O'E"]) == {res.carrier, res.carried}


@pytest.mark.parametrize("make,ang_tol", [(hu40t, 0.3e-6), (a_on_c, 0.3e-6), (b_on_c, 0.3e-6),
                                          (head_cb, 0.3e-6), (head_bc, 0.6e-6)])
def test_noise_free_four_step_is_exact_to_the_papers_approximation(make, ang_tol):
    """Without noise the four-step equations leave only the paper's
    approximations (docs/dbb.md, "Four-step approximations per
    configuration": below 0.05 µm and 0.24-0.51 µrad at this size; the
    angular part is the S'E = |S'O'| cross term of eq. 11)."""
    m = make()
    truth = _truth(m)
    ds = fivecal.simulate(m, dbb.four_step_plan(m), errors=truth)
    res = dbb.jiang_cripps(ds, engine=False)
    for n, v in truth.items():
        tol = ang_tol if n[1] in "ABC" else 0.05e-3
        assert abs(res.values[n] - v) < tol, (n, res.values[n], v)


def test_carrier_removal_matters_when_the_carrier_tilts():
    """The carried axis rides on the carrier: without the removal the
    carried tilt absorbs the carrier's (the paper's position-only removal
    leaves it there)."""
    m = hu40t()
    truth = _truth(m)
    ds = fivecal.simulate(m, dbb.four_step_plan(m), errors=truth)
    full = dbb.jiang_cripps(ds, engine=False)
    pos = dbb.jiang_cripps(ds, engine=False, a_removal="position")
    # C along Z, B along Y: B's tilt about X (EA0B) shows as C's EA0C.
    assert abs(full.values["EA0C"] - truth["EA0C"]) < 0.3e-6
    assert pos.values["EA0C"] - truth["EA0C"] == pytest.approx(truth["EA0B"], abs=0.5e-6)


def test_pivot_offset_correction_on_a_b_axis():
    m = hu40t()
    truth = _truth(m)
    # Carrier (B) plane axes are Z, X: a 1 mm pivot error along the tangent.
    plan = dbb.four_step_plan(m)
    piv = np.asarray(next(e for e in plan if e["setup"] == "B1")["table_ball"])
    p_b = np.array([0.0, 0.0, -120.0])
    radial = (piv - p_b) - np.array([0, 1, 0]) * (piv - p_b)[1]
    tangent = np.cross([0, 1, 0], radial / np.linalg.norm(radial))
    setup = {f"dbb.{s}.table.{c}": float(v) for s in ("B1", "B2") for c, v in zip("xyz", tangent)}
    ds = fivecal.simulate(m, plan, errors=truth, setup=setup)
    raw = dbb.jiang_cripps(ds, engine=False)
    # Eq. 1 takes P0P0' at the start position (B = -20 deg): the table offset
    # turned by B about its direction (0, -1, 0).
    q = math.radians(-20.0)
    u = np.array([0.0, -1.0, 0.0])
    K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    R = np.eye(3) + math.sin(q) * K + (1 - math.cos(q)) * K @ K
    t0 = R @ tangent
    off = (float(t0[2]), float(t0[0]))  # the B plane axes (Z, X)
    fixed = dbb.jiang_cripps(ds, a_pivot_offset=off)
    assert max(abs(raw.values[n] - truth[n]) for n in ("EZ0B", "EX0B")) > 0.1e-3
    for n in ("EZ0B", "EX0B", "EC0B", "EA0B"):
        tol = 0.3e-6 if n[1] in "ABC" else 0.05e-3  # the approximation without offset
        assert abs(fixed.values[n] - truth[n]) < tol, n
        assert abs(fixed.engine.values[n] - truth[n]) < 1e-3 * abs(truth[n]) + 1e-9, n


@pytest.mark.parametrize("topology,rot,pattern", [
    ("wCAfXYZSt", {"C": ((0, 0, -1), (0, 0, 0)), "A": ((0, 0, 1), (0, 0, 0))}, "parallel"),
    ("wCAfXYZSt", {"C": ((0, 0, -1), (0, 0, 0)), "A": ((-0.7071067811865476, 0, 0.7071067811865476), (0, 0, 0))},
     "not along X, Y or Z"),
    ("wCfXYZBSt", {"C": ((0, 0, 1), (0, 0, 0)), "B": ((0, 1, 0), (0, 0, 200))}, "one rotary axis on the table"),
    ("wCfXYZSt", {"C": ((0, 0, 1), (0, 0, 0))}, "1 rotary axes besides the spindle"),
    ("wXCAfYZSt", {"C": ((0, 0, 1), (0, 0, 0)), "A": ((1, 0, 0), (0, 0, 0))}, "linear axis X is carried"),
])
def test_refusals_say_what_the_geometry_cannot_do(topology, rot, pattern):
    m = _machine("refused", topology, rot)
    for call in (dbb.four_step_pair, dbb.four_step_plan):
        with pytest.raises(ValueError, match=pattern):
            call(m)


def test_kx8_nutating_table_is_refused_with_its_axis_named():
    kx8 = fivecal.Machine.load(os.path.join(MACHINES, "kx8.json"))
    with pytest.raises(ValueError, match=r"the A axis .* is not along X, Y or Z"):
        dbb.four_step_plan(kx8)


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "fivecal", *args], capture_output=True, text=True, cwd=cwd,
                          env=dict(os.environ))


@pytest.mark.parametrize("which", ["hu40t", "a_on_c"])
def test_cli_jiang_on_other_pairs_with_plot(tmp_path, which):
    if which == "hu40t":
        path = os.path.join(MACHINES, "hu40t.json")
        expect = ["EZ0B", "EC0B", "EA0C", "B1", "C2"]
    else:
        path = str(tmp_path / "ac.json")
        with open(path, "w") as f:
            f.write(json.dumps(a_on_c().to_dict()))
        expect = ["EX0C", "EB0A", "C1", "A2"]
    png, out = tmp_path / "jiang.png", tmp_path / "r.json"
    r = _cli("dbb", "jiang", "--machine", path, "--simulate", "paper", "--sigma", "0.0003",
             "--plot", str(png), "--out", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    for s in expect:
        assert s in r.stdout
    assert png.stat().st_size > 10000
    d = json.loads(out.read_text())  # the one result document: the method's values in its procedure section
    assert d["procedure"]["values"]["carrier"] == ("B" if which == "hu40t" else "C")
    # 'paper' by role: the carrier gets A's Table 2 positions (the engine's and the method's value).
    m = fivecal.Machine.load(path)
    name = dbb.four_step_pair(m)["names"][0]
    first = d["procedure"]["values"]["method_values"][name]
    assert first["value"] == pytest.approx(0.0342, abs=3 * first["std"] + 1e-6)
    # the engine's, under the name every command reports (the spindle's when it is the spindle's offset)
    (seen, v), = spindle_names(m, {name: 0.0342}).items()
    assert d["parameters"][seen]["value"] == pytest.approx(v, abs=3 * d["parameters"][seen]["std"] + 1e-6)


def test_csv_traces_of_a_trunnion_rebuild_the_dataset(tmp_path):
    m = hu40t()
    truth = _truth(m)
    ds = fivecal.simulate(m, dbb.four_step_plan(m), errors=truth, sigma={"dbb": 0.0002}, seed=4)
    traces = {}
    for sid, axis in (("B1", "B"), ("B2", "B"), ("C1", "C"), ("C2", "C")):
        obs = [o for o in ds.observations if o["setup"] == sid]
        t = dbb.Trace([o["axes"][axis] for o in obs], [o["reading"] for o in obs], label=sid)
        dbb.write_trace_csv(t, tmp_path / f"{sid}.csv")
        traces[sid] = dbb.read_trace_csv(tmp_path / f"{sid}.csv")
    rebuilt = dbb.four_step_dataset(m, traces)
    a = dbb.jiang_cripps(ds, engine=False)
    b = dbb.jiang_cripps(rebuilt, engine=False)
    for n in truth:
        assert b.values[n] == pytest.approx(a.values[n], abs=1e-9)
