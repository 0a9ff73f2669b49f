"""fivecal benchmark harness.

    python3 bench/run.py              # all cases, writes bench/results.json, prints a table
    python3 bench/run.py --quick      # smaller sizes (a smoke run)
    python3 bench/run.py --readme     # also rewrite the README's performance section

Every case runs fivecal and the numpy baseline (bench/baseline_numpy.py)
in this process on the same data, checks they agree, and records medians of
at least 5 runs, the problem sizes and the ratio baseline / fivecal. A second
baseline, the same model and fits in JAX (bench/baseline_jax.py: jit, exact
jacfwd Jacobians, fivecal's Levenberg-Marquardt rule in lax.while_loop,
lax.map over Monte Carlo trials), runs beside it when jax is installed (the ``bench`` extra): its first
call (trace, compile and one run) is recorded apart as ``jax_compile_s``, its
warm median as ``jax_s``, and ``ratio_jax`` = JAX / fivecal: for the fits and
forward kinematics the median of rounds that alternate one fivecal and one
JAX run (``ratio_jax_ci95`` its bootstrap interval), elsewhere jax_s /
fivecal_s. Without jax
the JAX columns say so and everything else runs.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import fivecal  # noqa: E402
from fivecal.procedures import tango  # noqa: E402

import baseline_numpy as base  # noqa: E402
import versus  # noqa: E402

try:
    import baseline_jax as jbase  # noqa: E402
    JAX_MISSING = None
except ImportError:   # jax is a bench extra: without it the JAX columns say so
    jbase, JAX_MISSING = None, "jax not installed"


def fivecal_jacobians(r):
    """Jacobian evaluations of fivecal's fit (not counting identify's
    determinacy check at the start and covariance at the solution): on the
    normal-equation path (long data) one at the start and one per accepted
    step, Result.iterations counting the last candidate, costed without
    derivatives; on the dense path the same, Result.iterations counting the
    accepted steps only. Exact when no step was rejected (none is on these
    nearly linear fits)."""
    return r.iterations + (0 if r.fit_path == "normal_equations" else 1)


def timed(fn, repeat=5):
    """Median wall time (s) of `repeat` runs and the last return value."""
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), times, out


def timed_jax(fn, repeat):
    """JAX timing: the first call (trace + XLA compile + one run) apart, then
    the median of `repeat` warm runs, each waiting for the device result."""
    t = time.perf_counter()
    jbase.block(fn())
    first = time.perf_counter() - t
    t_w, runs, out = timed(lambda: jbase.block(fn()), repeat)
    return first, t_w, runs, out


def timed_jax_paired(fivecal_fn, jax_fn, repeat):
    """JAX's first call (trace + compile + one run) apart, then `repeat`
    rounds of one fivecal run and one warm JAX run, in alternating order.
    This VM runs in two speeds that last seconds to minutes (the same call
    at 4 or 7 ms): five runs of one side then five of the other can fall in
    different speeds, a round's two runs seldom do (bench/NOTES.md, session
    17). Returns (first, jax median, jax runs, fivecal runs, JAX output)."""
    t = time.perf_counter()
    jbase.block(jax_fn())
    first = time.perf_counter() - t
    runs_f, runs_j, out = [], [], None
    for k in range(repeat):
        for side in ((0, 1) if k % 2 == 0 else (1, 0)):
            t = time.perf_counter()
            if side == 0:
                fivecal_fn()
                runs_f.append(time.perf_counter() - t)
            else:
                out = jbase.block(jax_fn())
                runs_j.append(time.perf_counter() - t)
    return first, statistics.median(runs_j), runs_j, runs_f, out


def jax_result(t_f, first, t_w, runs, paired_fivecal=None, **agreement):
    """The JAX keys of a case. ratio_jax = warm JAX / fivecal: with
    ``paired_fivecal`` (fivecal's runs interleaved with ``runs``,
    timed_jax_paired) the median of the rounds' ratios and its bootstrap 95 %
    interval; otherwise the ratio of the medians (JAX run with other sizes
    or counts than fivecal's, then scaled)."""
    if paired_fivecal is None:
        return {"jax_s": t_w, "jax_compile_s": first, "ratio_jax": t_w / t_f, "runs_jax_s": runs, **agreement}
    ratio, ci = versus.paired_ratio(runs, paired_fivecal)
    return {"jax_s": t_w, "jax_compile_s": first, "ratio_jax": ratio, "ratio_jax_ci95": ci, "runs_jax_s": runs,
            "runs_fivecal_with_jax_s": paired_fivecal, **agreement}


def machine_info():
    cpu = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import scipy

    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__, "fivecal": fivecal.__version__,
            "jax": jbase.jax.__version__ if jbase else JAX_MISSING,
            "platform": platform.platform(), "date": time.strftime("%Y-%m-%d %H:%M:%S")}


# ---- cases -------------------------------------------------------------------

def case_forward_kinematics(n, repeat):
    m = tango.hu40t_machine()
    errors = tango.thesis_s4_errors()
    rng = np.random.default_rng(0)
    axes = {"X": rng.uniform(-300, 300, n), "Y": rng.uniform(-300, 300, n), "Z": rng.uniform(-300, 300, n),
            "B": rng.uniform(-90, 90, n), "C": rng.uniform(-360, 360, n), "S": rng.uniform(0, 360, n)}
    q = m.axes_matrix(axes)
    theta = m.theta(errors)
    # The core batch call (what a controller links: validation included) on
    # an (N, num_axes) array, and the public call a Python user makes (dict of
    # axis arrays in, with the Python-side checks and the column stacking).
    run_f = lambda: fivecal._core.tool_poses(m._core, theta, q, None, None, False)[0]  # noqa: E731
    t_f, runs_f, p_f = timed(run_f, repeat)
    t_api, runs_api, p_api = timed(lambda: m.tool_point(axes, errors), repeat)
    assert np.array_equal(p_f, p_api)
    qi = q.copy()
    for i, a in enumerate(m.axis_names):
        if m.is_rotary(a):
            qi[:, i] = np.deg2rad(qi[:, i])
    t_b, runs_b, p_b = timed(lambda: base.fused_tool_points(m, qi, errors), repeat)
    diff = float(np.abs(p_f - p_b).max())
    assert diff < 1e-9, f"forward kinematics disagree by {diff} mm"
    if jbase is None:
        jx = {"jax_skipped": JAX_MISSING}
    else:
        fk = jbase.forward_kinematics(m, list(errors))
        x = np.array(list(errors.values()))
        first, t_j, runs_j, runs_fj, p_j = timed_jax_paired(run_f, lambda: fk(qi, x), repeat)
        d_j = float(np.abs(p_f - np.asarray(p_j)).max())
        assert d_j < 1e-9, f"JAX forward kinematics disagree by {d_j} mm"
        jx = jax_result(t_f, first, t_j, runs_j, runs_fj, jax_poses_per_s=n / t_j, jax_max_difference_mm=d_j)
    return {**jx, "case": "forward_kinematics", "size": {"poses": n, "parameters_nonzero": len(errors)},
            "fivecal_s": t_f, "baseline_s": t_b, "ratio": t_b / t_f,
            "fivecal_poses_per_s": n / t_f, "baseline_poses_per_s": n / t_b,
            "api_s": t_api, "api_poses_per_s": n / t_api, "runs_api_s": runs_api,
            "max_difference_mm": diff, "runs_fivecal_s": runs_f, "runs_baseline_s": runs_b,
            "note": "single thread; fivecal_s is the C++ batch (fivecal._core.tool_poses on an "
                    "(N, num_axes) array, validation included), api_s is Machine.tool_point from a "
                    "dict of axis arrays"}


