"""Double ball bar (DBB) tests: the Jiang & Cripps four-step test of a pair
of rotary axes (the paper's A and C, B/C trunnions, either order, table or
head), the Wang et al. simultaneous A/C path, planar circular tests
(ISO 230-4 and ballbar diagnosis) and reading import.

The algorithms live in the C++ core (``dbb_four_step.h``, ``wang_path.h``,
``circular_test.h``, ``circle_fit.h``); this module builds plans, moves
readings between CSV files, datasets and the core, runs the general engine
beside the papers' methods and writes reports. Units: mm, degrees for axis
commands and angles, rad for angular errors; reports show µm and µrad.
See docs/dbb.md for the formulas and the limits of each method.
"""
from __future__ import annotations

import csv
import json
import math
import os
import warnings
from dataclasses import dataclass, field
from typing import Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from .. import _core, files, guards
from ..dataset import Dataset
from ..identification import finding_lines, identify, verdict_lines
from ..machine import Machine, RadiansWarning
from ..simulation import simulate
from ..views import Viewable
from ..units import column_unit, display_scale, looks_like_radians, radians_message
from .sphere_check import spindle_equivalent

#: Setup ids and PIGEs of the four-step test on the paper's machine (C on A);
#: other pairs: :func:`four_step_pair`.
FOUR_STEP_SETUPS = ("A1", "A2", "C1", "C2")
FOUR_STEP_PARAMETERS = tuple(_core.four_step_parameter_names())
#: The four errors Wang et al. (2013) study: the C axis relative to the A axis.
WANG_ERRORS = ("EX0C", "EY0C", "EZ0C", "EA0C")
#: What a Wang path could be asked to separate: the C and A location errors and
#: the placement of both balls.
WANG_CANDIDATES = ("EX0C", "EY0C", "EZ0C", "EA0C", "EB0C", "EC0C", "EY0A", "EZ0A", "EB0A", "EC0A")
WANG_SETUP = "W1"
#: degrees: the shortest sweep :func:`circular_test` accepts. ISO 230-4 asks for a
#: full circle; under 10 degrees a circle fit has no meaning (its centre and
#: radius are undetermined), and such a "circle" is most often angles in radians.
MIN_CIRCLE_SWEEP = 10.0


def _fmt(name: str, value: float) -> str:
    f, unit = display_scale(name)
    return f"{value * f:10.3f} {unit}"


# --------------------------------------------------------------------------
# Traces and CSV import
# --------------------------------------------------------------------------
@dataclass
class Trace:
    """One DBB run: angles (deg) and readings (mm, bar length minus nominal).

    ``direction``: +1 counter-clockwise (angle increasing), -1 clockwise, 0 unknown.
    """

    angles: np.ndarray
    readings: np.ndarray
    direction: int = 0
    label: str = ""

    def __post_init__(self):
        self.angles = np.asarray(self.angles, dtype=float).ravel()
        self.readings = np.asarray(self.readings, dtype=float).ravel()
        if self.angles.shape != self.readings.shape:
            raise ValueError(f"trace {self.label or ''}: {self.angles.size} angles but "
                             f"{self.readings.size} readings")
        if self.direction == 0:
            self.direction = run_direction(self.angles)


def run_direction(angles) -> int:
    """+1 (counter-clockwise, angle increasing), -1 (clockwise) or 0 (no net
    turn) from the angles themselves (deg): the net turn of the unwrapped
    angles, so a trace printed modulo 360 (a CW turn 0, 359.5, ..., 0.5) is
    CW although its last angle is larger than its first."""
    a = np.asarray(angles, dtype=float).ravel()
    if a.size < 2 or not np.all(np.isfinite(a)):
        return 0
    turn = float(np.sum(np.diff(np.unwrap(np.radians(a)))))
    return 1 if turn > 1e-9 else (-1 if turn < -1e-9 else 0)


def claimed_direction(label: str) -> int:
    """The run direction a file name or setup id claims: +1 for a ``ccw``
    word or a trailing ``+`` (the planar plan's ``P+``), -1 for ``cw`` or a
    trailing ``-``, 0 when it claims none."""
    base = os.path.splitext(os.path.basename(str(label)))[0].strip()
    words = {w for w in "".join(c if c.isalnum() else " " for c in base.lower()).split()}
    if "ccw" in words or "counterclockwise" in words:
        return 1
    if "cw" in words or "clockwise" in words:
        return -1
    if base.endswith("+"):
        return 1
    if base.endswith("-"):
        return -1
    return 0


def check_direction(trace: "Trace", source: str, label: Optional[str] = None) -> int:
    """The trace's run direction from its angles; ValueError naming
    ``source`` (a file, or a dataset and setup) when its name (``label``,
    default ``source``) claims the other one."""
    claim = claimed_direction(source if label is None else label)
    d = trace.direction
    if claim and d and claim != d:
        words = {1: "counter-clockwise (CCW)", -1: "clockwise (CW)"}
        a = np.degrees(np.unwrap(np.radians(trace.angles)))
        raise ValueError(f"{source}: its name says {words[claim]} but its angles run {words[d]} "
                         f"(from {a[0]:g} to {a[-1]:g} deg, unwrapped); the run direction is taken from "
                         "the data: rename the file or setup, or check the sign of the angles")
    return d


def _split(line: str) -> list:
    return [p for p in line.replace(";", " ").replace(",", " ").replace("\t", " ").split(" ") if p]


def _header_names(line: str) -> list:
    """Column names of a header line: split at commas, semicolons or tabs when
    it has them (so 'reading (um)' stays one name), else at spaces."""
    for sep in (",", ";", "\t"):
        if sep in line:
            return [p.strip() for p in line.split(sep) if p.strip()]
    return line.split()


def read_trace_csv(path: Union[str, os.PathLike], label: Optional[str] = None,
                   sweep: Optional[float] = None, start: float = 0.0, units: Optional[str] = None,
                   angle_units: Optional[str] = None) -> Trace:
    """Read ``angle, reading`` rows (deg, mm) from a CSV file.

    Separators: comma, semicolon, tab or spaces; a header line and ``#``
    comments are skipped. A file with a single column holds readings only;
    the angles then follow Jiang & Cripps eq. 2 (``theta_i = i/N * sweep``
    from ``start``), which needs ``sweep`` (deg, signed).

    Units named in the header are honoured: a suffix ``_um``, ``_mm`` (or
    ``_m``, ``_in``) on the reading column, ``_deg`` or ``_rad`` on the angle
    column, or the unit in brackets (``reading [um]``); another suffix is
    refused naming the column. Without a unit, readings beyond ±2 mm are
    refused as µm (a ballbar measures about ±1 mm), and angles that look like
    radians give one :class:`fivecal.RadiansWarning`. ``units`` (``mm``,
    ``um``) and ``angle_units`` (``deg``, ``rad``) name the unit of columns
    whose header names none; a header naming another unit is refused.
    A readings-only file with a signed ``sweep`` (deg, negative = clockwise)
    runs that way from ``start``.
    """
    given = {"length": _unit_factor_of(units, "units", {"mm": 1.0, "um": 1e-3, "µm": 1e-3}),
             "angle": _unit_factor_of(angle_units, "angle units", {"deg": 1.0, "rad": 180.0 / math.pi})}
    path = os.fspath(path)
    text = files.read_text(path, "trace CSV")
    rows = []
    header = None
    for lineno, line in enumerate(text.splitlines(), 1):
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        parts = _split(s)
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            if not rows:
                header = s  # the last line before the data names the columns
                continue
            raise ValueError(f"{path}:{lineno}: not a number in {line.strip()!r}") from None
        if len(vals) not in (1, 2):
            raise ValueError(f"{path}:{lineno}: expected 'angle, reading' (2 columns), got {len(vals)}")
        if rows and len(vals) != len(rows[0]):
            raise ValueError(f"{path}:{lineno}: {len(vals)} columns, earlier rows have {len(rows[0])}")
        if not all(math.isfinite(v) for v in vals):
            raise ValueError(f"{path}:{lineno}: value is not finite")
        rows.append(vals)
    if len(rows) < 3:
        raise ValueError(f"{path}: {len(rows)} data rows; a trace needs at least 3")
    a = np.array(rows)
    names = _header_names(header) if header is not None else []
    if len(names) != a.shape[1]:
        names = []  # a title line, not column names
    kinds = ["length"] if a.shape[1] == 1 else ["angle", "length"]
    units = [column_unit(n, k, path) for n, k in zip(names, kinds)] if names else [(1.0, None)] * len(kinds)
    for j, k in enumerate(kinds):
        if given[k] is None:
            continue
        factor, named = units[j]
        if named is not None and abs(factor - given[k][0]) > 1e-12 * factor:
            opt = "--units" if k == "length" else "--angle-units"
            raise ValueError(f"{path}: column '{names[j]}' is in {named} but {opt} says {given[k][1]}; "
                             "drop the option or fix the header")
        units[j] = (given[k][0], given[k][1])
    for j, (factor, _) in enumerate(units):
        a[:, j] *= factor
    readings = a[:, -1]
    reading_col = names[-1] if names else "reading"
    k = int(np.argmax(np.abs(readings)))
    if abs(readings[k]) > 2.0:
        hint = (f"readings look like µm: divide by 1000 or name the column {reading_col.split('_')[0]}_um"
                if units[-1][1] is None else "check the unit in the column name")
        raise ValueError(f"{path}: column '{reading_col}': reading {readings[k]:.6g} mm (row {k + 1}) is "
                         f"beyond a ballbar's range (about ±1 mm); {hint}")
    if a.shape[1] == 1:
        if sweep is None:
            raise ValueError(f"{path}: one column (readings only); give the sweep angle to space "
                             "the samples evenly (Jiang & Cripps eq. 2)")
        if not (isinstance(sweep, (int, float)) and math.isfinite(sweep) and 10.0 <= abs(sweep) <= 3600.0):
            raise ValueError(f"{path}: sweep {sweep!r} deg; a readings-only trace needs the signed angle its "
                             "samples sweep, 10 to 3600 deg (negative: clockwise)")
        if not math.isfinite(start):
            raise ValueError(f"{path}: start angle {start!r} is not finite")
        n = a.shape[0] - 1
        angles = start + np.arange(a.shape[0]) / n * sweep
        return Trace(angles, readings, 1 if sweep > 0 else -1, label=label or os.path.basename(path))
    if units[0][1] is None and looks_like_radians(a[:, 0]):
        col = names[0] if names else "angle"
        warnings.warn(radians_message(f"{path}: column '{col}'", a[:, 0]) +
                      f" or name the column {col.split('_')[0]}_rad", RadiansWarning, stacklevel=2)
    return Trace(a[:, 0], readings, label=label or os.path.basename(path))


def _unit_factor_of(text: Optional[str], what: str, table: Mapping[str, float]):
    """(factor to mm or deg, unit) of a unit option, None when not given."""
    if text is None:
        return None
    key = str(text).strip()
    if key not in table:
        raise ValueError(f"{what}: '{key}'; give one of {', '.join(table)}")
    return table[key], key


def write_trace_csv(trace: Trace, path: Union[str, os.PathLike]) -> None:
    import io

    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow(["angle_deg", "reading_mm"])
    for a, r in zip(trace.angles, trace.readings):
        w.writerow([f"{a:.6f}", f"{r:.9f}"])
    files.write_text(path, f.getvalue())


