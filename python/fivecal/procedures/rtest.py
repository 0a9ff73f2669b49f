"""R-test tests of the rotary axes (ISO 10791-6 style), on any topology: the
precision ball and the three-sensor nest, one on the spindle and one on the
table; a rotary axis turns while the linear axes follow so that, on the
nominal machine, the ball stays centred in the nest (tool-centre-point
motion). The nest records the ball's 3D displacement; the test's figure is
its range in each direction, and the same data identify the location errors
of the rotary axes through the ``ball3d`` observation.

Which tests (named as ISO 10791-6:2014 does for five-axis machining centres;
the standard's text is not public, so each test is defined here in full):

* ``K1``: the axis that turns the table about its normal (C on a table-table
  machine) through a full turn, the other rotary axes at 0;
* ``K2``: the tilting axis (A or B) over its range, the other at 0;
* ``K3``: as K1 with the tilting axis at ``tilt`` degrees (the C-axis test at
  a tilted table, which separates the C pivot from the tilting axis');
* ``K4``: both rotary axes together, C through a full turn while the tilt
  follows ``tilt * sin(C)`` (a five-axis path).

On a head-head or table-head machine the same tests turn the head's axes; the
ball then sits on the tool side and the nest on the table, as a real R-test
is set up. Units: mm, degrees for commands; deviations in µm in reports.

    from fivecal.procedures import rtest
    plan = rtest.plan(machine, "K1", table_ball=[150, 0, 100])
    ds = fivecal.simulate(machine, plan, errors=..., sigma={"ball3d": 0.0005})
    print(rtest.evaluate(ds).report())
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

from .. import _core
from ..dataset import Dataset
from ..identification import Result, result_document, warn_when_unusable
from ..machine import Machine
from ..views import Viewable

TESTS = ("K1", "K2", "K3", "K4")


def _rotary(machine: Machine) -> List[str]:
    return list(_core.checked_rotary_axes(machine._core))


def _roles(machine: Machine) -> Dict[str, str]:
    """The turning axis (the one nearest the table normal / tool axis, +Z at
    the zero pose) and the tilting axis of the machine (the core's
    ``procedures/rtest.h`` RTestAxisRoles)."""
    return dict(_core.rtest_axis_roles(machine._core))


def _sequence(machine: Machine, test: str, step: float, tilt: float, tilt_range) -> List[Dict[str, float]]:
    """The rotary poses of K test ``test`` (the core's RTestSequence)."""
    r = _roles(machine)
    lo, hi = tilt_range
    seq = np.asarray(_core.rtest_sequence(machine._core, str(test), float(step), float(tilt), (float(lo), float(hi))))
    return [{r["turn"]: float(c), r["tilt"]: float(a)} for c, a in seq]


#: smallest step (deg) of a K test's samples: 100000 a turn, the plans' bound on entries
MIN_STEP = 360.0 / 100_000


def plan(machine: Union[Machine, Mapping], test: str, *, table_ball: Sequence[float],
         tool_ball: Optional[Sequence[float]] = None, step: float = 15.0, tilt: float = -45.0,
         tilt_range: Sequence[float] = (-90.0, 90.0), setup: Optional[str] = None) -> list:
    """ball3d plan entries of one K test (:data:`TESTS`). ``table_ball``: the
    table-side sphere or nest centre in the workpiece frame (mm; off the
    turning axis, or the test sees no pivot); ``tool_ball``: the tool-side
    centre in the machine frame at the zero pose (default the machine's tool
    tip). ``step`` (deg) between samples, ``tilt`` (deg) the tilting axis'
    position of K3 and amplitude of K4, ``tilt_range`` that of K2. The linear
    axes come from the nominal inverse, so on a perfect machine every reading
    is zero. ``setup`` names the mounting (default the test's name): one
    mounting per test, or the same name for tests run without re-mounting."""
    m = Machine.from_dict(machine)
    # bounded here, not only by the command line: a tiny step builds millions of entries before anything is said
    if isinstance(step, bool) or not isinstance(step, numbers.Real) or not (math.isfinite(step)
                                                                           and step >= MIN_STEP):
        raise ValueError(f"step: {step!r} deg; expected a number >= {MIN_STEP:g} deg (at most "
                         f"{360.0 / MIN_STEP:.0f} samples a turn)")
    seq = _sequence(m, test, float(step), float(tilt), tilt_range)
    tb = np.asarray(table_ball, float)
    if tb.shape != (3,) or not np.isfinite(tb).all():
        raise ValueError(f"table_ball: expected [x, y, z] mm, got {table_ball!r}")
    tool = np.asarray(tool_ball if tool_ball is not None else m.tip, float)
    # the linear axes that keep the ball in the nest, each sample solved from the one before (the core's
    # RTestPathCommands)
    rotary = np.zeros((len(seq), len(m.axis_names)))
    for k, rot in enumerate(seq):
        for a, v in rot.items():
            rotary[k, m.axis_names.index(a)] = v
    cmds = np.asarray(_core.rtest_path_commands(m._core, rotary, np.zeros(len(m.axis_names)), tb, tool, True))
    entries = []
    prev = {a: 0.0 for a in m.axis_names}
    for k, rot in enumerate(seq):
        axes = {a: float(cmds[k, i]) for i, a in enumerate(m.axis_names)}
        direction = {a: (1 if rot[a] >= prev.get(a, 0.0) else -1) for a in rot}
        entries.append({"type": "ball3d", "setup": setup or test, "axes": axes, "direction": direction,
                        "tool_ball": [float(x) for x in tool], "table_ball": [float(x) for x in tb],
                        "id": f"{test}-{k}"})
        prev = axes
    return entries


@dataclass
class KTest:
    """One test's deviation ranges (mm) in X, Y, Z of the workpiece frame."""
    name: str
    samples: int
    ranges: np.ndarray
    deviations: np.ndarray  #: (samples, 3) recorded deviation, mm

    def passes(self, tolerance: Optional[float]) -> Optional[bool]:
        return None if tolerance is None else bool((self.ranges <= tolerance).all())


@dataclass
class RTestResult(Viewable):
    tests: Dict[str, KTest]
    result: object = None                   #: the fivecal.Result when identified
    estimated: List[str] = field(default_factory=list)

    def report(self, tolerance: Optional[float] = None) -> str:
        L = ["R-test: deviation range per direction (workpiece frame, µm)",
             f"  {'test':<6}{'samples':>8}{'X':>10}{'Y':>10}{'Z':>10}" + ("   verdict" if tolerance else "")]
        for t in self.tests.values():
            v = t.passes(tolerance)
            L.append(f"  {t.name:<6}{t.samples:>8}" + "".join(f"{x * 1e3:>10.2f}" for x in t.ranges)
                     + ("" if v is None else ("   pass" if v else f"   FAIL (> {tolerance * 1e3:g} µm)")))
        if self.result is not None:
            r = self.result
            L += ["", f"  location errors from the same data ({r.verdict}, rms {r.rms * 1e3:.2f} µm):"]
            for n in self.estimated:
                unit, k = ("µrad", 1e6) if n[1] in "ABC" else ("µm", 1e3)
                L.append(f"    {n:<8}{r.values.get(n, 0.0) * k:>10.2f} ± {r.std.get(n, float('nan')) * k:.2f} {unit}")
            und = list(getattr(r, "undetermined", []) or [])
            if und:
                L.append("    not determined by these tests: " + ", ".join(und))
        return "\n".join(L)

    def procedure_values(self, tolerance: Optional[float] = None) -> dict:
        """The K tests' own values, the ``procedure.values`` of the result
        document (docs/formats.md): per test its samples and the deviation
        range in X, Y, Z of the workpiece frame (mm), and with ``tolerance``
        (mm) whether it passes."""
        tests = {}
        for t in self.tests.values():
            d = {"samples": t.samples, "range": {k: float(v) for k, v in zip("xyz", t.ranges)}}
            if tolerance is not None:
                d["passes"] = t.passes(tolerance)
            tests[t.name] = d
        out = {"tests": tests}
        if tolerance is not None:
            out["tolerance"] = float(tolerance)
        return out

    def to_dict(self, tolerance: Optional[float] = None) -> dict:
        """The result document (the one every procedure writes): the
        location-error fit, with the K tests' ranges as ``procedure``
        ``rtest``. Without a fit (``identify=False``) it holds no machine
        error and its verdict is ``undetermined``: no consumer takes it as
        measured errors."""
        vals = self.procedure_values(tolerance)
        if self.result is not None:
            return result_document(self.result, "rtest", vals)
        return result_document({"parameters": {}, "estimated": [], "converged": True, "iterations": 0,
                                "n_observations": sum(t.samples for t in self.tests.values()),
                                "n_parameters": 0, "verdict": "undetermined"}, "rtest", vals)


def location_errors(machine: Machine) -> List[str]:
    """The location errors (ISO 230-7 position and orientation errors of an
    axis line) an R-test of both rotary axes can see: for each rotary axis the
    two positions across it and the two tilts (a position that is the
    spindle's offset under another name carries the spindle's name, as in
    ``identify --estimate location``: :func:`fivecal.procedures.sphere_check.spindle_equivalent`).
    The core's list (``procedures/rtest.h`` RTestLocationErrors)."""
    return list(_core.rtest_location_errors(machine._core))


def evaluate(dataset: Union[Dataset, Mapping], identify: bool = True,
             estimate: Union[None, str, Sequence[str]] = None) -> RTestResult:
    """The deviation range of each test (observations grouped by ``setup``)
    in X, Y and Z, and, with ``identify``, the location errors of the rotary
    axes fitted to all tests at once (``estimate``: default
    :func:`location_errors`; each mounting's ball positions are part of the
    fit, as for any ball3d data). The evaluation is the core's
    (``procedures/rtest.h`` EvaluateRTest). Raises ValueError without ball3d data."""
    ds = Dataset.from_dict(dataset)
    # a string names parameters as identify's does ("EX0C,EY0C"), never its letters
    names = [s for s in estimate.replace(",", " ").split() if s] if isinstance(estimate, str) else \
        [str(n) for n in (estimate or [])]
    core = _core.rtest(ds._core, bool(identify), names)
    tests = {g.name: KTest(g.name, len(g.observations), np.asarray(g.ranges), np.asarray(g.deviations))
             for g in core.tests}
    out = RTestResult(tests)
    if core.identified:
        out.result = warn_when_unusable(Result(core.fit, ds))
        out.estimated = list(core.estimated)
    return out


__all__ = ["TESTS", "plan", "evaluate", "location_errors", "KTest", "RTestResult"]
