"""The numpy/SciPy baseline of bench/ must compute what fivecal computes, or
the speed ratios in the README compare different things."""
import json
import os
import statistics
import sys

import numpy as np
import pytest

import fivecal
from fivecal.procedures import tango

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
sys.path.insert(0, os.path.join(ROOT, "bench"))

import baseline_numpy as base  # noqa: E402
import run as bench  # noqa: E402


def _poses(m, n, rng):
    return {a: rng.uniform(-360, 360, n) if m.is_rotary(a) else rng.uniform(-300, 300, n)
            for a in m.axis_names}


def _radians(m, q):
    q = q.copy()
    for i, a in enumerate(m.axis_names):
        if m.is_rotary(a):
            q[:, i] = np.deg2rad(q[:, i])
    return q


@pytest.mark.parametrize("name", ["hu40t", "kx8", "c600u"])
def test_numpy_forward_kinematics_is_fivecal_s(name):
    m = fivecal.Machine.load(os.path.join(ROOT, "examples", "machines", f"{name}.json"))
    rng = np.random.default_rng(4)
    names = m.parameter_names()
    # Every kind of parameter at realistic sizes, including cubic motions and backlash.
    errors = {n: float(rng.normal(0, 2e-5 if n[1] in "ABC" else 5e-3))
              for n in rng.choice(names, 40, replace=False) if not n.endswith(("2", "3"))}
    errors.update({n: float(rng.normal(0, 1e-9)) for n in names if n.endswith("3")})
    axes = _poses(m, 500, rng)
    dirs = {a: rng.choice([-1, 1], 500) for a in m.axis_names if a != "S"}
    ours = m.tool_point(axes, errors, directions=dirs)
    q = _radians(m, m.axes_matrix(axes))
    d = m.directions_matrix(dirs, 500).astype(float)
    theirs = base.NumpyMachine(m).tool_points(q, errors, d)
    assert np.abs(ours - theirs).max() < 1e-9


def test_numpy_residuals_are_fivecal_s():
    ds = tango.hu40t_dataset(errors=tango.thesis_s3_errors(), seed=2)
    values = dict(tango.thesis_s3_errors())
    values.update({"tip.x": 0.01, "facet.F3": 0.004})
    ours, source = fivecal._core.predict_residuals(ds._core, values)
    prob = base.NumpyProblem(ds)
    theirs = prob.residuals(values)
    # The baseline stacks facets, spheres, then the scale bars; fivecal keeps
    # observation order with the bars last.
    bars = [s for s in source if s < 0]
    order = list(prob.f_idx) + list(prob.s_idx) + bars
    rows = {s: i for i, s in enumerate(source)}
    assert ours.shape == theirs.shape and len(order) == len(ours)
    assert np.abs(ours[[rows[s] for s in order]] - theirs).max() < 1e-9


def test_tango_case_agrees_with_the_baseline_fit():
    r = bench.case_tango("S3", 1, 1)
    assert r["max_difference_in_sigma"] < 0.01
    assert r["ratio"] > 1


def test_readme_section_is_generated_from_the_json():
    doc = {"machine": {"cpu": "test cpu", "cores": 2, "date": "today"},
           "results": [{"case": "forward_kinematics", "size": {"poses": 10}, "fivecal_s": 1e-3,
                        "baseline_s": 2e-2, "ratio": 20.0, "fivecal_poses_per_s": 1e4,
                        "baseline_poses_per_s": 5e2, "api_poses_per_s": 9e3},
                       {"case": "design_search", "skipped": "not here"}]}
    text = bench.readme_section(doc)
    assert text.startswith("<!-- performance:begin") and text.endswith("<!-- performance:end -->")
    assert "| forward_kinematics | poses 10 | 1.00 ms | 20.0 ms | 20× |" in text
    assert "not measured: not here" in text
    # The JAX columns: warm time, first call (compile) apart, ratio against fivecal.
    doc["results"][0].update({"jax_s": 4e-3, "jax_compile_s": 2.5, "ratio_jax": 4.0, "jax_poses_per_s": 2.5e3})
    text = bench.readme_section(doc)
    assert "| forward_kinematics | poses 10 | 1.00 ms | 20.0 ms | 20× | 4.0 ms | 2.50 s | 4× |" in text
    assert "JAX 0.00 M poses/s" in text
    json.dumps(doc)  # the harness writes this document as JSON


