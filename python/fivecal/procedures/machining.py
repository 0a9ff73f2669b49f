"""Machining tests in error-sensitive directions (Zhang & Zhang,
``shared/seeds/004_*``): the test poses and sensitive directions, the
machining errors the full machine model predicts, and the identification of
the tilt-axis errors from measured machining errors.  The algorithms are in
the C++ core (``cpp/include/fivecal/procedures/machining_test.h``, where the model and
the paper's first-order equations are written out)::

    from fivecal.procedures import machining
    m = fivecal.Machine.load("examples/machines/c600u.json")
    tests = machining.zhang_tests(m, L=150.0, H=60.0)         # T1, T2, T3
    e = machining.predict(m, tests, errors={"EA0C": 30e-6, "EY0C": 0.02})
    for t, v in zip(tests, e):
        t["measured"] = v                                       # measured on the part
    r = machining.identify(m, tests, sigma=0.001)               # EA0C, EY0C, EZ0C
    print(r.report())

A test is a dict ``{"id": "T1", "point": [0, L, H] (workpiece frame, mm),
"direction": [0, -1, 0] (sensitive direction r in the machine frame),
"pose": {"A": -90, "C": -180}, "reference": {"A": -90, "C": 0} (optional),
"measured": 0.0123 (mm, for identification)}``.  The machining error is the
table's displacement of the feature along r at ``pose`` minus that at
``reference`` (zero on a perfect machine).  Workpiece set-up errors are the
parameters ``workpiece.x|y|z`` (mm) and ``workpiece.a|b|c`` (rad).

Units: mm, degrees for rotary commands, rad for angular errors.
"""
from __future__ import annotations

import json
import math
from typing import Dict, Iterable, List, Mapping, Optional, Sequence

import numpy as np

from .. import _core
from ..identification import result_document
from ..views import Viewable
from ..machine import Machine
from ..units import display_scale

__all__ = ["TILT_AXIS_ERRORS", "WORKPIECE_SETUP", "zhang_tests", "poses", "predict", "sensitivity", "first_order",
           "identify", "MachiningResult"]

#: The three errors of the tilt axis the paper identifies (A_xi_x, A_delta_y, A_delta_z).
TILT_AXIS_ERRORS = ("EA0C", "EY0C", "EZ0C")
#: Workpiece set-up parameters (the paper's C_delta, C_xi).
WORKPIECE_SETUP = ("workpiece.x", "workpiece.y", "workpiece.z", "workpiece.a", "workpiece.b", "workpiece.c")


def _values(values) -> Dict[str, float]:
    if values is None:
        return {}
    if hasattr(values, "values") and not isinstance(values, Mapping):
        values = values.values
    return {str(k): float(v) for k, v in values.items()}


def _pose_vector(m: Machine, pose: Mapping[str, float], where: str) -> np.ndarray:
    q = np.zeros(len(m.axis_names))
    for a, v in pose.items():
        letter = "S" if a == "C1" else a
        if letter not in m.axis_names:
            raise ValueError(f"{where}: machine {m.name!r} has no axis '{a}' (axes {m.axis_names})")
        q[m.axis_names.index(letter)] = float(v)
    return q


def _pose_dict(m: Machine, q) -> Dict[str, float]:
    return {a: float(q[i]) for i, a in enumerate(m.axis_names)}


def _core_tests(m: Machine, tests: Sequence[Mapping]) -> list:
    out = []
    for i, t in enumerate(tests):
        w = f"tests[{i}]"
        for key in ("point", "direction", "pose"):
            if key not in t:
                raise ValueError(f"{w}.{key}: missing")
        ref = t.get("reference")
        out.append(_core.MachiningTest(
            str(t.get("id", f"T{i + 1}")), np.asarray(t["point"], float).reshape(3),
            np.asarray(t["direction"], float).reshape(3), _pose_vector(m, t["pose"], f"{w}.pose"),
            None if ref is None else _pose_vector(m, ref, f"{w}.reference"), float(t.get("measured", 0.0))))
    return out