def case_tango(subset, repeat, baseline_repeat):
    errors = tango.thesis_s4_errors() if subset == "S4" else tango.thesis_s3_errors()
    ds = tango.hu40t_dataset(errors=errors, seed=3)
    # S4 on this plan leaves some errors undetermined (identify refuses it);
    # the bench times the same solver path with the refusal switched off.
    run_f = lambda: fivecal.identify(ds, subset, allow_unidentifiable=subset == "S4")  # noqa: E731
    t_f, runs_f, r = timed(run_f, repeat)
    names = r.estimated
    prob = base.FusedProblem(ds, names)
    t_b, runs_b, sol = timed(lambda: base.lm(prob.evaluate, np.zeros(len(names))), baseline_repeat)
    assert sol["converged"], "numpy Levenberg-Marquardt did not converge"
    # The baseline must find the same optimum (the fivecal values are its reference).
    fitted = dict(zip(names, sol["x"]))
    z = max(abs(fitted[n] - r.values[n]) / r.std[n] for n in names if n not in r.undetermined and r.std[n] > 0)
    if jbase is None:
        jx = {"jax_skipped": JAX_MISSING}
    else:
        fit = jbase.JaxProblem(ds, names).fit_function()
        first, t_j, runs_j, runs_fj, (x_j, it_j, _, ok_j, *_) = timed_jax_paired(run_f, fit, baseline_repeat)
        assert bool(ok_j), "JAX Levenberg-Marquardt did not converge"
        z_j = max(abs(float(x_j[i]) - r.values[n]) / r.std[n] for i, n in enumerate(names)
                  if n not in r.undetermined and r.std[n] > 0)
        assert z_j < 0.1, f"JAX fit off fivecal's by {z_j} sigma"
        jx = jax_result(t_f, first, t_j, runs_j, runs_fj, jax_jacobian_evaluations=int(it_j),
                        jax_max_difference_in_sigma=float(z_j))
    return {**jx, "case": f"tango_{subset}", "size": {"touches": len(ds), "unknowns": len(names),
                                                "rows": r.n_observations},
            "fivecal_s": t_f, "baseline_s": t_b, "ratio": t_b / t_f,
            "fivecal_iterations": r.iterations, "fivecal_jacobian_evaluations": fivecal_jacobians(r),
            "baseline_jacobian_evaluations": sol["jacobian_evaluations"],
            "max_difference_in_sigma": float(z), "runs_fivecal_s": runs_f, "runs_baseline_s": runs_b,
            "note": "fivecal time is identify() end to end: identifiability check, fit, covariance; the "
                    "baselines' is the fit alone (Levenberg-Marquardt with fivecal's rule from zero)"}


def auto_agreement(r, values, std, scales, factors, groups=()):
    """How far an "auto" baseline is from fivecal's Result ``r``: its values
    in fivecal's sigma, its sigma relative to fivecal's, its class scales and
    noise factors as |log ratio|. ``values``, ``std``: dicts by name;
    ``scales``: class -> lambda; ``factors``: group -> factor."""
    names = [n for n in r.estimated if r.std[n] > 0]
    out = {"max_difference_in_sigma": max(abs(values[n] - r.values[n]) / r.std[n] for n in names),
           "max_std_relative_difference": max(abs(std[n] / r.std[n] - 1) for n in names),
           "max_class_scale_log_ratio": max(abs(np.log(scales[c] / v)) for c, v in r.class_scales.items())}
    if groups:
        out["max_variance_factor_log_ratio"] = max(
            abs(np.log(factors[g] / r.variance_components[g]["factor"])) for g in groups)
    return {k: float(v) for k, v in out.items()}


# An "auto" baseline agrees with fivecal when its values are within 0.001 of
# fivecal's sigma, its sigmas and noise factors within 1e-4 relative, and its
# class scales within the stopping rule's 1 % (loops stopping one round apart
# differ by less). Measured on TANGO: about 5e-5 sigma for the numpy baseline
# (finite differences), 1e-5 for JAX; SciPy's default difference step gave
# 0.006 sigma and 6e-4 in the sigmas, which these bounds reject.
AUTO_TOLERANCE = {"max_difference_in_sigma": 1e-3, "max_std_relative_difference": 1e-4,
                  "max_class_scale_log_ratio": 0.01, "max_variance_factor_log_ratio": 1e-4}


def check_auto_agreement(agreement, who):
    for k, v in agreement.items():
        assert v < AUTO_TOLERANCE[k], f"{who} auto baseline off fivecal's: {k} = {v:.3g}"


def small_auto_problem():
    """A smaller "auto" problem than the bench's (61 unknowns, not 166, so
    the baselines take seconds, not a minute): TANGO S3
    data with every motion error but the scale gains fixed. Its loop still
    shrinks three classes and estimates the probe's noise. Used by the
    tests and by ``--quick``."""
    ds = tango.hu40t_dataset(errors=tango.thesis_s3_errors(), seed=2)
    m = ds.machine
    fix = [n for n in m.parameter_names() if n[-1] in "123" and base.prior_class(m, n) != "scale_gain"]
    return ds, fix


def case_tango_auto(repeat, variance_components=False, baseline_repeat=None, dataset=None, fix=None,
                    jax_repeat=None):
    """estimate="auto" on the TANGO touches: every candidate error under its
    prior with the class scales found by the evidence (a loop of MAP fits),
    optionally with variance components. The baselines run the same loop over
    fivecal's candidates (baseline_numpy.identify_auto: fivecal's LM rule on
    the dual-number Jacobian of the fused model; baseline_jax.JaxAuto: a
    jitted LM round with jacfwd)
    and must reproduce fivecal's values, sigmas, class scales and noise
    factors. The numpy baseline runs ``baseline_repeat`` times (default
    ``repeat``; on the full problem one run takes about 30 s).
    ``dataset``, ``fix``: another problem (``small_auto_problem``)."""
    ds = tango.hu40t_dataset(errors=tango.thesis_s3_errors(), seed=3) if dataset is None else dataset
    fix = list(fix or [])
    vc = bool(variance_components)
    run_f = lambda: fivecal.identify(ds, "auto", fix=fix, variance_components=vc)  # noqa: E731
    t_f, runs_f, r = timed(run_f, repeat)
    if baseline_repeat == 0:
        why = ("not run in this bench run (bench/run.py --auto-baselines 0): one numpy run of the evidence "
               "loop takes about 30 s and a JAX one about a minute after a compile of minutes")
        return {"case": "tango_auto" + ("_vce" if vc else ""),
                "size": {"touches": len(ds), "unknowns": r.n_parameters, "rows": r.n_observations},
                "fivecal_s": t_f, "runs_fivecal_s": runs_f, "fivecal_iterations": r.iterations,
                "jax_skipped": why, "baseline_skipped": why,
                "class_scales": {c: float(v) for c, v in r.class_scales.items()}}
    names = r.estimated
    setup = base.AutoSetup(ds, names)
    groups = setup.groups if vc else ()
    t1, _, b = timed(lambda: base.identify_auto(ds, names, vc, setup=setup), 1)
    runs_b = [t1]
    n_b = repeat if baseline_repeat is None else baseline_repeat
    if n_b > 1:
        runs_b += timed(lambda: base.identify_auto(ds, names, vc, setup=setup), n_b - 1)[1]
    t_b = statistics.median(runs_b)
    agree = auto_agreement(r, b["values"], b["std"], b["class_scales"], b["variance_factors"], groups)
    check_auto_agreement(agree, "numpy")
    note = ("identify(auto) end to end: class-scale loop of MAP fits" + (" with variance components" if vc else "")
            + ", covariance, determination; the baselines run the same loop (same priors, update, stopping "
            "rule and final fit) over fivecal's candidates")
    if len(runs_b) < 5:
        note += f"; numpy baseline: median of {len(runs_b)} run(s) (one takes {t1:.0f} s), not 5"
    if jbase is None:
        jx = {"jax_skipped": JAX_MISSING}
    else:
        ja = jbase.JaxAuto(ds, names, vc)
        first, t_j, runs_j, runs_fj, out = timed_jax_paired(run_f, ja.run, repeat if jax_repeat is None else jax_repeat)
        assert out["converged"], "JAX Levenberg-Marquardt did not converge in every round"
        x, s, lam, f = (np.asarray(out[k]) for k in ("values", "std", "class_scales", "variance_factors"))
        agree_j = auto_agreement(r, dict(zip(names, x)), dict(zip(names, s)), dict(zip(setup.classes, lam)),
                                 dict(zip(setup.groups, f)), groups)
        check_auto_agreement(agree_j, "JAX")
        jx = jax_result(t_f, first, t_j, runs_j, runs_fj, jax_rounds=out["rounds"],
                        jax_jacobian_evaluations=out["jacobian_evaluations"],
                        **{"jax_" + k: v for k, v in agree_j.items()})
    return {**jx, "case": "tango_auto" + ("_vce" if vc else ""),
            "size": {"touches": len(ds), "unknowns": r.n_parameters, "rows": r.n_observations},
            "fivecal_s": t_f, "runs_fivecal_s": runs_f, "fivecal_iterations": r.iterations,
            "baseline_s": t_b, "ratio": t_b / t_f, "runs_baseline_s": runs_b,
            "baseline_rounds": b["rounds"], "baseline_function_evaluations": b["function_evaluations"],
            "baseline_jacobian_evaluations": b["jacobian_evaluations"],
            "class_scales": {c: float(v) for c, v in r.class_scales.items()},
            **({"variance_factors": {g: float(r.variance_components[g]["factor"]) for g in groups}} if vc else {}),
            **agree, "note": note}