def test_core_choices_measure_the_used_paths_faster():
    exe = os.path.join(ROOT, "build", "ctest", "fivecal_bench_choices")
    if not os.path.exists(exe):
        pytest.skip("C++ build (scripts/test.sh builds it) not present")
    choices = bench.core_choices(3)
    assert [c["preset"] for c in choices] == ["S3", "S4"]
    for c in choices:
        assert c["jacobian_ms"]["analytic"] * 10 < c["jacobian_ms"]["autodiff"]
        assert c["solve_iterations"]["dense_normal_cholesky"] == c["solve_iterations"]["dense_qr"]
        assert c["analysis_ms"]["normal_eigen"] > 0 and c["analysis_ms"]["qr_svd"] > 0


# ---- the JAX baseline (bench extra; skipped without jax) ---------------------

def test_jax_forward_kinematics_is_fivecal_s():
    pytest.importorskip("jax")
    import baseline_jax as jbase

    m = fivecal.Machine.load(os.path.join(ROOT, "examples", "machines", "hu40t.json"))
    rng = np.random.default_rng(5)
    names = m.parameter_names()
    # Every kind of parameter, cubic motions and backlash included (as the numpy test).
    errors = {n: float(rng.normal(0, 2e-5 if n[1] in "ABC" else 5e-3))
              for n in rng.choice(names, 40, replace=False) if not n.endswith(("2", "3"))}
    errors.update({n: float(rng.normal(0, 1e-9)) for n in names if n.endswith("3")})
    errors.update({"tip.x": 0.02, "tip.z": -0.01})
    axes = _poses(m, 3000, rng)
    dirs = {a: rng.choice([-1, 1], 3000) for a in m.axis_names if a != "S"}
    ours = m.tool_point(axes, errors, directions=dirs)
    q = _radians(m, m.axes_matrix(axes))
    d = m.directions_matrix(dirs, 3000).astype(float)
    model = jbase.JaxMachine(m)
    theirs = np.asarray(model.tool_points(q, errors, d))
    assert np.abs(ours - theirs).max() < 1e-9
    fk = jbase.forward_kinematics(m, list(errors))     # the jitted call the bench times (no directions)
    jitted = np.asarray(fk(q, np.array(list(errors.values()))))
    assert np.abs(m.tool_point(axes, errors) - jitted).max() < 1e-9


def test_jax_fits_are_fivecal_s():
    """The JAX Levenberg-Marquardt finds fivecal's optimum (within a small
    fraction of sigma) on the bench's ball3d case, small, and on TANGO S3."""
    pytest.importorskip("jax")
    r = bench.case_ball3d(500, 1, baseline_repeat=0)
    assert r["jax_max_difference_in_sigma"] < 0.01
    # the paired rounds' ratio: JAX / fivecal in rounds that alternate them
    assert r["jax_compile_s"] > 0 and r["jax_s"] > 0 and len(r["runs_fivecal_with_jax_s"]) == len(r["runs_jax_s"])
    assert r["ratio_jax"] == pytest.approx(statistics.median(
        j / f for j, f in zip(r["runs_jax_s"], r["runs_fivecal_with_jax_s"])))
    import baseline_jax as jbase

    ds = tango.hu40t_dataset(errors=tango.thesis_s3_errors(), seed=2)
    res = fivecal.identify(ds, "S3")
    x, evaluations, cost, ok, *_ = jbase.JaxProblem(ds, res.estimated).fit_function()()
    assert bool(ok) and int(evaluations) < 20
    z = max(abs(float(x[i]) - res.values[n]) / res.std[n] for i, n in enumerate(res.estimated))
    assert z < 0.01
    assert abs(2 * float(cost) - res.chi2) < 1e-6 * res.chi2


def test_bench_runs_and_says_so_without_jax(monkeypatch):
    monkeypatch.setattr(bench, "jbase", None)
    monkeypatch.setattr(bench, "JAX_MISSING", "jax not installed")
    r = bench.case_ball3d(200, 1, baseline_repeat=0)
    assert r["jax_skipped"] == "jax not installed" and "jax_s" not in r
    doc = {"machine": {"cpu": "test cpu", "cores": 2, "date": "today"}, "results": [r]}
    assert "| not measured: jax not installed |" in bench.readme_section(doc)
    assert "not measured: jax not installed" in bench.table([r])


