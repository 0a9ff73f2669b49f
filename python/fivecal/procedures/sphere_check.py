"""Quick sphere check, in the style of the controller cycles (Heidenhain
KinematicsOpt, Siemens CYCLE996, AxiSet): one calibrated sphere on the table,
a calibrated stylus, a few positions of each rotary axis in turn, each
position approached from both sides. The general engine fits each rotary
axis' pivot (its line's position across the axis and its tilt) and its
reversal error; the check reports them with their uncertainty, their change
since the previous check, the dispersion of the sphere positions before and
after, and how well the positions determine the pivots.

    from fivecal.procedures import sphere_check
    m = fivecal.Machine.load("examples/machines/c600u.json")
    ball = {"id": "S1", "center": [80, 50, 60], "radius": 12.5}
    plan = sphere_check.plan(m, ball, tip_radius=3.0)           # positions, both sides
    ds = ...  # the touches, recorded (or fivecal.simulate(m, plan, ...))
    check = sphere_check.evaluate(ds, previous="last_check.json")
    print(check.report())

Units: mm, degrees for commands, rad for angular errors; reports in µm / µrad.
"""
from __future__ import annotations

import json
import math
import numbers
import os
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

from .. import _core
from ..dataset import Dataset
from ..files import read_json
from ..identification import Result, result_document, warn_when_unusable
from ..machine import Machine
from ..views import Viewable
from . import sphere_test

def _rotary_axes(machine: Machine) -> List[str]:
    return list(_core.checked_rotary_axes(machine._core))


def pivot_parameters(machine: Machine, axis: str, backlash: bool = True) -> List[str]:
    """The error parameters a sphere check estimates for rotary ``axis``: the
    position of its line across the axis (two ``E<X|Y|Z>0<axis>``), its tilt
    (two ``E<A|B|C>0<axis>``) and, with ``backlash``, its reversal error
    ``E<axis><axis>b``. The position along the axis and the zero angle are
    left out: a sphere check cannot tell them from the sphere's own place.
    For an inclined axis the pair of machine directions most across it is
    used (fivecal's parameters are along the machine axes). The rule is the
    core's (``procedures/sphere_check.h`` PivotParameters)."""
    return list(_core.pivot_parameters(machine._core, str(axis), bool(backlash)))


#: positions per rotary axis at most: one a degree over a full turn, far more than a pivot needs
MAX_POSITIONS = _core.sphere_check_max_positions


def spindle_equivalent(machine: Machine, name: str) -> str:
    """The name every fivecal command gives the position error ``name``
    (``E<X|Y|Z>0<axis>`` of a rotary axis): the spindle's ``E<d>0S`` when the
    two are the same error, else ``name`` itself.

    A rotary axis' offset along d is a constant offset between tool and
    part when every rotary axis between it and the foundation turns about d
    (or there is none): on an A/C trunnion EX0C (C's line moved along A) and
    EY0A, on a B/C table EY0C and EX0B. The spindle's offset across its own
    line is the same constant (exactly for the first axis from the
    foundation, to first order beyond: they differ by the product of the
    parent's tilt errors and the offset), so no data can tell them apart; identify's
    location selection (docs/identification.md, the thesis' set) names it
    by the spindle, and so does every procedure, so results of different
    commands compare by name. The spindle's value is minus the axis' on the
    workpiece side (README, sign conventions). The rule is the core's
    (``procedures/sphere_check.h`` SpindleEquivalent), used by the core's
    procedures too."""
    return _core.spindle_equivalent(machine._core, str(name))


def spindle_names(machine: Machine, errors: Mapping[str, float]) -> Dict[str, float]:
    """``errors`` (name -> mm / rad) under the names every fivecal command
    reports them (:func:`spindle_equivalent`): a rotary offset that is the
    spindle's offset becomes the spindle's, minus its value on the
    workpiece side (equal errors add up). What a sphere check, an R-test or
    ``identify --estimate location`` of a machine with these errors
    recovers."""
    return dict(_core.spindle_names(machine._core, [(str(n), float(v)) for n, v in errors.items()]))


