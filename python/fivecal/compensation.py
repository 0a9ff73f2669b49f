"""Compensation: from identified errors back to the machine.

Three outputs, all computed on the erroneous model of DESIGN.md:

* :func:`compensate_poses` -- for a list of nominal axis commands (mm,
  degrees), the commands that put the real tool point (and, where the
  kinematics allow, the real tool axis) where the nominal machine would have
  put them (inverse kinematics on the erroneous model, seeded at each nominal
  pose so every pose stays on its own solution branch).
* :func:`compensate_gcode` -- an ISO G-code program with G0/G1 moves in
  absolute coordinates (G90) written back with compensated X Y Z and rotary
  words; comments, N numbers, F, S, M and every other word, spacing and case
  are left as they are. With zero errors the output is byte-for-byte the input.
* :func:`error_table` / :func:`write_error_table` -- the identified errors as
  a controller-neutral table (CSV or JSON) with the sign convention stated.

Units: mm for linear commands and errors, degrees for rotary commands, rad for
angular errors. Setup parameters of a result (``facet.*``, ``sphere.*``,
``dbb.*``, ``ball3d.*``) and the probe stylus offsets ``tip.x|y|z`` describe
the measurement, not the machine, and are never applied.
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _core, guards
from .guards import CorrectionLimitError, UnusableResultError
from .machine import Machine
from .progress import Progress
from .units import display_scale

__all__ = ["load_errors", "usable_errors", "compensate_poses", "CorrectionLimitError", "UnusableResultError",
           "MAX_CORRECTION", "MAX_CORRECTION_DEG", "CompensatedPoses", "compensate_gcode",
           "GcodeCompensation", "error_table", "write_error_table", "SIGN_CONVENTION"]

ROTARY = "ABC"
INCH = 25.4  # mm
#: Plausibility limits of a compensation, like the maximum-modification limit of
#: controller calibration cycles: a linear command corrected by more than
#: MAX_CORRECTION mm or a rotary one by more than MAX_CORRECTION_DEG degrees
#: stops compensation. Geometric errors of a machine in working order move the
#: tool by micrometres to some 0.1 mm; half a millimetre or more is far more
#: often a bad identification (wrong units, an unconverged or ill-posed fit)
#: than the machine, and a crash is the price of getting it wrong.
MAX_CORRECTION = 0.5
MAX_CORRECTION_DEG = 0.5


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------
def load_errors(source, machine: Machine) -> Dict[str, float]:
    """Machine error values (name -> mm / rad) from a result JSON file path, a
    result dict (``{"parameters": {name: {"value": ..}}}``), a plain dict name
    -> value or a :class:`fivecal.Result`. Setup parameters and the probe
    stylus offsets ``tip.*`` are dropped; an unknown machine parameter name is
    a ValueError naming it."""
    where = "errors"
    undetermined = set(guards.assess(source).undetermined)  # never exported as if measured
    if isinstance(source, (str, os.PathLike)):
        where = os.fspath(source)
        try:
            with open(where) as f:
                source = json.load(f)
        except OSError as e:
            raise ValueError(f"{where}: cannot read ({e.strerror})") from None
        except json.JSONDecodeError as e:
            raise ValueError(f"{where}: not valid JSON ({e.msg}, line {e.lineno})") from None
    if hasattr(source, "values") and hasattr(source, "estimated"):  # a Result
        source = dict(source.values)
    if not isinstance(source, Mapping):
        raise ValueError(f"{where}: expected a result JSON object or a mapping name -> value")
    if "parameters" in source and isinstance(source["parameters"], Mapping):
        flat = {}
        for name, p in source["parameters"].items():
            if isinstance(p, Mapping):
                if "value" not in p:
                    raise ValueError(f"{where}: parameters.{name}: 'value' missing")
                flat[name] = p["value"]
            else:
                flat[name] = p
        source = flat
    known = set(machine.parameter_names())
    out: Dict[str, float] = {}
    for name, value in source.items():
        if not isinstance(name, str):
            raise ValueError(f"{where}: parameter names must be strings, got {name!r}")
        if name.startswith("tip.") or ("." in name) or name in undetermined:
            continue  # probe stylus / setup parameters: not machine errors; undetermined: not measured
        if name not in known:
            raise ValueError(f"{where}: '{name}' is not a parameter of machine {machine.name!r} "
                             f"({machine.topology})")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: {name}: expected a number, got {value!r}") from None
        if not math.isfinite(v):
            raise ValueError(f"{where}: {name}: value is not finite")
        out[name] = v
    return out


def usable_errors(source, machine: Machine, force: bool = False,
                  what: str = "this identification result") -> Dict[str, float]:
    """:func:`load_errors` after the guard every consumer applies: a result
    that did not converge, holds non-finite values, failed the chi-square test
    or left requested parameters undetermined raises
    :class:`fivecal.UnusableResultError` with the reason, unless ``force``."""
    guards.require_usable(source, force, what)
    return load_errors(source, machine)


def _check_correction(machine: Machine, nominal: np.ndarray, commands: np.ndarray,
                      max_correction: Optional[float], max_correction_deg: Optional[float],
                      label=lambda i: f"pose {i}") -> None:
    """Raise CorrectionLimitError at the largest correction beyond a limit."""
    delta = np.abs(commands - nominal)
    worst = None
    for k, a in enumerate(machine.axis_names):
        if a == "S":
            continue
        limit, unit = (max_correction_deg, "deg") if a in ROTARY else (max_correction, "mm")
        if limit is None or not len(delta):
            continue
        i = int(np.argmax(delta[:, k]))
        excess = delta[i, k] / limit if limit > 0 else (np.inf if delta[i, k] > 0 else 0.0)
        if delta[i, k] > limit and (worst is None or excess > worst[0]):
            worst = (excess, i, a, float(delta[i, k]), float(limit), unit)
    if worst is not None:
        _, i, a, size, limit, unit = worst
        raise CorrectionLimitError(label(i), i, a, size, limit, unit)


def _with_tool_tip(machine: Machine, tool_tip) -> Machine:
    if tool_tip is None:
        return machine
    tip = np.asarray(tool_tip, dtype=float).reshape(-1)
    if tip.shape != (3,) or not np.all(np.isfinite(tip)):
        raise ValueError(f"tool_tip: expected three finite numbers (mm), got {tool_tip!r}")
    d = machine.to_dict()
    d.setdefault("tool", {})["tip"] = tip.tolist()
    return Machine.from_dict(d)


# ---------------------------------------------------------------------------
# poses
# ---------------------------------------------------------------------------
@dataclass
class CompensatedPoses:
    """Result of :func:`compensate_poses` (N poses).

    ``axes``: compensated commands, dict axis -> (N,) array (mm / degrees).
    ``nominal``: the nominal commands in the same form. ``points`` (N, 3) mm and
    ``tool_axes`` (N, 3): where the nominal machine puts the tool (workpiece
    frame). ``error_before`` (N, 3) mm: tool-point error of the erroneous machine
    at the nominal commands; ``remaining`` (N, 3) mm: tool-point error left at
    the compensated commands. ``axis_error_before`` / ``axis_error_remaining``
    (N,) rad: angle between the real and the nominal tool axis.
    ``orientation`` (N,) bool: True where the tool axis was compensated too,
    False where only the tool point was (next to a kinematic singularity, e.g.
    tool axis along the table axis, the tool axis cannot be corrected by a
    small rotary move; the rotary axes then keep their nominal values).
    """

    axes: Dict[str, np.ndarray]
    nominal: Dict[str, np.ndarray]
    points: np.ndarray
    tool_axes: np.ndarray
    error_before: np.ndarray
    remaining: np.ndarray
    axis_error_before: np.ndarray
    axis_error_remaining: np.ndarray
    orientation: np.ndarray

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def max_remaining(self) -> float:
        """Largest remaining tool-point error (mm)."""
        return float(np.linalg.norm(self.remaining, axis=1).max()) if len(self) else 0.0

    def max_before(self) -> float:
        """Largest tool-point error before compensation (mm)."""
        return float(np.linalg.norm(self.error_before, axis=1).max()) if len(self) else 0.0


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    c = np.cross(a, b)
    return np.arctan2(np.linalg.norm(c, axis=1), np.einsum("ij,ij->i", a, b))


def compensate_poses(machine: Union[Machine, Mapping], errors, axes: Mapping[str, Sequence[float]],
                     directions: Optional[Mapping[str, Sequence[float]]] = None,
                     orientation: bool = True, max_rotary_correction: float = 0.1,
                     tool_tip: Optional[Sequence[float]] = None,
                     progress: Optional[bool] = None,
                     max_correction: Optional[float] = MAX_CORRECTION,
                     max_correction_deg: Optional[float] = MAX_CORRECTION_DEG,
                     force: bool = False) -> CompensatedPoses:
    """Compensated axis commands for a list of nominal poses.

    ``axes``: nominal commands, dict axis letter -> array (mm, rotary in
    degrees; the spindle S defaults to 0). ``errors``: identified machine
    errors (a :class:`fivecal.Result`, a result JSON path or dict, or a dict
    name -> value in mm / rad). ``directions``: dict axis -> ±1 arrays, the
    direction each axis last moved (needed when the errors hold backlash).
    ``orientation``: also keep the tool axis on its nominal direction (default);
    where that needs a rotary correction larger than ``max_rotary_correction``
    degrees (next to a singularity) or has no solution, the pose falls back to
    tool point only and ``orientation[i]`` is False. ``tool_tip`` (mm): the
    cutting tool's tip in the machine frame at the zero pose, replacing the
    machine file's ``tool.tip``. Raises ValueError naming a pose whose tool
    point cannot be reached.

    Guards: a result that is not usable (see :meth:`fivecal.Result.usable`)
    raises :class:`fivecal.UnusableResultError` unless ``force``; parameters
    the data did not determine are left out. A compensated command that
    differs from the nominal one by more than ``max_correction`` mm (linear
    axes, default 0.5) or ``max_correction_deg`` degrees (rotary axes,
    default 0.5) raises :class:`fivecal.CorrectionLimitError` naming the pose,
    the axis and the size (None switches a limit off).
    """
    machine = _with_tool_tip(Machine.from_dict(machine), tool_tip)
    errs = usable_errors(errors, machine, force)
    q = machine.axes_matrix(axes)
    n, na = q.shape
    d = machine.directions_matrix(directions, n)
    theta = machine.theta(errs)
    zero = machine.theta(None)
    core = machine._core
    P, A = _core.tool_poses(core, zero, q, None)
    P0, A0 = _core.tool_poses(core, theta, q, d)
    rot = np.array([a in ROTARY for a in machine.axis_names])
    out = np.empty_like(q)
    oriented = np.zeros(n, dtype=bool)
    with Progress(n, "compensating poses", enabled=progress) as bar:
        for i in range(n):
            di = None if d is None else d[i:i + 1]
            sol = None
            if orientation:
                try:
                    c = _core.inverse(core, theta, P[i:i + 1], A[i:i + 1], q[i], di)[0]
                    if not rot.any() or np.abs(c[rot] - q[i, rot]).max() <= max_rotary_correction:
                        sol = c
                        oriented[i] = True
                except ValueError:
                    sol = None
            if sol is None:
                try:
                    sol = _core.inverse(core, theta, P[i:i + 1], None, q[i], di)[0]
                except ValueError as e:
                    raise ValueError(f"pose {i}: {e}") from None
            out[i] = sol
            bar.update()
    _check_correction(machine, q, out, max_correction, max_correction_deg)
    P1, A1 = _core.tool_poses(core, theta, out, d)
    return CompensatedPoses(axes=machine.axes_dict(out), nominal=machine.axes_dict(q), points=P,
                            tool_axes=A, error_before=P0 - P, remaining=P1 - P,
                            axis_error_before=_angle(A0, A), axis_error_remaining=_angle(A1, A),
                            orientation=oriented)


# ---------------------------------------------------------------------------
# G-code
# ---------------------------------------------------------------------------
_WORD = re.compile(r"([A-Za-z])[ \t]*([+-]?(?:\d+\.?\d*|\.\d+))")
_EXPR = re.compile(r"([XYZABCxyzabc])[ \t]*[=#\[]")
_MOTION_LINEAR = {0.0, 1.0}
_MOTION_ARC = {2.0, 3.0}
_CYCLES = {73.0, 74.0, 76.0, 81.0, 82.0, 83.0, 84.0, 85.0, 86.0, 87.0, 88.0, 89.0}
_NONMODAL_AXIS_WORDS = {4.0, 10.0, 28.0, 30.0, 53.0}  # axis words are not a G0/G1 target
_REFUSED = {92.0: "G92 (set position) changes the coordinate system",
            52.0: "G52 (local coordinate system) shifts the coordinates",
            68.0: "G68 (coordinate rotation) rotates the coordinates",
            68.2: "G68.2 (tilted working plane) transforms the coordinates",
            53.1: "G53.1 (tool axis control for a tilted plane) moves the rotary axes implicitly",
            43.4: "G43.4 (tool centre point control) means the words are tool-tip coordinates, "
                  "not axis commands",
            43.5: "G43.5 (tool centre point control) means the words are tool-tip coordinates, "
                  "not axis commands",
            51.0: "G51 (scaling) scales the coordinates"}


def _code_spans(text: str) -> List[Tuple[int, int]]:
    """(start, end) of the parts of a line outside ( ) and ; comments."""
    spans = []
    i, start, n = 0, 0, len(text)
    while i < n:
        ch = text[i]
        if ch == "(":
            spans.append((start, i))
            j = text.find(")", i + 1)
            i = n if j < 0 else j + 1
            start = i
            continue
        if ch == ";":
            spans.append((start, i))
            start = i = n
            break
        i += 1
    spans.append((start, n))
    return [(a, b) for a, b in spans if b > a]


@dataclass
class _Word:
    letter: str        # upper case
    raw_letter: str
    value: float
    start: int         # span of the number text in the line
    end: int
    decimals: int
    plus: bool


def _parse_words(text: str) -> List[_Word]:
    words = []
    for a, b in _code_spans(text):
        seg = text[a:b]
        for m in _WORD.finditer(seg):
            num = m.group(2)
            dec = len(num.split(".", 1)[1]) if "." in num else 0
            words.append(_Word(m.group(1).upper(), m.group(1), float(num), a + m.start(2), a + m.end(2),
                               dec, num.startswith("+")))
    return words


def _has_expression(text: str) -> Optional[str]:
    for a, b in _code_spans(text):
        m = _EXPR.search(text[a:b])
        if m:
            return m.group(0)
    return None


@dataclass
class _Move:
    line: int                      # 0-based line index
    words: Dict[str, _Word]        # axis words present on the line
    program: Dict[str, float]      # modal program values of every machine axis after the line
    insert_at: int                 # where missing axis words go (end of the last axis word)
    sep: str
    lower: bool
    inch: bool


@dataclass
class GcodeCompensation:
    """Result of :func:`compensate_gcode`.

    ``text``: the compensated program (str, same line endings as the input).
    ``moves``: number of G0/G1 moves compensated; ``changed_lines``: lines whose
    text changed; ``skipped``: (line number, reason) of moves left as written
    (an axis position not yet known from the program or ``start``);
    ``poses``: the :class:`CompensatedPoses` of the compensated moves, in order.
    ``written_error`` (moves, 3) mm: the tool-point error of the erroneous
    machine at the commands as written (after rounding to the output
    decimals), relative to the nominal target; ``lines``: the 1-based line
    number of each compensated move.
    """

    text: str
    moves: int
    changed_lines: int
    skipped: List[Tuple[int, str]] = field(default_factory=list)
    poses: Optional[CompensatedPoses] = None
    written_error: Optional[np.ndarray] = None
    lines: List[int] = field(default_factory=list)

    def max_written_error(self) -> float:
        """Largest tool-point error (mm) left by the written program."""
        if self.written_error is None or not len(self.written_error):
            return 0.0
        return float(np.linalg.norm(self.written_error, axis=1).max())

    def summary(self) -> str:
        p = self.poses
        s = (f"{self.moves} moves compensated, {self.changed_lines} lines changed")
        if p is not None and len(p):
            s += (f"; tool-point error {p.max_before() * 1e3:.2f} µm max before, "
                  f"{self.max_written_error() * 1e3:.2g} µm max after (as written, rounded to the "
                  f"output decimals)")
            n_pos = int((~p.orientation).sum())
            if n_pos:
                s += (f"; {n_pos} moves next to a singularity compensated for the tool point only "
                      f"(tool axis kept at the nominal rotary positions)")
        if self.skipped:
            s += f"; {len(self.skipped)} moves left as written (first: line {self.skipped[0][0]}: " \
                 f"{self.skipped[0][1]})"
        return s


def _fmt(value: float, decimals: int, plus: bool) -> str:
    s = f"{value:.{decimals}f}"
    if float(s) == 0.0:
        s = s.lstrip("-")
    if plus and not s.startswith("-"):
        s = "+" + s
    return s


def compensate_gcode(program: str, machine: Union[Machine, Mapping], errors,
                     start: Optional[Mapping[str, float]] = None,
                     work_offset: Optional[Mapping[str, float]] = None,
                     orientation: bool = True, max_rotary_correction: float = 0.1,
                     tool_tip: Optional[Sequence[float]] = None, min_decimals: int = 4,
                     name: str = "program", progress: Optional[bool] = None,
                     max_correction: Optional[float] = MAX_CORRECTION,
                     max_correction_deg: Optional[float] = MAX_CORRECTION_DEG,
                     force: bool = False) -> GcodeCompensation:
    """Compensate the G0/G1 moves of an ISO G-code program.

    The program's X Y Z words and the rotary words of the machine's rotary
    axes (A B C) are read as machine axis commands (mm, or inch after G20;
    degrees): machine command = word + ``work_offset`` (linear axes, mm).
    Each move's modal pose goes through :func:`compensate_poses` and the words
    are written back with the same number of decimals as the input word, at
    least ``min_decimals``; a word whose compensated value does not differ at
    that resolution is left exactly as written, and an axis the line does not
    name is added (after the line's last axis word) only when its compensated
    value differs from the value the controller holds. Backlash directions are
    taken from the sequence of moves. ``start``: axis positions before the
    first line (default: unknown; moves before every axis is known are left
    as written and listed in ``skipped``). ``name``: used in error messages.

    Refused with ValueError naming the line: incremental moves (G91), arcs
    (G2/G3), canned cycles (G73-G89), coordinate transformations (G92, G52,
    G68, G68.2, G51), tool centre point control (G43.4/G43.5), variables or
    expressions in axis words, rotary words of axes the machine does not have,
    and more than one work offset (G54-G59.x) in one program.

    Guards as in :func:`compensate_poses`: an unusable result is refused
    unless ``force``; a correction beyond ``max_correction`` mm /
    ``max_correction_deg`` degrees stops with a
    :class:`fivecal.CorrectionLimitError` naming the program line.
    """
    if not isinstance(program, str):
        raise ValueError(f"{name}: expected the program text (str)")
    machine = _with_tool_tip(Machine.from_dict(machine), tool_tip)
    errs = usable_errors(errors, machine, force)
    axis_letters = [a for a in machine.axis_names if a != "S"]
    offset = {a: 0.0 for a in axis_letters}
    for k, v in (work_offset or {}).items():
        if k not in axis_letters or k in ROTARY:
            raise ValueError(f"work_offset: '{k}' is not a linear axis of machine {machine.name!r}")
        offset[k] = float(v)
    modal: Dict[str, Optional[float]] = {a: None for a in axis_letters}  # program units
    for k, v in (start or {}).items():
        if k == "S":
            continue
        if k not in modal:
            raise ValueError(f"start: unknown axis '{k}' (machine axes {', '.join(axis_letters)})")
        modal[k] = float(v)
    spindle = float((start or {}).get("S", 0.0))

    lines = program.splitlines(keepends=True)
    motion: Optional[float] = None
    absolute = True
    g91_line = 0
    inch = False
    wcs: Optional[Tuple[str, int]] = None
    moves: List[_Move] = []
    skipped: List[Tuple[int, str]] = []
    decimals = {a: None for a in axis_letters}

    for li, raw in enumerate(lines):
        ln = li + 1
        text = raw.rstrip("\r\n")
        words = _parse_words(text)
        if not words:
            continue
        expr = _has_expression(text)
        if expr:
            raise ValueError(f"{name}:{ln}: axis word '{expr.strip()}…' uses a variable or expression; "
                             "only literal numbers can be compensated")
        gs = [w.value for w in words if w.letter == "G"]
        nonmodal_axis = False
        for g in gs:
            g = round(g, 1)
            if g in _REFUSED:
                raise ValueError(f"{name}:{ln}: {_REFUSED[g]}; compensation needs plain machine axis "
                                 "commands")
            if g in _MOTION_LINEAR or g in _MOTION_ARC or g in _CYCLES:
                motion = g
            elif g == 80.0:
                motion = None
            elif g == 90.0:
                absolute = True
            elif g == 91.0:
                absolute, g91_line = False, ln
            elif g == 20.0:
                inch = True
            elif g == 21.0:
                inch = False
            elif g in _NONMODAL_AXIS_WORDS:
                nonmodal_axis = True
            elif 54.0 <= g < 60.0:
                code = f"G{g:g}"
                if wcs is None:
                    wcs = (code, ln)
                elif wcs[0] != code:
                    raise ValueError(f"{name}:{ln}: work offset {code} after {wcs[0]} (line {wcs[1]}); "
                                     "compensate the parts of the program for each work offset separately")
        axis_words: Dict[str, _Word] = {}
        for w in words:
            if w.letter in "XYZABC":
                if w.letter not in axis_letters:
                    if w.letter in ROTARY and not nonmodal_axis:
                        raise ValueError(f"{name}:{ln}: rotary word {w.raw_letter} but machine "
                                         f"{machine.name!r} has no {w.letter} axis (axes "
                                         f"{', '.join(axis_letters)})")
                    continue
                if w.letter in axis_words:
                    raise ValueError(f"{name}:{ln}: axis word {w.letter} appears twice")
                axis_words[w.letter] = w
        if not axis_words:
            continue
        if nonmodal_axis:
            # G28/G30 (via a point to home), G53 (machine coordinates), G10, G4: left as
            # written; the axes they move end where the program does not say.
            for a in axis_words:
                modal[a] = None
            continue
        if motion is not None and motion in _MOTION_ARC:
            raise ValueError(f"{name}:{ln}: G{motion:g} arc moves are not supported; post the program "
                             "with linear moves (G1)")
        if motion is not None and motion in _CYCLES:
            raise ValueError(f"{name}:{ln}: canned cycle G{motion:g} is not supported; post the "
                             "program with explicit G0/G1 moves")
        if not absolute:
            raise ValueError(f"{name}:{ln}: incremental move (G91 set at line {g91_line}); only "
                             "absolute programs (G90) can be compensated")
        for a, w in axis_words.items():
            modal[a] = w.value
            decimals[a] = w.decimals
        unknown = [a for a in sorted(axis_letters, key="XYZABC".index) if modal[a] is None]
        if unknown:
            skipped.append((ln, f"position of {', '.join(unknown)} not known yet"))
            continue
        last = max(axis_words.values(), key=lambda w: w.end)
        first = min(axis_words.values(), key=lambda w: w.start)
        codes = [text[a:b] for a, b in _code_spans(text)]
        sep = " " if any(c in " \t" for c in "".join(codes).strip()) else ""
        moves.append(_Move(li, axis_words, {a: float(modal[a]) for a in axis_letters}, last.end, sep,
                           first.raw_letter.islower(), inch))

    result_lines = list(lines)
    if not moves:
        return GcodeCompensation(program, 0, 0, skipped, None)

    # Nominal machine commands (mm, degrees) and the backlash directions of the sequence.
    def to_machine(a: str, v: float, inch_mode: bool) -> float:
        if a in ROTARY:
            return v
        return (v * INCH if inch_mode else v) + offset[a]

    def to_program(a: str, v: float, inch_mode: bool) -> float:
        if a in ROTARY:
            return v
        v = v - offset[a]
        return v / INCH if inch_mode else v

    Q = {a: np.array([to_machine(a, mv.program[a], mv.inch) for mv in moves]) for a in axis_letters}
    if "S" in machine.axis_names:
        Q["S"] = np.full(len(moves), spindle)
    dirs = {}
    for a in axis_letters:
        d = np.zeros(len(moves))
        cur = 0.0
        prev = None
        for i, v in enumerate(Q[a]):
            if prev is not None and abs(v - prev) > 1e-9:
                cur = 1.0 if v > prev else -1.0
            d[i] = cur
            prev = v
        dirs[a] = d
    try:
        comp = compensate_poses(machine, errs, Q, directions=dirs, orientation=orientation,
                                max_rotary_correction=max_rotary_correction, progress=progress,
                                max_correction=max_correction, max_correction_deg=max_correction_deg)
    except CorrectionLimitError as e:
        raise e.at(f"{name}:{moves[e.index].line + 1}") from None

    # The values the controller holds, in program units, as the program is rewritten.
    held: Dict[str, Optional[float]] = {a: None for a in axis_letters}
    held_dec: Dict[str, int] = {a: min_decimals for a in axis_letters}
    written = np.zeros((len(moves), len(machine.axis_names)))
    mi = 0
    changed = 0
    move_at = {mv.line: i for i, mv in enumerate(moves)}
    # Replay the program to keep `held` in step with lines that are not compensated moves.
    for li, raw in enumerate(lines):
        if li not in move_at:
            words = _parse_words(raw.rstrip("\r\n"))
            gs = {round(w.value, 1) for w in words if w.letter == "G"}
            for w in words:
                if w.letter in held:
                    if gs & _NONMODAL_AXIS_WORDS:
                        held[w.letter] = None
                    else:
                        held[w.letter] = w.value
                        held_dec[w.letter] = max(w.decimals, min_decimals)
            continue
        mi = move_at[li]
        mv = moves[mi]
        text = raw.rstrip("\r\n")
        ending = raw[len(text):]
        edits: List[Tuple[int, int, str]] = []
        inserts: List[str] = []
        for a in sorted(axis_letters, key="XYZABC".index):
            v = to_program(a, float(comp.axes[a][mi]), mv.inch)
            if a in mv.words:
                w = mv.words[a]
                dec = max(w.decimals, min_decimals)
                held_dec[a] = dec
                if abs(v - w.value) < 0.5 * 10.0 ** (-dec):
                    held[a] = w.value
                    continue
                s = _fmt(v, dec, w.plus)
                edits.append((w.start, w.end, s))
                held[a] = float(s)
            else:
                dec = held_dec[a]
                h = held[a] if held[a] is not None else mv.program[a]
                if abs(v - h) < 0.5 * 10.0 ** (-dec):
                    continue
                s = _fmt(v, dec, False)
                inserts.append(mv.sep + (a.lower() if mv.lower else a) + s)
                held[a] = float(s)
        for k, a in enumerate(machine.axis_names):
            if a == "S":
                written[mi, k] = spindle
            else:
                h = held[a] if held[a] is not None else mv.program[a]
                written[mi, k] = to_machine(a, h, mv.inch)
        if not edits and not inserts:
            continue
        new = text
        if inserts:
            new = new[:mv.insert_at] + "".join(inserts) + new[mv.insert_at:]
        for s0, e0, s in sorted(edits, reverse=True):
            new = new[:s0] + s + new[e0:]
        result_lines[li] = new + ending
        changed += 1
    d = machine.directions_matrix(dirs, len(moves))
    real = _core.tool_poses(machine._core, machine.theta(errs), written, d)[0]
    return GcodeCompensation("".join(result_lines), len(moves), changed, skipped, comp,
                             written_error=real - comp.points, lines=[mv.line + 1 for mv in moves])


def compensate_gcode_file(path: Union[str, os.PathLike], out: Union[str, os.PathLike], machine, errors,
                          **kwargs) -> GcodeCompensation:
    """:func:`compensate_gcode` from file to file. Bytes outside the changed
    numbers are copied unchanged (the file is read and written as Latin-1,
    which maps every byte to itself). The guards of :func:`compensate_gcode`
    (``force``, ``max_correction``, ``max_correction_deg``) apply before
    anything is written."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            text = f.read().decode("latin-1")
    except OSError as e:
        raise ValueError(f"{path}: cannot read ({e.strerror})") from None
    res = compensate_gcode(text, machine, errors, name=path, **kwargs)
    with open(os.fspath(out), "wb") as f:
        f.write(res.text.encode("latin-1"))
    return res


# ---------------------------------------------------------------------------
# controller-neutral error table
# ---------------------------------------------------------------------------
SIGN_CONVENTION = [
    "Sign convention (fivecal machine model; README, Sign conventions):",
    "Every axis k has a frame that is parallel to the machine frame F when all axes are at 0 (the zero "
    "pose), with its origin at the axis point p_k of the machine file.",
    "Chains are built from the foundation outward (workpiece side and tool side separately); the parent "
    "of axis k is the next axis toward the foundation (the foundation itself for the first axis).",
    "T_k(q) = Trans(p_k - p_parent) * E_k * M_k(q + Ekkb*dir) * e_k(q), with the location errors "
    "E_k = Trans(EX0k, EY0k, EZ0k) * Rz(EC0k) * Ry(EB0k) * Rx(EA0k).",
    "Location errors: a positive EX0k (EY0k, EZ0k) means axis k and everything it carries sit "
    "+value mm along x (y, z) of the parent axis frame (= F at the zero pose) from their nominal place; "
    "a positive EA0k (EB0k, EC0k) means they are rotated by +value rad about x (y, z) of that frame "
    "through the axis point p_k, right-hand rule (rotations about fixed axes: first x, then y, then z).",
    "On the workpiece side this displaces the workpiece, so the tool point seen from the workpiece "
    "moves the opposite way (a positive EX0C on a rotary table puts the tool at -x on the part); on the "
    "tool side it displaces the tool.",
    "Error motions: E{D}{k}{d} is the coefficient of q^d (q in mm for a linear axis, rad for a rotary "
    "axis) in the error motion along (D = X, Y, Z, mm) or about (D = A, B, C, rad) the axes of F; for "
    "an axis that moves along a negative basis vector a positive E{k}{k}1 shortens the travel.",
    "Backlash: Ekkb (mm or rad) is added to the command in the direction dir = +1/-1 the axis last moved.",
    "Values are in mm (linear) and rad (angular); display_value/display_std repeat them in µm, µrad, "
    "µm/m. std is the one-sigma standard uncertainty; an empty std means the value was fixed, not "
    "estimated.",
]


def _describe(machine: Machine, name: str) -> Tuple[str, str, str, str]:
    """(kind, axis, component, description)."""
    kind = machine.parameter_kind(name)
    comp = name[1]
    axis = name[3] if kind == "location" else name[2]
    chains = [machine.workpiece_chain, machine.tool_chain]
    parent = "the foundation"
    for ch in chains:
        if axis in ch:
            i = ch.index(axis)
            parent = f"axis {ch[i - 1]}" if i > 0 else "the foundation"
    dirname = {"X": "along x", "Y": "along y", "Z": "along z", "A": "about x", "B": "about y",
               "C": "about z"}[comp]
    if kind == "location":
        desc = f"location of axis {axis} relative to {parent}: {'offset' if comp in 'XYZ' else 'tilt'} " \
               f"{dirname} of F"
    elif kind == "motion":
        deg = name[3]
        var = "rad" if axis in "ABCS" else "mm"
        desc = f"error motion of axis {axis} {dirname} of F, coefficient of q^{deg} (q in {var})"
        a = next((x for x in machine.axes if x["name"] == axis), None)
        if a is not None and comp == axis and deg == "1" and min(a["direction"]) < -0.5 \
                and max(a["direction"]) < 0.5:
            desc += "; axis moves along a negative basis vector: positive shortens the travel"
    elif kind == "backlash":
        desc = f"backlash of axis {axis}, added to the command in the direction of the last move"
    else:
        desc = kind
    return kind, axis, comp, desc


def error_table(result, machine: Union[Machine, Mapping],
                kinds: Sequence[str] = ("location",), force: bool = False) -> List[dict]:
    """Rows (dicts) of the identified machine errors of the given ``kinds``
    (``location``, ``motion``, ``backlash``), in the machine's parameter order:
    name, kind, axis, component, value and std (mm or rad), unit, display_value,
    display_std, display_unit, estimated, description. ``result``: a Result, a
    result JSON path or dict. An unusable result raises
    :class:`fivecal.UnusableResultError` unless ``force``; parameters the data
    did not determine are left out (:func:`write_error_table` names them)."""
    machine = Machine.from_dict(machine)
    std: Dict[str, float] = {}
    if isinstance(result, (str, os.PathLike)):
        path = os.fspath(result)
        try:
            with open(path) as f:
                result = json.load(f)
        except OSError as e:
            raise ValueError(f"{path}: cannot read ({e.strerror})") from None
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}: not valid JSON ({e.msg}, line {e.lineno})") from None
    guards.require_usable(result, force, "this identification result")
    if hasattr(result, "std") and hasattr(result, "estimated"):
        std = dict(result.std)
    elif isinstance(result, Mapping) and isinstance(result.get("parameters"), Mapping):
        for n, p in result["parameters"].items():
            if isinstance(p, Mapping) and p.get("std") is not None:
                std[n] = float(p["std"])
    values = load_errors(result, machine)
    for k in kinds:
        if k not in ("location", "motion", "backlash"):
            raise ValueError(f"kinds: '{k}' is not one of location, motion, backlash")
    rows = []
    for name in machine.parameter_names():
        if name not in values:
            continue
        kind, axis, comp, desc = _describe(machine, name)
        if kind not in kinds:
            continue
        f, dunit = display_scale(name)
        angular = machine.parameter_is_angular(name)
        s = std.get(name)
        rows.append({"name": name, "kind": kind, "axis": axis, "component": comp,
                     "value": values[name], "std": s, "unit": "rad" if angular else "mm",
                     "display_value": values[name] * f, "display_std": None if s is None else s * f,
                     "display_unit": dunit, "estimated": s is not None, "description": desc})
    return rows


