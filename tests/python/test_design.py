"""Test design (issue 5, item 4): plan quality, Table 8-4 comparison, the
K-indexation search and ``fivecal design``.

Must show: a designed plan with half the thesis' indexations (14 of Table
4-2's 28 visits) has a condition number no worse than the full Table 4-2
plan for the S3 parameter set, and recovers the truth as well in simulation
(every S3 parameter within 3 sigma, with uncertainties comparable to the full
plan's).  Two pools:

* a grid of candidate indexations (B every 15 deg, C every 90 deg, spindle
  indexed at B = C = 0) with every facet and bar-ball touch that faces the
  probe and clears the table (``tango.facet_accessible``): the design beats
  Table 4-2 on the condition number and on the D-criterion with fewer touches;
* Table 4-2's own visits (the thesis' Table 8-4 situation): subsets chosen by
  the search beat the complete set; with as many touches per visit as the
  full plan has in total (3 per facet visit) the uncertainties are comparable.

Units: mm, rad; comments in µm and µrad.
"""
from __future__ import annotations

import json
import math
import pathlib

import numpy as np
import pytest

import fivecal
from fivecal import design
from fivecal.procedures import tango
from fivecal.cli import main

ROOT = pathlib.Path(__file__).resolve().parents[2]
SPEC = ROOT / "examples" / "design" / "hu40t_table_4_2.json"


@pytest.fixture(scope="module")
def pool(plan, table, hu40t):
    """Table 4-2 touches simulated noise-free on the nominal machine."""
    return fivecal.simulate(hu40t, plan, artefact=table, tip_radius=tango.TIP_RADIUS)


@pytest.fixture(scope="module")
def full_quality(pool):
    return design.plan_quality(pool, "S3")


def truth(table) -> dict:
    t = dict(tango.thesis_s3_errors())
    t.update(tango.STYLUS_OFFSETS)
    return t


def identify_plan(plan, table, seed):
    ds = tango.hu40t_dataset(plan=plan, artefact=table, seed=seed)
    return fivecal.identify(ds, "S3")


def z_scores(r, table):
    t = truth(table)
    return {n: (r.values[n] - t.get(n, 0.0)) / r.std[n] for n in tango.S3_NAMES}


@pytest.fixture(scope="module")
def full_result(plan, table):
    return identify_plan(plan, table, seed=11)


# --------------------------------------------------------------------------
# plan quality
# --------------------------------------------------------------------------

def test_condition_number_is_the_one_identify_reports(pool, full_quality, full_result):
    q = full_quality
    assert q.condition_number == pytest.approx(full_result.condition_number, rel=1e-4)
    assert q.rank == q.n_parameters == full_result.n_parameters
    assert set(tango.S3_NAMES) <= set(q.machine_parameters)
    # predicted uncertainties (sigma 0.6 µm) are identify's, up to the fitted sigma
    ratio = [full_result.std[n] / q.predicted_std[n] for n in tango.S3_NAMES]
    assert np.allclose(ratio, full_result.sigma / 0.0006, rtol=0.05)
    assert math.isfinite(q.d_criterion) and 0 < q.d_std < 1e-3


def test_plan_without_the_scale_bar_cannot_see_the_scale(plan, table, hu40t):
    no_bar = [e for e in plan if e["type"] == "facet"]
    q = design.plan_quality(no_bar, "S3", machine=hu40t, artefact=table, tip_radius=3.0)
    assert math.isinf(q.condition_number) and q.rank < q.n_parameters
    assert any({"EXX1", "EYY1", "EZZ1"} & set(g) for g in q.confounded), q.confounded
    assert math.isinf(q.d_std)
    assert "confounded" in q.report()


def test_visit_groups_of_table_4_2(plan):
    g = design.visit_groups(plan)
    assert len(set(g)) == 28 and g == sorted(g)
    # visit i is row i of Table 4-2
    for e, gi in zip(plan, g):
        s, b, c, _ = tango.TABLE_4_2[gi]
        assert (e["axes"]["S"], e["axes"]["B"], e["axes"]["C"]) == (s, b, c)


# --------------------------------------------------------------------------
# the search on Table 4-2's visits (thesis Table 8-4)
# --------------------------------------------------------------------------