@pytest.mark.parametrize("kind", ["ball3d", "dbb"])
def test_jax_ball_rows_are_fivecal_s(kind):
    """JaxProblem's ball rows (a prefix per mounting, gathered setup offsets,
    one row per DBB reading or three per 3D sample) are fivecal's residuals."""
    pytest.importorskip("jax")
    import baseline_jax as jbase

    m = fivecal.Machine.load(os.path.join(ROOT, "examples", "machines", "c600u.json"))
    rng = np.random.default_rng(1)
    n = 40
    rot = {"X": np.zeros(n), "Y": np.zeros(n), "Z": np.zeros(n), "A": rng.uniform(-90, 90, n),
           "C": rng.uniform(0, 360, n)}
    tool, table = [0.0, 0.0, 150.0], [50.0, 0.0, 80.0]
    _, tool_axes = m.tool_pose(rot, tip=tool)
    axes = m.inverse(np.tile(table, (n, 1)), tool_axes=tool_axes, start={k: v[0] for k, v in rot.items()})
    if kind == "ball3d":
        ds = fivecal.ball_dataset(m, kind, axes, tool, table, measured=rng.normal(0, 5e-3, (n, 3)), setup="R1")
    else:
        ds = fivecal.ball_dataset(m, kind, axes, tool, table, length=100.0, readings=rng.normal(0, 5e-3, n),
                                  setup="R1")
    values = {"EB0A": 3e-5, "EY0C": -0.01, f"{kind}.R1.tool.x": 0.003, f"{kind}.R1.table.z": -0.002}
    if kind == "dbb":
        values["dbb.R1.length"] = 0.004
    ours, _ = fivecal._core.predict_residuals(ds._core, values)
    theirs = np.asarray(jbase.JaxProblem(ds, list(values)).residuals(np.array(list(values.values()))))
    assert ours.shape == theirs.shape and np.abs(ours - theirs).max() < 1e-9


# ---- the JAX design search (bench extra; skipped without jax) -----------------

def _scan(scores, start=None):
    """fivecal's DesignPlan scan, literally: every candidate in order, the pick
    replaced by a strictly better one."""
    import baseline_jax as jbase

    pick, best = None, start
    for j, s in enumerate(zip(*scores)):
        if best is None or jbase._better(s, best):
            pick, best = j, s
    return pick


def test_jax_design_pick_is_fivecals_scan():
    """The JAX search picks as fivecal's scan does among near ties (within the
    1e-9 relative tolerance a later candidate does not replace an earlier one),
    not the arithmetic best, and scans only the candidates near the best."""
    jax = pytest.importorskip("jax")  # noqa: F841
    import baseline_jax as jbase

    rng = np.random.default_rng(3)
    for trial in range(300):
        n = int(rng.integers(1, 12))
        defi = rng.integers(0, 2, n) if trial % 3 else np.zeros(n, int)
        base = 17.0 + rng.integers(0, 3, n) * 1e-3
        # near ties: offsets around the ordering's tolerance (1e-9 relative)
        dcrit = base + rng.choice([0.0, 5e-9, 2e-8, 1e-7], n) * rng.choice([-1, 1], n)
        nonnull = rng.integers(0, 3, n) * 1e-13 + rng.integers(0, 2, n) * 1e-3
        dcrit = np.where(defi == 0, dcrit, -np.inf)
        scores = (defi, nonnull, dcrit)
        cand = np.arange(n)
        assert jbase._pick(scores, cand) == _scan(scores), trial
        start = (0, 0.0, 17.001)
        assert jbase._pick(scores, cand, start) == _scan(scores, start), trial
    # the tolerance matters: a later, barely better candidate does not replace the first
    scores = (np.zeros(2, int), np.zeros(2), np.array([17.0, 17.0 + 5e-9]))
    assert jbase._pick(scores, np.arange(2)) == 0
    assert jbase._pick((scores[0], scores[1], np.array([17.0, 17.0 + 1e-7])), np.arange(2)) == 1


def test_jax_design_search_picks_fivecals_plan():
    """On a small pool of the bench's kind the JAX search (exact jacfwd
    Jacobian) takes fivecal's design_plan's steps: the same indexations, the
    same D-criterion after every greedy step and swap, as many candidate
    selections scored (fivecal also scores the empty one)."""
    pytest.importorskip("jax")
    import baseline_jax as jbase
    from fivecal import design

    m, art, plan, groups = bench.design_pool(400, seed=11)
    ds = fivecal.simulate(m, plan, artefact=art, tip_radius=tango.TIP_RADIUS)
    k = 8
    d = design.design_plan(ds, k, "S3", groups=groups, criterion="d", method="exchange")
    assert len(d.history) > k        # the exchange passes swapped: they are checked too
    ref = d.reference
    scale = [design.characteristic_scale(m, x) for x in ref.parameters]
    run = jbase.design_search_function(ds, ref.parameters, ref.n_machine, scale, groups, k)
    g, obs, history, evaluations = run()
    assert g == d.groups
    assert obs == list(d.observations)
    assert len(history) == len(d.history)
    for ours, theirs in zip(history, d.history):
        assert ours == theirs == -np.inf or abs(ours - theirs) < 1e-9 * abs(theirs)
    assert evaluations + 1 == d.evaluations