def _dbb_rows(ds: Dataset, setup: str):
    obs = ds.observations
    idx = [i for i, o in enumerate(obs) if o.get("type") == "dbb" and o.get("setup", "") == setup]
    if not idx:
        setups = sorted({o.get("setup", "") for o in obs if o.get("type") == "dbb"})
        raise ValueError(f"dataset: no DBB observations with setup {setup!r} "
                         f"(setups: {', '.join(s or '(default)' for s in setups) or 'none'})")
    return idx


def ball_positions(ds: Dataset, setup: str, rows=None):
    """Nominal spindle-ball and table-ball positions in F (N x 3 each, mm) and
    the observation indices of one DBB setup (or of ``rows``, indices of its
    observations: a report splits a setup by bar length without copying the
    dataset)."""
    ds = Dataset.from_dict(ds)
    idx = _dbb_rows(ds, setup) if rows is None else [int(i) for i in rows]
    m = ds.machine
    q = ds._core.columns()["axes"][idx]  # machine axis order, without a dict per sample
    tool = np.asarray(ds.observations[idx[0]]["tool_ball"], float)
    table = np.asarray(ds.observations[idx[0]]["table_ball"], float)
    S, B = _core.dbb_ball_positions(m._core, q, tool, table)
    return np.asarray(S), np.asarray(B), idx


_PLANES = {0: ("Y", "Z"), 1: ("Z", "X"), 2: ("X", "Y")}


def trace_from_dataset(ds: Union[Dataset, Mapping], setup: str, rows=None) -> Trace:
    """The readings of one DBB setup (or of its observations ``rows``) as a
    polar trace: the angle of the moving ball about the stationary one, in the
    plane the moving ball sweeps (YZ, ZX or XY: measured from the first axis
    towards the second)."""
    ds = Dataset.from_dict(ds)
    S, B, idx = ball_positions(ds, setup, rows)
    moving, fixed = (B, S) if np.ptp(B, axis=0).sum() >= np.ptp(S, axis=0).sum() else (S, B)
    rel = moving - fixed
    _, _, vt = np.linalg.svd(rel - rel.mean(axis=0), full_matrices=False)
    k = int(np.argmax(np.abs(vt[2])))
    e = np.eye(3)
    e1, e2 = e[(k + 1) % 3], e[(k + 2) % 3]
    ang = np.unwrap(np.arctan2(rel @ e2, rel @ e1))
    readings = np.array([ds.observations[i]["reading"] for i in idx])
    t = Trace(np.degrees(ang), readings, label=setup)
    t.plane = "".join(_PLANES[k])  # type: ignore[attr-defined]
    return t


# --------------------------------------------------------------------------
# Jiang & Cripps four-step test
# --------------------------------------------------------------------------
def four_step_pair(machine: Union[Machine, Mapping]) -> dict:
    """The rotary pair the four-step test runs on: ``carrier`` (the axis
    nearer the foundation, tested first; the paper's A), ``carried`` (the
    paper's C), ``tool_side``, the default ``setups`` and the eight PIGE
    ``names``. Raises ValueError saying why a machine's geometry does not
    allow the test (parallel axes, a nutating axis, one axis on each side...)."""
    return dict(_core.four_step_pair(Machine.from_dict(machine)._core))


def four_step_plan(machine: Union[Machine, Mapping], length: float = 100.0,
                   extended_length: float = 150.0, a_range=None, c_range=None,
                   step: float = 1.0, a_pivot=None, c_pivot=None, tool_ball=None,
                   a_extension_sign: Optional[float] = None, c_extension_sign: Optional[float] = None,
                   setups: Optional[Sequence[str]] = None) -> list:
    """Plan entries of the four steps for :func:`fivecal.simulate` (and the axis
    commands of a real test), on any rotary pair :func:`four_step_pair`
    accepts. ``a_*`` is the carrier (tested first, the paper's A), ``c_*`` the
    carried axis (the paper's C). Defaults follow Jiang & Cripps Section 3.1
    and Table 1: a tilting axis from -20 to 70 deg, an axis along the tool
    axis over a full turn, 100 mm bar and 150 mm with the extension; pivots
    (the moving balls) one bar length from the axes. ``tool_ball``: the fixed
    ball (the spindle ball, F at the zero pose, on a table pair; the table
    ball, workpiece frame, on a head pair). Extension signs (+1/-1 along
    the positive axis direction) default to "towards the tool" for an axis
    along the tool axis and -1 for a tilting axis. Setup ids default to
    ``<carrier>1 <carrier>2 <carried>1 <carried>2``."""
    m = Machine.from_dict(machine)
    opt = lambda v: None if v is None else np.asarray(v, float)  # noqa: E731
    nan = float("nan")
    a_range = a_range if a_range is not None else (nan, nan)
    c_range = c_range if c_range is not None else (nan, nan)
    return json.loads(_core.four_step_plan(m._core, float(length), float(extended_length),
                                           float(a_range[0]), float(a_range[1]), float(c_range[0]),
                                           float(c_range[1]), float(step), opt(a_pivot), opt(c_pivot),
                                           opt(tool_ball), nan if a_extension_sign is None else float(a_extension_sign),
                                           nan if c_extension_sign is None else float(c_extension_sign),
                                           list(setups or [])))


def _step_plane(step) -> tuple:
    """Names of a step's plane axes (e1, e2), e.g. ('Y', 'Z')."""
    return tuple("XYZ"[int(np.argmax(np.abs(np.asarray(e))))] for e in (step.e1, step.e2))


class FourStepResult(Viewable):
    """The four-step PIGEs, the per-step fits and (optionally) the general
    engine's fit of the same readings."""

    def __init__(self, core, dataset: Dataset, engine=None, engine_error: Optional[str] = None,
                 options: Optional[dict] = None):
        self._core = core
        self.dataset = dataset
        self.names: list = list(core.names)
        self.values: dict = {n: float(v) for n, v in zip(core.names, np.asarray(core.values))}
        self.std: dict = {n: float(s) for n, s in zip(core.names, np.asarray(core.std))}
        self.steps = list(core.steps)
        self.engine = engine
        self.engine_error = engine_error
        self.options = options or {}

    @property
    def carrier(self) -> str:
        """The axis tested first (the paper's A): it carries the other."""
        return self._core.carrier

    @property
    def carried(self) -> str:
        return self._core.carried

    @property
    def tool_side(self) -> bool:
        return bool(self._core.tool_side)

    @property
    def a_oe(self) -> np.ndarray:
        return np.asarray(self._core.a_oe)

    @property
    def c_oe(self) -> np.ndarray:
        return np.asarray(self._core.c_oe)

    def step(self, setup: str):
        for s in self.steps:
            if s.setup == setup:
                return s
        raise KeyError(setup)

    def step_trace(self, setup: str) -> Trace:
        """Radial deviations from the fitted circle of one step, against the
        angle (deg) of each measured point about the fitted centre: drawn at
        (angle, radius + deviation) about that centre, the trace lands on the
        measured points. (The step's ``angles`` are about the nominal pivot
        O', as the command put the ball: they are off by up to |centre| /
        radius, a few mrad with a pivot tens of µm away.)"""
        s = self.step(setup)
        d = np.asarray(s.points) - np.asarray(s.centre)
        a = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        # the same turn as the step's own angles (unwrap starts at -pi..pi)
        a += 2 * np.pi * np.round((np.asarray(s.angles)[0] - a[0]) / (2 * np.pi))
        return Trace(np.degrees(a), np.asarray(s.residuals), label=setup)

    def engine_value(self, name: str):
        """(value, std) of PIGE ``name`` in the engine's fit, or None. An
        engine that named an offset by the spindle (``spindle_names``: EX0S
        for EX0C on an A/C trunnion, the same error) gives it back under the
        PIGE's name, minus the spindle's value for an axis on the workpiece
        side."""
        eng = self.engine
        if eng is None:
            return None
        if name in eng.values:
            return eng.values[name], eng.std.get(name, float("nan"))
        m = self.dataset.machine
        s = spindle_equivalent(m, name)
        if s != name and s in eng.values:
            sign = -1.0 if name[3] in m.workpiece_chain else 1.0
            return sign * eng.values[s], eng.std.get(s, float("nan"))
        return None

    def procedure_values(self) -> dict:
        """The values of the four-step method itself (the ``procedure.values``
        of the result document; the machine errors, ``parameters``, are the
        general engine's fit of the same readings): the method's PIGEs with
        their standard uncertainties, each step's circle, O'E, eq. 20's
        substitution error, the options and, per PIGE, the method minus the
        engine."""
        d = self.to_dict()
        d.pop("engine", None)
        d["method_values"] = d.pop("parameters")
        if self.engine is not None:
            d["method_minus_engine"] = {n: self.values[n] - self.engine_value(n)[0] for n in self.names
                                        if self.engine_value(n) is not None}
        return d

    def to_dict(self) -> dict:
        d = {"method": "Jiang & Cripps 2015 four-step DBB test",
             "carrier": self.carrier, "carried": self.carried,
             "side": "spindle" if self.tool_side else "table",
             "parameters": {n: {"value": self.values[n], "std": self.std[n]} for n in self.names},
             "steps": [{"setup": s.setup, "axis": s.axis, "extended": bool(s.extended),
                        "samples": int(len(s.residuals)), "centre": list(map(float, s.centre)),
                        "radius": float(s.radius), "fit_rms": float(s.rms),
                        "start_angle_error": float(s.start_angle_error), "arm": float(s.arm)}
                       for s in self.steps],
             "O'E": {self.carrier: list(map(float, self.a_oe)), self.carried: list(map(float, self.c_oe))},
             "delta_eq20": {self.carrier: float(self._core.a_delta), self.carried: float(self._core.c_delta)},
             "options": self.options}
        if self.engine is not None:
            d["engine"] = json.loads(self.engine.to_json())
        if self.engine_error:
            d["engine_error"] = self.engine_error
        return d

    def report(self) -> str:
        m = self.dataset.machine
        side = "spindle head" if self.tool_side else "table"
        L = [f"Jiang & Cripps four-step DBB test: {m.name} ({m.topology})",
             f"  {self.carried} carried by {self.carrier} on the {side}; {self.carrier} tested first", ""]
        L.append("  step  axis  extension  samples   centre (µm, plane axes)   radius (mm)  "
                 "fit rms (µm)  d_e (µrad)  |S'O'| (mm)")
        planes = {s.axis: _step_plane(s) for s in self.steps}
        for s in self.steps:
            c = np.asarray(s.centre) * 1e3
            L.append(f"  {s.setup:<5} {s.axis:<5} {'yes' if s.extended else 'no':<10} {len(s.residuals):>6}  "
                     f"({','.join(planes[s.axis])}) {c[0]:9.3f} {c[1]:9.3f}   {s.radius:11.4f}  "
                     f"{s.rms * 1e3:11.3f}  {s.start_angle_error * 1e6:10.2f}  {s.arm:10.3f}")
        pa, pc = planes[self.carrier], planes[self.carried]
        L.append(f"  O'E (eqs. 18-19): {self.carrier} ({','.join(pa)}) = ({self.a_oe[0] * 1e3:.3f}, "
                 f"{self.a_oe[1] * 1e3:.3f}) µm, {self.carried} ({','.join(pc)}) = ({self.c_oe[0] * 1e3:.3f}, "
                 f"{self.c_oe[1] * 1e3:.3f}) µm")
        L.append(f"  eq. 20 substitution error Delta: {self.carrier} {self._core.a_delta:.2e} mm, "
                 f"{self.carried} {self._core.c_delta:.2e} mm")
        L.append("")
        eng = self.engine
        head = f"  {'parameter':<10}{'four-step':>16}{'± std':>10}"
        if eng is not None:
            head += f"{'engine':>16}{'± std':>10}{'difference':>14}"
        L.append(head)
        for n in self.names:
            f, unit = display_scale(n)
            row = f"  {n:<10}{self.values[n] * f:>16.3f}{self.std[n] * f:>10.3f}"
            ev = self.engine_value(n)
            if ev is not None:
                row += f"{ev[0] * f:>16.3f}{ev[1] * f:>10.3f}{(self.values[n] - ev[0]) * f:>14.3f}"
            L.append(row + f"  {unit}")
        if eng is not None:
            fd = guards.findings(eng)
            L.append("")
            L.append(f"  general engine: {eng.n_observations} readings, {eng.n_parameters} parameters "
                     f"(with the bar lengths), rank {eng.rank}, condition {eng.condition_number:.3g}, "
                     f"rms {eng.rms * 1e3:.3f} µm")
            m = self.dataset.machine
            moved = [(n, spindle_equivalent(m, n)) for n in self.names if n not in eng.values
                     and spindle_equivalent(m, n) in eng.values]
            if moved:
                L.append("  the engine and the result file name " + ", ".join(
                    f"{n} by the spindle: {s} = {'-' if n[3] in m.workpiece_chain else ''}{n}" for n, s in moved)
                    + " (the same error; no ball bar reading tells it from the spindle ball's placement)")
            # identify's own verdict words: the engine's fit is the one a consumer uses
            L += ["  " + t for t in verdict_lines(eng, fd)]
            L += ["  " + t for t in finding_lines(fd)]
        if self.engine_error:
            L.append(f"  general engine: not run ({self.engine_error})")
        L.append("  signs: fivecal's (E = Trans.Rz.Ry.Rx); on the paper's machine its eq. 18 gives "
                 "E_B0A with the opposite sign.")
        return "\n".join(L)

    def __repr__(self) -> str:
        return "FourStepResult(" + ", ".join(f"{n}={self.values[n]:.4g}" for n in self.names) + ")"