def positions(machine: Machine, n: int = 5, limits: Optional[Mapping[str, Sequence[float]]] = None
              ) -> Dict[str, List[float]]:
    """``n`` positions of each rotary axis spread over its range (``limits``
    axis -> (min, max) degrees; default a full turn for C, ±90° otherwise).
    The rule is the core's (``procedures/sphere_check.h`` SphereCheckPositions)."""
    # bounded here, not only by the command line: n = 10**9 would build the plan before anything is said
    if isinstance(n, bool) or not isinstance(n, numbers.Real) or not (n == int(n) if math.isfinite(n) else False) \
            or not 3 <= n <= MAX_POSITIONS:
        raise ValueError(f"n: {n!r} positions per axis; expected a whole number from 3 (a pivot needs at "
                         f"least 3) to {MAX_POSITIONS}")
    rotary = set(_rotary_axes(machine))
    lim = {}
    for a, v in (limits or {}).items():
        if a in rotary:
            lo, hi = v
            lim[a] = (float(lo), float(hi))
    return {a: [float(x) for x in v] for a, v in _core.sphere_check_positions(machine._core, int(n), lim)}


def plan(machine: Union[Machine, Mapping], sphere: Mapping, *, tip_radius: float, n: int = 5,
         axis_positions: Optional[Mapping[str, Sequence[float]]] = None,
         limits: Optional[Mapping[str, Sequence[float]]] = None, both_sides: bool = True,
         min_dot: float = 0.0) -> list:
    """Plan of a sphere check: each rotary axis in turn through its positions
    (the others at 0), upwards then, with ``both_sides``, downwards, so every
    position is reached from both directions (the reversal error); at each
    position the touches of the thesis' sphere distribution that face the
    probe. ``axis_positions`` (axis -> degrees) replaces the ``n`` spread
    positions of :func:`positions`."""
    m = Machine.from_dict(machine)
    pos = dict(axis_positions) if axis_positions is not None else positions(m, n, limits)
    unknown = [a for a in pos if a not in _rotary_axes(m)]
    if unknown:
        raise ValueError(f"axis_positions: machine {m.name!r} has no rotary axis {unknown[0]!r} "
                         f"(rotary axes: {', '.join(_rotary_axes(m))})")
    visits = []
    for a, vals in pos.items():
        vals = [float(v) for v in vals]
        if len(vals) > MAX_POSITIONS:
            raise ValueError(f"axis_positions.{a}: {len(vals)} positions; at most {MAX_POSITIONS}")
        if len(vals) < 3:
            raise ValueError(f"axis_positions.{a}: {len(vals)} positions; a pivot needs at least 3")
        visits += [{a: v} for v in vals]
        if both_sides:
            visits += [{a: v} for v in vals[::-1]]
    return sphere_test.sphere_plan(m, sphere, visits, tip_radius=tip_radius, min_dot=min_dot,
                                   limits=limits)


