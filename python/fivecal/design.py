"""Test design: how well a plan identifies a parameter set, plan comparison
(thesis Table 8-4) and the search for K rotary indexations that minimise the
condition number (C++ core: ``cpp/include/fivecal/design/design.h``).

A *plan* is a list of plan entries in the format :func:`fivecal.simulate`
takes (``{"type": "facet", "target": "F3", "axes": {"B": 30, "C": -90, "S": 0},
...}``).  Its quality is judged on the Jacobian of the touches it would record
(simulated noise-free on the nominal machine, or at ``values``), over the
parameters :func:`fivecal.identify` would estimate on them::

    from fivecal import design
    from fivecal.procedures import tango
    m, art = tango.hu40t_machine(), tango.octagonal_table()
    pool = tango.hu40t_plan(art, m)                      # Table 4-2, 28 visits
    q = design.plan_quality(pool, "S3", machine=m, artefact=art, tip_radius=3.0)
    q.condition_number                                    # as identify reports it
    d = design.design_plan(pool, 14, "S3", machine=m, artefact=art, tip_radius=3.0)
    d.plan                                                # the 14 chosen visits
    print(d.report())

Units: mm, degrees for rotary commands, rad for angular errors.
"""
from __future__ import annotations

import json
import math
from typing import Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Union

import numpy as np

from . import _core
from .dataset import Dataset, dumps
from .machine import Machine
from .units import display_scale
from .simulation import simulate
from .progress import Progress

__all__ = ["PlanQuality", "Design", "visit_groups", "plan_quality", "compare_plans", "format_comparison",
           "candidate_plan", "design_plan", "characteristic_scale", "rotary_directions"]

PlanLike = Union[Dataset, Sequence[Mapping]]


def _names(estimate) -> List[str]:
    if estimate is None:
        return []
    if isinstance(estimate, str):
        return [s.strip() for s in estimate.split(",") if s.strip()]
    return [str(s) for s in estimate]


def _values(values) -> Dict[str, float]:
    if values is None:
        return {}
    if hasattr(values, "values") and not isinstance(values, Mapping):
        values = values.values  # a Result
    return {str(k): float(v) for k, v in values.items()}


def characteristic_scale(machine, name: str, length: float = 400.0) -> float:
    """Size (mm) of the error a unit change of parameter ``name`` makes at
    ``length`` (1 for mm parameters, L for angles, L^d for degree-d linear-axis
    error motions...). ``1e-3 / scale`` is the thesis Table 6-1 error size."""
    return _core.characteristic_scale(Machine.from_dict(machine)._core, name, float(length))


def visit_groups(plan_or_dataset) -> List[int]:
    """Group label of each entry: consecutive entries at the same rotary pose
    (and last-move directions) form one visit (an indexation of the plan).
    Table 4-2 gives 28 visits (its (0, 0, 0) triplet recurs in separate rows)."""
    obs = plan_or_dataset.observations if hasattr(plan_or_dataset, "observations") else plan_or_dataset
    out, prev, g = [], object(), -1
    for o in obs:
        ax = o.get("axes", {})
        key = (tuple(sorted((a, round(float(v), 3)) for a, v in ax.items() if a in "ABCS")),
               tuple(sorted((a, int(v)) for a, v in (o.get("direction") or {}).items() if a in "ABCS")))
        if key != prev:
            g += 1
            prev = key
        out.append(g)
    return out


def rotary_directions(indexations: Sequence[Mapping[str, float]], axes: Iterable[str] = "ABC",
                      start: Optional[Mapping[str, int]] = None) -> List[Dict[str, int]]:
    """Last-move direction (+1/-1) of each rotary axis of ``axes`` at each
    indexation, visited in order: one dict per indexation with every axis of
    ``axes``. An indexation that does not name an axis holds it at 0, the
    command a plan writes for it, so going back to 0 is a move like any
    other. An axis that does not move keeps its direction; ``start`` gives
    the directions before the first indexation (default +1: the axes were
    brought to 0 by positive moves)."""
    axes = list(axes)
    prev = {a: 0.0 for a in axes}
    dirs = {a: int((start or {}).get(a, 1)) for a in axes}
    out = []
    for ix in indexations:
        for a in axes:
            v = float(ix.get(a, 0.0))
            if v > prev[a]:
                dirs[a] = 1
            elif v < prev[a]:
                dirs[a] = -1
            prev[a] = v
        out.append(dict(dirs))
    return out