def _moving_ball_offset(m: Machine, axes: Mapping, offset_f: np.ndarray, tool_side: bool) -> np.ndarray:
    """A displacement of the moving ball given in F at pose `axes`, expressed
    where that ball is defined: the workpiece frame for a table ball, F at the
    zero pose for a tool ball (the ball's chain is rigid apart from its axes,
    so the map is linear)."""
    q = np.array([[axes.get(a, 0.0) for a in m.axis_names]])
    k = 0 if tool_side else 1
    z = np.zeros(3)
    b0 = np.asarray(_core.dbb_ball_positions(m._core, q, z, z)[k])[0]
    R = np.zeros((3, 3))
    for j in range(3):
        e = np.eye(3)[j]
        bj = np.asarray(_core.dbb_ball_positions(m._core, q, e if tool_side else z, z if tool_side else e)[k])[0]
        R[:, j] = bj - b0
    return R.T @ offset_f


def jiang_cripps(dataset: Union[Dataset, Mapping], setups: Optional[Sequence[str]] = None,
                 length_offsets: Optional[Mapping[str, float]] = None,
                 a_pivot_offset=(0.0, 0.0), c_pivot_offset=(0.0, 0.0), uniform_angles: bool = False,
                 refer_positions: bool = True, a_removal: str = "full", engine: bool = True,
                 engine_estimate: Optional[Sequence[str]] = None,
                 spindle_names: bool = False) -> FourStepResult:
    """Run the four-step analysis (C++ core) on the DBB observations of the
    four setups (default ``<carrier>1 <carrier>2 <carried>1 <carried>2``,
    ``A1 A2 C1 C2`` on the paper's machine; see :func:`four_step_pair`) and,
    with ``engine=True``, fit the same readings with the general engine (the
    eight PIGEs plus every setup's bar length).

    ``a_*`` refers to the carrier (the paper's A), ``c_*`` to the carried
    axis (the paper's C). ``a_pivot_offset`` / ``c_pivot_offset``: the pivot's
    start position error P0P0' (mm) in the step's plane axes (the report
    names them; A: Y, Z; C: X, Y; B: Z, X), from the planar test around it
    (eq. 1); the engine gets them as known ball offsets. ``length_offsets``:
    calibrated minus nominal bar length per setup (mm). ``a_removal``:
    ``full`` | ``position`` | ``none``: how the carrier's errors are removed
    from the carried axis (see ``dbb_four_step.h``). ``spindle_names``: the
    engine estimates an offset that is the spindle's (EX0C and EY0A on an
    A/C trunnion: no ball bar reading tells them from the spindle ball's
    placement) under the spindle's name, as every fivecal command names it
    (:func:`fivecal.procedures.sphere_check.spindle_equivalent`).
    """
    ds = Dataset.from_dict(dataset)
    setups = list(setups) if setups else list(four_step_pair(ds.machine)["setups"])
    core = _core.four_step(ds._core, setups, {k: float(v) for k, v in (length_offsets or {}).items()},
                           np.asarray(a_pivot_offset, float), np.asarray(c_pivot_offset, float),
                           bool(uniform_angles), bool(refer_positions), str(a_removal))
    options = {"setups": setups, "a_pivot_offset": list(map(float, a_pivot_offset)),
               "c_pivot_offset": list(map(float, c_pivot_offset)), "uniform_angles": uniform_angles,
               "refer_positions": refer_positions, "a_removal": a_removal,
               "length_offsets": dict(length_offsets or {})}
    eng, err = None, None
    if engine:
        m = ds.machine
        ball = "tool" if core.tool_side else "table"
        initial = {}
        for k, (setup_ids, off) in enumerate(((setups[:2], a_pivot_offset), (setups[2:], c_pivot_offset))):
            off = np.asarray(off, float)
            if not np.any(off):
                continue
            step = core.steps[2 * k]
            off_f = off[0] * np.asarray(step.e1) + off[1] * np.asarray(step.e2)
            first = ds.observations[step.observations[0]]["axes"]
            w = _moving_ball_offset(m, first, off_f, bool(core.tool_side))
            for sid in setup_ids:
                for c, v in zip("xyz", w):
                    initial[f"dbb.{sid}.{ball}.{c}"] = float(v)
        for sid in setups:
            if length_offsets and sid in length_offsets:
                initial[f"dbb.{sid}.length"] = float(length_offsets[sid])
        try:
            names = list(engine_estimate or core.names)
            if spindle_names:
                names = list(dict.fromkeys(spindle_equivalent(m, n) for n in names))
            eng = identify(ds, names, initial=initial)
        except ValueError as e:
            err = str(e)
    return FourStepResult(core, ds, eng, err, options)


#: deg: how far a trace's angle may go back against its run direction (a
#: logger's rounding), or beyond the planned range of a tilting axis
TRACE_ANGLE_TOLERANCE = 1e-3


def _check_trace(sid: str, trace: Trace, entries: list, axis: str) -> None:
    """Refuse, naming the data row, a trace that is not its setup's run of
    the plan: angles outside the planned range (a trace of another axis or
    plan), going back (rows out of order) or run the other way than planned
    (a reversed file gives every sample the wrong approach direction)."""
    name = f"trace {sid}" + (f" ({trace.label})" if trace.label and trace.label != sid else "")
    planned = np.array([float(e["axes"][axis]) for e in entries])
    want = int(np.sign(entries[0].get("direction", {}).get(axis, 0)))
    a = trace.angles
    if want and trace.direction and trace.direction != want:
        raise ValueError(f"{name}: row 1: the trace runs {'+-'[trace.direction < 0]}{axis} ({a[0]:g} to "
                         f"{a[-1]:g} deg), the plan's {sid} runs {'+-'[want < 0]}{axis}: rows reversed, or "
                         "the run of the other direction (its readings would carry the wrong approach side)")
    d = trace.direction or want
    back = np.nonzero(np.diff(a) * d < -TRACE_ANGLE_TOLERANCE)[0] if d else []
    if len(back):
        k = int(back[0]) + 1
        raise ValueError(f"{name}: row {k + 1}: angle {a[k]:g} deg goes back from {a[k - 1]:g} deg: the rows are "
                         f"not in the order the axis ran")
    step = float(np.max(np.abs(np.diff(planned)))) if planned.size > 1 else 0.0
    if np.ptp(planned) + step < 360.0 - 1e-6:  # a full turn: any angle is on it
        lo, hi = planned.min() - step - TRACE_ANGLE_TOLERANCE, planned.max() + step + TRACE_ANGLE_TOLERANCE
        out = np.nonzero((a < lo) | (a > hi))[0]
        if len(out):
            k = int(out[0])
            raise ValueError(f"{name}: row {k + 1}: angle {a[k]:g} deg is outside the plan's {axis} range "
                             f"{planned.min():g} to {planned.max():g} deg for {sid} (a trace of another setup "
                             "or plan?)")


def four_step_dataset(machine: Union[Machine, Mapping], traces: Mapping[str, Trace],
                      plan: Optional[list] = None, **plan_options) -> Dataset:
    """A dataset from four CSV traces (angle = the moving axis command in deg,
    reading in mm), one per setup id, placed on the geometry of
    :func:`four_step_plan` (same keyword options). Each trace is checked
    against its setup's run of the plan (:func:`_check_trace`: the planned
    range, one direction, the planned direction); a refusal names the row."""
    m = Machine.from_dict(machine)
    plan = plan or four_step_plan(m, **plan_options)
    by_setup: dict = {}
    for e in plan:
        by_setup.setdefault(e["setup"], []).append(e)
    obs = []
    for sid, trace in traces.items():
        if sid not in by_setup:
            raise ValueError(f"four-step traces: unknown setup {sid!r} (plan setups: "
                             f"{', '.join(by_setup)})")
        template = by_setup[sid][0]
        axis = next(iter(template["direction"]))
        _check_trace(sid, trace, by_setup[sid], axis)
        for a, r in zip(trace.angles, trace.readings):
            o = {k: (dict(v) if isinstance(v, dict) else v) for k, v in template.items()}
            o["axes"][axis] = float(a)
            o["direction"] = {axis: int(np.sign(trace.direction) or 1)}
            o["reading"] = float(r)
            obs.append(o)
    return Dataset.from_dict({"machine": m.to_dict(), "observations": obs})