def ball3d_dataset(n):
    """The ball3d case's data: an R-test on the C600U-like machine, n samples
    at random (A, C), four location errors, 0.5 µm noise. Returns the
    machine, the dataset, the estimated names, the axes, both balls and the
    measured displacements (what the baselines fit)."""
    m = fivecal.Machine.load(os.path.join(HERE, "..", "examples", "machines", "c600u.json"))
    true = {"EB0A": 3e-5, "EA0C": 4e-5, "EB0C": -2e-5, "EY0C": -0.012}
    rng = np.random.default_rng(1)
    rot = {"X": np.zeros(n), "Y": np.zeros(n), "Z": np.zeros(n), "A": rng.uniform(-90, 90, n),
           "C": rng.uniform(0, 360, n)}
    tool, table = [0.0, 0.0, 150.0], [50.0, 0.0, 80.0]
    # An R-test: at each (A, C) the linear axes put the nominal tool ball on the nest.
    _, tool_axes = m.tool_pose(rot, tip=tool)
    axes = m.inverse(np.tile(table, (n, 1)), tool_axes=tool_axes, start={k: v[0] for k, v in rot.items()})
    meas = m.tool_point(axes, true, tip=tool) - np.array(table) + rng.normal(0, 5e-4, (n, 3))
    ds = fivecal.ball_dataset(m, "ball3d", axes, tool, table, measured=meas, setup="R1")
    return m, ds, list(true), axes, tool, table, meas


def case_ball3d(n, repeat, baseline_repeat):
    m, ds, names, axes, tool, table, meas = ball3d_dataset(n)
    run_f = lambda: fivecal.identify(ds, names, default_setup=False)  # noqa: E731
    t_f, runs_f, r = timed(run_f, repeat)
    assert r.verdict == "ok", r.verdict
    out = {"case": f"ball3d_fit_{n}", "size": {"samples": n, "rows": 3 * n, "unknowns": len(names)},
           "fivecal_s": t_f, "runs_fivecal_s": runs_f, "fivecal_iterations": r.iterations,
           "fivecal_jacobian_evaluations": fivecal_jacobians(r),
           "fivecal_us_per_sample": 1e6 * t_f / n}
    if baseline_repeat:
        nm = base.NumpyMachine(m)
        q = m.axes_matrix(axes)
        q[:, [m.axis_names.index("A"), m.axis_names.index("C")]] = np.deg2rad(
            q[:, [m.axis_names.index("A"), m.axis_names.index("C")]])
        fun = base.ball3d_fused(m, names, q, tool, table, meas)
        t_b, runs_b, sol = timed(lambda: base.lm(fun, np.zeros(len(names))), baseline_repeat)
        assert sol["converged"], "numpy Levenberg-Marquardt did not converge"
        z = max(abs(sol["x"][i] - r.values[k]) / r.std[k] for i, k in enumerate(names))
        assert z < 0.01, f"numpy ball3d fit off fivecal's by {z} sigma"
        out.update({"baseline_s": t_b, "ratio": t_b / t_f, "runs_baseline_s": runs_b,
                    "max_difference_in_sigma": float(z),
                    "baseline_jacobian_evaluations": sol["jacobian_evaluations"]})
        if baseline_repeat < 5:
            out["note"] = (f"numpy: median of {baseline_repeat} run(s), each {min(runs_b):.0f} s or more "
                           "(bench run with --numpy-runs-1e6)")
    if jbase is None:
        out["jax_skipped"] = JAX_MISSING
    else:
        qj = m.axes_matrix(axes)
        for i, a in enumerate(m.axis_names):
            if m.is_rotary(a):
                qj[:, i] = np.deg2rad(qj[:, i])
        fit = jbase.ball3d_fit_function(m, names)
        tool_a, table_a = np.asarray(tool, float), np.asarray(table, float)
        first, t_j, runs_j, runs_fj, (x_j, it_j, _, ok_j, *_) = timed_jax_paired(
            run_f, lambda: fit(qj, tool_a, table_a, meas), repeat)
        assert bool(ok_j), "JAX Levenberg-Marquardt did not converge"
        z_j = max(abs(float(x_j[i]) - r.values[k]) / r.std[k] for i, k in enumerate(names))
        assert z_j < 0.01, f"JAX ball3d fit off fivecal's by {z_j} sigma"
        out.update(jax_result(t_f, first, t_j, runs_j, runs_fj, jax_jacobian_evaluations=int(it_j),
                              jax_max_difference_in_sigma=float(z_j)))
    return out


# JAX Monte Carlo trials actually run (then scaled to the case's count): every
# trial costs several forward-mode Jacobians of the 389-row problem.
JAX_MC_TRIALS = 256


def case_monte_carlo(trials, threads, repeat, baseline_trials=5, jax_trials=JAX_MC_TRIALS):
    """Monte Carlo re-fits of the TANGO S3 problem (issue 5). The numpy
    figure is the median of ``baseline_trials`` single SciPy re-fits times
    the trial count (one thread: a plain SciPy user has no threaded re-fit).
    ``jax_trials``: run that many JAX trials (one Levenberg-Marquardt
    solve per trial, from the reference fit, on the weighted rows plus N(0, 1)
    noise on every row, scale bars included) and scale the time to ``trials``
    when fewer; their spread is checked against fivecal's Monte Carlo of the
    same size. Both baseline runs are measured once and shared by every case
    (they re-fit the same dataset); JAX picks its own threads."""
    from fivecal import uncertainty

    ds = tango.hu40t_dataset(seed=5)
    run = lambda: uncertainty.monte_carlo(ds, "S3", trials=trials, threads=threads, seed=1,  # noqa: E731
                                          progress=False, keep_samples=False)
    t_f, runs_f, _ = timed(run, repeat)
    out = {"case": f"monte_carlo_{trials}_t{threads}",
           "size": {"trials": trials, "threads": threads, "touches": len(ds)},
           "fivecal_s": t_f, "runs_fivecal_s": runs_f, "fivecal_ms_per_trial": 1e3 * t_f / trials}
    if baseline_trials:
        if baseline_trials not in _NUMPY_MC:
            r = fivecal.identify(ds, "S3")
            prob = base.FusedProblem(ds, r.estimated)
            x_ref = np.array([r.values[n] for n in r.estimated])
            rng = np.random.default_rng(11)
            jac = []

            def trial():
                prob.noise = rng.normal(size=prob.n_rows)
                out = base.lm(prob.evaluate, x_ref)
                jac.append(out["jacobian_evaluations"])
                return out

            t_b, runs_b, _ = timed(trial, baseline_trials)
            prob.noise = None
            _NUMPY_MC[baseline_trials] = (t_b, runs_b, float(np.mean(jac)))
        t_b, runs_b, jac_b = _NUMPY_MC[baseline_trials]
        out.update({"baseline_s": t_b * trials, "ratio": t_b * trials / t_f,
                    "baseline_s_per_trial": t_b, "runs_baseline_s": runs_b,
                    "baseline_jacobian_evaluations_per_trial": jac_b,
                    "note": f"numpy: median of {baseline_trials} single re-fits (fused model, dual-number "
                            f"Jacobian, fivecal's LM rule from the reference fit; one thread) times {trials} trials"})
    if jbase is None:
        out["jax_skipped"] = JAX_MISSING
    elif jax_trials:
        out.update(jax_monte_carlo(ds, trials, jax_trials, t_f, repeat))
    return out