def zhang_tests(machine, L: float, H: float) -> List[dict]:
    """Zhang & Zhang's tests T1-T3 on an A/C tilting table (A along +-X, C
    along +-Z): feature point (0, L, H); T1 r = (0, -1, 0) at (alpha, gamma) =
    (90, 180) minus (90, 0) (eq. 6); T2 r = (0, 0, 1) at (90, 180) minus (0, 0)
    (eq. 11); T3 r = (0, -1, 0), same poses (eq. 16).  Commands are signed for
    the machine's axis directions.  L large (feature far from the table
    centre) makes the tests sensitive."""
    m = Machine.from_dict(machine)
    out = []
    for t in _core.zhang_zhang_tests(m._core, float(L), float(H)):
        out.append({"id": t.id, "point": [float(x) for x in t.point], "direction": [float(x) for x in t.direction],
                    "pose": {a: v for a, v in _pose_dict(m, t.pose).items() if m.is_rotary(a)},
                    "reference": {a: v for a, v in _pose_dict(m, t.reference).items() if m.is_rotary(a)}})
    return out


def poses(machine, tests: Sequence[Mapping]) -> List[dict]:
    """The cutting programme: per test ``{"id", "pose": {...all axes...},
    "reference": {...} or None}`` with the linear commands that put the
    nominal tool point on the feature (mm / degrees)."""
    m = Machine.from_dict(machine)
    P = np.asarray(_core.machining_poses(m._core, _core_tests(m, tests)))
    out = []
    for i, t in enumerate(tests):
        ref = P[2 * i + 1]
        out.append({"id": t.get("id", f"T{i + 1}"), "pose": _pose_dict(m, P[2 * i]),
                    "reference": None if np.isnan(ref).any() else _pose_dict(m, ref)})
    return out


def predict(machine, tests: Sequence[Mapping], errors=None, setup: Optional[Mapping[str, float]] = None) -> np.ndarray:
    """Machining errors (mm) of the tests predicted by the full model with
    machine ``errors`` and workpiece ``setup`` (``workpiece.*``)."""
    m = Machine.from_dict(machine)
    v = _values(errors)
    v.update(_values(setup))
    return np.asarray(_core.predict_machining(m._core, _core_tests(m, tests), v))


def sensitivity(machine, tests: Sequence[Mapping], names: Iterable[str], errors=None,
                setup: Optional[Mapping[str, float]] = None) -> np.ndarray:
    """d(machining error) / d(parameter): (tests, names) matrix, mm per
    parameter unit, at ``errors`` / ``setup`` (default nominal): which errors
    each test is sensitive to (the automatic derivatives of the identification)."""
    m = Machine.from_dict(machine)
    v = _values(errors)
    v.update(_values(setup))
    return np.asarray(_core.machining_jacobian(m._core, _core_tests(m, tests), [str(n) for n in names], v))


def first_order(L: float, H: float, errors=None, setup: Optional[Mapping[str, float]] = None) -> np.ndarray:
    """The paper's closed forms for T1-T3: eq. (6), eq. (11) as its eq. (10)
    gives it to first order (the printed eq. (11) has the A_xi_x coefficient
    (L - H) instead of -(H + L)), eq. (16).  A_delta = (EX0C, EY0C, EZ0C),
    A_xi = (EA0C, EB0C, EC0C), C_delta / C_xi = workpiece.x|y|z / a|b|c."""
    v = _values(errors)
    v.update(_values(setup))
    g = lambda names: np.array([v.get(n, 0.0) for n in names])
    return np.asarray(_core.zhang_zhang_first_order(float(L), float(H), g(["EX0C", "EY0C", "EZ0C"]),
                                                    g(["EA0C", "EB0C", "EC0C"]), g(WORKPIECE_SETUP[:3]),
                                                    g(WORKPIECE_SETUP[3:])))