def test_design_case_has_a_jax_figure():
    """case_design_search times the JAX search like the other JAX cases and
    records that it found fivecal's plan."""
    pytest.importorskip("jax")
    r = bench.case_design_search(300, 1, 1, k=6)
    assert "jax_skipped" not in r
    # the design search's JAX runs are timed apart from fivecal's: the ratio of the medians
    assert r["jax_compile_s"] > 0 and r["jax_s"] > 0 and r["ratio_jax"] == r["jax_s"] / r["fivecal_s"]
    assert r["jax_agreement"] == "same indexations" and r["jax_same_indexations"]
    assert r["jax_evaluations"] + 1 == r["fivecal_evaluations"]
    assert r["jax_criterion_relative_error"] < 1e-9


def test_jax_design_scoring_runs_its_lapack_calls_one_after_the_other():
    """The scoring's two batched LAPACK calls (eigvalsh, then the Cholesky of
    the setup block) must not run at once: on XLA:CPU each blocks a thread of
    the intra-op pool until the pool has run its share of the batch, and on a
    2-core machine the two deadlocked (the 10,000-candidate case hung). The
    compiled program must make the Cholesky depend on the eigenvalues."""
    pytest.importorskip("jax")
    import re

    import baseline_jax as jbase

    p, G, pm = 12, 5, 6
    rng = np.random.default_rng(0)
    X = rng.normal(size=(G, 20, p))
    data = (np.einsum("gri,grj->gij", X, X), np.ones((G, p), int), np.ones((G, 1), int), np.zeros((0, p, p)),
            np.zeros((0, 2), int), np.arange(p) < pm, np.zeros(pm))
    hlo = jbase._design_add_scores.lower(np.zeros((p, p)), np.zeros(p, int), np.zeros(1, int), data,
                                         tol=1e-7, pm=pm).compile().as_text()
    entry = hlo[hlo.index("\nENTRY"):]
    uses, target = {}, {}
    for line in entry.splitlines():
        m = re.match(r"\s*(?:ROOT )?%(\S+) = (.*)", line)
        if m:
            uses[m.group(1)] = set(re.findall(r"%([\w.\-]+)", m.group(2)))
            t = re.search(r'custom_call_target="(\w+)"', line)
            if t:
                target[t.group(1)] = m.group(1)
    eigh = next(v for k, v in target.items() if "syevd" in k)
    chol = next(v for k, v in target.items() if "potrf" in k)
    seen, todo = set(), [chol]
    while todo:
        n = todo.pop()
        if n not in seen:
            seen.add(n)
            todo += uses.get(n, ())
    assert eigh in seen, "the Cholesky can run concurrently with eigvalsh"


# ---- estimate "auto": the numpy and JAX baselines of the evidence loop ---------

def _small_auto_problem():
    ds, fix = bench.small_auto_problem()
    r = fivecal.identify(ds, "auto", fix=fix, variance_components=True)
    assert sum(0.01 < s < 0.9 for s in r.class_scales.values()) >= 3   # the loop has work to do
    assert r.variance_components["probe"]["estimated"]
    return ds, r


def test_numpy_auto_is_fivecal_s():
    """baseline_numpy.identify_auto reproduces identify(ds, "auto",
    variance_components=True): the same documented priors, values within
    0.001 of fivecal's sigma, sigmas, class scales and the probe's noise
    factor (bench.AUTO_TOLERANCE)."""
    ds, r = _small_auto_problem()
    setup = base.AutoSetup(ds, r.estimated)
    assert list(setup.prior) == [r.prior_std[n] for n in r.estimated]
    b = base.identify_auto(ds, r.estimated, True, setup=setup)
    agree = bench.auto_agreement(r, b["values"], b["std"], b["class_scales"], b["variance_factors"],
                                 setup.groups)
    assert set(agree) == set(bench.AUTO_TOLERANCE)
    bench.check_auto_agreement(agree, "numpy")