@dataclass
class SphereCheck(Viewable):
    """Result of :func:`evaluate` (mm, rad)."""

    result: object                       #: the fivecal.Result of the fit
    axes: List[str]
    pivots: Dict[str, Dict[str, tuple]]  #: axis -> parameter -> (value, std)
    backlash: Dict[str, tuple]           #: axis -> (value, std) rad
    change: Dict[str, tuple] = field(default_factory=dict)  #: parameter -> (change, std of the change)
    centres_before: np.ndarray = None    #: per position, sphere centre with the nominal model
    centres_after: np.ndarray = None     #: ... with the identified model
    groups: List[str] = field(default_factory=list)
    dispersion_before: float = 0.0       #: max |centre - mean centre|, nominal model
    dispersion_after: float = 0.0        #: the same with the identified model
    condition_number: float = 0.0
    informed: Dict[str, float] = field(default_factory=dict)  #: parameter -> posterior / prior sigma
    #: ``expect``: did the loaded change take effect (:func:`verify_change`)
    verification: Optional["ChangeVerification"] = None

    def procedure_values(self) -> dict:
        """The check's own values, the ``procedure.values`` of its result
        document (docs/formats.md): mm and rad; a σ that is not finite is null."""
        vs = lambda v, s: {"value": v, "std": s}
        return {"axes": list(self.axes),
                "pivots": {a: {n: vs(*p) for n, p in ax.items()} for a, ax in self.pivots.items()},
                "reversal": {a: dict(vs(*p), name=f"E{a}{a}b") for a, p in self.backlash.items()},
                "change": {n: {"change": c, "std": s} for n, (c, s) in self.change.items()},
                "positions": list(self.groups),
                "dispersion_before": self.dispersion_before, "dispersion_after": self.dispersion_after,
                "condition_number": self.condition_number, "informed": dict(self.informed)} | \
            ({"verification": self.verification.to_dict()} if self.verification is not None else {})

    def to_dict(self) -> dict:
        """The result document (the one every procedure writes): the pivot
        fit with the check's values as ``procedure`` ``sphere-check``; the
        next check takes it as ``previous``."""
        return result_document(self.result, "sphere-check", self.procedure_values())

    def values(self) -> Dict[str, float]:
        return {n: v for ax in self.pivots.values() for n, (v, _) in ax.items()} | \
               {f"E{a}{a}b": v for a, (v, _) in self.backlash.items()}

    def report(self) -> str:
        r = self.result
        L = [f"Sphere check on {r.dataset.machine.name}: {len(self.groups)} positions, "
             f"{r.n_observations} touches, rms {r.rms * 1e3:.2f} µm, verdict {r.verdict}", ""]
        L.append(f"  {'parameter':<10}{'value':>12}{'± 1σ':>10}{'change':>12}{'± 1σ':>10}")
        for a in self.axes:
            L.append(f"  axis {a}: pivot")
            for n, (v, s) in self.pivots[a].items():
                unit, k = ("µrad", 1e6) if n[1] in "ABC" else ("µm", 1e3)
                ch = self.change.get(n)
                chs = f"{ch[0] * k:>12.2f}{ch[1] * k:>10.2f}" if ch else f"{'':>22}"
                same = f"  (the {a} line's offset, named as the spindle's)" if n[3] != a else ""
                L.append(f"  {n:<10}{v * k:>12.2f}{s * k:>10.2f}{chs}  {unit}{same}")
            if a in self.backlash:
                v, s = self.backlash[a]
                L.append(f"  E{a}{a}b{'':<5}{v * 1e6:>12.2f}{s * 1e6:>10.2f}{'':>22}  µrad reversal")
        L += ["", f"  dispersion of the sphere positions: {self.dispersion_before * 1e3:.2f} µm with the nominal "
                  f"model, {self.dispersion_after * 1e3:.2f} µm with the checked pivots",
              f"  quality of the positions: condition number {self.condition_number:.3g}; "
              "posterior/prior sigma " + ", ".join(f"{n} {v:.2g}" for n, v in self.informed.items())]
        und = list(getattr(r, "undetermined", []) or [])
        if und:
            L.append("  NOT determined by these positions: " + ", ".join(und))
        if self.verification is not None:
            L += ["", self.verification.report()]
        return "\n".join(L)


def _previous_values(previous) -> Dict[str, tuple]:
    """The previous check read into name -> (value, std): a SphereCheck, a
    Result, a result document (any procedure's, a file or a dict) or a plain
    mapping name -> value. The core names a table axis' offset that is the
    spindle's by the spindle too (a check written before the spindle names)."""
    if previous is None:
        return {}
    if isinstance(previous, SphereCheck):
        return {n: (v, s) for ax in previous.pivots.values() for n, (v, s) in ax.items()}
    if hasattr(previous, "values") and hasattr(previous, "std") and not isinstance(previous, (str, dict)):
        return {n: (v, previous.std.get(n, 0.0)) for n, v in previous.values.items()}
    if not isinstance(previous, Mapping):
        previous = read_json(previous, "previous check")
    # any result document (any procedure's), or a plain mapping name -> value
    params = previous.get("parameters", previous)
    if not isinstance(params, Mapping):
        raise ValueError("previous: expected a result document with 'parameters'")
    out = {}
    for n, p in params.items():
        try:
            if isinstance(p, Mapping):
                out[n] = (float(p["value"]), float(p.get("std") or 0.0))
            else:
                out[n] = (float(p), 0.0)
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"previous: parameters.{n}: expected a number or {{value, std}}") from None
    return out


#: the ``kind`` of the export document ``fivecal export <vendor> --out DIR`` writes as DIR/export.json
EXPORT_KIND = "fivecal controller export"
EXPORT_FILE = "export.json"