def write_error_table(path: Union[str, os.PathLike], result, machine: Union[Machine, Mapping],
                      kinds: Sequence[str] = ("location",), force: bool = False) -> List[dict]:
    """Write :func:`error_table` to ``path``: JSON when it ends in ``.json``,
    otherwise CSV with the sign convention as leading ``#`` comment lines.
    Parameters the data did not determine are left out and named in the
    header (JSON ``not_determined``); an unusable result is refused unless
    ``force``, and a forced table says so in its header (JSON ``usable``)."""
    machine = Machine.from_dict(machine)
    if isinstance(result, (str, os.PathLike)):
        src = os.fspath(result)
        try:
            with open(src) as f:
                result = json.load(f)
        except OSError as e:
            raise ValueError(f"{src}: cannot read ({e.strerror})") from None
        except json.JSONDecodeError as e:
            raise ValueError(f"{src}: not valid JSON ({e.msg}, line {e.lineno})") from None
    rows = error_table(result, machine, kinds, force=force)
    a = guards.assess(result)
    known = set(machine.parameter_names())
    left_out = [n for n in a.undetermined if n in known and not n.startswith("tip.")
                and machine.parameter_kind(n) in kinds]
    path = os.fspath(path)
    head = [f"fivecal machine errors: {machine.name} ({machine.topology}); kinds: {', '.join(kinds)}"]
    if left_out:
        head.append("Not determined by the measurement, left out of this table (their values were "
                    "arbitrary, not measured): " + ", ".join(left_out))
    if not a.usable:
        head.append(f"NOT USABLE, written only because it was forced: {a.reason}")
    if a.implausible:
        head.append("Implausible (far outside the plausible size; check before use): "
                    + ", ".join(a.implausible))
    if path.lower().endswith(".json"):
        doc = {"format": "fivecal-error-table", "version": 1, "machine": machine.name,
               "topology": machine.topology, "kinds": list(kinds),
               "usable": a.usable, "verdict": a.verdict, "not_determined": left_out,
               "notes": head[1:],
               "convention": SIGN_CONVENTION, "errors": rows}
        with open(path, "w") as f:
            json.dump(doc, f, indent=1, ensure_ascii=False)
            f.write("\n")
        return rows
    import csv

    cols = ["name", "kind", "axis", "component", "value", "std", "unit", "display_value", "display_std",
            "display_unit", "estimated", "description"]
    with open(path, "w", newline="", encoding="utf-8") as f:
        for line in head + SIGN_CONVENTION:
            f.write(f"# {line}\n")
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow(["" if r[c] is None else (repr(r[c]) if isinstance(r[c], float) else r[c])
                        for c in cols])
    return rows