def _as_dataset(plan: PlanLike, machine, artefact, tip_radius, values) -> Dataset:
    if isinstance(plan, Dataset):
        return plan
    if machine is None or artefact is None:
        raise ValueError("a plan needs machine= and artefact= (and tip_radius=) to be judged; "
                         "or pass a Dataset")
    m = Machine.from_dict(machine)
    names = set(m.parameter_names())
    v = _values(values)
    errors = {k: x for k, x in v.items() if k in names}
    setup = {k: x for k, x in v.items() if k not in names}
    return simulate(m, list(plan), errors=errors, artefact=artefact, tip_radius=tip_radius,
                    sigma=0.0, setup=setup)


class PlanQuality:
    """Condition number, rank, D-optimality and predicted uncertainties of a plan."""

    def __init__(self, core: "_core.PlanQuality", machine: Optional[Machine] = None):
        self._core = core
        self.machine = machine
        self.parameters: List[str] = list(core.parameters)
        self.n_observations: int = core.n_observations
        self.n_rows: int = core.n_rows
        self.n_parameters: int = core.n_parameters
        self.n_machine: int = core.n_machine
        #: sigma_max / sigma_min of the column-scaled Jacobian (inf: rank deficient)
        self.condition_number: float = core.condition_number
        self.rank: int = core.rank
        self.log_det_per_parameter: float = core.log_det_per_parameter
        #: Ds-optimality: log det of the machine-parameter information (setup
        #: eliminated) per parameter, characteristic units; larger is better
        self.d_criterion: float = core.d_criterion
        #: geometric mean predicted standard uncertainty (mm at the characteristic length)
        self.d_std: float = core.d_std
        #: name -> predicted one-sigma uncertainty (parameter units)
        self.predicted_std: Dict[str, float] = dict(zip(self.parameters, np.asarray(core.predicted_std)))
        self.confounded: List[List[str]] = [list(g) for g in core.confounded]

    @property
    def machine_parameters(self) -> List[str]:
        return self.parameters[: self.n_machine]

    def to_dict(self) -> dict:
        return json.loads(self._core.to_json())

    def report(self) -> str:
        lines = [f"  touches {self.n_observations}, residual rows {self.n_rows}, parameters "
                 f"{self.n_parameters} ({self.n_machine} machine), rank {self.rank}",
                 f"  condition number {self.condition_number:.4g}, D-criterion {self.d_criterion:.4g} "
                 f"(geometric mean std {self.d_std * 1e3:.4g} µm at the characteristic length)"]
        if self.confounded:
            lines.append("  confounded: " + "; ".join("{" + ", ".join(g) + "}" for g in self.confounded))
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"PlanQuality(touches={self.n_observations}, parameters={self.n_parameters}, "
                f"condition_number={self.condition_number:.4g}, d_criterion={self.d_criterion:.4g})")