def _estimate(obj, where: str):
    """(names, values, covariance) of a check or result: a SphereCheck, a
    Result, a result document (a file or a dict: ``parameters`` with value
    and std, ``correlation`` in ``estimated`` order) or a plain mapping
    name -> value (no uncertainty). A σ the document leaves out (null) is NaN:
    the core refuses it only where it is compared."""
    if isinstance(obj, SphereCheck):
        obj = obj.result
    if isinstance(obj, Result):
        names = list(obj.estimated)
        return names, np.array([obj.values.get(n, 0.0) for n in names]), np.asarray(obj.covariance, float)
    if not isinstance(obj, Mapping):
        obj = read_json(obj, where)
    params = obj.get("parameters", obj)
    if not isinstance(params, Mapping):
        raise ValueError(f"{where}: expected a result document with 'parameters'")
    names, values, std = [], [], []
    for n, p in params.items():
        try:
            if isinstance(p, Mapping):
                v, sd = p["value"], p.get("std", 0.0 if p.get("fixed") else None)
            else:
                v, sd = p, 0.0
            names.append(str(n))
            values.append(math.nan if v is None else float(v))
            std.append(math.nan if sd is None else float(sd))
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"{where}: parameters.{n}: expected a number or {{value, std}}") from None
    cov = np.diag(np.square(std))
    est, corr = obj.get("estimated"), obj.get("correlation")
    if isinstance(est, list) and isinstance(corr, list) and len(corr) == len(est):
        try:
            R = np.array([[math.nan if x is None else float(x) for x in row] for row in corr], float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: correlation: expected a square matrix of numbers") from None
        if R.shape != (len(est), len(est)):
            raise ValueError(f"{where}: correlation: expected {len(est)} x {len(est)} (estimated), got {R.shape}")
        idx = [names.index(n) if n in names else -1 for n in est]
        for a, i in enumerate(idx):
            for b, j in enumerate(idx):
                if i >= 0 and j >= 0 and i != j:
                    cov[i, j] = R[a, b] * std[i] * std[j]
    return names, np.asarray(values, float), cov


def read_export(expect) -> dict:
    """The export document (``fivecal export <vendor> ... --out DIR`` writes
    DIR/export.json; a path to it or to DIR, or the dict) checked: its
    ``kind``, ``machine`` and ``absorbed`` (``names``, ``change`` and
    ``covariance``: the fivecal errors the controller's new values
    compensate). Returns vendor, machine, path, names, change, covariance
    (NaN where not given)."""
    path = None
    if not isinstance(expect, Mapping):
        path = os.fspath(expect)
        if os.path.isdir(path):
            path = os.path.join(path, EXPORT_FILE)
        expect = read_json(path, "expect")
    where = f"expect ({path})" if path else "expect"
    if expect.get("kind") != EXPORT_KIND:
        raise ValueError(f"{where}: kind {expect.get('kind')!r}: not a controller export (expected "
                         f"{EXPORT_KIND!r}: the export.json `fivecal export <vendor> --out DIR` writes)")
    ab = expect.get("absorbed")
    if not isinstance(ab, Mapping):
        raise ValueError(f"{where}: absorbed: expected an object with names, change and covariance")
    names, change = ab.get("names"), ab.get("change")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"{where}: absorbed.names: expected a list of parameter names")
    if not isinstance(change, list) or len(change) != len(names):
        raise ValueError(f"{where}: absorbed.change: expected {len(names)} numbers (one per absorbed.names)")
    c = []
    for i, v in enumerate(change):
        if isinstance(v, bool) or not isinstance(v, numbers.Real):
            raise ValueError(f"{where}: absorbed.change[{i}] ({names[i]}): expected a number, got {v!r}")
        c.append(float(v))
    n = len(names)
    cov = ab.get("covariance")
    if cov is None:
        C = np.full((n, n), math.nan)
    else:
        if not isinstance(cov, list) or len(cov) != n or not all(isinstance(r, list) and len(r) == n for r in cov):
            raise ValueError(f"{where}: absorbed.covariance: expected {n} x {n} numbers")
        try:
            C = np.array([[math.nan if x is None else float(x) for x in r] for r in cov], float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: absorbed.covariance: expected numbers") from None
    machine = expect.get("machine")
    if not isinstance(machine, str) or not machine:
        raise ValueError(f"{where}: machine: expected the machine's name")
    # what the export says a sphere check cannot verify (its error-motion
    # tables); an export written before the field existed says nothing
    unverifiable = (expect.get("sphere_check") or {}).get("unverifiable")
    return {"path": path, "vendor": str(expect.get("vendor", "")), "machine": machine, "names": list(names),
            "change": np.asarray(c, float), "covariance": C,
            "unverifiable": unverifiable if isinstance(unverifiable, str) else None}


@dataclass
class ChangeVerification:
    """Did a change loaded into the controller take effect as predicted
    (:func:`verify_change`; the core's ``controllers/verify.h``)? mm, rad."""

    verdict: str          #: "took effect", "cause", "one of", "cannot tell", "differs"
    message: str          #: one line a person reads
    causes: List[str]     #: the causes named (or, "cannot tell", the alternatives not excluded)
    parameters: Dict[str, dict]  #: check name -> previous, expected, now, predicted, z, ratio, ... with std
    ratio: float          #: observed / expected change (weighted over the parameters)
    ratio_std: float
    k: float
    not_compared: List[str]
    export: dict          #: path, vendor, machine of the export

    @property
    def took_effect(self) -> bool:
        return self.verdict == "took effect"

    def to_dict(self) -> dict:
        """The ``procedure.values.verification`` of the check's result document."""
        return {"expect": self.export.get("path"), "vendor": self.export.get("vendor"),
                "machine": self.export.get("machine"), "verdict": self.verdict, "took_effect": self.took_effect,
                "message": self.message, "causes": list(self.causes), "ratio": self.ratio,
                "ratio_std": self.ratio_std, "k": self.k, "not_compared": list(self.not_compared),
                "parameters": {n: dict(p) for n, p in self.parameters.items()},
                # a record that says "took effect" must keep what the check could not see
                "unverifiable": self.export.get("unverifiable")}

    def report(self) -> str:
        e = self.export
        L = [f"Verify after loading ({e.get('vendor') or 'controller'} export"
             + (f" {e['path']}" if e.get("path") else "") + f", machine {e.get('machine')}): "
             "the change expected against the drop this check saw since the previous one",
             f"  {'parameter':<10}{'previous':>11}{'change':>11}{'predicted':>11}{'now':>11}{'± 1σ':>9}"
             f"{'z':>9}  {'ratio ± 1σ':<18}unit  this parameter"]
        for n, p in self.parameters.items():
            unit, f = ("µrad", 1e6) if n[1] in "ABC" else ("µm", 1e3)
            ratio = f"{p['ratio']:.4g} ± {p['ratio_std']:.2g}" if math.isfinite(p["ratio"]) else "-"
            L.append(f"  {n:<10}{p['previous'] * f:>11.2f}{p['expected'] * f:>11.2f}{p['predicted'] * f:>11.2f}"
                     f"{p['now'] * f:>11.2f}{p['predicted_std'] * f:>9.2f}{p['z']:>9.3g}  {ratio:<18}{unit:<4}  "
                     f"{'as predicted' if p['as_predicted'] else 'NOT as predicted'}: {_row_verdict(p)}")
        if self.not_compared:
            L.append("  not compared (no change): " + ", ".join(self.not_compared))
        L.append(f"  overall ({self.k:g}σ): {self.message}")
        if e.get("unverifiable"):
            L.append(f"  verified the kinematics only; not verified: {e['unverifiable']}")
        return "\n".join(L)


def _row_verdict(p: Mapping) -> str:
    v, causes = p["verdict"], p.get("causes") or []
    if v == "cause":
        return " or ".join(causes)
    if v == "one of":
        return "one of " + ", ".join(causes)
    return v


def verify_change(check: "SphereCheck", previous, expect, k: float = 3.0,
                  change_covariance: bool = False) -> ChangeVerification:
    """Verify after loading (docs/controllers.md): did the change an export
    says the controller's new values compensate (``expect``: its export.json,
    :func:`read_export`) take effect, from the check before loading
    (``previous``: a result document, Result or SphereCheck) and ``check``,
    the one after? Predicted: previous − change, per parameter and overall,
    within ``k`` σ of the two checks; else the cause the numbers support
    (not applied, sign reversed, applied twice, a unit, the sign of one
    component), "cannot tell" or "differs" with the numbers. The comparison
    is the core's (``controllers/verify.h`` VerifyChange). The export's
    covariance of the change (how well it corrects the machine) enters only
    with ``change_covariance``: the controller runs the exported numbers
    exactly, so by default the two checks' σ alone decide (a wider, weaker
    test otherwise). ValueError for an export of another machine or of
    parameters this check does not measure."""
    ex = read_export(expect)
    m = check.result.dataset.machine
    if ex["machine"] != m.name:
        raise ValueError(f"expect: the export is for machine {ex['machine']!r}; this check is of machine "
                         f"{m.name!r}")
    pn, pv, pc = _estimate(previous, "previous")
    nn, nv, nc = _estimate(check, "check")
    v = _core.verify_change(m._core, pn, pv, pc, ex["names"], ex["change"], ex["covariance"], nn, nv, nc, float(k),
                            bool(change_covariance))
    rows = {r["name"]: {key: r[key] for key in ("previous", "previous_std", "expected", "expected_std", "now",
                                                "now_std", "predicted", "predicted_std", "observed", "observed_std",
                                                "z", "as_predicted", "ratio", "ratio_std")}
            | {"verdict": r["outcome"]["verdict"], "causes": [c["text"] for c in r["outcome"]["causes"]],
               "message": r["outcome"]["message"]}
            for r in v["parameters"]}
    o = v["outcome"]
    return ChangeVerification(o["verdict"], o["message"], [c["text"] for c in o["causes"]], rows, v["ratio"],
                              v["ratio_std"], v["k"], list(v["not_compared"]),
                              {key: ex[key] for key in ("path", "vendor", "machine", "unverifiable")})


def evaluate(dataset: Union[Dataset, Mapping], *, previous=None, calibrated_stylus: bool = True,
             backlash: Optional[bool] = None, sphere: Optional[str] = None, expect=None,
             k: float = 3.0) -> SphereCheck:
    """Evaluate a sphere check: fit the pivot parameters of every rotary axis
    that moved (:func:`pivot_parameters`) with the stylus known
    (``calibrated_stylus``: ``tip.*`` fixed) and the sphere's place free.
    ``backlash``: estimate each axis' reversal error (default: when its
    positions were reached from both directions). ``previous``: the last
    check (a SphereCheck, a Result, or a result file / dict) for the change of
    each pivot, with the σ of the change from both checks (independent
    checks). ``expect``: the export.json of a change loaded into the
    controller since ``previous``: :attr:`SphereCheck.verification` says
    whether it took effect (:func:`verify_change`, ``k`` σ). The evaluation
    is the core's (``procedures/sphere_check.h`` EvaluateSphereCheck).
    Raises ValueError when the data cannot determine a pivot."""
    if expect is not None and previous is None:
        raise ValueError("expect: needs previous, the check before loading (the one the change is predicted from)")
    ds = Dataset.from_dict(dataset)
    core = _core.sphere_check(ds._core, sphere or "", bool(calibrated_stylus),
                              -1 if backlash is None else int(bool(backlash)), _previous_values(previous))
    r = warn_when_unusable(Result(core.fit, ds))
    axes = [a.axis for a in core.axes]
    pivots = {a.axis: {v.name: (v.value, v.std) for v in a.pivot} for a in core.axes}
    lash = {a.axis: (a.backlash.value, a.backlash.std) for a in core.axes if a.has_backlash}
    change = {c.name: (c.value, c.std) for c in core.change}
    pos = np.asarray(core.positions)
    labels = [", ".join(f"{a} {v:g}°" for a, v in zip(axes, row)) for row in pos]
    check = SphereCheck(r, axes, pivots, lash, change, np.asarray(core.centres_before),
                        np.asarray(core.centres_after), labels, core.dispersion_before, core.dispersion_after,
                        float(core.condition_number), dict(core.informed))
    if expect is not None:
        check.verification = verify_change(check, previous, expect, k)
    return check


def to_json(check: SphereCheck) -> str:
    """The check's result document (:meth:`SphereCheck.to_dict`) as JSON."""
    return json.dumps(check.to_dict(), indent=1, sort_keys=True, ensure_ascii=False)


__all__ = ["plan", "positions", "pivot_parameters", "spindle_equivalent", "spindle_names", "evaluate", "SphereCheck",
           "to_json", "verify_change", "read_export", "ChangeVerification"]