# --------------------------------------------------------------------------
# Wang et al. simultaneous A/C path
# --------------------------------------------------------------------------
class WangPath:
    """The path of :func:`wang_path` (C++ ``wang_path.h``)."""

    def __init__(self, core, machine: Machine):
        self._core = core
        self.machine = machine
        self.tilt_axis: str = core.tilt_axis
        self.rotary_axis: str = core.rotary_axis
        self.tracking = np.asarray(core.tracking)
        self.tilt = np.asarray(core.tilt)
        self.rotary = np.asarray(core.rotary)
        self.other_tilt = np.asarray(core.other_tilt)
        self.other_rotary = np.asarray(core.other_rotary)
        self.tilt_direction = np.asarray(core.tilt_direction)
        self.rotary_direction = np.asarray(core.rotary_direction)
        self.centre = np.asarray(core.centre)
        self.spindle_ball = np.asarray(core.spindle_ball)
        self.radius: float = core.radius
        self.height: float = core.height
        self.bar_length: float = core.bar_length
        self.max_circle_error: float = core.max_circle_error
        self.table_ball = np.zeros(3)

    def table(self, every: float = 45.0) -> list:
        """Rows (tracking angle, tilt, rotary, other branch tilt, rotary,
        direction of each axis) every ``every`` degrees (Wang et al. Table 1)."""
        rows = []
        for i, phi in enumerate(self.tracking):
            k = (phi - self.tracking[0]) / every
            if abs(k - round(k)) < 1e-9:
                rows.append((float(phi), float(self.tilt[i]), float(self.rotary[i]),
                             float(self.other_tilt[i]), float(self.other_rotary[i]),
                             int(self.tilt_direction[i]), int(self.rotary_direction[i])))
        return rows

    def format_table(self, every: float = 45.0) -> str:
        t, r = self.tilt_axis, self.rotary_axis
        sgn = {1: "+", -1: "-", 0: "0"}
        L = [f"Wang et al. path on {self.machine.name}: table ball on a horizontal circle of radius "
             f"{self.radius:g} mm, centre ({', '.join(f'{x:.3f}' for x in self.centre)}) mm",
             f"spindle ball at ({', '.join(f'{x:.3f}' for x in self.spindle_ball)}) mm, bar "
             f"{self.bar_length:.3f} mm; max deviation of the table ball from the circle "
             f"{self.max_circle_error:.1e} mm",
             "",
             f"  {'phi (deg)':>9}  {t + ' (deg)':>11}  {r + ' (deg)':>11}   {'moving':>8}   "
             f"{'other branch ' + t:>17}  {r:>9}"]
        for phi, a, c, oa, oc, da, dc in self.table(every):
            L.append(f"  {phi:9.0f}  {a:11.4f}  {c:11.4f}   {t}{sgn[da]} {r}{sgn[dc]:<3}   {oa:17.4f}  {oc:9.4f}")
        L.append("  (smallest-move branch; 'moving' is the direction of each axis into the row)")
        return "\n".join(L)


def wang_path(machine: Union[Machine, Mapping], table_ball=(0.0, 150.0, 130.0), radius: float = 80.0,
              height: float = 60.0, start: float = 0.0, end: float = 540.0, step: float = 1.0,
              start_pose=(0.0, 0.0)) -> WangPath:
    """Rotary commands that keep the table ball on a horizontal circle of
    ``radius`` around the stationary spindle ball, ``height`` mm above its
    centre; tracking angle from ``start`` to ``end`` deg (Wang et al. 0-540).
    Defaults (the paper's Table 2 did not survive): table ball 150 mm off the
    C axis and 130 mm above the A axis, circle radius 80 mm and the spindle
    ball 60 mm above it, i.e. a 100 mm bar; A then swings between about -25
    and -73 deg and C between -32 and +32 deg."""
    m = Machine.from_dict(machine)
    core = _core.wang_path(m._core, np.asarray(table_ball, float), float(radius), float(height),
                           float(start), float(end), float(step), float(start_pose[0]),
                           float(start_pose[1]))
    p = WangPath(core, m)
    p.table_ball = np.asarray(table_ball, float)
    return p


def wang_plan(machine: Union[Machine, Mapping], capture=(90.0, 450.0), setup: str = WANG_SETUP,
              tool_ball=None, path: Optional[WangPath] = None, **path_options) -> list:
    """DBB plan entries along the Wang path, sampled where the paper captures
    data (tracking angle 90-450 deg), with the direction of each rotary axis
    recorded for backlash. The linear axes hold the spindle ball still."""
    m = Machine.from_dict(machine)
    p = path or wang_path(m, **path_options)
    tb = np.asarray(tool_ball if tool_ball is not None else m.tip, float)
    table_ball = [float(x) for x in p.table_ball]
    # Linear commands: the nominal inverse puts the tool ball at the spindle ball.
    lin = m.inverse([p.spindle_ball + (m.tip - tb)], start={a: 0.0 for a in m.axis_names})
    plan = []
    for i, phi in enumerate(p.tracking):
        if phi < capture[0] - 1e-9 or phi > capture[1] + 1e-9:
            continue
        axes = {a: float(v[0]) for a, v in lin.items()}
        axes[p.tilt_axis] = float(p.tilt[i])
        axes[p.rotary_axis] = float(p.rotary[i])
        plan.append({"type": "dbb", "setup": setup, "axes": axes, "length": float(p.bar_length),
                     "direction": {p.tilt_axis: int(p.tilt_direction[i]),
                                   p.rotary_axis: int(p.rotary_direction[i])},
                     "tool_ball": [float(x) for x in tb], "table_ball": table_ball,
                     "tracking": float(phi)})
    return plan


def _plan_for_simulation(plan: list) -> list:
    return [{k: v for k, v in e.items() if k != "tracking"} for e in plan]


@dataclass
class Pattern:
    """A simulated trace and its Fourier harmonics (row k: a_k cos + b_k sin, mm)."""

    name: str
    value: float
    tracking: np.ndarray
    readings: np.ndarray
    harmonics: np.ndarray

    def shift(self) -> np.ndarray:
        """Centre shift of the polar pattern (first harmonic, mm, along X and Y)."""
        return self.harmonics[1].copy()


def trace_harmonics(angles, values, max_order: int = 4) -> np.ndarray:
    """Least-squares Fourier coefficients, rows (a_k, b_k), k = 0..max_order."""
    return np.asarray(_core.trace_harmonics(np.asarray(angles, float), np.asarray(values, float),
                                            int(max_order)))


def wang_patterns(machine: Union[Machine, Mapping], errors: Mapping[str, float], max_order: int = 4,
                  capture=(90.0, 450.0), **path_options) -> dict:
    """Noise-free traces of the Wang path for each error alone (name -> value),
    with their harmonics: the patterns of Wang et al. Section 4."""
    m = Machine.from_dict(machine)
    plan = wang_plan(m, capture=capture, **path_options)
    phi = np.array([e["tracking"] for e in plan])
    out = {}
    for name, value in errors.items():
        ds = simulate(m, _plan_for_simulation(plan), errors={name: float(value)})
        r = np.array([o["reading"] for o in ds.observations])
        out[name] = Pattern(name, float(value), phi, r, trace_harmonics(phi, r, max_order))
    return out


@dataclass
class WangIdentification(Viewable):
    """Least-squares identification from a whole Wang trace, and what the
    path can and cannot separate: each further candidate is classified as
    ``no effect`` (its column is zero on this path), ``confounded`` (exactly,
    the engine's rank analysis names the group), ``practically confounded``
    (full rank but correlated beyond ``|r| > 0.9999`` with one fitted
    parameter) or ``separable`` (with its largest correlation)."""

    result: object                                   # fivecal.Result for the requested errors
    verdicts: dict = field(default_factory=dict)     # candidate -> (kind, partners, figure)

    @property
    def confounded(self) -> dict:
        """Candidates this path cannot separate: name -> the parameters it is tied to."""
        return {c: p for c, (k, p, _) in self.verdicts.items() if k != "separable"}

    @property
    def separable(self) -> dict:
        """Candidates this path separates: name -> largest |correlation| with the fitted set."""
        return {c: f for c, (k, _, f) in self.verdicts.items() if k == "separable"}

    setup: str = WANG_SETUP

    def procedure_values(self, path: Optional["WangPath"] = None) -> dict:
        """The path's own values (the ``procedure.values`` of the result
        document): the trace (setup, samples, bar length, both balls, the
        range of each rotary axis), the path geometry when ``path`` is given,
        and what this path separates from the fitted errors."""
        ds = self.result.dataset
        idx = _dbb_rows(ds, self.setup)
        obs = [ds.observations[i] for i in idx]
        m = ds.machine
        rotary = [a["name"] for a in m.axes if a["type"] == "rotary" and a["name"] != "S"]
        d = {"setup": self.setup, "samples": len(idx), "bar_length": float(obs[0]["length"]),
             "tool_ball": list(map(float, obs[0]["tool_ball"])), "table_ball": list(map(float, obs[0]["table_ball"])),
             "axis_range": {a: [min(float(o["axes"].get(a, 0.0)) for o in obs),
                                max(float(o["axes"].get(a, 0.0)) for o in obs)] for a in rotary},
             "identifiability": {c: {"kind": k, "partners": list(p), "correlation": float(f)}
                                 for c, (k, p, f) in self.verdicts.items()}}
        if path is not None:
            d["path"] = {"tilt_axis": path.tilt_axis, "rotary_axis": path.rotary_axis,
                         "circle_radius": float(path.radius), "height": float(path.height),
                         "circle_centre": list(map(float, path.centre)),
                         "spindle_ball": list(map(float, path.spindle_ball)),
                         "max_circle_error": float(path.max_circle_error)}
        return d

    def report(self) -> str:
        L = ["Wang et al. simultaneous A/C DBB test: least squares on the whole trace", "",
             self.result.report(), "",
             "  identifiability: each further candidate added to the fitted set on its own"]
        order = {"no effect": 0, "confounded": 1, "practically confounded": 2, "separable": 3}
        for c, (kind, partners, fig) in sorted(self.verdicts.items(), key=lambda kv: order[kv[1][0]]):
            if kind == "no effect":
                L.append(f"    {c:<16} no effect on this path")
            elif kind == "confounded":
                L.append(f"    {c:<16} cannot be separated from {', '.join(partners)}")
            elif kind == "practically confounded":
                L.append(f"    {c:<16} practically confounded with {', '.join(partners)} "
                         f"(correlation {fig:.6f})")
            else:
                L.append(f"    {c:<16} separable (largest correlation {fig:.3f}, with {partners[0]})")
        return "\n".join(L)


def wang_identify(dataset: Union[Dataset, Mapping], estimate: Sequence[str] = WANG_ERRORS,
                  setup: str = WANG_SETUP, candidates: Sequence[str] = WANG_CANDIDATES,
                  include_ball_placement: bool = True) -> WangIdentification:
    """Fit ``estimate`` (default the paper's four errors; the bar length is
    added) to every reading of the trace, with the ball placements
    ``dbb.<setup>.tool|table.x|y|z`` estimated under their placement
    uncertainty (docs/setup_uncertainty.md): the table ball's height and
    offset are not known to the micrometre, and an error this path confounds
    with them gets the sigma the placement allows instead of a confident
    wrong value. Then add each further candidate (the other C and A location
    errors and, with ``include_ball_placement``, the ball placements) on its
    own to ``estimate`` with the set-up taken as exact, and let the engine
    say whether the path itself separates it from the fitted set."""
    import warnings

    ds = Dataset.from_dict(dataset)
    _dbb_rows(ds, setup)
    estimate = list(estimate)
    placements = [f"dbb.{setup}.{b}.{c}" for b in ("tool", "table") for c in "xyz"]
    result = identify(ds, estimate + [p for p in placements if p not in estimate])
    cand = [c for c in candidates if c not in estimate]
    if include_ball_placement:
        cand += [p for p in placements if p not in estimate]
    verdicts = {}
    for c in cand:
        with warnings.catch_warnings():  # probing confounded sets on purpose: not a failed fit
            warnings.simplefilter("ignore", guards.FitWarning)
            r = identify(ds, estimate + [c], allow_unidentifiable=True, setup_priors=False)
        if r.rank < r.n_parameters:
            groups = [list(g) for g in r.unidentifiable if c in g]
            partners = [n for n in (groups[0] if groups else []) if n != c]
            verdicts[c] = ("confounded" if partners else "no effect", partners, 1.0)
            continue
        i = r.estimated.index(c)
        corr = np.abs(np.asarray(r.correlation)[i])
        corr[i] = 0.0
        j = int(np.argmax(corr))
        kind = "practically confounded" if corr[j] > 0.9999 else "separable"
        verdicts[c] = (kind, [r.estimated[j]], float(corr[j]))
    return WangIdentification(result, verdicts, setup)


