"""fivecal demo: the bundled HU40T-like TANGO example end to end.

Simulates the thesis experiment (Rahman 2016, ch. 4: octagonal table facets
probed at the Table 4-2 indexations, a scale bar, 0.6 µm probing noise, true
errors of the size of Table 4-5), identifies subset S3 on all but five
indexation triplets, predicts the held-out touches and writes a report folder.
"""
from __future__ import annotations

import os
import time
import warnings

import numpy as np

from .procedures import tango
from .dataset import save_dataset
from .guards import FitWarning
from .identification import identify
from .machine import Machine
from .simulation import simulate
from .units import display_scale
from .files import make_dirs
from .files import write_text
from .report.plots import plot_residual_vectors
from .report.document import write_report
from .report.markup import table_html

SIGMA = 0.0006  # mm, the thesis's probing repeatability


def example_machine_path(name: str) -> str:
    """Path of a bundled example machine (hu40t, kx8, c600u, vmc0656)."""
    here = os.path.dirname(os.path.abspath(__file__))
    for base in (os.path.join(here, "examples", "machines"),
                 os.path.join(here, "..", "..", "examples", "machines")):
        p = os.path.join(base, f"{name}.json")
        if os.path.exists(p):
            return p
    raise ValueError(f"example machine '{name}' not found")


def indexation_keys(dataset, axes: str = "BCS") -> list:
    """Per observation, its rotary indexation as a tuple of whole degrees over ``axes``."""
    return [tuple(round(o["axes"].get(a, 0.0)) for a in axes) for o in dataset.observations]