def plan_quality(plan: PlanLike, estimate="S3", *, machine=None, artefact=None, tip_radius: float = 0.0,
                 fix=None, values=None, sigma: float = 0.0006, characteristic_length: float = 400.0,
                 subset: Optional[Iterable[int]] = None) -> PlanQuality:
    """Quality of a plan (or a recorded/simulated Dataset) for the parameter
    set ``estimate`` (names and/or presets, as :func:`fivecal.identify`) plus the
    default setup set.  A plan is simulated noise-free first (needs
    ``machine``, ``artefact``, ``tip_radius``), at ``values`` (the
    linearisation point, default nominal).  ``subset``: observation indices.
    ``sigma`` (mm): the probe noise of touches that declare none; the predicted
    uncertainties weight rows as :func:`fivecal.identify` does (a declared sigma
    is kept, a scale bar has its own)."""
    ds = _as_dataset(plan, machine, artefact, tip_radius, values)
    sub = None if subset is None else [int(i) for i in subset]
    q = _core.plan_quality(ds._core, _names(estimate), _names(fix), _values(values), float(sigma),
                           float(characteristic_length), True, sub)
    return PlanQuality(q, ds.machine)


def compare_plans(plans: Mapping[str, PlanLike], estimate="S3", **kwargs) -> List[dict]:
    """Thesis Table 8-4: one row per named plan with its number of visits
    (indexations), touches, condition number and D-optimality figures.
    ``kwargs`` as :func:`plan_quality`. A value may also be ``(plan_or_dataset,
    indices)`` to judge a subset of observations."""
    rows = []
    for name, p in plans.items():
        subset = None
        if isinstance(p, tuple):
            p, subset = p
        ds = _as_dataset(p, kwargs.get("machine"), kwargs.get("artefact"), kwargs.get("tip_radius", 0.0),
                         kwargs.get("values"))
        obs = ds.observations if subset is None else [ds.observations[i] for i in subset]
        q = plan_quality(ds, estimate, subset=subset,
                         **{k: v for k, v in kwargs.items() if k not in ("machine", "artefact", "tip_radius")})
        rows.append({"plan": name, "indexations": len(set(visit_groups(obs))), "touches": q.n_observations,
                     "condition_number": q.condition_number, "d_criterion": q.d_criterion,
                     "d_std": q.d_std, "rank": q.rank, "n_parameters": q.n_parameters, "quality": q})
    return rows


def format_comparison(rows: Sequence[Mapping]) -> str:
    """Rows of :func:`compare_plans` as a Table 8-4-like text table."""
    head = f"{'plan':<22}{'indexations':>12}{'touches':>9}{'cond. number':>14}{'D-crit':>9}{'gm std µm':>11}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{str(r['plan']):<22}{r['indexations']:>12}{r['touches']:>9}"
                     f"{r['condition_number']:>14.4g}{r['d_criterion']:>9.3f}{r['d_std'] * 1e3:>11.4g}")
    return "\n".join(lines)