@dataclass
class FourPointAnalysis:
    """The paper's four-point extraction (Section 5.1: the readings where the
    trace crosses the two diagonals, four equations for the four errors),
    analysed instead of trusted. ``sensitivity`` (4 x 4): reading change (mm)
    per unit error at each diagonal angle; ``singular_values`` of it with its
    columns scaled by ``scale`` (a plausible size of each error);
    ``rank``; ``null_space``: error combinations (per unit of ``scale``,
    each signed so that its largest component is positive) the four
    readings cannot see; ``estimable``: the errors the four points
    do determine; ``values``: the four-point solution, or None when the system
    is singular (then nothing but ``estimable`` is reported)."""

    angles: np.ndarray
    errors: tuple
    sensitivity: np.ndarray
    scale: np.ndarray
    singular_values: np.ndarray
    rank: int
    null_space: np.ndarray
    estimable: list
    values: Optional[dict] = None

    def report(self) -> str:
        L = ["Wang et al. four-point extraction (readings at tracking angles "
             + ", ".join(f"{a:g}" for a in self.angles) + " deg)",
             "  scaled singular values: " + ", ".join(f"{v:.3g}" for v in self.singular_values),
             f"  rank {self.rank} of {len(self.errors)}"]
        for v in self.null_space.T:
            terms = " ".join(f"{c:+.3f} {n}" for c, n in zip(v, self.errors) if abs(c) > 1e-6)
            L.append(f"  invisible to the four points: {terms} (per prior size)")
        L.append("  determined by the four points: " + (", ".join(self.estimable) or "none"))
        if self.values is None:
            L.append("  the four equations are singular: no values (use the whole-trace fit, wang_identify)")
        return "\n".join(L)


def wang_four_point(machine: Union[Machine, Mapping], readings: Optional[Mapping[float, float]] = None,
                    angles=(135.0, 225.0, 315.0, 405.0), errors: Sequence[str] = WANG_ERRORS,
                    scale: Optional[Mapping[str, float]] = None, **path_options) -> FourPointAnalysis:
    """Analyse (and, where it is regular, solve) the paper's four-point
    extraction on this machine's Wang path. The readings are linear in the
    errors (the patterns of :func:`wang_patterns`), so the four equations are
    ``S e = r`` with ``S`` the patterns at the diagonal angles. ``readings``:
    tracking angle (deg) -> DBB reading (mm) at those angles; without them
    only the analysis is returned. ``scale``: plausible size of each error
    (default 10 µm, 50 µrad) to make the rank judgement unit-free. The
    analysis is the core's (``wang_path.h``, ``AnalyzeWangFourPoint``)."""
    angles = np.asarray(angles, float)
    scale = dict(scale or {})
    sc = np.array([scale.get(n, 50e-6 if n.startswith(("EA", "EB", "EC")) else 0.01) for n in errors])
    pats = wang_patterns(machine, {n: float(v) for n, v in zip(errors, sc)}, **path_options)
    S = np.empty((len(angles), len(errors)))
    for j, n in enumerate(errors):
        p = pats[n]
        for i, a in enumerate(angles):
            k = np.flatnonzero(np.abs(p.tracking - a) < 1e-6)
            if k.size == 0:
                raise ValueError(f"wang_four_point: tracking angle {a:g} deg is not on the sampled path "
                                 f"({p.tracking[0]:g}-{p.tracking[-1]:g} deg, step of the path)")
            S[i, j] = p.readings[k[0]] / sc[j]
    r = None if readings is None else np.array([float(readings[a]) for a in angles])
    a = _core.wang_four_point(S, sc, r)
    values = dict(zip(errors, np.asarray(a.values).tolist())) if a.solved else None
    return FourPointAnalysis(angles, tuple(errors), S, sc, np.asarray(a.singular_values), int(a.rank),
                             np.asarray(a.null_space), [errors[j] for j in a.estimable], values)


# --------------------------------------------------------------------------
# Planar circular tests
# --------------------------------------------------------------------------
_DIAG_LABELS = {
    "radius": ("radius change (bar length + mean scale)", 1e3, "µm"),
    "centre.1": ("centre offset {a1}", 1e3, "µm"),
    "centre.2": ("centre offset {a2}", 1e3, "µm"),
    "scale_mismatch": ("scale mismatch {a1}-{a2}", 1e6, "µm/m"),
    "squareness": ("squareness {a1}{a2} (angle - 90°)", 1e6, "µrad"),
    "servo_mismatch": ("servo mismatch (lag {a1} - lag {a2}) x feed", 1e3, "µm"),
    "backlash.1+": ("backlash {a1}+ (reversal at the +{a1} end; offset along the motion)", 1e3, "µm"),
    "backlash.1-": ("backlash {a1}- (reversal at the -{a1} end; offset along the motion)", 1e3, "µm"),
    "backlash.2+": ("backlash {a2}+ (reversal at the +{a2} end; offset along the motion)", 1e3, "µm"),
    "backlash.2-": ("backlash {a2}- (reversal at the -{a2} end; offset along the motion)", 1e3, "µm"),
    "backlash.1": ("backlash {a1} (mean of {a1}+ and {a1}-)", 1e3, "µm"),
    "backlash.2": ("backlash {a2} (mean of {a2}+ and {a2}-)", 1e3, "µm"),
    "reversal_spike.1+": ("reversal spike {a1}+ (height, outward > 0)", 1e3, "µm"),
    "reversal_spike.1-": ("reversal spike {a1}- (height, outward > 0)", 1e3, "µm"),
    "reversal_spike.2+": ("reversal spike {a2}+ (height, outward > 0)", 1e3, "µm"),
    "reversal_spike.2-": ("reversal spike {a2}- (height, outward > 0)", 1e3, "µm"),
    "lateral_play.1": ("lateral play along {a1} (at {a2} reversals)", 1e3, "µm"),
    "lateral_play.2": ("lateral play along {a2} (at {a1} reversals)", 1e3, "µm"),
    "straightness.1": ("straightness {a1} (bow along {a2}, peak-valley)", 1e3, "µm"),
    "straightness.2": ("straightness {a2} (bow along {a1}, peak-valley)", 1e3, "µm"),
    "radial_play.1": ("radial play along {a1}", 1e3, "µm"),
    "radial_play.2": ("radial play along {a2}", 1e3, "µm"),
    "cyclic_error.1.cos": ("cyclic error {a1}, cos component", 1e3, "µm"),
    "cyclic_error.1.sin": ("cyclic error {a1}, sin component", 1e3, "µm"),
    "cyclic_error.2.cos": ("cyclic error {a2}, cos component", 1e3, "µm"),
    "cyclic_error.2.sin": ("cyclic error {a2}, sin component", 1e3, "µm"),
}
#: Short names of the ranked diagnoses (a cyclic error is ranked by its amplitude).
_RANK_LABELS = {
    "scale_mismatch": "scale mismatch {a1}-{a2}", "squareness": "squareness {a1}{a2}",
    "servo_mismatch": "servo mismatch", "backlash.1+": "backlash {a1}+", "backlash.1-": "backlash {a1}-",
    "backlash.2+": "backlash {a2}+", "backlash.2-": "backlash {a2}-",
    "reversal_spike.1+": "reversal spikes {a1}+", "reversal_spike.1-": "reversal spikes {a1}-",
    "reversal_spike.2+": "reversal spikes {a2}+", "reversal_spike.2-": "reversal spikes {a2}-",
    "lateral_play.1": "lateral play {a1}", "lateral_play.2": "lateral play {a2}",
    "straightness.1": "straightness {a1}", "straightness.2": "straightness {a2}",
    "radial_play.1": "radial play {a1}", "radial_play.2": "radial play {a2}",
    "cyclic_error.1": "cyclic error {a1}", "cyclic_error.2": "cyclic error {a2}",
}


@dataclass
class Trimmed:
    """What overshoot trimming removed from one run."""
    label: str
    removed_start: int
    removed_end: int
    arc_start: float  # deg of feed-in removed
    arc_end: float  # deg of feed-out removed

    def line(self) -> str:
        return (f"{self.label or 'run'}: feed-in {self.arc_start:.1f}° ({self.removed_start} samples) and "
                f"feed-out {self.arc_end:.1f}° ({self.removed_end} samples) removed")


def trim_overshoot(trace: Trace, data_arc: float = 360.0, feed_in: Optional[float] = None,
                   direction: Optional[int] = None):
    """The data arc of a run recorded with feed-in and feed-out (overshoot)
    arcs, and what was removed (C++ ``TrimOvershoot``): angles unwrapped,
    samples going against the run at either end dropped, the sweep beyond
    ``data_arc`` removed, ``feed_in`` deg at the start (default half of it,
    the symmetric arcs ballbar programs use). ``direction``: +1/-1, or 0 to
    take it from the unwrapped angles (default: the trace's). Returns
    (trace, Trimmed)."""
    if trace.angles.size < 2:
        return trace, Trimmed(trace.label, 0, 0, 0.0, 0.0)
    d = trace.direction if direction is None else direction
    t = _core.trim_overshoot(trace.angles, trace.readings, int(d), float(data_arc),
                             float("nan") if feed_in is None else float(feed_in))
    out = Trace(np.asarray(t["angles"]), np.asarray(t["readings"]), int(t["direction"]), trace.label)
    return out, Trimmed(trace.label, int(t["removed_start"]), int(t["removed_end"]), float(t["arc_start"]),
                        float(t["arc_end"]))