_NUMPY_MC = {}   # baseline_trials -> (median s per SciPy re-fit, runs)
_JAX_MC = {}     # jax_trials -> the measured run (every Monte Carlo case re-fits the same dataset)


def jax_monte_carlo(ds, trials, jax_trials, t_f, repeat):
    """The JAX Monte Carlo: ``jax_trials`` LM re-fits (the median of
    ``repeat`` warm runs, measured once for every case), scaled to ``trials``. Agreement:
    the reference fit within sigma of fivecal's, and the trials' mean and
    standard deviation those of fivecal's Monte Carlo with as many trials,
    within five times their sampling error."""
    if jax_trials not in _JAX_MC:
        _JAX_MC[jax_trials] = _jax_monte_carlo_run(ds, jax_trials, repeat)
    run = _JAX_MC[jax_trials]
    t_j, scale = run["jax_s_per_trial"] * jax_trials, trials / jax_trials
    return {**run, "jax_s": t_j * scale, "ratio_jax": t_j * scale / t_f,
            "jax_note": ("JAX: lax.map of the LM re-fit over trials (one at a time: vmapped batches were "
                         "slower), the median of "
                         f"{len(run['runs_jax_s'])} warm runs of {jax_trials} trials"
                         + (f" scaled to {trials}" if scale != 1 else "")
                         + "; its first call (compile + the same run) is jax_compile_s")}


def _jax_monte_carlo_run(ds, jax_trials, repeat):
    import jax
    from fivecal import uncertainty

    r = fivecal.identify(ds, "S3")
    names = r.estimated
    prob = jbase.JaxProblem(ds, names)
    x_ref, _, _, ok, *_ = jbase.block(prob.fit_function()())
    assert bool(ok), "JAX reference fit did not converge"
    z = max(abs(float(x_ref[i]) - r.values[n]) / r.std[n] for i, n in enumerate(names))
    assert z < 0.1, f"JAX reference fit off fivecal's by {z} sigma"
    mc = prob.monte_carlo_function()
    keys = iter(range(1, 1000))
    first, t_j, runs_j, (X, nj) = timed_jax(lambda: mc(x_ref, jax.random.PRNGKey(next(keys)), jax_trials), repeat)
    X = np.asarray(X)
    ref = uncertainty.monte_carlo(ds, "S3", trials=jax_trials, threads=0, seed=1, progress=False,
                                  keep_samples=False)
    sf = np.array([ref.std[n] for n in names])
    mean_z = float(np.max(np.abs(X.mean(0) - np.array([ref.mean[n] for n in names])) / sf))
    std_ratio = X.std(0, ddof=1) / sf
    tol_mean = 5 * np.sqrt(2.0 / jax_trials)
    tol_std = 5 * np.sqrt(1.0 / jax_trials)     # relative sampling error of a std: 1/sqrt(2n), two of them
    assert mean_z < tol_mean, f"JAX Monte Carlo mean off fivecal's by {mean_z} sigma"
    assert np.all(np.abs(std_ratio - 1) < tol_std), \
        f"JAX Monte Carlo std ratios {std_ratio.min()}..{std_ratio.max()}"
    return {"jax_compile_s": first, "runs_jax_s": runs_j, "jax_trials_run": jax_trials,
            "jax_s_per_trial": t_j / jax_trials, "jax_max_difference_in_sigma": z,
            "jax_jacobian_evaluations_per_trial": float(np.mean(np.asarray(nj))),
            "jax_mean_difference_in_sigma": mean_z,
            "jax_std_ratio_range": [float(std_ratio.min()), float(std_ratio.max())]}


def design_pool(n, seed=7):
    """Candidate pool of exactly ``n`` touches for the design search: random
    rotary indexations of the HU40T-like machine (B in [-90, 90], C in
    [-180, 180), spindle S at 0/90/180/270 deg, whole degrees, last-move
    directions as visited in order), at each every facet of the octagonal
    table and every scale-bar ball touch (top and four at 45 deg) that faces
    the probe, is inside the X/Y/Z travel and clears the table and its housing
    (tango.facet_accessible): the accessibility rules of the grid pool of
    tests/python/test_design.py; the first ``n`` touches are kept. Returns (machine,
    artefact, plan, groups), groups numbered 0..G-1."""
    import math

    from fivecal import design

    m, art = tango.hu40t_machine(), tango.octagonal_table()
    obstacles = tango.octagonal_table_obstacles()
    s2 = math.sqrt(0.5)
    normals = [(0, 0, 1), (s2, 0, s2), (-s2, 0, s2), (0, s2, s2), (0, -s2, s2)]
    limits = {"X": (-400, 400), "Y": (-400, 400), "Z": (-500, 500)}
    rng = np.random.default_rng(seed)
    n_idx = n // 5 + 50     # about 17 accessible touches per indexation: plenty
    idx = [{"B": float(b), "C": float(c), "S": float(sp)}
           for b, c, sp in zip(rng.integers(-90, 91, n_idx), rng.integers(-180, 180, n_idx),
                               rng.choice([0, 90, 180, 270], n_idx))]
    dirs = design.rotary_directions(idx, "BC")
    plan, groups = [], []
    for start in range(0, n_idx, 50):   # in chunks: the collision check is slow (Python)
        pc, gc = design.candidate_plan(m, art, idx[start:start + 50], tip_radius=tango.TIP_RADIUS,
                                       sphere_normals=normals, limits=limits, directions=dirs[start:start + 50],
                                       accessible=lambda p, nn, a: tango.facet_accessible(p, nn, a, obstacles))
        plan += pc
        groups += [start + g for g in gc]
        if len(plan) >= n:
            break
    if len(plan) < n:
        raise RuntimeError(f"design pool: only {len(plan)} touches from {n_idx} indexations")
    plan, groups = plan[:n], groups[:n]
    label = {g: i for i, g in enumerate(sorted(set(groups)))}
    return m, art, plan, [label[g] for g in groups]


