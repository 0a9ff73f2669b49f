"""The machine as a coordinate measuring machine (thesis ch. 6): probe a
precision sphere at many rotary indexations, express the touches in the table
frame with the nominal and with the identified model, fit a sphere
(Gauss-Newton) and compare the out-of-sphericity; and the one-error-at-a-time
sensitivity table (Table 6-1).  The algorithms are in the C++ core
(``cpp/include/fivecal/procedures/sphere_test.h``)::

    from fivecal.procedures import sphere_test, tango
    m = tango.hu40t_machine()
    ball = {"id": "P", "center": [120, -60, 80], "radius": 9.525}   # phi 19.05 mm
    plan = sphere_test.sphere_plan(m, ball, [{"B": b, "C": c} for b, c in ...], tip_radius=3.0)
    ds = fivecal.simulate(m, plan, errors=..., artefact={"spheres": [ball]}, tip_radius=3.0)
    print(sphere_test.format_sphere_tests({"nominal": sphere_test.sphere_test(ds),
                                           "identified": sphere_test.sphere_test(ds, result)}))

Units: mm, degrees for rotary commands, rad for angular errors; reports in µm.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Iterable, List, Mapping, Optional, Sequence

import numpy as np

from .. import _core
from ..dataset import Dataset, dumps
from ..design import candidate_plan
from ..identification import result_document
from ..machine import Machine
from ..units import display_scale

__all__ = ["sphere_test_values", "sphere_test_document", "THESIS_RINGS", "sphere_points", "sphere_plan", "SphereFit", "fit_sphere", "fit_sphere_centre",
           "table_points", "SphereTest", "sphere_test", "format_sphere_tests", "sensitivity_table",
           "format_sensitivity"]

#: Thesis §6.3 point distribution (ISO 230-10-like): (latitude deg, points) rings.
THESIS_RINGS = [(0.0, 12), (30.0, 8), (-30.0, 8), (60.0, 4), (90.0, 1)]


def _values(values) -> dict:
    if values is None:
        return {}
    if hasattr(values, "values") and not isinstance(values, Mapping):
        values = values.values  # a Result
    return {str(k): float(v) for k, v in values.items()}


def sphere_points(rings: Optional[Sequence] = None, pole=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Unit touch directions (N, 3) on a sphere: ``rings`` of (latitude deg,
    count) points equally spaced in azimuth about ``pole`` (default: the
    thesis' 33 points, :data:`THESIS_RINGS`)."""
    r = [(float(a), int(n)) for a, n in (rings or [])]
    return np.asarray(_core.sphere_points(r, np.asarray(pole, float).reshape(3)))


def sphere_plan(machine, sphere: Mapping, indexations: Sequence[Mapping[str, float]], *, tip_radius: float,
                rings: Optional[Sequence] = None, pole=(0.0, 0.0, 1.0), min_dot: float = 0.0,
                limits: Optional[Mapping] = None, directions="visit") -> list:
    """Plan touching ``sphere`` (``{"id", "center", "radius"}``, workpiece frame)
    at each indexation along every :func:`sphere_points` direction that faces
    the probe (normal . tool axis >= ``min_dot``: at or above the sphere's
    equator as seen from the spindle) and keeps the axes within ``limits``."""
    art = {"spheres": [dict(sphere)]}
    plan, _ = candidate_plan(machine, art, indexations, tip_radius=tip_radius, limits=limits, min_dot=min_dot,
                             sphere_normals=sphere_points(rings, pole), directions=directions)
    return plan


@dataclass
class SphereFit:
    """Least-squares sphere (Gauss-Newton): centre, radius and residual statistics (mm)."""
    center: np.ndarray
    radius: float
    residuals: np.ndarray
    out_of_sphericity: float
    max_residual: float
    min_residual: float
    std_residual: float
    rms: float
    iterations: int
    converged: bool

    @classmethod
    def _from_core(cls, f) -> "SphereFit":
        return cls(np.asarray(f.center), f.radius, np.asarray(f.residuals), f.out_of_sphericity,
                   f.max_residual, f.min_residual, f.std_residual, f.rms, f.iterations, f.converged)