class MachiningResult(Viewable):
    """Parameters identified from machining errors, with uncertainties."""

    def __init__(self, core, machine: Machine, tests: Sequence[Mapping]):
        self._core = core
        self.machine = machine
        self.tests = list(tests)
        self.estimated: List[str] = list(core.estimated)
        self.values: Dict[str, float] = dict(zip(self.estimated, map(float, np.asarray(core.values))))
        self.std: Dict[str, float] = dict(zip(self.estimated, map(float, np.asarray(core.std))))
        self.covariance = np.asarray(core.covariance)
        self.predicted = np.asarray(core.predicted)
        self.residuals = np.asarray(core.residuals)
        self.sigma: float = core.sigma
        self.condition_number: float = core.condition_number
        self.rank: int = core.rank
        self.converged: bool = core.converged
        self.iterations: int = core.iterations

    def to_dict(self) -> dict:
        """The result document (the one every procedure writes): the
        identified parameters with their σ, and per test its measured and
        modelled machining error (mm) as ``procedure`` ``machining``."""
        finite = all(math.isfinite(v) for v in self.values.values()) and \
            all(math.isfinite(s) for s in self.std.values())
        doc = {"parameters": {n: {"value": self.values[n], "std": self.std[n] if math.isfinite(self.std[n]) else None}
                              for n in self.estimated},
               "estimated": list(self.estimated), "n_observations": len(self.tests),
               "n_parameters": len(self.estimated), "rank": int(self.rank), "converged": bool(self.converged),
               "iterations": int(self.iterations), "finite": finite, "sigma": float(self.sigma),
               "condition_number": float(self.condition_number) if math.isfinite(self.condition_number) else None,
               "verdict": ("non_finite" if not finite else "not_converged" if not self.converged else
                           "undetermined" if self.rank < len(self.estimated) else "ok")}
        tests = {str(t.get("id", f"T{i + 1}")): {"measured": float(t.get("measured", 0.0)), "model": float(p)}
                 for i, (t, p) in enumerate(zip(self.tests, self.predicted))}
        return result_document(doc, "machining", {"tests": tests})

    def report(self) -> str:
        lines = [f"fivecal machining-test identification: {self.machine.name} ({len(self.tests)} tests, "
                 f"{len(self.estimated)} parameters, condition number {self.condition_number:.4g}, "
                 f"{'converged' if self.converged else 'NOT converged'})",
                 f"  {'parameter':<14}{'value':>12}{'std':>12}  unit"]
        for n in self.estimated:
            f, unit = display_scale(n) if not n.startswith("workpiece.") else \
                ((1e6, "µrad") if n[-1] in "abc" else (1e3, "µm"))
            s = self.std[n]
            lines.append(f"  {n:<14}{self.values[n] * f:>12.3f}{(s * f if math.isfinite(s) else math.nan):>12.3f}  {unit}")
        lines.append(f"  {'test':<8}{'measured µm':>13}{'model µm':>11}")
        for t, p in zip(self.tests, self.predicted):
            lines.append(f"  {str(t.get('id', '')):<8}{float(t.get('measured', 0.0)) * 1e3:>13.3f}{p * 1e3:>11.3f}")
        return "\n".join(lines)


def identify(machine, tests: Sequence[Mapping], estimate: Iterable[str] = TILT_AXIS_ERRORS, values=None,
             setup: Optional[Mapping[str, float]] = None, sigma: float = 0.0,
             max_iterations: int = 50) -> MachiningResult:
    """Fit ``estimate`` (default the tilt-axis errors EA0C, EY0C, EZ0C) to the
    tests' ``measured`` machining errors with the full model; other machine
    errors (``values``) and the workpiece ``setup`` are held at the given
    values (default 0: the set-up must be known, it is confounded with EZ0C
    in T2 and T3).  ``sigma`` (mm): measurement uncertainty for the standard
    uncertainties; 0 estimates it from the residuals (more tests than unknowns)."""
    m = Machine.from_dict(machine)
    v = _values(values)
    v.update(_values(setup))
    names = [estimate] if isinstance(estimate, str) else [str(n) for n in estimate]
    core = _core.identify_machining(m._core, _core_tests(m, tests), names, v, float(sigma), int(max_iterations))
    return MachiningResult(core, m, tests)