def test_table_8_4_designed_subsets_beat_the_complete_set(pool, full_quality):
    """Thesis Table 8-4: subsets of 21-25 of the 28 indexations with a lower
    condition number than the complete set (10073 there; 60.2 here, column-
    scaled)."""
    designs = {k: design.design_plan(pool, k, "S3") for k in (21, 22, 23, 24, 25)}
    rows = design.compare_plans({"complete": pool, **{f"subset k={k}": (pool, d.observations)
                                                     for k, d in designs.items()}}, "S3")
    assert rows[0]["indexations"] == 28 and rows[0]["touches"] == 388
    assert rows[0]["condition_number"] == pytest.approx(full_quality.condition_number)
    for r, (k, d) in zip(rows[1:], designs.items()):
        assert r["indexations"] == k
        assert r["condition_number"] == pytest.approx(d.quality.condition_number)
        assert r["condition_number"] < rows[0]["condition_number"]
    text = design.format_comparison(rows)
    assert "complete" in text and "subset k=21" in text


def test_search_beats_random_subsets_and_greedy(pool, full_quality):
    d = design.design_plan(pool, 14, "S3")
    greedy = design.design_plan(pool, 14, "S3", method="greedy")
    assert d.quality.condition_number <= greedy.quality.condition_number * (1 + 1e-9)
    assert d.history[-1] == pytest.approx(d.quality.condition_number, rel=1e-6)
    groups = np.array(design.visit_groups(pool))
    rng = np.random.default_rng(5)
    best_random = min(design.plan_quality(pool, "S3", subset=np.flatnonzero(
        np.isin(groups, rng.choice(28, 14, replace=False)))).condition_number for _ in range(40))
    assert d.quality.condition_number < best_random


def test_half_of_table_4_2_with_equal_touches(pool, full_quality, full_result, table, hu40t):
    """14 of the 28 visits chosen on the condition number (33.7 vs 60.2) and
    probed 3 times per facet visit (a few mm apart): fewer touches than the
    full plan, every S3 error within 3 sigma, uncertainties comparable."""
    d = design.design_plan(pool, 14, "S3")
    assert len(d.groups) == 14
    assert d.quality.condition_number <= full_quality.condition_number
    plan = tango.hu40t_plan(table, hu40t, rows=d.groups, points_per_visit=3)
    assert len(plan) < len(tango.hu40t_plan(table, hu40t))
    r = identify_plan(plan, table, seed=12)
    assert r.converged
    assert r.condition_number <= full_result.condition_number
    z = z_scores(r, table)
    assert max(abs(v) for v in z.values()) < 3, z
    ratio = np.array([r.std[n] / full_result.std[n] for n in tango.S3_NAMES])
    assert np.exp(np.mean(np.log(ratio))) < 1.3, dict(zip(tango.S3_NAMES, ratio.round(2)))
    assert ratio.max() < 2.5, dict(zip(tango.S3_NAMES, ratio.round(2)))


# --------------------------------------------------------------------------
# the search on a grid of candidate indexations (accessibility limits)
# --------------------------------------------------------------------------

def grid_indexations():
    idx = [{"B": float(b), "C": float(c), "S": 0.0} for b in range(-90, 91, 15) for c in range(-270, 271, 90)]
    return idx + [{"B": 0.0, "C": 0.0, "S": float(s)} for s in (90, 180, 270)]


@pytest.fixture(scope="module")
def grid(table, hu40t):
    obstacles = tango.octagonal_table_obstacles()
    s2 = math.sqrt(0.5)
    plan, groups = design.candidate_plan(
        hu40t, table, grid_indexations(), tip_radius=tango.TIP_RADIUS,
        sphere_normals=[(0, 0, 1), (s2, 0, s2), (-s2, 0, s2), (0, s2, s2), (0, -s2, s2)],
        limits={"X": (-400, 400), "Y": (-400, 400), "Z": (-500, 500)},
        accessible=lambda p, n, a: tango.facet_accessible(p, n, a, obstacles))
    return plan, groups