def fit_sphere(points) -> SphereFit:
    """Gauss-Newton least-squares sphere through (N >= 4, 3) points: minimises
    the sum of squared radial distances |P_i - c| - R."""
    P = np.atleast_2d(np.asarray(points, float))
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points: expected shape (N, 3), got {P.shape}")
    return SphereFit._from_core(_core.fit_sphere(P))


def fit_sphere_centre(points, radius: float, start) -> np.ndarray:
    """Least-squares centre (3,) of a sphere of KNOWN ``radius`` (mm, e.g.
    sphere + stylus ball) through (N >= 3, 3) points, by Gauss-Newton from
    ``start`` (the nominal centre): a few touches on a cap leave a free
    radius (:func:`fit_sphere`) undetermined, a known one needs three."""
    P = np.atleast_2d(np.asarray(points, float))
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points: expected shape (N, 3), got {P.shape}")
    c0 = np.asarray(start, float)
    if c0.shape != (3,):
        raise ValueError(f"start: expected 3 coordinates, got shape {c0.shape}")
    f = _core.fit_sphere_centre(P, float(radius), c0)
    if not f.converged:
        raise ValueError(f"fit_sphere_centre: Gauss-Newton did not converge in {f.iterations} iterations "
                         "(points far from a sphere of that radius, or start far from the centre)")
    return np.asarray(f.center)


def table_points(dataset: Dataset, values=None, indices: Optional[Iterable[int]] = None) -> np.ndarray:
    """Stylus-ball centres (N, 3) in the table (workpiece) frame computed from
    the readings of ``dataset`` with the machine model ``values`` (a dict or an
    identification Result; None = nominal). ``indices`` default: all observations."""
    idx = list(range(len(dataset))) if indices is None else [int(i) for i in indices]
    return np.asarray(_core.table_points(dataset._core, _values(values), idx))


@dataclass
class SphereTest:
    """Sphere test result (thesis Table 6-3 quantities, mm)."""
    sphere: str
    observations: List[int]
    points: np.ndarray
    fit: SphereFit
    size_error: float
    #: the stylus ball radius the touches were taken with (mm)
    tip_radius: float = 0.0
    center: np.ndarray = field(init=False)
    #: radius of the sphere through the stylus-ball centres (ball radius + tip radius)
    radius: float = field(init=False)
    out_of_sphericity: float = field(init=False)
    #: diameter of the probed ball itself, as thesis Table 6-3 prints it
    #: ("Diameter of the sphere"): 2 (fitted radius - tip radius)
    ball_diameter: float = field(init=False)

    def __post_init__(self):
        self.center = self.fit.center
        self.radius = self.fit.radius
        self.out_of_sphericity = self.fit.out_of_sphericity
        self.ball_diameter = 2.0 * (self.fit.radius - self.tip_radius)


def sphere_test(dataset: Dataset, values=None, sphere: Optional[str] = None) -> SphereTest:
    """Fit a sphere to the touches of ``sphere`` (default: the only sphere
    touched) computed with the model ``values`` (None: nominal model; a dict
    or an identification Result: the compensated model)."""
    r = _core.sphere_test(dataset._core, sphere or "", _values(values))
    return SphereTest(r.sphere, list(r.observations), np.asarray(r.points), SphereFit._from_core(r.fit),
                      r.size_error, float(dataset._core.tip_radius))


def format_sphere_tests(tests: Mapping[str, SphereTest]) -> str:
    """Thesis Table 6-3: out of sphericity, max / min residual, standard
    deviation of the residuals (µm) and the diameter of the probed ball (mm)
    per model; the stylus-centre sphere (ball + 2 × tip radius), which is what
    the touches' centres lie on, is labelled as such."""
    names = list(tests)
    w = max(14, *(len(n) + 2 for n in names))
    lines = [f"{'':<36}" + "".join(f"{n:>{w}}" for n in names)]
    rows = [("Out of sphericity (µm)", lambda t: t.fit.out_of_sphericity * 1e3),
            ("Maximum residual (µm)", lambda t: t.fit.max_residual * 1e3),
            ("Minimum residual (µm)", lambda t: t.fit.min_residual * 1e3),
            ("Std of the residuals (µm)", lambda t: t.fit.std_residual * 1e3),
            ("Diameter of the sphere (mm)", lambda t: t.ball_diameter, ".4f"),
            ("Stylus-centre sphere diameter (mm)", lambda t: 2 * t.fit.radius, ".4f"),
            ("Size error (µm)", lambda t: t.size_error * 1e3),
            ("Points", lambda t: len(t.observations))]
    for label, f, *spec in rows:
        fmt = spec[0] if spec else ".4g"  # diameters to the µm, as Table 6-3
        lines.append(f"{label:<36}" + "".join(f"{f(tests[n]):>{w}{fmt}}" for n in names))
    return "\n".join(lines)