def candidate_plan(machine, artefact: Mapping, indexations: Sequence[Mapping[str, float]], *,
                   tip_radius: float, limits: Optional[Mapping[str, Sequence[float]]] = None,
                   min_dot: float = -0.02, targets: Optional[Iterable[str]] = None,
                   sphere_normals=None, directions="visit",
                   accessible: Optional[Callable] = None) -> tuple:
    """Candidate touches: at each rotary indexation (dicts like ``{"B": 30,
    "C": -90, "S": 0}``) every facet, sphere or cylinder touch of ``artefact`` that faces
    the probe (normal . tool axis >= ``min_dot``) with all axis commands within
    ``limits`` (axis -> (min, max), mm / degrees).  Sphere touches go along
    ``sphere_normals`` (default: the ISO 230-10-like 33 points of
    :func:`fivecal.procedures.sphere_test.sphere_points`); cylinder touches at the section
    through the cylinder's ``point``, in the radial directions of those
    normals.  ``directions``: ``"visit"`` records the
    last-move directions of the rotary axes for the indexations visited in
    order, ``None`` records none, or a list of dicts.  ``accessible(point,
    normal, tool_axis)`` (e.g. :func:`fivecal.procedures.tango.facet_accessible` with the
    fixture obstacles) can veto touches further (collisions).

    Returns ``(plan, groups)``: plan entries and the indexation index of each."""
    m = Machine.from_dict(machine)
    setup = _core.Dataset.from_json(dumps({"machine": m.to_dict(), "probe": {"tip_radius": float(tip_radius)},
                                           "artefact": dict(artefact), "observations": []}), False)
    idx = [dict(ix) for ix in indexations]
    q = np.zeros((len(idx), len(m.axis_names)))
    for i, ix in enumerate(idx):
        for a, v in ix.items():
            letter = "S" if a == "C1" else a
            if letter not in m.axis_names:
                raise ValueError(f"indexations[{i}]: machine {m.name!r} has no axis '{a}'")
            q[i, m.axis_names.index(letter)] = float(v)
    dirs = None
    if directions is not None:
        dl = rotary_directions(idx, [a for a in m.axis_names if m.is_rotary(a) and a != "S"]) \
            if directions == "visit" else list(directions)
        if len(dl) != len(idx):
            raise ValueError("directions: one dict per indexation")
        dirs = np.zeros(q.shape, dtype=np.int32)
        for i, d in enumerate(dl):
            for a, v in d.items():
                dirs[i, m.axis_names.index(a)] = int(v)
    if sphere_normals is None:
        sphere_normals = _core.sphere_points([], np.array([0.0, 0.0, 1.0]))
    lim = {str(k): (float(v[0]), float(v[1])) for k, v in (limits or {}).items()}
    text, groups = _core.candidate_plan(setup, q, dirs, np.asarray(sphere_normals, float).reshape(-1, 3), lim,
                                        float(min_dot), [str(t) for t in (targets or [])])
    plan = json.loads(text)
    if accessible is not None:
        _, axis = m.tool_pose({a: q[:, i] for i, a in enumerate(m.axis_names)})
        keep_plan, keep_groups = [], []
        for e, g in zip(plan, groups):
            # where the stylus meets the surface and the surface's outward
            # normal there: the touch's kind knows (the registry)
            contact = _core.planned_contact(setup, dumps(e))
            ok = contact is None or accessible(contact[0], contact[1], axis[g])
            if ok:
                keep_plan.append(e)
                keep_groups.append(g)
        plan, groups = keep_plan, keep_groups
    return plan, list(groups)


class Design:
    """Result of :func:`design_plan`."""

    def __init__(self, core: "_core.DesignResult", plan: Optional[list], groups: List[int], criterion: str,
                 machine: Machine):
        self._core = core
        self.criterion = criterion
        #: chosen indexations (group labels of the pool), ascending
        self.groups: List[int] = list(core.groups)
        #: chosen observations / plan entries (indices into the pool), ascending
        self.observations: List[int] = list(core.observations)
        #: the chosen plan entries (when the pool was a plan), in pool order
        self.plan: Optional[list] = None if plan is None else [plan[i] for i in self.observations]
        self.quality = PlanQuality(core.quality, machine)
        self.reference = PlanQuality(core.reference, machine)
        self.history: List[float] = list(core.history)
        self.evaluations: int = core.evaluations
        self.stopped: bool = core.stopped
        self.pool_groups = groups

    def to_dict(self) -> dict:
        return json.loads(self._core.to_json())

    def report(self) -> str:
        q, r = self.quality, self.reference
        n_pool = len(set(self.pool_groups))
        lines = [f"fivecal design ({self.criterion}): {len(self.groups)} of {n_pool} indexations, "
                 f"{q.n_observations} of {r.n_observations} touches"
                 + (" (stopped early)" if self.stopped else ""),
                 f"  {'':<14}{'indexations':>12}{'touches':>9}{'cond. number':>14}{'D-crit':>9}{'gm std µm':>11}",
                 f"  {'candidates':<14}{n_pool:>12}{r.n_observations:>9}{r.condition_number:>14.4g}"
                 f"{r.d_criterion:>9.3f}{r.d_std * 1e3:>11.4g}",
                 f"  {'designed':<14}{len(self.groups):>12}{q.n_observations:>9}{q.condition_number:>14.4g}"
                 f"{q.d_criterion:>9.3f}{q.d_std * 1e3:>11.4g}",
                 f"  chosen indexations (pool visit numbers): {', '.join(str(g) for g in self.groups)}",
                 "",
                 f"  predicted standard uncertainty (sigma as given)",
                 f"  {'parameter':<12}{'candidates':>12}{'designed':>12}  unit"]
        for n in q.machine_parameters:
            f, unit = display_scale(n)
            a, b = r.predicted_std.get(n, math.nan), q.predicted_std.get(n, math.nan)
            lines.append(f"  {n:<12}{a * f:>12.4g}{b * f:>12.4g}  {unit}")
        if q.confounded:
            lines.append("  confounded in the design: " + "; ".join("{" + ", ".join(g) + "}" for g in q.confounded))
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"Design({len(self.groups)} indexations, {self.quality.n_observations} touches, "
                f"condition_number={self.quality.condition_number:.4g})")