def case_design_search(n, repeat, baseline_repeat, k=14):
    """Test design (issue 7): pick k of the candidate indexations of a pool of
    n candidate touches, S3 set, D-optimality (Ds, setup eliminated), greedy
    then exchange, with fivecal.design.design_plan; the numpy baseline runs the
    same search (bench/baseline_numpy.py: NumpyDesign) on the same pool, and so
    does the JAX one (bench/baseline_jax.py: JaxDesign, exact jacfwd Jacobian),
    which must pick fivecal's plan."""
    from fivecal import design

    m, art, plan, groups = design_pool(n)
    t0 = time.perf_counter()
    ds = fivecal.simulate(m, plan, artefact=art, tip_radius=tango.TIP_RADIUS)
    t_sim = time.perf_counter() - t0
    run = lambda: design.design_plan(ds, k, "S3", groups=groups, criterion="d", method="exchange")  # noqa: E731
    t_f, runs_f, d = timed(run, repeat)
    ref = d.reference
    names, pm = ref.parameters, ref.n_machine
    scale = [design.characteristic_scale(m, x) for x in names]
    brun = lambda: base.design_search(ds, names, pm, scale, groups, k)  # noqa: E731
    t_b, runs_b, (g_b, obs_b, hist_b, evals_b) = timed(brun, baseline_repeat)
    # Agreement: the baseline's plan judged exactly by fivecal, against fivecal's plan.
    q_b = design.plan_quality(ds, "S3", subset=obs_b)
    assert sorted(q_b.parameters[:q_b.n_machine]) == sorted(names[:pm])
    d_diff = float(q_b.d_criterion - d.quality.d_criterion)
    fd_diff = float(hist_b[-1] - q_b.d_criterion)       # numpy FD criterion vs fivecal's exact one, same plan
    same = len(set(g_b) & set(d.groups))
    assert abs(fd_diff) < 1e-6, f"baseline criterion off fivecal's by {fd_diff}"
    assert abs(d_diff) < 0.05, f"designed D-criteria differ by {d_diff}"
    G = len(set(groups))
    jx = {"jax_skipped": JAX_MISSING} if jbase is None else jax_design_search(
        ds, names, pm, scale, groups, k, baseline_repeat, t_f, d)
    return {**jx, "case": f"design_search_{n}",
            "size": {"candidate_touches": n, "candidate_indexations": G, "k": k,
                     "unknowns": ref.n_parameters},
            "fivecal_s": t_f, "baseline_s": t_b, "ratio": t_b / t_f,
            "fivecal_evaluations": d.evaluations, "baseline_evaluations": evals_b,
            "fivecal_exchange_swaps": len(d.history) - k, "baseline_exchange_swaps": len(hist_b) - k,
            "fivecal_d_criterion": d.quality.d_criterion, "baseline_plan_d_criterion": q_b.d_criterion,
            "d_criterion_difference": d_diff, "baseline_fd_criterion_error": fd_diff,
            "same_indexations": same, "fivecal_touches": d.quality.n_observations,
            "baseline_touches": q_b.n_observations, "fivecal_condition_number": d.quality.condition_number,
            "pool_d_criterion": ref.d_criterion, "simulate_s": t_sim,
            "runs_fivecal_s": runs_f, "runs_baseline_s": runs_b,
            "note": (f"candidate plans = the pool of {n} candidate touches (plan entries at {G} random "
                     f"accessible B/C/S indexations of the HU40T-like machine on the octagonal table) from "
                     f"which design_plan picks {k} indexations for the S3 set, criterion 'd', greedy + "
                     "exchange; each step scores every candidate selection (fivecal_evaluations in all). "
                     "fivecal time is design_plan() on the simulated pool (Jacobian, search, exact "
                     "assessment; simulate_s apart); the baseline's is NumpyProblem + central-difference "
                     "Jacobian + the same search with batched numpy eigvalsh. Agreement: the "
                     "baseline's plan, assessed by fivecal, has a D-criterion within 0.05 of fivecal's and "
                     "the baseline's own criterion matches fivecal's assessment of it within 1e-6")}


def jax_design_search(ds, names, pm, scale, groups, k, repeat, t_f, d):
    """The JAX design search on the pool (parsed once, apart; the first call
    compiles). Agreement: fivecal's indexations, or (a near tie decided the
    other way) a plan whose D-criterion, assessed by fivecal, is fivecal's to
    1e-9 relatively; and JAX's own criterion of its plan is fivecal's
    assessment of it (exact Jacobians: no finite-difference error)."""
    from fivecal import design

    t0 = time.perf_counter()
    search = jbase.design_search_function(ds, names, pm, scale, groups, k)
    t_setup = time.perf_counter() - t0
    first, t_j, runs_j, (g_j, obs_j, hist_j, evals_j) = timed_jax(search, repeat)
    same = sorted(g_j) == sorted(d.groups)
    q_j = design.plan_quality(ds, "S3", subset=obs_j)
    ref = d.quality.d_criterion
    d_rel = abs(q_j.d_criterion - ref) / abs(ref)
    own_rel = abs(hist_j[-1] - q_j.d_criterion) / abs(q_j.d_criterion)
    assert same or d_rel < 1e-9, f"JAX design plan {g_j} is not fivecal's {d.groups} (D-criterion off by {d_rel:.2e})"
    assert own_rel < 1e-9, f"JAX design criterion off fivecal's assessment by {own_rel:.2e} relatively"
    return jax_result(t_f, first, t_j, runs_j, jax_setup_s=t_setup, jax_evaluations=evals_j,
                      jax_exchange_swaps=len(hist_j) - k,
                      jax_agreement="same indexations" if same else "same D-criterion (a near tie)",
                      jax_same_indexations=same, jax_d_criterion_relative_difference=d_rel,
                      jax_criterion_relative_error=own_rel,
                      jax_note="JAX: Jacobian by jacfwd and per-indexation information in one jit; each "
                               "greedy step (every candidate) and exchange pass (every chosen x candidate, "
                               "lax.map over the chosen) scored by one jitted vmap of eigvalsh + Cholesky; "
                               "the discrete choices in Python. The pool's parsing (jax_setup_s) is done once "
                               "outside the timed runs; jax_evaluations omits fivecal's one evaluation of the "
                               "empty selection")



def optional_cases(quick, repeat):
    """Monte Carlo when fivecal.uncertainty is present; the design search."""
    out = []
    try:
        from fivecal import uncertainty  # noqa: F401
    except ImportError:
        out.append({"case": "monte_carlo", "skipped": "fivecal.uncertainty not available"})
    else:
        if quick:
            out.append(case_monte_carlo(100, 2, repeat, baseline_trials=1, jax_trials=64))
        else:
            for trials in (1000, 10000):
                for threads in (1, 2):
                    out.append(case_monte_carlo(trials, threads, repeat))
    out.append(case_design_search(500 if quick else 10_000, repeat, repeat))
    return out


def core_choices(repeat):
    """The C++ core's design choices measured side by side (bench/cpp/choices.cc,
    built with the C++ tests in build/ctest): analytic vs autodiff Jacobian,
    normal-equation vs QR solves, eigenvalue vs SVD analysis. Empty when that
    build is absent."""
    import subprocess
    import tempfile

    exe = os.path.join(HERE, "..", "build", "ctest", "fivecal_bench_choices")
    if not os.path.exists(exe):
        return []
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for subset in ("S3", "S4"):
            errors = tango.thesis_s4_errors() if subset == "S4" else tango.thesis_s3_errors()
            path = os.path.join(tmp, f"{subset}.json")
            fivecal.save_dataset(tango.hu40t_dataset(errors=errors, seed=3), path)
            run = subprocess.run([exe, path, subset, str(repeat)], capture_output=True, text=True, check=True)
            c = json.loads(run.stdout)
            c["dataset"] = f"hu40t_dataset(thesis {subset} errors, seed 3)"
            out.append(c)
    return out


# ---- output ------------------------------------------------------------------

def _ms(s, digits=1):
    return f"{s * 1e3:.{digits}f} ms" if s < 1 else f"{s:.2f} s"


def _ratio(x, times="x"):
    return f"{x:.0f}{times}" if x >= 10 else f"{x:.2g}{times}"


def jax_cells(r, times="x", dash="-"):
    """(JAX warm, JAX first call, ratio JAX / fivecal) as printed, or the
    reason there is no JAX figure in the first cell."""
    if "jax_s" in r:
        ci = r.get("ratio_jax_ci95")
        return (_ms(r["jax_s"]), _ms(r["jax_compile_s"]),
                _ratio(r["ratio_jax"], times) + (f" ({_ratio(ci[0], '')}–{_ratio(ci[1], '')})" if ci else ""))
    why = r.get("jax_skipped", "")
    if why.startswith("not run"):              # said once below the table
        return "not run (below)", "", ""
    if why and not why.startswith("no "):      # "no JAX ...": the case has no JAX version
        return f"not measured: {why}", "", ""
    return dash, dash, dash