class CircularResult(Viewable):
    """ISO 230-4 values per run and the least-squares diagnosis."""

    def __init__(self, core, plane: str, feed: Optional[float], traces: list, trimmed: Sequence = (),
                 machine: Optional[str] = None, date: Optional[str] = None):
        self._core = core
        self.plane = plane
        self.feed = feed
        self.traces = traces
        #: what overshoot trimming removed, per run that had feed-in/out arcs
        self.trimmed: list = list(trimmed)
        self.machine = machine
        self.date = date
        self.nominal_radius: float = core.nominal_radius
        self.runs = list(core.runs)
        self.hysteresis: Optional[float] = core.hysteresis if core.has_hysteresis else None
        d = core.diagnosis
        self.diagnosis: dict = {n: float(v) for n, v in zip(d.names, np.asarray(d.values))}
        self.diagnosis_std: dict = {n: float(s) for n, s in zip(d.names, np.asarray(d.std))}
        #: values the core derives from the fitted ones (backlash.k: the mean of its two ends)
        self.derived: tuple = tuple(d.derived_names)
        self.diagnosis.update(zip(d.derived_names, map(float, np.asarray(d.derived_values))))
        self.diagnosis_std.update(zip(d.derived_names, map(float, np.asarray(d.derived_std))))
        #: diagnoses left out as not significant: name -> (|value|, std) in the fit they left
        self.dropped: dict = {n: (float(v), float(sd)) for n, v, sd in
                              zip(d.dropped_names, np.asarray(d.dropped_values), np.asarray(d.dropped_std))}
        #: the largest circular deviation G of the runs (mm), what the percentages refer to
        self.circularity: float = float(d.circularity)
        self.not_fitted: list = list(d.not_fitted)
        #: extended diagnoses left out as below the significance threshold ("name (z sigma)")
        self.not_significant: list = list(d.not_significant)
        self.diagnosis_rms: float = d.rms
        #: (diagnosis, contribution to circularity in mm), largest first
        self.ranking: list = [(n, float(c)) for n, c in zip(d.ranking, np.asarray(d.contribution))]
        #: contribution of each ranked diagnosis in percent of the circularity
        self.ranking_percent: dict = {n: float(p) for n, p in zip(d.ranking, np.asarray(d.contribution_percent))}
        #: thermal compensation applied to the readings (None: none), as given
        self.thermal: Optional[dict] = None
        #: standard the values are named and graded by (STANDARDS)
        self.standard: str = "ISO 230-4"
        #: pitches (mm) the cyclic errors were fitted with (0 = none), and those found by the search
        self.cyclic_pitch: tuple = (0.0, 0.0)
        self.cyclic_pitch_searched: dict = {}

    @property
    def samples(self) -> int:
        return int(sum(t.angles.size for t in self.traces))

    def header_line(self) -> str:
        """Machine, date, feed, radius and sample count: the plot header."""
        feed = f"{self.feed:g} mm/min" if self.feed else "not given"
        return (f"machine {self.machine or 'not given'}  ·  date {self.date or 'not given'}  ·  feed {feed}  ·  "
                f"radius {self.nominal_radius:g} mm  ·  {self.samples} samples")

    def cyclic_amplitude(self, axis: int):
        """(amplitude, std) in mm of the cyclic error of plane axis 1 or 2, or None."""
        c, s = f"cyclic_error.{axis}.cos", f"cyclic_error.{axis}.sin"
        if c not in self.diagnosis:
            return None
        a, b = self.diagnosis[c], self.diagnosis[s]
        amp = math.hypot(a, b)
        # first order; the two components are nearly uncorrelated (orthogonal sampling)
        sd = math.hypot(a * self.diagnosis_std[c], b * self.diagnosis_std[s]) / amp if amp > 0 else \
            max(self.diagnosis_std[c], self.diagnosis_std[s])
        return amp, sd

    def ranking_lines(self, top: Optional[int] = None) -> list:
        a1, a2 = self.plane[0], self.plane[1]
        rows = self.ranking[:top] if top else self.ranking
        return [f"{i + 1:2d}. {_RANK_LABELS.get(n, n).format(a1=a1, a2=a2):<22}{self.ranking_percent[n]:5.0f} %"
                f"{c * 1e3:8.2f} µm" for i, (n, c) in enumerate(rows)]

    def label(self, name: str, short: bool = False) -> str:
        """The name ballbar users know for diagnosis ``name`` in this plane."""
        a1, a2 = self.plane[0], self.plane[1]
        text = _RANK_LABELS.get(name) if short else None
        return (text or _DIAG_LABELS.get(name, (name,))[0]).format(a1=a1, a2=a2)

    @property
    def servo_mismatch_ms(self) -> Optional[float]:
        """Lag difference in ms when the feed is known (dtau = l / v)."""
        if not self.feed or "servo_mismatch" not in self.diagnosis:
            return None
        return self.diagnosis["servo_mismatch"] / (self.feed / 60.0) * 1e3

    def run(self, direction: int):
        for r in self.runs:
            if r.direction == direction:
                return r
        return None

    def summary_lines(self) -> list:
        """Short ISO 230-4 lines (per run, then the hysteresis) for plots."""
        L = []
        for r in self.runs:
            name = "CCW" if r.direction > 0 else "CW "
            L.append(f"{name} G {r.circular_deviation * 1e3:6.2f} µm  F {r.radial_deviation_min * 1e3:+6.2f}"
                     f"/{r.radial_deviation_max * 1e3:+6.2f} µm")
            L.append(f"    centre ({r.centre[0] * 1e3:+.2f}, {r.centre[1] * 1e3:+.2f}) µm")
            L.append(f"    mean radius {r.mean_radius:.4f} mm")
        if self.hysteresis is not None:
            L.append(f"H (hysteresis) {self.hysteresis * 1e3:.2f} µm")
        return L

    def report(self) -> str:
        a1, a2 = self.plane[0], self.plane[1]
        L = [f"Circular test in the {self.plane} plane, nominal radius {self.nominal_radius:g} mm "
             f"(angles from +{a1} towards +{a2})", f"  {self.header_line()}"]
        for t in self.trimmed:
            L.append(f"  overshoot: {t.line()}")
        L += ["", "  ISO 230-4:"]
        for r in self.runs:
            name = "CCW" if r.direction > 0 else "CW "
            L.append(f"    {name} circular deviation G {r.circular_deviation * 1e3:8.3f} µm   radial "
                     f"deviation F max {r.radial_deviation_max * 1e3:+8.3f} µm, min "
                     f"{r.radial_deviation_min * 1e3:+8.3f} µm")
            L.append(f"        least-squares circle: centre ({r.centre[0] * 1e3:+.3f}, "
                     f"{r.centre[1] * 1e3:+.3f}) µm, mean radius {r.mean_radius:.5f} mm")
        if self.hysteresis is not None:
            L.append(f"    circular hysteresis H {self.hysteresis * 1e3:.3f} µm")
        L += ["", "  diagnosis (least squares on every reading; formulas: `fivecal docs dbb`, section Diagnosis):"]
        for n in self.diagnosis:
            label, f, unit = _DIAG_LABELS[n]
            L.append(f"    {label.format(a1=a1, a2=a2):<64}{self.diagnosis[n] * f:>10.3f} ± "
                     f"{self.diagnosis_std[n] * f:.3f} {unit}")
        if self.servo_mismatch_ms is not None:
            L.append(f"    {'servo mismatch as a lag difference':<64}{self.servo_mismatch_ms:>10.4f} ms "
                     f"(feed {self.feed:g} mm/min)")
        for k, ax in ((1, a1), (2, a2)):
            amp = self.cyclic_amplitude(k)
            if amp is not None:
                how = "found" if k in self.cyclic_pitch_searched else "given"
                L.append(f"    {f'cyclic error {ax} amplitude':<64}{amp[0] * 1e3:>10.3f} ± {amp[1] * 1e3:.3f} µm "
                         f"(pitch {self.cyclic_pitch[k - 1]:.4g} mm, {how})")
        for nf in self.not_fitted:
            L.append(f"    not fitted: {nf}")
        if self.not_significant:
            import textwrap

            L += textwrap.wrap("not significant, left out: " + ", ".join(self.not_significant), 100,
                               initial_indent="    ", subsequent_indent="      ")
        L.append(f"    residual rms after the diagnosis {self.diagnosis_rms * 1e3:.3f} µm")
        L += ["", f"  ranking by contribution to circularity (circular deviation of the term alone, in % of the "
              f"circularity {self.circularity * 1e3:.2f} µm; ranges of separate terms do not add up):"]
        L += ["    " + line for line in self.ranking_lines()]
        return "\n".join(L)

    def procedure_values(self, tolerances: Optional[Mapping[str, float]] = None) -> dict:
        """The ISO 230-4 values per run and direction, the hysteresis and the
        diagnosis (the ``procedure.values`` of the result document), with
        the grade against ``tolerances`` (:meth:`grade`) when given."""
        d = self.to_dict()
        for run, t in zip(d["runs"], self.traces):
            run["label"] = t.label
            run["samples"] = int(t.angles.size)
        if tolerances:
            d["grade"] = self.grade(tolerances)
        return d

    #: what a circular test's tolerance may name: ISO 230-4 circular deviation
    #: G (each run), radial deviation F (largest |F| of any run), hysteresis H;
    #: and every diagnosis (DIAGNOSIS_TOLERANCES) by its name, its kind (all of
    #: that kind), or with the axis letter of the plane (backlash.X+)
    TOLERANCE_NAMES = ("G", "F", "H")
    #: diagnosis kind -> the dimension of its tolerance (kind, denominator, degree)
    DIAGNOSIS_TOLERANCES = {"scale_mismatch": ("length", "length", 1), "squareness": ("angle", None, 0),
                            "servo_mismatch": ("length", None, 0), "backlash": ("length", None, 0),
                            "reversal_spike": ("length", None, 0), "lateral_play": ("length", None, 0),
                            "straightness": ("length", None, 0), "radial_play": ("length", None, 0),
                            "cyclic_error": ("length", None, 0)}

    @classmethod
    def tolerance_dimension(cls, name: str):
        """(kind, denominator, degree) of a tolerance name, ValueError naming it when unknown."""
        if name in cls.TOLERANCE_NAMES:
            return "length", None, 0
        kind = name.split(".", 1)[0]
        if kind not in cls.DIAGNOSIS_TOLERANCES:
            raise ValueError(f"--tolerance {name}: a circular test grades G (circular deviation), F (radial "
                             "deviation), H (hysteresis) and the diagnoses " +
                             ", ".join(cls.DIAGNOSIS_TOLERANCES) + " (e.g. backlash.X+=4um, squareness=20urad, "
                             "scale_mismatch=10um/m)")
        return cls.DIAGNOSIS_TOLERANCES[kind]

    def _targets(self, name: str) -> list:
        """The ranked diagnoses a tolerance name grades: an exact name, a
        kind (every one of it), or the plane's axis letter for 1 / 2."""
        kind, _, rest = name.partition(".")
        for k, ax in ((1, self.plane[0]), (2, self.plane[1])):
            if rest[:1].upper() == ax and ax not in "12":
                rest = str(k) + rest[1:]
        full = f"{kind}.{rest}" if rest else kind
        if rest and rest[:1] not in "12":
            raise ValueError(f"--tolerance {name}: '{rest[:1]}' is not an axis of the {self.plane} plane "
                             f"({self.plane[0]} or {self.plane[1]}, or 1 / 2)")
        known = [n for n, _ in self.ranking] + list(self.dropped)
        if not rest:
            return [n for n in known if n.split(".")[0] == kind] or [kind]
        if full in known:
            return [full]
        split = [n for n in known if n in (full + "+", full + "-")]
        return split or [full]

    def _graded_value(self, name: str):
        """(|value| in mm, mm/mm or rad, its std) of a ranked diagnosis, None when not fitted."""
        if name.startswith("cyclic_error") and name.count(".") == 1:
            amp = self.cyclic_amplitude(int(name[-1]))
            return amp
        if name not in self.diagnosis:
            return None
        return abs(self.diagnosis[name]), self.diagnosis_std[name]

    def grade(self, tolerances: Mapping[str, float]) -> dict:
        """PASS / FAIL of each toleranced value: the ISO 230-4 values (mm) and
        the diagnoses (|value| in mm, mm/mm or rad; a cyclic error by its
        amplitude): ``{"grade": "PASS"|"FAIL"|"NOT DETERMINED", "items":
        [{name, label, run, value, std, tolerance, grade, shown,
        tolerance_shown}]}``. A diagnosis left out as below 3 standard
        uncertainties passes only when |value| + 3 std (in the fit it left)
        is within the tolerance; otherwise, and for one not fitted at all,
        it is NOT DETERMINED, never a PASS. A value that is missing (H of a
        single run) is refused."""
        items = []
        for name, tol in tolerances.items():
            kind = self.tolerance_dimension(name)
            if name in self.TOLERANCE_NAMES:
                if name == "H":
                    if self.hysteresis is None:
                        raise ValueError("--tolerance H: hysteresis needs a CW and a CCW run")
                    pairs = [("CW/CCW", float(self.hysteresis))]
                else:
                    pairs = [("CCW" if r.direction > 0 else "CW",
                              float(r.circular_deviation) if name == "G" else
                              max(abs(float(r.radial_deviation_max)), abs(float(r.radial_deviation_min))))
                             for r in self.runs]
                for run, v in pairs:
                    ok = math.isfinite(v) and v <= tol
                    items.append({"name": name, "label": {"G": "circular deviation G", "F": "radial deviation F",
                                                          "H": "hysteresis H"}[name],
                                  "run": run, "value": v, "std": None, "tolerance": float(tol),
                                  "grade": "PASS" if ok else "FAIL", "shown": f"{v * 1e3:.2f} µm",
                                  "tolerance_shown": f"{tol * 1e3:.2f} µm"})
                continue
            f, unit = (1e6, "µrad") if kind[0] == "angle" else ((1e6, "µm/m") if kind[1] else (1e3, "µm"))
            for target in self._targets(name):
                got = self._graded_value(target)
                label = self.label(target, short=True)
                if got is None and target in self.dropped:
                    # below 3σ and left out: a PASS only when even |value| + 3σ is within the tolerance
                    v, sd = self.dropped[target]
                    ok = v + 3 * sd <= tol
                    items.append({"name": target, "label": label, "run": "both", "value": v, "std": sd,
                                  "tolerance": float(tol), "grade": "PASS" if ok else "NOT DETERMINED",
                                  "shown": f"not significant: |{v * f:.2f}| ± {sd * f:.2f} {unit}",
                                  "tolerance_shown": f"{tol * f:.2f} {unit}"})
                    continue
                if got is None:
                    items.append({"name": target, "label": label, "run": "both", "value": None, "std": None,
                                  "tolerance": float(tol), "grade": "NOT DETERMINED", "shown": "not determined",
                                  "tolerance_shown": f"{tol * f:.2f} {unit}"})
                    continue
                v, sd = got
                ok = math.isfinite(v) and v <= tol
                items.append({"name": target, "label": label, "run": "both", "value": float(v), "std": float(sd),
                              "tolerance": float(tol), "grade": "PASS" if ok else "FAIL",
                              "shown": f"{v * f:.2f} ± {sd * f:.2f} {unit}",
                              "tolerance_shown": f"{tol * f:.2f} {unit}"})
        grades = {i["grade"] for i in items}
        overall = "FAIL" if "FAIL" in grades else ("NOT DETERMINED" if "NOT DETERMINED" in grades else "PASS")
        return {"grade": overall, "items": items}

    def to_dict(self) -> dict:
        return {"plane": self.plane, "nominal_radius": self.nominal_radius, "feed": self.feed,
                "runs": [{"direction": "CCW" if r.direction > 0 else "CW",
                          "circular_deviation": float(r.circular_deviation),
                          "radial_deviation_max": float(r.radial_deviation_max),
                          "radial_deviation_min": float(r.radial_deviation_min),
                          "centre": list(map(float, r.centre)), "mean_radius": float(r.mean_radius)}
                         for r in self.runs],
                "hysteresis": self.hysteresis,
                "diagnosis": {n: {"value": v, "std": self.diagnosis_std[n]} for n, v in self.diagnosis.items()},
                "servo_mismatch_ms": self.servo_mismatch_ms, "not_fitted": self.not_fitted,
                "not_significant": self.not_significant, "cyclic_pitch": list(self.cyclic_pitch),
                "diagnosis_rms": self.diagnosis_rms,
                "ranking": [{"diagnosis": n, "contribution": c, "percent": self.ranking_percent[n]}
                            for n, c in self.ranking],
                "circularity": self.circularity, "derived": list(self.derived),
                "dropped": {n: {"value": v, "std": sd} for n, (v, sd) in self.dropped.items()},
                "thermal": self.thermal, "standard": self.standard,
                "overshoot_removed": [vars(t) for t in self.trimmed],
                "machine": self.machine, "date": self.date, "samples": self.samples}