def run_demo(out: str, seed: int = 1, verbose: bool = True) -> dict:
    """Simulate, identify (S3) and validate the HU40T-like TANGO example and
    write the report folder ``out`` (report.html, report.txt, result.json,
    dataset.json, PNGs). Returns the result, the true errors (mm / rad), the
    held-out and setup-only prediction rms (mm) and the largest |z|."""
    t0 = time.perf_counter()
    say = print if verbose else (lambda *a, **k: None)

    make_dirs(out)
    machine = Machine.load(example_machine_path("hu40t"))
    artefact = tango.octagonal_table()
    plan = tango.hu40t_plan(artefact, machine)
    truth = tango.thesis_s3_errors()
    rng = np.random.default_rng(seed)
    setup = {f"facet.{f['id']}": float(rng.normal(0, 0.05)) for f in artefact["facets"]}
    truth_all = {**truth, "tip.x": 0.004, "tip.y": -0.006, "tip.z": 0.012}
    ds = simulate(machine, plan, errors=truth_all, artefact=artefact, tip_radius=3.0, sigma=SIGMA,
                  seed=seed, setup=setup)
    save_dataset(ds, os.path.join(out, "dataset.json"))
    say(f"fivecal demo: {machine.name} ({machine.topology}), {len(ds)} simulated touches "
        f"(σ = {SIGMA * 1e3:.1f} µm) on {len(artefact['facets'])} facets and a scale bar")

    # Hold out five indexation triplets (thesis Table 4-9).
    keys = indexation_keys(ds)
    triplets = list(dict.fromkeys(keys))
    counts = {k: keys.count(k) for k in triplets}
    candidates = [k for k in triplets if counts[k] >= 8 and k != (0, 0, 0)]
    held = set(tuple(x) for x in rng.choice(np.array(candidates), size=5, replace=False).tolist())
    train_idx = [i for i, k in enumerate(keys) if k not in held]
    test_idx = [i for i, k in enumerate(keys) if k in held]
    train, test = ds.subset(train_idx), ds.subset(test_idx)

    t1 = time.perf_counter()
    result = identify(train, "S3")
    t_fit = time.perf_counter() - t1
    result.save(os.path.join(out, "result.json"))
    report = result.report()

    lines = ["", "  true vs identified (machine parameters):",
             f"  {'parameter':<10}{'true':>12}{'identified':>12}{'std':>10}{'z':>7}  unit"]
    worst = 0.0
    for n in result.estimated:
        if n not in truth:
            continue
        f, unit = display_scale(n)
        z = (result.values[n] - truth[n]) / result.std[n]
        worst = max(worst, abs(z))
        lines.append(f"  {n:<10}{truth[n] * f:>12.3f}{result.values[n] * f:>12.3f}"
                     f"{result.std[n] * f:>10.3f}{z:>7.2f}  {unit}")
    pred = result.predict(test)
    with warnings.catch_warnings():  # the setup-only model is meant to fall short: it is the baseline
        warnings.simplefilter("ignore", FitWarning)
        nominal = identify(train, "S1")
    pred_nominal = nominal.predict(test)
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))
    lines += ["",
              f"  validation on {len(test_idx)} touches at 5 held-out indexations (B, C, S in deg) "
              f"{', '.join(map(str, sorted(held)))}:",
              f"    setup-only model (S1) predicts them to {rms(pred_nominal) * 1e3:.2f} µm rms, "
              f"the identified S3 model to {rms(pred) * 1e3:.2f} µm rms"]
    text = report + "\n" + "\n".join(lines)

    write_text(os.path.join(out, "report.txt"), text + "\n")


    s1_png = plot_residual_vectors(nominal, os.path.join(out, "residuals_S1.png"),
                                   title="Unexplained residuals, subset S1 (setup only)")
    held_text = "; ".join(f"B {b}°, C {c}°, S {s}°" for b, c, s in sorted(held))
    validation = (f"<p>{len(test_idx)} touches at five indexations held out of the fit "
                  f"({held_text}), predicted from the identified values:</p>"
                  + table_html(["model", "held-out residual rms (µm)", "fit residual rms (µm)"],
                               [["S1: setup only (tip, facets, spheres)", f"{rms(pred_nominal) * 1e3:.2f}",
                                 f"{nominal.rms * 1e3:.2f}"],
                                ["S3: S1 + linear scales, location errors, backlash",
                                 f"{rms(pred) * 1e3:.2f}", f"{result.rms * 1e3:.2f}"]], [False, True, True])
                  + f"<p>Simulated truth: errors of the size of Rahman (2016) Table 4-5, probing noise "
                    f"σ = {SIGMA * 1e3:.1f} µm, seed {seed}. Largest |z| over the machine errors: "
                    f"{worst:.2f}.</p>")
    html_path = write_report(
        result, out, title=f"fivecal demo — {machine.name} TANGO, subset S3",
        truth={**truth_all, **setup},
        summary=(f"Simulated TANGO probing of the HU40T-like machine ({len(ds)} touches), subset S3 "
                 f"identified on {len(train_idx)} touches, validated on {len(test_idx)} held-out touches: "
                 f"{rms(pred) * 1e3:.2f} µm rms (setup-only model: {rms(pred_nominal) * 1e3:.2f} µm)."),
        sections=[("Validation on held-out indexations", validation)],
        figures=[(s1_png, "For comparison: residual vectors with the setup-only subset S1 (no machine "
                          "errors estimated) — the systematic pattern S3 removes.")])

    n_machine = len([n for n in result.estimated if n in truth])
    within = sum(1 for n in result.estimated if n in truth
                 and abs(result.values[n] - truth[n]) <= 2 * result.std[n])
    summary = [f"  identified subset S3 on {len(train_idx)} touches in {t_fit * 1e3:.0f} ms: "
               f"{result.n_parameters} parameters (rank {result.rank}, condition number "
               f"{result.condition_number:.3g}), residual rms {result.rms * 1e3:.2f} µm, "
               f"{'converged' if result.converged else 'NOT converged'}"]
    say(summary[0])
    say("\n".join(lines))
    say(f"\n  {within} of {n_machine} machine errors within 2σ of the truth (largest |z| = {worst:.2f}); "
        f"demo total {time.perf_counter() - t0:.1f} s")
    say(f"\n  report: {os.path.abspath(html_path)}  (open in a browser)")
    say(f"  also in {os.path.abspath(out)}: report.txt (full text report), result.json, dataset.json, *.png")
    return {"result": result, "truth": truth, "held_out_rms": rms(pred), "nominal_rms": rms(pred_nominal),
            "worst_z": worst}