def table(results):
    lines = [f"{'case':<26}{'size':<34}{'fivecal':>12}{'baseline':>12}{'ratio':>9}"
             f"{'jax':>12}{'jax 1st':>12}{'ratio':>17}"]
    for r in results:
        if "skipped" in r:
            lines.append(f"{r['case']:<26}skipped: {r['skipped']}")
            continue
        size = ", ".join(f"{k} {v}" for k, v in r["size"].items())
        f = f"{r['fivecal_s'] * 1e3:.2f} ms"
        b = _ms(r["baseline_s"]) if "baseline_s" in r else "-"
        ratio = _ratio(r["ratio"]) if "ratio" in r else "-"
        j, jc, jr = jax_cells(r)
        jax_part = f"  {j}" if not jc else f"{j:>12}{jc:>12}{jr:>17}"
        lines.append(f"{r['case']:<26}{size:<34}{f:>12}{b:>12}{ratio:>9}{jax_part}")
    return "\n".join(lines)


def jacobian_cell(r):
    """Jacobian evaluations per fit (per trial for Monte Carlo) on each side, as printed."""
    def g(*keys):
        for k in keys:
            if k in r:
                v = r[k]
                return f"{v:.2f}".rstrip("0").rstrip(".") if isinstance(v, float) else str(v)
        return "–"
    f = g("fivecal_jacobian_evaluations", "fivecal_jacobian_evaluations_per_trial")
    n = g("baseline_jacobian_evaluations", "baseline_jacobian_evaluations_per_trial")
    j = g("jax_jacobian_evaluations", "jax_jacobian_evaluations_per_trial")
    return "–" if f == n == j == "–" else f"{f} / {n} / {j}"


def previous_paragraph(doc):
    """The ratios of the previous bench run (bench/results_previous.json)
    beside this run's, case by case."""
    prev = doc.get("previous")
    if not prev:
        return []
    old = {r["case"]: r for r in prev["results"]}
    cells = []
    for r in doc["results"]:
        o = old.get(r["case"])
        if o and "ratio_jax" in o and "ratio_jax" in r:
            cells.append(f"{r['case']} {_ratio(o['ratio_jax'], '×')} → {_ratio(r['ratio_jax'], '×')}")
    if not cells:
        return []
    # What differs in how the two runs took the JAX ratio, said where it does.
    paired_now = any("ratio_jax_ci95" in r for r in doc["results"])
    paired_then = any("ratio_jax_ci95" in r for r in prev["results"])
    how = (": its JAX ratios were the ratios of the two sides' medians, this run's fits and forward kinematics "
           "pair alternating rounds" if paired_now and not paired_then else "")
    return ["", f"Against the previous bench run ({prev['machine']['date']}, `bench/results_previous.json`{how}), "
            "JAX / fivecal went: " + "; ".join(cells) + "."]


def versus_paragraph(doc):
    """fivecal's own times against another build, measured in this run
    (bench/run.py --versus TREE, bench/versus.py): interleaved runs, both
    outputs compared."""
    v = doc.get("versus")
    if not v:
        return []
    def ratio(r):
        ci = r.get("ratio_ci95")
        return f"{r['this_over_other']:.2f}" + (f", 95 % {ci[0]:.2f}–{ci[1]:.2f}" if ci else "")

    cells = [f"{r['case']} {_ms(r['this_s'], 2)} against {_ms(r['other_s'], 2)} ({ratio(r)})"
             + ("" if r["agree"] else " (outputs differ)") for r in v["results"]]
    slower = [r["case"] for r in v["results"] if r["this_over_other"] > 1.05]
    when = f"measured apart on {v['date']}" if v.get("measured_apart") else "in the same run"
    text = (f"fivecal's own time against commit {v['other']['commit']} {when} (`bench/versus.py`: "
            f"{v['rounds']} interleaved rounds of each build, a round the fastest of as many runs as take 0.3 s; "
            "medians of the rounds, and in brackets the median of each round's ratio this / other with its "
            "bootstrap 95 % interval; both builds' outputs agree to 1e-4 unless "
            "said): " + "; ".join(cells) + ". "
            + (f"Slower by more than 5 %: {', '.join(slower)}." if slower else "No case is slower by more than 5 %."))
    # A case named slower is measured again, apart and with more rounds
    # (bench/run.py --versus-recheck): both results stand in the text, and
    # the later, larger one decides.
    rc = doc.get("versus_recheck")
    if slower and rc and rc["other"]["commit"] == v["other"]["commit"]:
        again = {r["case"]: r for r in rc["results"]}
        cells = [f"{c} {ratio(again[c])}" + ("" if again[c]["agree"] else " (outputs differ)")
                 for c in slower if c in again]
        still = [c for c in slower if c not in again or again[c]["this_over_other"] > 1.05 or not again[c]["agree"]]
        text += (f" Measured again on {rc['date']} ({rc['rounds']} rounds, those cases only): " + "; ".join(cells)
                 + ". " + (f"Slower by more than 5 % in both: {', '.join(still)}." if still
                           else "None is slower by more than 5 % there."))
    return ["", text]