def circular_test(runs: Iterable[Trace], radius: float, plane: str = "XY",
                  feed: Optional[float] = None, *, trim: bool = True, data_arc: float = 360.0,
                  feed_in: Optional[float] = None, reversal_spikes: bool = True, spike_width: float = 3.0,
                  lateral_play: bool = True, straightness: bool = True, radial_play: bool = True,
                  cyclic_pitch=None, significance: float = 3.0, machine=None,
                  date: Optional[str] = None, thermal: Optional[Mapping[str, float]] = None,
                  standard: str = "ISO 230-4") -> CircularResult:
    """ISO 230-4 circular deviation, radial deviation, LSC centre and radius per
    run, hysteresis of a CW/CCW pair, and the least-squares diagnosis of
    centre offset, scale mismatch, squareness, backlash per axis, servo
    mismatch, reversal spikes, lateral play, straightness, radial play and
    (with ``cyclic_pitch``, mm, one value or one per plane axis, or
    ``"auto"`` to search the pitch) cyclic error, ranked by contribution to circularity (C++ ``circular_test.h``;
    formulas in docs/dbb.md). Those five are kept only when above
    ``significance`` standard uncertainties (0 keeps them all). ``feed`` (mm/min) converts the servo mismatch
    to a lag difference in ms. ``trim``: runs sweeping more than
    ``data_arc`` have their feed-in and feed-out arcs removed first
    (:func:`trim_overshoot`). ``machine`` (a name or a Machine) and ``date``
    go into the report and plot header. ``thermal``: ``bar_expansion``,
    ``machine_expansion`` (1/K), ``bar_temperature``, ``machine_temperature``
    (deg C): the readings are referred to 20 deg C first (C++
    ``CompensateBarTemperature``, docs/dbb.md "Thermal compensation").
    ``standard``: the standard the values are named and graded by
    (:data:`STANDARDS`; only those whose definitions are public)."""
    standard = check_standard(standard)
    runs = [r for r in runs if r is not None]
    th = check_thermal(thermal) if thermal else None
    if th:
        runs = [Trace(r.angles, np.asarray(_core.compensate_bar_temperature(
            r.readings, float(radius), th["bar_expansion"], th["bar_temperature"], th["machine_expansion"],
            th["machine_temperature"])), r.direction, r.label) for r in runs]
    for i, r in enumerate(runs):
        span = float(r.angles.max() - r.angles.min()) if r.angles.size else 0.0
        if span < MIN_CIRCLE_SWEEP:
            hint = (" (the angles look like radians: give degrees, or name the column angle_rad)"
                    if looks_like_radians(r.angles) else "")
            raise ValueError(f"run {i + 1} ({r.label or 'no label'}): angles sweep {span:.4g} degrees; a "
                             f"circular test needs a full circle (at least {MIN_CIRCLE_SWEEP:g} degrees "
                             f"here){hint}")
    trimmed = []
    if trim:
        cut = []
        for r in runs:
            # The unwrapped angles decide the direction: a trace printed modulo
            # 360 fools first-minus-last (a CW turn 0, 359.5, ..., 0.5 "rises").
            t, info = trim_overshoot(r, data_arc, feed_in, direction=0)
            if info.removed_start or info.removed_end:
                trimmed.append(info)
            cut.append(t)
        runs = cut
    plane = plane.upper()
    if plane not in ("XY", "YZ", "ZX", "YX", "ZY", "XZ"):
        raise ValueError(f"plane: {plane!r} (XY, YZ or ZX)")
    if cyclic_pitch is None:
        pitches = [0.0, 0.0]
    elif isinstance(cyclic_pitch, str) or np.ndim(cyclic_pitch) == 0:
        pitches = [cyclic_pitch] * 2
    else:
        pitches = list(cyclic_pitch)
        if len(pitches) != 2:
            raise ValueError(f"cyclic_pitch: one pitch or one per plane axis (2), got {len(pitches)}")
    search = [False, False]
    for i, p in enumerate(pitches):
        if isinstance(p, str):
            if p.strip().lower() != "auto":
                raise ValueError(f"cyclic_pitch: {p!r}; give mm or 'auto'")
            search[i], pitches[i] = True, 0.0
        else:
            pitches[i] = float(p or 0.0)
    packed = [(r.angles, r.readings, int(r.direction)) for r in runs]
    core = _core.circular_test(packed, float(radius), float(feed or 0.0), cyclic_pitch1=pitches[0],
                               cyclic_pitch2=pitches[1], significance=float(significance),
                               reversal_spikes=bool(reversal_spikes), spike_width=float(spike_width),
                               lateral_play=bool(lateral_play), straightness=bool(straightness),
                               radial_play=bool(radial_play), search_cyclic_pitch1=search[0],
                               search_cyclic_pitch2=search[1])
    name = machine.name if isinstance(machine, Machine) else machine
    res = CircularResult(core, plane, feed, runs, trimmed, name, date)
    res.cyclic_pitch = (float(core.cyclic_pitch1), float(core.cyclic_pitch2))
    res.thermal = th
    res.standard = standard
    res.cyclic_pitch_searched = {k: (res.cyclic_pitch[k - 1] or None) for k in (1, 2) if search[k - 1]}
    return res


#: Standards a circular test is evaluated by. ISO 230-4's definitions (G, F,
#: H, the least-squares circle) are the ones fivecal implements; the others
#: map to the reason fivecal refuses them (docs/dbb.md, "Standards").
STANDARDS = {"ISO 230-4": None,
             "ASME B5.54": "its definitions of the circular test values are not public (the standard is sold by "
                           "ASME and no public text states them), so fivecal cannot claim to compute them",
             "JIS B 6194": "its definitions are not public (JIS text is sold; no public text states them), so "
                           "fivecal cannot claim to compute them",
             "GB/T 17421.4": "its text is not public to fivecal (SAC sells it); it has ISO 230-4's title and "
                             "scope, but without its text fivecal cannot confirm that its definitions are ISO's: "
                             "evaluate by ISO 230-4"}


def check_standard(text: str) -> str:
    """The canonical name of a standard (``iso230-4``, ``ISO 230-4`` ...);
    ValueError naming it and why for one whose definitions are not public."""
    key = "".join(c for c in str(text).upper() if c.isalnum())
    for name, why in STANDARDS.items():
        if "".join(c for c in name if c.isalnum()) == key:
            if why:
                raise ValueError(f"standard {name}: not implemented: {why}")
            return name
    raise ValueError(f"standard {text!r}: unknown; fivecal evaluates by ISO 230-4 (known but not implemented: "
                     + ", ".join(n for n, w in STANDARDS.items() if w) + ")")


#: The keys of a thermal compensation (a sidecar's "thermal" object).
THERMAL_KEYS = ("bar_expansion", "bar_temperature", "machine_expansion", "machine_temperature")