def test_candidates_respect_accessibility(grid, hu40t, table):
    plan, groups = grid
    assert len(set(groups)) == len(grid_indexations())          # every indexation reaches something
    facets = {f["id"]: np.array(f["normal"]) for f in table["facets"]}
    axes = {a: np.array([e["axes"].get(a, 0.0) for e in plan]) for a in "BCS"}
    axes.update({a: np.zeros(len(plan)) for a in "XYZ"})
    _, tool_axis = hu40t.tool_pose(axes)
    obstacles = tango.octagonal_table_obstacles()
    for e, a in list(zip(plan, tool_axis))[::4]:     # a quarter of them: the check is slow
        if e["type"] == "facet":
            n = facets[e["target"]]
            assert n @ a >= -0.02 - 1e-12
            assert tango.facet_accessible(e["point"], n, a, obstacles)
    # a tighter X range removes touches
    tight, _ = design.candidate_plan(hu40t, table, grid_indexations()[:20], tip_radius=3.0,
                                     limits={"X": (-100, 100)})
    loose, _ = design.candidate_plan(hu40t, table, grid_indexations()[:20], tip_radius=3.0)
    assert 0 < len(tight) < len(loose)
    with pytest.raises(ValueError, match="no axis 'Q'"):
        design.candidate_plan(hu40t, table, [{"Q": 1}], tip_radius=3.0)


def test_half_indexations_designed_from_a_grid(grid, full_quality, full_result, table, hu40t):
    """The must-show: 14 indexations (half of Table 4-2's 28) picked from the
    grid have a lower condition number than the full Table 4-2 plan, a better
    D-criterion with fewer touches, and recover the S3 truth within 3 sigma
    with uncertainties comparable to (mostly smaller than) the full plan's."""
    plan, groups = grid
    progress = []
    d = design.design_plan(plan, 14, "S3", groups=groups, machine=hu40t, artefact=table,
                           tip_radius=tango.TIP_RADIUS,
                           progress=lambda phase, done, total, best: progress.append(phase) or True)
    assert {"greedy", "exchange"} <= set(progress)
    assert len(d.groups) == 14
    q = d.quality
    assert q.condition_number <= full_quality.condition_number
    assert q.d_criterion >= full_quality.d_criterion
    assert q.n_observations < full_quality.n_observations
    assert "designed" in d.report()
    r = identify_plan(d.plan, table, seed=13)
    assert r.converged and r.rank == r.n_parameters
    z = z_scores(r, table)
    assert max(abs(v) for v in z.values()) < 3, z
    ratio = np.array([r.std[n] / full_result.std[n] for n in tango.S3_NAMES])
    assert np.exp(np.mean(np.log(ratio))) < 1.0, dict(zip(tango.S3_NAMES, ratio.round(2)))
    assert ratio.max() < 3.0, dict(zip(tango.S3_NAMES, ratio.round(2)))


def test_d_criterion_and_touch_budget(pool, full_quality):
    c = design.design_plan(pool, 14, "S3")
    d = design.design_plan(pool, 14, "S3", criterion="d")
    assert d.quality.d_criterion > c.quality.d_criterion
    assert d.quality.condition_number <= full_quality.condition_number
    b = design.design_plan(pool, 14, "S3", criterion="d", max_touches=200)
    assert b.quality.n_observations == 200 and math.isfinite(b.quality.condition_number)
    assert b.quality.d_criterion <= d.quality.d_criterion        # information only decreases


def test_fixed_tip_offsets_stay_fixed_in_the_design_s_assessment(pool):
    """The probe tip's offsets are machine columns in the parameter table but
    default setup in a preset: fixing them must hold in the search and in the
    reported quality of the pool and of the chosen plan (they came back)."""
    tip = ["tip.x", "tip.y", "tip.z"]
    d = design.design_plan(pool, 14, "S3", fix=tip)
    for q in (d.quality, d.reference):
        assert not set(tip) & set(q.parameters) and q.n_parameters == 49
    full = design.plan_quality(pool, "S3", fix=tip)
    chosen = design.plan_quality(pool.subset(d.observations), "S3", fix=tip)
    assert d.reference.condition_number == pytest.approx(full.condition_number, rel=1e-9)
    assert d.quality.condition_number == pytest.approx(chosen.condition_number, rel=1e-9)
    assert "tip.x" not in d.report()


