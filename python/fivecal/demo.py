"""fivecal demo: the bundled HU40T-like TANGO example end to end.

Simulates the thesis experiment (Rahman 2016, ch. 4: octagonal table facets
probed at the Table 4-2 indexations, a scale bar, 0.6 µm probing noise, true
errors of the size of Table 4-5), identifies subset S3 on all but five
indexation triplets, predicts the held-out touches and writes a report folder.
"""
from __future__ import annotations

import os
import time

import numpy as np

from . import tango
from .dataset import save_dataset
from .identification import identify
from .machine import Machine
from .simulation import simulate
from .units import display_scale

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
    return [tuple(round(o["axes"].get(a, 0.0)) for a in axes) for o in dataset.observations]


def run_demo(out: str, seed: int = 1, verbose: bool = True) -> dict:
    t0 = time.perf_counter()
    say = print if verbose else (lambda *a, **k: None)
    os.makedirs(out, exist_ok=True)
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
    nominal = identify(train, "S1")
    pred_nominal = nominal.predict(test)
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))
    lines += ["",
              f"  validation on {len(test_idx)} touches at 5 held-out indexations {sorted(held)}:",
              f"    setup-only model (S1) predicts them to {rms(pred_nominal) * 1e3:.2f} µm rms, "
              f"the identified S3 model to {rms(pred) * 1e3:.2f} µm rms"]
    text = report + "\n" + "\n".join(lines)
    with open(os.path.join(out, "report.txt"), "w") as f:
        f.write(text + "\n")

    from .plots import plot_parameters, plot_residual_histogram, plot_residual_vectors

    machine_names = [n for n in result.estimated if n in truth]
    plot_parameters(result, os.path.join(out, "parameters.png"), names=machine_names, truth=truth)
    plot_residual_vectors(nominal, os.path.join(out, "residuals_S1.png"),
                          title="Unexplained residuals, subset S1 (setup only)")
    plot_residual_vectors(result, os.path.join(out, "residuals_S3.png"),
                          title="Unexplained residuals, subset S3")
    plot_residual_histogram(result, os.path.join(out, "residual_histogram.png"))

    say(text)
    say(f"\n  fit {t_fit * 1e3:.0f} ms; demo total {time.perf_counter() - t0:.1f} s; "
        f"largest |z| = {worst:.2f}")
    say(f"  report folder: {os.path.abspath(out)} (report.txt, result.json, dataset.json, *.png)")
    return {"result": result, "truth": truth, "held_out_rms": rms(pred), "nominal_rms": rms(pred_nominal),
            "worst_z": worst}