def sensitivity_table(machine, sphere: Mapping, plan: Sequence[Mapping], names: Iterable[str], *,
                      tip_radius: float, values: Optional[Mapping[str, float]] = None,
                      characteristic_length: float = 400.0) -> List[dict]:
    """Thesis Table 6-1: the probing ``plan`` of ``sphere`` simulated on a
    machine with one error at a time (size ``values[name]``, default 1 µm at
    the characteristic length: 1 µm, 2.5 µrad, 2.5 µm/m), processed with the
    nominal model.  Rows: ``{"name", "value", "size_error", "out_of_sphericity",
    "max_residual", "min_residual"}`` (mm), the first for no error (name "")."""
    m = Machine.from_dict(machine)
    setup = _core.Dataset.from_json(dumps({"machine": m.to_dict(), "probe": {"tip_radius": float(tip_radius)},
                                           "artefact": {"spheres": [dict(sphere)]}, "observations": []}), False)
    return list(_core.sphere_sensitivity(setup, dumps(list(plan), "plan"), str(sphere["id"]),
                                         [str(n) for n in names], _values(values), float(characteristic_length)))


def format_sensitivity(rows: Sequence[Mapping]) -> str:
    """Rows of :func:`sensitivity_table` as Table 6-1 text."""
    lines = [f"{'Parameter':<12}{'Value':>10}  {'unit':<6}{'Size error (mm)':>17}{'Out of sphericity (mm)':>24}"]
    for r in rows:
        if not r["name"]:
            lines.append(f"{'none':<12}{0:>10}  {'':<6}{r['size_error']:>17.3e}{r['out_of_sphericity']:>24.3e}")
            continue
        f, unit = display_scale(r["name"])
        lines.append(f"{r['name']:<12}{r['value'] * f:>10.4g}  {unit:<6}{r['size_error']:>17.3e}"
                     f"{r['out_of_sphericity']:>24.3e}")
    return "\n".join(lines)


def sphere_test_values(tests: Mapping[str, SphereTest]) -> dict:
    """The sphere tests' own values, the ``procedure.values`` of the result
    document (docs/formats.md): the sphere and, per model (``nominal model``,
    ``identified model``), the fitted stylus-centre sphere and its residual
    statistics (mm)."""
    t0 = next(iter(tests.values()))
    return {"sphere": t0.sphere, "models": {name: {
        "center": [float(x) for x in t.center], "radius": float(t.radius), "ball_diameter": float(t.ball_diameter),
        "out_of_sphericity": float(t.out_of_sphericity), "max_residual": float(t.fit.max_residual),
        "min_residual": float(t.fit.min_residual), "std_residual": float(t.fit.std_residual),
        "size_error": float(t.size_error), "points": len(t.observations), "converged": bool(t.fit.converged)}
        for name, t in tests.items()}}


def sphere_test_document(tests: Mapping[str, SphereTest], model: Optional[Mapping] = None) -> dict:
    """The result document of a sphere test: ``model`` (the result document
    whose machine errors made the ``identified model``) with the tests as
    ``procedure`` ``sphere-test``. Without one the test measured no machine
    error: no parameters, verdict ``undetermined``, so no consumer takes it
    for measured errors."""
    base = dict(model) if model is not None else {
        "parameters": {}, "estimated": [], "converged": all(t.fit.converged for t in tests.values()),
        "iterations": 0, "n_observations": len(next(iter(tests.values())).observations), "n_parameters": 0,
        "verdict": "undetermined"}
    return result_document(base, "sphere-test", sphere_test_values(tests))