def test_progress_can_stop_the_search(pool):
    d = design.design_plan(pool, 10, "S3", progress=lambda phase, done, total, best: done < 3)
    assert d.stopped
    assert "stopped early" in d.report()


@pytest.mark.parametrize("kwargs, pattern", [
    ({"k": 0}, "k = 0"),
    ({"k": 40}, "between 1 and the 28"),
    ({"k": 5, "criterion": "A"}, "criterion 'A'"),
    ({"k": 5, "method": "annealing"}, "method 'annealing'"),
    ({"k": 5, "groups": [0, 1]}, "2 labels for 388"),
    ({"k": 5, "estimate": "EQQ9"}, "EQQ9"),
])
def test_design_errors(pool, kwargs, pattern):
    k = kwargs.pop("k")
    with pytest.raises(ValueError, match=pattern):
        design.design_plan(pool, k, **{"estimate": "S3", **kwargs})


def test_plan_needs_its_machine(plan):
    with pytest.raises(ValueError, match="machine="):
        design.plan_quality(plan, "S3")


# --------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------

def test_cli_design_writes_a_simulation_spec(tmp_path, capsys):
    out = tmp_path / "plan{k}.json"
    assert main(["design", str(SPEC), "-k", "14", "--estimate", "S3", "--out", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "14 of 28 indexations" in text and "cond. number" in text and "EX0C" in text
    spec = json.loads((tmp_path / "plan14.json").read_text())
    assert len(set(design.visit_groups(spec["plan"]))) == 14
    assert spec["design"]["condition_number"] < spec["design"]["candidate_condition_number"]
    # the written spec simulates as it stands
    ds_path = tmp_path / "data.json"
    assert main(["simulate", str(tmp_path / "plan14.json"), "--out", str(ds_path)]) == 0
    assert len(fivecal.load_dataset(ds_path)) == len(spec["plan"])


def test_cli_design_table_8_4(capsys):
    assert main(["design", str(SPEC), "-k", "21,25", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "complete" in text and "designed k=21" in text and "designed k=25" in text


def test_cli_design_help_and_errors(capsys, tmp_path):
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    assert "fivecal design examples/design/hu40t_table_4_2.json -k 14" in capsys.readouterr().out
    assert main(["design", str(SPEC), "-k", "99", "--no-progress"]) == 2
    assert "between 1 and the 28" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"machine": "../nowhere.json"}))
    assert main(["design", str(bad), "-k", "3"]) == 2


def test_cli_design_from_candidate_indexations(tmp_path, capsys):
    """A spec with 'candidates' (indexations + accessibility limits) instead of a plan."""
    s2 = math.sqrt(0.5)
    spec = {"machine": str(ROOT / "examples" / "machines" / "hu40t.json"), "probe": {"tip_radius": 3.0},
            "artefact": tango.octagonal_table(),
            "candidates": {"indexations": [{"B": float(b), "C": float(c)} for b in (-90, -45, 0, 45, 90)
                                           for c in (-180, -90, 0, 90)] + [{"B": 0.0, "C": 0.0, "S": 90.0}],
                           "limits": {"X": [-400, 400]}, "min_dot": 0.0,
                           "sphere_normals": [[0, 0, 1], [s2, 0, s2], [-s2, 0, s2], [0, s2, s2], [0, -s2, s2]]},
            "errors": {**tango.thesis_s3_errors(), **tango.STYLUS_OFFSETS}, "sigma": 0.0006, "seed": 2}
    path = tmp_path / "cand.json"
    path.write_text(json.dumps(spec))
    out = tmp_path / "designed.json"
    assert main(["design", str(path), "-k", "8", "--estimate", "S3", "--out", str(out), "--no-progress"]) == 0
    assert "8 of 21 indexations" in capsys.readouterr().out
    designed = json.loads(out.read_text())
    assert "candidates" not in designed and designed["plan"]
    assert math.isfinite(designed["design"]["condition_number"])
    assert main(["simulate", str(out), "--out", str(tmp_path / "d.json")]) == 0
    r = fivecal.identify(fivecal.load_dataset(tmp_path / "d.json"), "S3")
    t = truth(None)
    assert all(abs(r.values[n] - t.get(n, 0.0)) < 3 * r.std[n] for n in tango.S3_NAMES)