def check_thermal(thermal: Mapping) -> dict:
    """The four numbers of a thermal compensation, ValueError naming a
    missing, unknown or non-numeric key (ranges are the core's)."""
    if not isinstance(thermal, Mapping):
        raise ValueError(f"thermal: expected an object with {', '.join(THERMAL_KEYS)}")
    unknown = [k for k in thermal if k not in THERMAL_KEYS]
    if unknown:
        raise ValueError(f"thermal.{unknown[0]}: unknown key (expected {', '.join(THERMAL_KEYS)})")
    missing = [k for k in THERMAL_KEYS if k not in thermal]
    if missing:
        raise ValueError(f"thermal.{missing[0]}: missing; a thermal compensation needs {', '.join(THERMAL_KEYS)} "
                         "(expansion in 1/K, temperatures in deg C; 0 expansion = not compensated)")
    out = {}
    for k in THERMAL_KEYS:
        v = thermal[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f"thermal.{k}: expected a finite number, got {v!r}")
        out[k] = float(v)
    return out


@dataclass
class VolumetricResult:
    """Three planar circular tests (XY, YZ, ZX) evaluated together.

    ``planes``: the :class:`CircularResult` per plane. Combined values:
    ``circularity`` = the largest circular deviation G of any run of any
    plane; ``volumetric`` = the width of the spherical shell, about each
    plane's least-squares centre, that holds every sample of every plane
    (max - min over all runs of |P - c| - R, R the nominal radius); and the
    per-axis values that two planes share (each axis' backlash is seen in two
    planes, the scale mismatches of the three planes close to zero)."""
    planes: dict

    def plane_rows(self) -> list:
        rows = []
        for p, r in self.planes.items():
            g = max(float(run.circular_deviation) for run in r.runs)
            rows.append({"plane": p, "circularity": g, "hysteresis": r.hysteresis,
                         "top": r.ranking[0] if r.ranking else None, "samples": r.samples})
        return rows

    @property
    def circularity(self) -> float:
        return max(row["circularity"] for row in self.plane_rows())

    @property
    def volumetric(self) -> float:
        lo, hi = math.inf, -math.inf
        for r in self.planes.values():
            for run in r.runs:
                dev = np.asarray(run.radial) + (float(run.mean_radius) - r.nominal_radius)
                lo, hi = min(lo, float(dev.min())), max(hi, float(dev.max()))
        return hi - lo

    def header_line(self) -> str:
        """Machine, date, feed, radius and the sample count of each plane."""
        r = next(iter(self.planes.values()))
        feeds = sorted({x.feed for x in self.planes.values() if x.feed})
        feed = ", ".join(f"{f:g}" for f in feeds) + " mm/min" if feeds else "not given"
        n = ", ".join(f"{p} {x.samples}" for p, x in self.planes.items())
        return (f"machine {r.machine or 'not given'}  ·  date {r.date or 'not given'}  ·  feed {feed}  ·  "
                f"radius {r.nominal_radius:g} mm  ·  samples {n}")

    def scale_closure(self) -> Optional[float]:
        """(X-Y) + (Y-Z) + (Z-X) of the fitted scale mismatches: zero within
        noise when the three planes are consistent (mm/mm); None unless all
        three planes have it."""
        total, n = 0.0, 0
        for p, r in self.planes.items():
            if "scale_mismatch" in r.diagnosis:
                total += r.diagnosis["scale_mismatch"]
                n += 1
        return total if n == 3 else None

    def axis_values(self) -> dict:
        """Backlash of each linear axis from every plane that sees it: {axis: [(plane, value, std)]}."""
        out: dict = {}
        for p, r in self.planes.items():
            for k in (1, 2):
                n = f"backlash.{k}"
                if n in r.diagnosis:
                    out.setdefault(p[k - 1], []).append((p, r.diagnosis[n], r.diagnosis_std[n]))
        return out

    def report(self) -> str:
        L = ["Volumetric evaluation of the planar circular tests", f"  {self.header_line()}", "",
             f"  {'plane':<6}{'circularity G':>16}{'hysteresis H':>15}   largest contribution"]
        for row in self.plane_rows():
            p = row["plane"]
            top = (f"{_RANK_LABELS.get(row['top'][0], row['top'][0]).format(a1=p[0], a2=p[1])} "
                   f"{row['top'][1] * 1e3:.2f} µm") if row["top"] else "-"
            h = f"{row['hysteresis'] * 1e3:12.2f} µm" if row["hysteresis"] is not None else f"{'-':>15}"
            L.append(f"  {p:<6}{row['circularity'] * 1e3:13.2f} µm{h}   {top}")
        L += ["", f"  combined circularity (largest G of any plane)   {self.circularity * 1e3:8.2f} µm",
              f"  volumetric (shell holding every plane's trace)   {self.volumetric * 1e3:8.2f} µm"]
        c = self.scale_closure()
        if c is not None:
            L.append(f"  scale mismatch closure (X-Y)+(Y-Z)+(Z-X)         {c * 1e6:8.2f} µm/m (0 when consistent)")
        for ax, vals in sorted(self.axis_values().items()):
            L.append(f"  backlash {ax}: " + ", ".join(f"{v * 1e3:+.2f} ± {s * 1e3:.2f} µm ({p})"
                                                   for p, v, s in vals))
        return "\n".join(L)

    def to_dict(self) -> dict:
        return {"planes": {p: r.to_dict() for p, r in self.planes.items()},
                "circularity": self.circularity, "volumetric": self.volumetric,
                "scale_closure": self.scale_closure()}


def volumetric_evaluation(results: Mapping[str, CircularResult]) -> VolumetricResult:
    """Combine circular tests of the XY, YZ and ZX planes (keys: the planes).
    The planes must share the nominal radius: the volumetric shell compares
    their radial deviations."""
    planes = {}
    for p, r in results.items():
        key = str(p).upper()
        if key not in ("XY", "YZ", "ZX"):
            raise ValueError(f"volumetric evaluation: plane {p!r}; give XY, YZ and ZX")
        if r.plane.upper() != key:
            raise ValueError(f"volumetric evaluation: the result given for {key} is of plane {r.plane}")
        planes[key] = r
    if len(planes) < 2:
        raise ValueError(f"volumetric evaluation: {len(planes)} plane(s); give at least two of XY, YZ, ZX")
    radii = {r.nominal_radius for r in planes.values()}
    if max(radii) - min(radii) > 1e-9:
        raise ValueError(f"volumetric evaluation: the planes were run with different radii {sorted(radii)}; "
                         "the volumetric shell needs one radius")
    return VolumetricResult(planes)


def planar_plan(machine: Union[Machine, Mapping], plane: str = "XY", radius: float = 100.0,
                centre=None, step: float = 1.0, directions=(1, -1), setup_prefix: str = "P",
                tool_ball=None) -> list:
    """DBB plan of planar circular tests: the spindle ball runs a circle of
    ``radius`` around the table ball ``centre`` (workpiece frame; default the
    tool tip at the zero pose) with the rotary axes at 0, CCW (+1) and/or CW
    (-1), one sample per ``step`` degrees, recording each linear axis'
    direction of motion (for backlash). Setup ids ``P+`` / ``P-``."""
    m = Machine.from_dict(machine)
    step = float(step)
    # bounded before allocating: one sample per step over 360 deg
    if not (math.isfinite(step) and step > 0) or 360.0 / step > 1e6:
        raise ValueError(f"step: {step:g} deg; must be > 0 and give at most 1000000 samples per turn")
    if not (math.isfinite(float(radius)) and radius > 0):
        raise ValueError(f"radius: {radius!r}; must be a finite number > 0 mm")
    plane = plane.upper()
    idx = {"X": 0, "Y": 1, "Z": 2}
    if len(plane) != 2 or plane[0] not in idx or plane[1] not in idx or plane[0] == plane[1]:
        raise ValueError(f"plane: {plane!r} (XY, YZ or ZX)")
    plan = []
    for s in directions:
        phis = np.arange(0.0, 360.0, step) * (1 if s > 0 else -1)
        plan += _planar_entries(m, plane, float(radius), centre, tool_ball, phis, 1 if s > 0 else -1,
                                f"{setup_prefix}{'+' if s > 0 else '-'}")
    return plan


def planar_dataset(machine: Union[Machine, Mapping], traces: Sequence[Trace], plane: str = "XY",
                   radius: float = 100.0, centre=None, tool_ball=None, setup_prefix: str = "P") -> Dataset:
    """A dataset of measured planar runs (angle of the spindle ball about the
    table ball in deg, reading in mm), placed on the geometry of
    :func:`planar_plan`: each run a setup ``P+`` (CCW) or ``P-`` (CW), its
    direction taken from its angles; the linear axes' directions of motion
    recorded for backlash. The machine-error fit of ``dbb circular``."""
    m = Machine.from_dict(machine)
    plane = plane.upper()
    if not (math.isfinite(float(radius)) and radius > 0):
        raise ValueError(f"radius: {radius!r}; must be a finite number > 0 mm")
    obs, seen = [], set()
    for t in traces:
        d = t.direction or run_direction(t.angles)
        if d == 0:
            raise ValueError(f"{t.label or 'run'}: its angles make no net turn; a run direction cannot be told")
        setup = f"{setup_prefix}{'+' if d > 0 else '-'}"
        if setup in seen:
            raise ValueError(f"{t.label or 'run'}: a second {'CCW' if d > 0 else 'CW'} run; give one CW and "
                             "one CCW run")
        seen.add(setup)
        entries = _planar_entries(m, plane, float(radius), centre, tool_ball, t.angles, d, setup)
        for e, r in zip(entries, t.readings):
            e["reading"] = float(r)
            obs.append(e)
    return Dataset.from_dict({"machine": m.to_dict(), "observations": obs})


def _planar_entries(m: Machine, plane: str, radius: float, centre, tool_ball, phis, s: int, setup: str) -> list:
    idx = {"X": 0, "Y": 1, "Z": 2}
    if len(plane) != 2 or plane[0] not in idx or plane[1] not in idx or plane[0] == plane[1]:
        raise ValueError(f"plane: {plane!r} (XY, YZ or ZX)")
    tb = np.asarray(tool_ball if tool_ball is not None else m.tip, float)
    c = np.asarray(centre if centre is not None else m.tip, float)
    e1, e2 = np.eye(3)[idx[plane[0]]], np.eye(3)[idx[plane[1]]]
    plan = []
    pts = np.array([c + radius * (math.cos(math.radians(p)) * e1 + math.sin(math.radians(p)) * e2)
                    for p in phis])
    cmd = m.inverse(pts + (m.tip - tb), start={a: 0.0 for a in m.axis_names})
    for i, p in enumerate(phis):
        axes = {a: float(v[i]) for a, v in cmd.items()}
        # Velocity of the circle point: d/dphi (cos, sin) times the direction.
        vel = s * (-math.sin(math.radians(p)) * e1 + math.cos(math.radians(p)) * e2)
        direction = {}
        for ax in m.axes:
            if ax["type"] != "linear":
                continue
            # Command sign of the motion: a table axis moves the part, so
            # the tool runs against its direction relative to the part.
            side = -1.0 if ax["name"] in m.workpiece_chain else 1.0
            v = side * float(np.dot(vel, ax["direction"]))
            direction[ax["name"]] = 0 if abs(v) < 1e-12 else int(np.sign(v))
        plan.append({"type": "dbb", "setup": setup, "axes": axes,
                     "direction": direction, "length": float(radius),
                     "tool_ball": [float(x) for x in tb], "table_ball": [float(x) for x in c]})
    return plan
