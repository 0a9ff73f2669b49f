"""Uncertainty of identified parameters: Monte Carlo (JCGM 101/102) and the
GUM framework with an input covariance (thesis ch. 5 and 8).

The algorithms are in C++ (``cpp/include/fivecal/uncertainty/monte_carlo.h``, ``gum.h``);
this module builds their inputs, shows a progress bar, formats and plots.

Monte Carlo on a simulated TANGO experiment::

    from fivecal import uncertainty
    from fivecal.procedures import tango
    spec = uncertainty.make_spec(tango.hu40t_machine(), tango.hu40t_plan(),
                                 errors={**tango.STYLUS_OFFSETS, **tango.thesis_s3_errors()},
                                 artefact=tango.octagonal_table(), tip_radius=3.0,
                                 sigma=0.0006, setup=tango.hu40t_setup())
    mc = uncertainty.monte_carlo(spec, "S3", trials=10000)
    print(mc.report())

On recorded data the measured readings are the centre of the input
distributions and the noise is the fit's residual standard deviation (or
``sigma``): ``uncertainty.monte_carlo(dataset, "S3")``.

GUM with an input covariance pooled from repeated cycles (thesis §5.6)::

    u = uncertainty.gum_input_covariance([[day1_c1, day1_c2], [day2_c1, day2_c2]],
                                         "S3", pooling="days")
    print(u.report())

Units: mm and rad in values; reports in µm, µrad and µm/m.
"""
from __future__ import annotations

import json
import math
import os
from typing import Callable, Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _core
from ._json import dumps
from .dataset import Dataset
from .figures import _pyplot
from .identification import _names, identify
from .machine import Machine
from .units import display_scale
from . import files
from .simulation import integer, seed_value
from .progress import Progress
from .files import save_figure

__all__ = ["make_spec", "simulation_plan", "monte_carlo", "MonteCarloResult", "gum_input_covariance",
           "CyclesUncertainty", "propagate", "pooled_covariance", "sensitivity", "coverage_factor"]


# --------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------

def make_spec(machine, plan: Sequence[Mapping], errors: Optional[Mapping] = None,
              artefact: Optional[Mapping] = None, tip_radius: float = 0.0,
              sigma: Union[float, Mapping] = 0.0, seed: int = 0,
              setup: Optional[Mapping[str, float]] = None) -> dict:
    """The simulation spec :func:`fivecal.simulate` builds from the same
    arguments (``docs/formats.md, "Simulation spec"``), as a dict."""

    machine = Machine.from_dict(machine)
    return {"machine": machine.to_dict(), "errors": dict(errors or {}), "setup": dict(setup or {}),
            "probe": {"tip_radius": float(tip_radius)}, "artefact": dict(artefact or {}),
            "plan": list(plan), "sigma": sigma, "seed": seed_value(seed)}


def _noise_levels(sigma, default: float, default_angle: float = 0.0) -> dict:
    """One simulator noise level per noise class of the registered kinds
    (``fivecal._core.noise_classes()``): mm, or rad for the classes of rows in
    rad (``fivecal._core.noise_class_units()``: a pose's ``pose_angle``)."""
    units = _core.noise_class_units()
    classes = list(_core.noise_classes())

    def _angular(c: str) -> bool:
        return units[c] == "rad"
    if sigma is None:
        return {c: default_angle if _angular(c) else default for c in classes}

    def level(v, name, unit="mm"):
        try:
            x = float(v)
        except (TypeError, ValueError):
            x = float("nan")
        if isinstance(v, bool) or not (math.isfinite(x) and x >= 0):
            raise ValueError(f"{name}: must be a finite number >= 0 {unit}, got {v!r}")
        return x

    if isinstance(sigma, Mapping):
        unknown = sorted(set(map(str, sigma)) - set(classes))
        if unknown:
            raise ValueError(f"sigma.{unknown[0]}: unknown key ({', '.join(classes)})")
        return {c: level(sigma.get(c, default_angle if _angular(c) else default), f"sigma.{c}",
                         "rad" if _angular(c) else "mm") for c in classes}
    x = level(sigma, "sigma")
    # A number is in mm: a pose's rotation rows keep their own default.
    return {c: default_angle if _angular(c) else x for c in classes}