class _DesignProgress:
    """Progress bars (fivecal.progress) for the search phases: greedy (k
    steps), exchange (passes until no swap improves), touches (removals)."""

    def __init__(self, enabled: Optional[bool]):
        self.enabled = enabled
        self.bar = None
        self.phase = None

    def __call__(self, phase: str, done: int, total: int, best: float) -> bool:
        if phase != self.phase:
            self.close()
            self.phase = phase
            self.bar = Progress(None if phase == "exchange" else total, label=f"design {phase}",
                                enabled=self.enabled)
        self.bar.label = f"design {phase} (best {best:.5g})"
        self.bar.update(max(0, done - self.bar.n))
        return True

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def design_plan(candidates: PlanLike, k: int, estimate="S3", *, groups: Optional[Sequence[int]] = None,
                machine=None, artefact=None, tip_radius: float = 0.0, fix=None, values=None,
                required: Optional[Iterable[int]] = None, criterion: str = "condition",
                method: str = "exchange", max_passes: int = 50, max_touches: int = 0,
                sigma: float = 0.0006, characteristic_length: float = 400.0,
                progress: Union[None, bool, Callable] = None) -> Design:
    """Pick ``k`` indexations from a pool of candidate touches.

    ``candidates``: a plan (simulated noise-free on the nominal machine, needs
    ``machine``, ``artefact``, ``tip_radius``) or a Dataset.  ``groups``: the
    indexation label of each candidate (default :func:`visit_groups`).
    ``criterion``: ``"condition"`` (minimise the condition number) or ``"d"``
    (maximise the Ds-optimality of the machine parameters: more information).
    ``method``: ``"greedy"`` (forward selection) or ``"exchange"`` (greedy, then
    swaps of one chosen and one unchosen indexation while they improve).
    ``required``: groups always kept.  ``max_touches`` > 0 then removes single
    touches down to that budget.  ``progress``: True for a progress bar on
    stderr, ``"auto"`` for one when stderr is a terminal (or
    ``FIVECAL_PROGRESS=1``), or ``callable(phase, done, total, best) -> bool``
    (False stops the search; the best plan so far is returned)."""
    plan = None if isinstance(candidates, Dataset) else list(candidates)
    ds = _as_dataset(candidates, machine, artefact, tip_radius, values)
    g = visit_groups(plan if plan is not None else ds) if groups is None else [int(x) for x in groups]
    if len(g) != len(ds):
        raise ValueError(f"groups: {len(g)} labels for {len(ds)} candidates")
    bars = None
    if progress is True or progress == "auto":
        bars = _DesignProgress(True if progress is True else None)
        cb = bars
    else:
        cb = progress or None
    try:
        core = _core.design_plan(ds._core, g, _names(estimate), _names(fix), _values(values), float(sigma),
                                 float(characteristic_length), int(k), [int(x) for x in (required or [])],
                                 criterion, method, int(max_passes), int(max_touches), cb)
    finally:
        if bars is not None:
            bars.close()
    return Design(core, plan, g, criterion, ds.machine)