def test_jax_auto_is_fivecal_s_and_the_check_has_teeth():
    """baseline_jax.JaxAuto reproduces the same result; the agreement check
    rejects the same loop stopped after its first round, and a class prior
    twice its documented sigma (the scale compensates, the check sees it)."""
    pytest.importorskip("jax")
    import baseline_jax as jbase

    ds, r = _small_auto_problem()
    ja = jbase.JaxAuto(ds, r.estimated, True)
    a = ja.setup

    def agreement(out, setup=a):
        x, s, lam, f = (np.asarray(out[k]) for k in ("values", "std", "class_scales", "variance_factors"))
        return bench.auto_agreement(r, dict(zip(r.estimated, x)), dict(zip(r.estimated, s)),
                                    dict(zip(setup.classes, lam)), dict(zip(setup.groups, f)), setup.groups)

    out = ja.run()
    assert out["converged"] and out["rounds"] > 1
    bench.check_auto_agreement(agreement(out), "JAX")
    ja.max_rounds = 1                                  # the same compiled round, one round only
    with pytest.raises(AssertionError, match="JAX auto baseline off"):
        bench.check_auto_agreement(agreement(ja.run()), "JAX")
    # numpy with the location-angle class prior doubled: the same fit with
    # that class's scale halved (two rounds only, to save time: the doubling
    # alone is a log ratio of 0.69)
    setup = base.AutoSetup(ds, r.estimated)
    k = setup.classes.index("location_angle")
    setup.prior = np.where(setup.cls_idx == k, 2 * setup.prior, setup.prior)
    b = base.identify_auto(ds, r.estimated, True, setup=setup, max_rounds=2)
    agree = bench.auto_agreement(r, b["values"], b["std"], b["class_scales"], b["variance_factors"],
                                 setup.groups)
    assert agree["max_class_scale_log_ratio"] > 0.5
    with pytest.raises(AssertionError, match="numpy auto baseline off"):
        bench.check_auto_agreement(agree, "numpy")


def test_every_case_of_the_committed_bench_carries_both_ratios_or_says_why_not():
    """bench/results.json (the figures the README prints) compares every case
    with the numpy and the JAX baselines, in medians of at least 5 runs of
    each, with its size and the machine it ran on. No case is left out or
    run fewer times (the 'auto' numpy baseline takes about 30 s a run since it
    uses the fused model's exact Jacobian; the 10^6-sample numpy fit about 10 s)."""
    with open(os.path.join(ROOT, "bench", "results.json")) as f:
        doc = json.load(f)
    assert not doc["quick"]
    assert {"cpu", "cores", "date"} <= set(doc["machine"])
    for r in doc["results"]:
        case = r["case"]
        assert "skipped" not in r, case
        assert r["size"] and len(r["runs_fivecal_s"]) >= 5, case
        assert "baseline_skipped" not in r and "jax_skipped" not in r, case
        assert r["ratio"] == pytest.approx(r["baseline_s"] / r["fivecal_s"]), case
        if "runs_fivecal_with_jax_s" in r:   # rounds alternating fivecal and JAX: the median of their ratios
            assert len(r["runs_fivecal_with_jax_s"]) == len(r["runs_jax_s"]) >= 5, case
            q = [j / f for j, f in zip(r["runs_jax_s"], r["runs_fivecal_with_jax_s"])]
            assert r["ratio_jax"] == pytest.approx(statistics.median(q)), case
            assert r["ratio_jax_ci95"][0] <= r["ratio_jax"] <= r["ratio_jax_ci95"][1], case
        else:
            assert r["ratio_jax"] == pytest.approx(r["jax_s"] / r["fivecal_s"]), case
        assert r["jax_compile_s"] > 0, case
        # the baselines' figures are medians of at least 5 runs too (the numpy
        # Monte Carlo: 5 single re-fits times the trial count)
        assert len(r["runs_baseline_s"]) >= 5 and len(r["runs_jax_s"]) >= 5, case
        per_trial = case.startswith("monte_carlo")
        assert r["baseline_s"] == pytest.approx(statistics.median(r["runs_baseline_s"])
                                                * (r["size"]["trials"] if per_trial else 1)), case
        assert r["jax_s"] == pytest.approx(statistics.median(r["runs_jax_s"])
                                           * (r["size"]["trials"] / r["jax_trials_run"] if per_trial else 1)), case