def readme_section(doc):
    res = {r["case"]: r for r in doc["results"]}
    jax_measured = any("jax_s" in r for r in doc["results"])
    jax_words = ("and the JAX baseline (`bench/baseline_jax.py`: the same fused model jit-compiled in double "
                 "precision, exact `jax.jacfwd` Jacobians, fivecal's Levenberg–Marquardt in one `lax.while_loop`, "
                 "`lax.map` over Monte Carlo trials) " if jax_measured else "")
    lines = ["<!-- performance:begin (generated by python3 bench/run.py --readme) -->",
             f"Measured on {doc['machine']['cpu']} ({doc['machine']['cores']} cores), "
             f"{doc['machine']['date']}" + (f" (load average {doc['machine']['load_average_before'][0]:.1f} "
                                            f"at the start, {doc['machine']['load_average_after'][0]:.1f} at "
                                            "the end: the 2 cores were shared)"
                                            if "load_average_before" in doc["machine"] else "")
             + "; medians of at least 5 runs, the numpy baseline "
             "(`bench/baseline_numpy.py`: the model of `bench/fused_model.py`, one expression per matrix "
             "entry specialised to the estimated parameters, on numpy arrays, exact Jacobians by forward-mode "
             "dual numbers, fivecal's Levenberg–Marquardt start and stopping rule, in the `auto` loop too; "
             "central differences for the one Jacobian of the design search) "
             + jax_words + "run in the same process on the same data"
             + ("; JAX's first call (trace, XLA compile and one run) is shown apart from its warm median "
                "and left out of its ratio, and XLA picks its own threads (it may use every core)"
                if jax_measured else "")
             + ("; where fivecal's and JAX's runs alternate (the fits and forward kinematics), the JAX ratio is "
                "the median of each round's JAX / fivecal with its bootstrap 95 % interval in brackets: this "
                "machine runs at two speeds for seconds to minutes, which a round's two runs share"
                if any("ratio_jax_ci95" in r for r in doc["results"]) else "") + ".", "",
             "| case | size | fivecal | numpy | ratio | JAX (warm) | JAX first call | ratio JAX "
             "| Jacobians per fit: fivecal / numpy / JAX |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in doc["results"]:
        if "skipped" in r:
            lines.append(f"| {r['case']} | – | not measured: {r['skipped']} | | | | | |")
            continue
        size = ", ".join(f"{k} {v}" for k, v in r["size"].items())
        b = _ms(r["baseline_s"]) if "baseline_s" in r else ("not run (below)" if "baseline_skipped" in r else "–")
        ratio = _ratio(r["ratio"], "×") if "ratio" in r else "–"
        j, jc, jr = jax_cells(r, "×", "–")
        lines.append(f"| {r['case']} | {size} | {r['fivecal_s'] * 1e3:.2f} ms | {b} | {ratio} | {j} | {jc} | {jr} "
                     f"| {jacobian_cell(r)} |")
    fk = res.get("forward_kinematics")
    if fk:
        api = (f"; {fk['api_poses_per_s'] / 1e6:.2f} M poses/s through `Machine.tool_point` from a dict "
               "of axis arrays" if "api_poses_per_s" in fk else "")
        lines += ["", f"Forward kinematics: {fk['fivecal_poses_per_s'] / 1e6:.2f} M poses/s on one core "
                  f"in the C++ batch call{api} (baseline {fk['baseline_poses_per_s'] / 1e6:.2f} M poses/s"
                  + (f", JAX {fk['jax_poses_per_s'] / 1e6:.2f} M poses/s" if "jax_poses_per_s" in fk else "")
                  + ")."]
    for r in doc["results"]:
        if r["case"].startswith("design_search_") and "fivecal_s" in r:
            sz = r["size"]
            lines += ["", f"Design search: {sz['k']} of {sz['candidate_indexations']} indexations from "
                      f"{sz['candidate_touches']:,} candidate touches (S3, D-criterion, greedy + exchange, "
                      f"{r['fivecal_evaluations']:,} candidate selections scored) in {r['fivecal_s']:.2f} s "
                      f"(numpy baseline {r['baseline_s']:.2f} s, same search; D-criteria of the two plans "
                      f"{r['fivecal_d_criterion']:.4f} and {r['baseline_plan_d_criterion']:.4f}"
                      + (f"; JAX {r['jax_s']:.2f} s warm, {r['jax_agreement']}" if "jax_s" in r else "")
                      + ")."]
    extrapolated = [r for r in doc["results"] if "baseline_s_per_trial" in r]
    if extrapolated:
        lines += ["", "Monte Carlo numpy baseline: the median of "
                  f"{len(extrapolated[0]['runs_baseline_s'])} single re-fits on one thread "
                  f"({_ms(extrapolated[0]['baseline_s_per_trial'])} each) times the trial count, for "
                  + ", ".join(r["case"] for r in extrapolated) + "."]
    few = [r for r in doc["results"] if "runs_baseline_s" in r and "baseline_s_per_trial" not in r
           and len(r["runs_baseline_s"]) < 5]
    for r in few:
        jax_runs = r.get("runs_jax_s", [])
        lines += ["", f"{r['case']}: the numpy baseline is the median of {len(r['runs_baseline_s'])} "
                  f"run(s) ({', '.join(f'{t:.0f} s' for t in r['runs_baseline_s'])})"
                  + (f", JAX of {len(jax_runs)} warm run(s) ({', '.join(f'{t:.0f} s' for t in jax_runs)})"
                     if 0 < len(jax_runs) < 5 else "") + "."]
    scaled = [r for r in doc["results"] if "jax_trials_run" in r and r["jax_trials_run"] < r["size"]["trials"]]
    if scaled:
        kinds = sorted({(len(r["runs_jax_s"]), r["jax_trials_run"]) for r in scaled})
        lines += ["", "JAX Monte Carlo: " + "; ".join(
            f"the median of {n} warm run(s) of {k} trials (lax.map)" for n, k in kinds)
            + f", shared by {', '.join(r['case'] for r in scaled)} and scaled to each case's trial count."]
    for when in sorted({r["measured_apart"] for r in doc["results"] if "measured_apart" in r}):
        cases = [r["case"] for r in doc["results"] if r.get("measured_apart") == when]
        lines += ["", f"{', '.join(cases)}: fivecal and both baselines measured in a run of their own "
                  f"({when})."]
    not_run = [r["case"] for r in doc["results"] if r.get("baseline_skipped", "").startswith("not run")]
    if not_run:
        lines += ["", f"{', '.join(not_run)}: baselines "
                  + next(r["baseline_skipped"] for r in doc["results"] if r["case"] == not_run[0]) + "."]
    no_jax = sorted({r["jax_skipped"] for r in doc["results"] if r.get("jax_skipped", "").startswith("no JAX")})
    for reason in no_jax:
        cases = [r["case"] for r in doc["results"] if r.get("jax_skipped") == reason]
        lines += ["", f"{', '.join(cases)}: {reason}."]
    scaling = [r for r in doc["results"] if r["case"].startswith("ball3d_fit_")]
    if scaling:
        lines += ["", "Fit cost per 3D ball sample: " + ", ".join(
            f"{r['size']['samples']:.0e} samples {r['fivecal_us_per_sample']:.2f} µs" for r in scaling) + "."]
    for c in doc.get("choices", []):
        j, sv, an = c["jacobian_ms"], c["solve_ms"], c["analysis_ms"]
        lines += ["", f"Core choices on TANGO {c['preset']} ({c['rows']} rows, {c['unknowns']} unknowns, "
                  f"`bench/cpp/choices.cc`): analytic Jacobian {j['analytic']:.2f} ms vs autodiff "
                  f"{j['autodiff']:.1f} ms ({j['autodiff'] / j['analytic']:.0f}×); Ceres solve with dense "
                  f"normal Cholesky {sv['dense_normal_cholesky']:.2f} ms vs dense QR {sv['dense_qr']:.2f} ms; "
                  f"identifiability and covariance from the normal matrix {an['normal_eigen']:.2f} ms vs "
                  f"QR + SVD {an['qr_svd']:.2f} ms"
                  + (f" (measured {c['measured']}, not in this run: build/ctest absent)" if "measured" in c else "")
                  + "."]
    lines += previous_paragraph(doc)
    lines += versus_paragraph(doc)
    lines += ["", targets_paragraph(doc)]
    lines.append("<!-- performance:end -->")
    return "\n".join(lines)


def _read_json(name):
    path = os.path.join(HERE, name)
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def targets_paragraph(doc):
    """The speed targets of the issue that asked for the JAX baseline and the
    long-data path, each with the figure measured against it, generated so
    that the prose cannot drift from results.json and the long-data JSONs."""
    res = {r["case"]: r for r in doc["results"]}
    out = []

    def say(text, met):
        out.append(f"{text}: {'met' if met else '**missed**'}")

    behind = [f"{r['case']} {r['ratio_jax']:.2g}×" for r in doc["results"] if "ratio_jax" in r
              and r["ratio_jax"] < 2]
    if any("ratio_jax" in r for r in doc["results"]):
        say("every case with a JAX version ≥ 2× faster than the warm JAX baseline" + (f" (below: {', '.join(behind)})"
                                                                  if behind else ""), not behind)
    s4 = res.get("tango_S4")
    if s4:
        say(f"TANGO S4 identify < 4 ms ({s4['fivecal_s'] * 1e3:.1f} ms)", s4["fivecal_s"] < 4e-3)
    mc = res.get("monte_carlo_10000_t2")
    if mc:
        say(f"10,000 Monte Carlo re-fits of S3 on 2 threads < 2 s ({mc['fivecal_s']:.2f} s)", mc["fivecal_s"] < 2)
    long = _read_json("long_data.json")
    by_n = {r["samples"]: r for r in long["results"]} if long else {}
    if 1_000_000 in by_n:
        r = by_n[1_000_000]
        say(f"10⁶ samples within 3× of the arithmetic floor (identify {r['identify_s']:.2f} s; "
            f"{r['ratio_to_floor']:.1f}× the measured floor of {r['floor_s']:.2f} s, two Jacobian passes "
            "and one residual pass of tool points plus JᵀJ, bench/long_data.json)", r["ratio_to_floor"] <= 3)
    pq = _read_json("load_dataset_parquet.json")
    pq_n = {r["observations"]: r for r in pq["results"]} if pq else {}
    if 10_000_000 in by_n and "load_s" in by_n[10_000_000]:
        # load and fit measured in one process from the Parquet file (long_data.py --parquet)
        r = by_n[10_000_000]
        total, peak = r["identify_s"] + r["load_s"], r["peak_rss_mb"] / 1024
        say(f"10⁷ 3D-ball samples from Parquet, load plus fit < 10 s and < 2 GB ({r['load_s']:.0f} s load + "
            f"{r['identify_s']:.0f} s fit, {peak:.1f} GB peak, one process, machine load "
            f"{r['load_average_before'][0]:.0f}; bench/long_data.json)", total < 10 and peak < 2)
    elif 10_000_000 in by_n and 10_000_000 in pq_n:
        r, load = by_n[10_000_000], pq_n[10_000_000]["modes"]["load"]
        total = r["identify_s"] + load["wall_s"]
        peak = max(r["peak_rss_mb"], load["peak_rss_mb"]) / 1024
        say(f"10⁷ 3D-ball samples from Parquet, load plus fit < 10 s and < 2 GB ({load['wall_s']:.0f} s load + "
            f"{r['identify_s']:.0f} s fit, {peak:.1f} GB peak; bench/load_dataset_parquet.json, "
            "bench/long_data.json)", total < 10 and peak < 2)
    if not out:
        return ""
    return ("Speed targets against these figures (single runs vary by about 10 % within a bench run, and "
            "the shared machine's speed by up to 1.7× between days, baselines alike: compare ratios; "
            "what bounds each case: "
            "[docs/bench_bounds.md](docs/bench_bounds.md)): " + "; ".join(out) + ".")


def update_readme(doc, path):
    with open(path) as f:
        text = f.read()
    section = readme_section(doc)
    b, e = "<!-- performance:begin", "<!-- performance:end -->"
    if b in text:
        i = text.index(b)
        j = text.index(e) + len(e)
        text = text[:i] + section + text[j:]
    else:
        text = text.rstrip() + "\n\n## Performance\n\n" + section + "\n"
    with open(path, "w") as f:
        f.write(text)


def _write_json(path, doc):
    """Write-then-rename: a run that fails while writing leaves the old file."""
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(doc, f, indent=1, default=_plain)
    os.replace(tmp, path)


def _plain(o):
    """numpy scalars as JSON numbers: a run of half an hour must not be lost
    at its last line to an int64 a count picked up."""
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"Object of type {type(o).__name__} is not JSON serializable")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="small sizes, for a smoke run")
    p.add_argument("--readme", action="store_true", help="rewrite the README performance section")
    p.add_argument("--out", default=os.path.join(HERE, "results.json"))
    p.add_argument("--auto-baselines", type=int, default=None, metavar="N",
                   help="numpy runs of the 'auto' cases (default: as many as fivecal's, 5; one takes about "
                   "30 s; 0: neither baseline)")
    p.add_argument("--auto-jax-runs", type=int, default=None, metavar="N",
                   help="warm JAX runs of the 'auto' cases (default: as many as fivecal's; one takes about a minute)")
    p.add_argument("--auto-from", metavar="JSON", help="take the two 'auto' cases from this results file "
                   "(bench/run.py --only-auto --out JSON) instead of running them")
    p.add_argument("--only-auto", action="store_true", help="run the two 'auto' cases only")
    p.add_argument("--versus", metavar="TREE", help="also time fivecal's side of every case with the build of "
                   "another checkout, interleaved with this one (bench/versus.py), and keep it in results.json")
    p.add_argument("--versus-only", action="store_true",
                   help="with --versus: run only the comparison and put it into the existing --out file (and the "
                   "README with --readme); the cases' figures stay those of the file's own run")
    p.add_argument("--versus-rounds", type=int, default=7, metavar="N", help="interleaved rounds of --versus")
    p.add_argument("--versus-recheck", metavar="JSON", help="a bench/versus.py result that measured again, with "
                   "more rounds, the cases the --out file's comparison named slower: kept beside it in the file "
                   "(and the README with --readme); nothing is rerun")
    p.add_argument("--numpy-runs-1e6", type=int, default=5, metavar="N",
                   help="runs of the numpy baseline of the 1e6-sample fit (about 2 min each; 0: none)")
    a = p.parse_args(argv)
    repeat = 5
    results = []
    load_before = os.getloadavg()
    # The previous run's figures stay beside the new ones (its baselines were another's).
    previous = None
    if not a.quick and not a.only_auto and not a.versus_only and not a.versus_recheck and os.path.exists(a.out):
        with open(a.out) as f:
            old = json.load(f)
        if not old.get("quick"):
            keep = os.path.join(os.path.dirname(os.path.abspath(a.out)), "results_previous.json")
            _write_json(keep, old)
            previous = {"machine": old["machine"], "choices": old.get("choices", []),
                        "results": [{k: r[k] for k in ("case", "fivecal_s", "ratio", "ratio_jax", "ratio_jax_ci95",
                                                       "jax_s") if k in r}
                                    for r in old["results"]]}
    if a.only_auto:
        for vc in (False, True):
            before = os.getloadavg()
            results.append(case_tango_auto(repeat, vc, baseline_repeat=a.auto_baselines,
                                           jax_repeat=a.auto_jax_runs))
            results[-1].update(load_average_before=before, load_average_after=os.getloadavg())
        doc = {"machine": machine_info(), "quick": False, "results": results, "choices": []}
        _write_json(a.out, doc)
        print(table(results))
        return 0
    if a.versus_recheck or a.versus_only:
        # Only the file's comparison changes; its cases keep their run's figures.
        with open(a.out) as f:
            doc = json.load(f)
        if a.versus_recheck:
            with open(a.versus_recheck) as f:
                doc["versus_recheck"] = json.load(f)
            if doc.get("versus", {}).get("other", {}).get("commit") != doc["versus_recheck"]["other"]["commit"]:
                p.error("--versus-recheck: compares another commit than the --out file's comparison")
        else:
            if not a.versus:
                p.error("--versus-only needs --versus TREE")
            doc["versus"] = {**versus.compare(a.versus, a.versus_rounds), "measured_apart": True}
        _write_json(a.out, doc)
        print(f"written {a.out}")
        if a.readme:
            update_readme(doc, os.path.join(HERE, "..", "README.md"))
            print("README performance section updated")
        return 0
    # First, in a quiet process: once JAX has run here, its thread pool
    # disturbed the two builds' workers by tens of percent.
    versus_doc = versus.compare(a.versus, a.versus_rounds) if a.versus else None
    results.append(case_forward_kinematics(20_000 if a.quick else 1_000_000, repeat))
    print(table(results[-1:]), flush=True)
    for s in ("S3", "S4"):
        results.append(case_tango(s, repeat, 1 if a.quick else 5))
        print(table(results[-1:]), flush=True)
    if a.auto_from:
        # measured apart (a JAX run of the evidence loop takes about a minute)
        with open(a.auto_from) as f:
            apart = json.load(f)
    for vc in (False, True):
        if a.auto_from:
            results.append({**next(r for r in apart["results"] if r["case"] == "tango_auto" + ("_vce" if vc else "")),
                            "measured_apart": apart["machine"]["date"]})
        elif a.quick:
            # the tests' smaller problem: the full one's JAX baseline takes a minute a run
            ds, fix = small_auto_problem()
            results.append(case_tango_auto(3, vc, baseline_repeat=a.auto_baselines, jax_repeat=a.auto_jax_runs,
                                           dataset=ds, fix=fix))
        else:
            results.append(case_tango_auto(repeat, vc, baseline_repeat=a.auto_baselines,
                                           jax_repeat=a.auto_jax_runs))
        print(table(results[-1:]), flush=True)
    for n in ((10_000,) if a.quick else (10_000, 100_000, 1_000_000)):
        results.append(case_ball3d(n, repeat, repeat if n < 1_000_000 else a.numpy_runs_1e6))
        print(table(results[-1:]), flush=True)
    results += optional_cases(a.quick, repeat)
    doc = {"machine": {**machine_info(), "load_average_before": load_before, "load_average_after": os.getloadavg()},
           "quick": a.quick, "results": results, "choices": core_choices(5 if a.quick else 21)}
    if versus_doc:
        doc["versus"] = versus_doc
    if previous:
        doc["previous"] = previous
        if not doc["choices"]:
            # the C++ bench binary is not built here: the last measured choices, dated
            doc["choices"] = [{**c, "measured": c.get("measured", previous["machine"]["date"])}
                              for c in previous["choices"]]
    for c in doc["choices"]:
        print(json.dumps(c))
    _write_json(a.out, doc)
    print()
    print(table(results))
    print(f"\nwritten {a.out}")
    if a.readme:
        update_readme(doc, os.path.join(HERE, "..", "README.md"))
        print("README performance section updated")
    return 0


if __name__ == "__main__":
    sys.exit(main())