def _default_levels(fit) -> tuple:
    """The noise a recorded dataset's plan assumes by default: the fit's
    residual standard deviation of its mm rows, and of its rad rows (a pose's
    rotation rows; 0 without)."""
    rad = fit.residual_units.get("rad")
    return fit.sigma, rad["sigma"] if rad else 0.0


def simulation_plan(source, estimate=None, sigma=None, fix=None, initial=None):
    """A ``_core.SimulationPlan`` from a simulation spec (dict with a
    ``plan``, or the path of one), or from a dataset (a :class:`Dataset`, a
    dataset dict or path): then the readings are the centre of the noise, the
    parameter values are those of ``identify(dataset, estimate)`` and the
    noise is ``sigma`` (mm; a number or ``{"probe", "dbb", "ball3d", ...}``, one per
    noise class of ``fivecal._core.noise_classes()``; ``pose_angle`` in rad),
    default the fit's residual standard deviation (with a pose's rotation
    rows, the rad rows and the mm rows each their own).  Returns ``(plan, fit)``
    (``fit`` is None for a spec)."""
    if isinstance(source, _core.SimulationPlan):
        return source, None
    if isinstance(source, (str, os.PathLike)):

        source = files.read_json(source, "spec or dataset")
    if isinstance(source, Mapping) and "plan" in source and "observations" not in source:
        spec = dict(source)
        if sigma is not None:
            spec["sigma"] = sigma
        machine = spec.get("machine")
        if isinstance(machine, Machine):
            spec["machine"] = machine.to_dict()
        return _core.SimulationPlan.from_spec(dumps(spec, "spec")), None
    ds = Dataset.from_dict(source)
    fit = identify(ds, estimate if estimate is not None else "auto", fix=fix, initial=initial)
    noise = _noise_levels(sigma, *_default_levels(fit))
    values = dict(zip(fit._core.names, np.asarray(fit._core.values, float)))
    return _core.SimulationPlan.from_dataset(ds._core, values, noise), fit


# --------------------------------------------------------------------------
# Progress bar
# --------------------------------------------------------------------------

class _Bar:
    """Adapter from the core's ``(done, total)`` callback to the shared
    :class:`fivecal.progress.Progress` bar (drawn on a terminal or with
    ``FIVECAL_PROGRESS=1``)."""

    def __init__(self, total: int, label: str = "Monte Carlo"):
        self.bar = Progress(total, label)

    def __call__(self, done: int, total: int) -> bool:
        self.bar.update(done - self.bar.n)
        if done >= total:
            self.bar.close()
        return True


# --------------------------------------------------------------------------
# Monte Carlo
# --------------------------------------------------------------------------

class MonteCarloResult:
    """Monte Carlo result (JCGM 101): per estimated parameter the sample mean
    and standard deviation, the shortest coverage interval, the GUM
    (linearised) standard uncertainty and interval, the JCGM 101 §8
    validation (numerical tolerance ``tolerance``, ``d_low``, ``d_high``,
    ``validated``) and whether the Monte Carlo itself is stable at that
    tolerance (``stable``).  Dicts are keyed by parameter name; mm and rad."""

    def __init__(self, core: "_core.MonteCarloResult", fit=None):
        self._core = core
        self.fit = fit
        self.names: list = list(core.estimated)
        n = self.names

        def d(v):
            return {k: float(x) for k, x in zip(n, np.asarray(v, float))}

        self.reference, self.truth = d(core.reference), d(core.truth)
        self.mean, self.std = d(core.mean), d(core.std)
        self.low, self.high = d(core.low), d(core.high)
        self.symmetric_low, self.symmetric_high = d(core.symmetric_low), d(core.symmetric_high)
        self.gum_std, self.gum_low, self.gum_high = d(core.gum_std), d(core.gum_low), d(core.gum_high)
        self.tolerance, self.d_low, self.d_high = d(core.tolerance), d(core.d_low), d(core.d_high)
        self.std_ratio = d(core.std_ratio)
        self.stability = d(core.stability)
        self.validated = dict(zip(n, core.validated))
        self.stable = dict(zip(n, core.stable))
        self.covariance = np.asarray(core.covariance)
        self.gum_covariance = np.asarray(core.gum_covariance)
        self.correlation = np.asarray(core.correlation)
        self.samples = np.asarray(core.samples)
        self.trial_std = np.asarray(core.trial_std)
        self.usable = np.asarray(core.usable, int)
        self.trials, self.used = core.trials, core.used
        self.not_converged, self.failed = core.not_converged, core.failed
        self.threads, self.seed, self.seconds = core.threads, core.seed, core.seconds
        self.probability, self.gum_k = core.probability, core.gum_k
        self.significant_digits = core.significant_digits

    def ordered_names(self) -> list:
        """Machine errors first (as estimated), then the setup parameters."""
        return [k for k in self.names if k.startswith("E")] + [k for k in self.names if not k.startswith("E")]

    @property
    def interval(self) -> dict:
        """Shortest coverage intervals, name -> (low, high)."""
        return {k: (self.low[k], self.high[k]) for k in self.names}

    def verdict(self, name: str) -> str:
        if self.validated[name]:
            return "validated"
        if not self.stable[name]:
            return "not validated (Monte Carlo not stable: more trials)"
        return "not validated"

    def to_dict(self, include_samples: bool = False) -> dict:
        return json.loads(self._core.to_json(include_samples))

    def to_json(self, include_samples: bool = False) -> str:
        return self._core.to_json(include_samples)

    def save(self, path, include_samples: bool = False) -> None:

        files.write_text(path, self.to_json(include_samples) + "\n")

    def report(self, names: Optional[Iterable[str]] = None) -> str:
        """Table in µm, µrad, µm/m: MC mean and u, shortest interval, GUM u,
        ratio, tolerance and the JCGM 101 §8 verdict."""
        names = list(names) if names is not None else self.ordered_names()
        p = self.probability
        lines = [f"fivecal Monte Carlo (JCGM 101): {self.used} of {self.trials} trials used "
                 f"({self.not_converged} not converged, {self.failed} failed), {self.threads} threads, "
                 f"seed {self.seed}, {self.seconds:.1f} s",
                 f"  {100 * p:g} % shortest coverage intervals; GUM interval y +- {self.gum_k:.3f} u(y); "
                 f"numerical tolerance from u(y) with {self.significant_digits} significant digits",
                 "",
                 f"  {'parameter':<14}{'mean':>11}{'u MC':>9}{'low':>11}{'high':>11}{'u GUM':>9}"
                 f"{'ratio':>7}{'delta':>8}{'d_low':>8}{'d_high':>8}  verdict  unit"]
        needed = self.trials_needed(names)
        # Too few trials when most parameters are not stable at the tolerance:
        # their verdicts would only reflect Monte Carlo noise.
        judged = needed is None or 2 * sum(bool(self.stable[k]) for k in names) >= len(names)
        if not judged:
            lines[-1] = lines[-1].replace("  verdict  unit", "  unit")
        for k in names:
            f, unit = display_scale(k)
            lines.append(f"  {k:<14}{self.mean[k] * f:>11.3f}{self.std[k] * f:>9.3f}{self.low[k] * f:>11.3f}"
                         f"{self.high[k] * f:>11.3f}{self.gum_std[k] * f:>9.3f}{self.std_ratio[k]:>7.3f}"
                         f"{self.tolerance[k] * f:>8.3f}{self.d_low[k] * f:>8.3f}{self.d_high[k] * f:>8.3f}"
                         + (f"  {self.verdict(k)}" if judged else "") + f"  {unit}")
        lines.append("")
        ratio = max((abs(self.std_ratio[k] - 1) for k in names), default=float("nan"))
        if not judged:
            lines.append(f"  GUM not judged: {self.used} trials are too few for the numerical tolerance of "
                         f"{self.significant_digits} significant digits; about {needed} trials are needed "
                         f"(max |u_MC/u_GUM - 1| = {ratio:.3f})")
        else:
            nv = sum(bool(self.validated[k]) for k in names)
            lines.append(f"  GUM validated for {nv} of {len(names)} parameters "
                         f"(max |u_MC/u_GUM - 1| = {ratio:.3f})")
            if needed is not None:
                lines.append(f"  {sum(not self.stable[k] for k in names)} not stable at this tolerance: about "
                             f"{needed} trials are needed to judge them")
        return "\n".join(lines)

    def trials_needed(self, names: Optional[Iterable[str]] = None) -> Optional[int]:
        """None when the Monte Carlo is stable at the numerical tolerance for
        every parameter (its JCGM 101 §8 verdicts mean something); otherwise
        about how many trials would make it so.  The stability figure (twice
        the spread of the block means) falls as 1/sqrt(M)."""
        names = list(names) if names is not None else self.names
        worst = 1.0
        for k in names:
            if self.stable[k]:
                continue
            s, tol = self.stability[k], self.tolerance[k]
            if math.isfinite(s) and tol > 0:
                worst = max(worst, (s / tol) ** 2)
            else:
                worst = max(worst, 10.0)
        if worst == 1.0 and all(self.stable[k] for k in names):
            return None
        m = max(self.used, 2) * worst * 1.1
        digits = 10 ** max(0, int(math.floor(math.log10(m))) - 1)  # two significant digits, rounded up
        return int(math.ceil(m / digits) * digits)

    def plot(self, path: str, names: Optional[Iterable[str]] = None, bins: int = 40) -> str:
        """Histograms of the trial values with the GUM normal density, the
        shortest interval (solid) and the GUM interval (dashed); PNG at ``path``."""
        plt = _pyplot()
        names = list(names) if names is not None else self.ordered_names()[:12]
        cols = min(4, len(names))
        rows = int(math.ceil(len(names) / cols))
        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.5 * rows), squeeze=False)
        ok = self.usable == 1
        for ax, k in zip(axes.flat, names):
            j = self.names.index(k)
            f, unit = display_scale(k)
            x = self.samples[ok, j] * f if self.samples.size else np.array([])
            if x.size:
                ax.hist(x, bins=bins, density=True, color="0.75")
            y, u = self.reference[k] * f, self.gum_std[k] * f
            if u > 0:
                t = np.linspace(y - 4 * u, y + 4 * u, 200)
                ax.plot(t, np.exp(-0.5 * ((t - y) / u) ** 2) / (u * math.sqrt(2 * math.pi)), "k-", lw=1)
            for v in (self.low[k], self.high[k]):
                ax.axvline(v * f, color="C0", lw=1.2)
            for v in (self.gum_low[k], self.gum_high[k]):
                ax.axvline(v * f, color="C3", lw=1, ls="--")
            ax.set_title(k, fontsize=9)
            ax.set_xlabel(unit, fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in list(axes.flat)[len(names):]:
            ax.axis("off")
        fig.tight_layout()

        save_figure(fig, path, dpi=110)
        plt.close(fig)
        return path

    def __repr__(self) -> str:
        return f"MonteCarloResult({len(self.names)} parameters, {self.used}/{self.trials} trials)"


def monte_carlo(dataset_or_spec, estimate: Union[str, Sequence[str]] = "auto", trials: int = 10000,
                threads: int = 0, seed: int = 1, progress: Union[bool, Callable[[int, int], object]] = True,
                probability: float = 0.95, significant_digits: int = 2, fix=None, initial=None,
                sigma=None, input_covariance: Optional[np.ndarray] = None, trial_std: bool = False,
                keep_samples: bool = True, blocks: int = 10, robust: Optional[str] = None,
                robust_scale: float = 0.0,
                default_setup: bool = True, max_iterations: int = 200,
                selection_tolerance: Optional[float] = None) -> MonteCarloResult:
    """Monte Carlo uncertainty of the identified parameters (JCGM 101).

    ``dataset_or_spec``: a simulation spec (dict with ``plan``, or its path;
    the truth is the spec's errors and setup, see :func:`make_spec`), a
    dataset (its readings are the centre of the noise, see
    :func:`simulation_plan`) or a ``_core.SimulationPlan``.  Each of
    ``trials`` trials re-draws the noise of every input (probe trigger along
    its approach line, DBB reading, ball3d component, and the calibrated
    length of each scale bar, with the sigma the fit weighs its row with) and re-fits ``estimate``
    (as :func:`fivecal.identify`) in C++ on ``threads`` threads (0: all
    cores).  Trial ``t`` uses the seed ``_core.trial_seed(seed, t)``: the
    result does not depend on ``threads``.  ``input_covariance``: optional
    inputs x inputs covariance (mm^2, along the residuals; one row per
    input of the plan: the observations' in order, then the scale bars') for
    correlated noise.  ``robust``/``robust_scale``: a robust loss with a fixed scale (mm;
    give it for simulated specs, whose noise-free reference fit has no
    residual scale).  ``progress``: True for the shared bar on stderr (drawn on a
    terminal or with ``FIVECAL_PROGRESS=1``), or a callable ``(done, total)
    -> bool`` called about every 0.1 s (False cancels).  Ctrl-C cancels too.
    """

    trials = integer(trials, "trials", 2, 2 ** 31)
    threads = integer(threads, "threads", 0, 2 ** 16)
    seed = seed_value(seed)
    significant_digits = integer(significant_digits, "significant_digits", 1, 16)
    blocks = integer(blocks, "blocks", 2, 2 ** 31)
    max_iterations = integer(max_iterations, "max_iterations", 1, 2 ** 31)
    if not (0 < probability < 1):
        raise ValueError(f"probability: must be between 0 and 1, got {probability!r}")
    plan, fit = simulation_plan(dataset_or_spec, estimate=estimate, sigma=sigma, fix=fix,
                                initial=initial)
    bar = _Bar(trials) if progress is True else None
    cb = bar if bar is not None else (progress or None)
    cov = None if input_covariance is None else np.asarray(input_covariance, float)
    kw = {} if selection_tolerance is None else {"selection_tolerance": float(selection_tolerance)}
    try:
        core = _core.monte_carlo(plan, _names(estimate), _names(fix), dict(initial or {}),
                                 robust=robust or "", robust_scale=float(robust_scale),
                                 max_iterations=int(max_iterations), include_default_setup=bool(default_setup),
                                 trials=int(trials), threads=int(threads), seed=int(seed),
                                 probability=float(probability), significant_digits=int(significant_digits),
                                 blocks=int(blocks), input_covariance=cov, trial_std=bool(trial_std),
                                 keep_samples=bool(keep_samples), progress=cb, **kw)
    finally:
        if bar is not None:
            bar.bar.close()
    return MonteCarloResult(core, fit)


# --------------------------------------------------------------------------
# GUM with an input covariance
# --------------------------------------------------------------------------

def coverage_factor(probability: float = 0.95, dof: float = math.inf, outputs: int = 0,
                    k: Optional[float] = None):
    """``_core.CoverageFactor``: ``k`` (Student t with ``dof``, normal for
    infinite dof, or the given ``k``), ``k_joint`` for the joint region of
    ``outputs`` parameters, and ``method`` saying how k was chosen."""
    return _core.coverage_factor(float(probability), float(dof), int(outputs), float(k or 0.0))


def propagate(C, Ux, names: Sequence[str], values, probability: float = 0.95, dof: float = math.inf,
              k: Optional[float] = None, prior_term=None):
    """U_y = C U_x C^T (thesis eq. 8-3) with a stated coverage factor;
    returns ``_core.GumResult`` (``covariance``, ``std``, ``expanded``,
    ``coverage``). ``prior_term``: after a MAP fit (``estimate="auto"``), the
    prior's share of U_y, :attr:`Sensitivity.prior_term` of :func:`sensitivity`
    (without it an error the data did not determine would look as certain as
    the data make the rest)."""
    C = np.atleast_2d(np.asarray(C, float))
    cf = coverage_factor(probability, dof, C.shape[0], k)
    extra = np.zeros((0, 0)) if prior_term is None else np.atleast_2d(np.asarray(prior_term, float))
    return _core.gum_propagate(C, np.atleast_2d(np.asarray(Ux, float)), list(names),
                               np.asarray(values, float), cf, extra)


def pooled_covariance(samples, groups: Sequence[int]):
    """Covariance of the rows of ``samples`` (cycles x inputs) pooled within
    ``groups`` (one label per row): ``_core.PooledCovariance``."""
    return _core.pool_covariance(np.asarray(samples, float), [int(g) for g in groups])


def sensitivity(dataset, result):
    """C = -(J^T J)^-1 J_in^T of a fit (``_core.Sensitivity``): the change of
    each estimated parameter per mm of each input (along its residual). After a
    MAP fit, C = -(J^T W J + P)^-1 J_in^T W and ``prior_term`` holds the prior's
    share of the covariance (pass it to :func:`propagate`)."""
    ds = Dataset.from_dict(dataset)
    return _core.sensitivity_matrix(ds._core, result._core)


class CyclesUncertainty:
    """GUM uncertainty from an input covariance pooled over repeated cycles."""

    def __init__(self, core: "_core.CyclesUncertainty"):
        self._core = core
        g = core.gum
        self.names: list = list(g.names)
        self.values = dict(zip(self.names, np.asarray(g.values, float)))
        self.std = dict(zip(self.names, np.asarray(g.std, float)))
        self.expanded = dict(zip(self.names, np.asarray(g.expanded, float)))
        self.covariance = np.asarray(g.covariance)
        self.k = g.coverage.k
        self.k_joint = g.coverage.k_joint
        self.dof = g.coverage.dof
        self.probability = g.coverage.probability
        self.coverage = g.coverage.method
        self.pooling = core.pooling
        self.input_covariance = np.asarray(core.inputs.covariance)
        self.cycle_values = np.asarray(core.cycle_values)
        self.output_pooled_std = dict(zip(self.names, np.sqrt(np.maximum(np.diag(core.output_pooled), 0))))
        self.day, self.cycle = list(core.day), list(core.cycle)

    def to_dict(self) -> dict:
        return json.loads(self._core.to_json())

    def save(self, path) -> None:

        files.write_text(path, self._core.to_json() + "\n")

    def report(self, names: Optional[Iterable[str]] = None) -> str:
        """Table in µm, µrad, µm/m (machine errors first): value, u, U = k u
        and the same pooling applied to the cycles' own estimates."""
        if names is None:
            names = [k for k in self.names if k.startswith("E")] + [k for k in self.names if not k.startswith("E")]
        names = list(names)
        lines = [f"fivecal GUM with input covariance (thesis eq. 8-3): {len(self.day)} cycles pooled by "
                 f"{self.pooling}, {int(self.dof)} degrees of freedom",
                 f"  coverage: {self.coverage}; joint region of {len(self.names)} parameters: "
                 f"k_q = {self.k_joint:.3f}" if math.isfinite(self.k_joint) else
                 f"  coverage: {self.coverage}; too few degrees of freedom for a joint region",
                 "",
                 f"  {'parameter':<14}{'value':>12}{'u':>10}{'U=k u':>10}{'cycles sd':>11}  unit"]
        for k in names:
            f, unit = display_scale(k)
            lines.append(f"  {k:<14}{self.values[k] * f:>12.3f}{self.std[k] * f:>10.3f}"
                         f"{self.expanded[k] * f:>10.3f}{self.output_pooled_std[k] * f:>11.3f}  {unit}")
        return "\n".join(lines)


def gum_input_covariance(cycles, estimate: Union[str, Sequence[str]] = "auto",
                         day: Optional[Sequence[int]] = None, cycle: Optional[Sequence[int]] = None,
                         pooling: str = "cycles", probability: float = 0.95, k: Optional[float] = None,
                         reference: int = 0, fix=None, initial=None,
                         default_setup: bool = True) -> CyclesUncertainty:
    """GUM uncertainty U_y = C U_x C^T with U_x pooled from repeated cycles.

    ``cycles``: datasets of the same plan (same observations in the same
    order), either a flat list with ``day`` (and optionally ``cycle``) labels,
    or a list of days, each a list of that day's cycles in time order.
    ``pooling``: ``"cycles"`` (cycle k of every day pooled together: removes
    the machine's change through the day), ``"days"`` (the cycles of a day
    pooled: removes the change between days) or ``"none"``.  The coverage
    factor is Student's t with the pooled degrees of freedom for
    ``probability`` unless ``k`` is given; the result states it.
    """
    flat = []
    if cycles and isinstance(cycles[0], (list, tuple)):
        day, cycle = [], []
        for d, group in enumerate(cycles):
            for c, ds in enumerate(group):
                flat.append(ds)
                day.append(d)
                cycle.append(c)
    else:
        flat = list(cycles)
        if day is None:
            day = [0] * len(flat)
        if cycle is None:
            seen: dict = {}
            cycle = []
            for dd in day:
                cycle.append(seen.get(dd, 0))
                seen[dd] = seen.get(dd, 0) + 1
    cores = [Dataset.from_dict(ds)._core for ds in flat]
    core = _core.gum_from_cycles(cores, [int(x) for x in day], [int(x) for x in cycle], _names(estimate),
                                 _names(fix), dict(initial or {}), pooling, float(probability),
                                 float(k or 0.0), int(reference), bool(default_setup))
    return CyclesUncertainty(core)
