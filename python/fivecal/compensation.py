"""Compensation: from identified errors back to the machine.

Three outputs, all computed on the erroneous model of fivecal (README, "Concepts"):

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

import math
import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _core, files, gcode, guards, schema
from .guards import CorrectionLimitError, UnusableResultError
from .machine import Machine
from .progress import Progress
from .units import display_scale

__all__ = ["load_errors", "usable_errors", "compensate_poses", "CorrectionLimitError", "UnusableResultError",
           "MAX_CORRECTION", "MAX_CORRECTION_DEG", "CompensatedPoses", "compensate_gcode",
           "GcodeCompensation", "error_table", "write_error_table", "SIGN_CONVENTION"]

ROTARY = "ABC"
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
def load_errors(source, machine: Machine, tool_offset: bool = False) -> Dict[str, float]:
    """Machine error values (name -> mm / rad) from a result JSON file path, a
    result dict (``{"parameters": {name: {"value": ..}}}``), a plain dict name
    -> value or a :class:`fivecal.Result`. Setup parameters are dropped, and
    so are the probe stylus offsets ``tip.*`` unless ``tool_offset``: G-code
    compensation and LinuxCNC pins must not take a stylus offset for a
    machine error, while a controller vendor's export takes its length along
    the spindle as the tool length (the core's ``ExportToVendor`` keeps only
    that component). An unknown machine parameter name is a ValueError
    naming it."""
    where = "errors"
    undetermined = set(guards.assess(source).undetermined)  # never exported as if measured
    if isinstance(source, (str, os.PathLike)):
        where = os.fspath(source)
        source = schema.validate(files.read_json(where, "result"), "errors", where)
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
        if name in undetermined or ("." in name and not (tool_offset and name.startswith("tip."))):
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
                  what: str = "this identification result", tool_offset: bool = False) -> Dict[str, float]:
    """:func:`load_errors` (``tool_offset`` as there) after the guard every consumer applies: a result
    that did not converge, holds non-finite values, failed the chi-square test
    or left requested parameters undetermined raises
    :class:`fivecal.UnusableResultError` with the reason, unless ``force``."""
    if isinstance(source, (str, os.PathLike)):
        # a malformed file is bad input whatever its verdict: name the bad key
        # first, not a refusal that --force would only trade for it
        schema.validate(files.read_json(os.fspath(source), "result"), "errors", os.fspath(source))
    guards.require_usable(source, force, what)
    return load_errors(source, machine, tool_offset)


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
                     force: bool = False, reference_theta: Optional[np.ndarray] = None,
                     reference_shift: Optional[Sequence[float]] = None) -> CompensatedPoses:
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

    ``reference_theta`` (a full parameter vector) and ``reference_shift``
    (mm): the targets are where a machine with those parameters puts the tool
    (and its axis), shifted by ``reference_shift``, instead of the nominal
    machine: a controller that already runs a corrected kinematic model
    (fivecal.io.controllers).
    """
    machine = _with_tool_tip(Machine.from_dict(machine), tool_tip)
    errs = usable_errors(errors, machine, force)
    q = machine.axes_matrix(axes)
    n, na = q.shape
    d = machine.directions_matrix(directions, n)
    theta = machine.theta(errs)
    zero = machine.theta(None)
    core = machine._core
    ref = zero if reference_theta is None else np.asarray(reference_theta, dtype=float)
    P, A = _core.tool_poses(core, ref, q, None)
    if reference_shift is not None:
        P = P + np.asarray(reference_shift, dtype=float).reshape(1, 3)
    P0, A0 = _core.tool_poses(core, theta, q, d)
    # one core call over every pose (CompensateCommands), each seeded at its nominal commands
    with Progress(n, "compensating poses", enabled=progress) as bar:
        out, oriented = _core.compensate_commands(core, theta, P, A, q, d, orientation,
                                                  float(max_rotary_correction))
        bar.update(n)
    oriented = np.asarray(oriented, dtype=bool)
    _check_correction(machine, q, out, max_correction, max_correction_deg)
    P1, A1 = _core.tool_poses(core, theta, out, d)
    return CompensatedPoses(axes=machine.axes_dict(out), nominal=machine.axes_dict(q), points=P,
                            tool_axes=A, error_before=P0 - P, remaining=P1 - P,
                            axis_error_before=_angle(A0, A), axis_error_remaining=_angle(A1, A),
                            orientation=oriented)


def origin_shift(machine: Union[Machine, Mapping], errors, axes: Mapping[str, Sequence[float]],
                 directions: Optional[Mapping[str, Sequence[float]]] = None, **options) -> CompensatedPoses:
    """Compensation by shifting the work origin, pose by pose, as Wang et al.
    (2013, Section 5.2) do through the controller's external origin shift:
    the rotary commands stay as programmed and only the linear axes move, by
    the shift that puts the tool point back on its nominal place. The tool
    axis keeps the rotary axes' angular errors (``axis_error_remaining``);
    :func:`compensate_poses` corrects both. The shift of pose i is
    ``axes[a][i] - nominal[a][i]`` for the linear axes a. Options as
    :func:`compensate_poses` (guards, limits, tool tip)."""
    options.pop("orientation", None)
    return compensate_poses(machine, errors, axes, directions, orientation=False, **options)


# ---------------------------------------------------------------------------
# G-code (reader and writer in gcode.py)
# ---------------------------------------------------------------------------
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

    Units: G20/G70 inch, G21/G71 mm; each word is converted with the unit
    mode of its own line and positions are held in mm, so a unit switch never
    reinterprets a held position; a linear word on an inch line gets at least
    ``min_decimals`` + 1 decimals (the same resolution). ``start`` is in
    program coordinates in mm.

    Refused with ValueError naming the line (``name:N: ... (line N: text)``):
    incremental moves (G91), arcs (G2/G3), canned cycles (G73-G89), coordinate
    transformations (G92, G52, G68, G68.2, G51, G51.1, G16, G7.1, G12.1),
    offset changes (G10), macro and subprogram calls (G65, G66, M98, M99),
    tool centre point control (G43.4/G43.5), variables or expressions,
    rotary words of axes the machine does not have, more than one work offset
    (G54-G59.x) in one program, and text that is not ISO words: exponent
    notation (``X1e2``), a letter without a number, a number without a
    letter, numbers of more than 15 digits, an unclosed ``(`` comment.

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
    for k in (start or {}):
        if k != "S" and k not in axis_letters:
            raise ValueError(f"start: unknown axis '{k}' (machine axes {', '.join(axis_letters)})")
    spindle = float((start or {}).get("S", 0.0))
    prog = gcode.read_program(program, axis_letters, machine.name, offset,
                              {k: v for k, v in (start or {}).items() if k != "S"}, name)
    moves = prog.moves
    if not moves:
        return GcodeCompensation(program, 0, 0, prog.skipped, None)

    # Nominal machine commands (mm, degrees) and the backlash directions of the sequence.
    Q = {a: np.array([mv.pose[a] for mv in moves]) for a in axis_letters}
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
    except ValueError as e:
        m = re.match(r"pose (\d+): (.*)", str(e), re.S)
        if m is None:
            raise
        mv = moves[int(m.group(1))]
        raise ValueError(f"{name}:{mv.line + 1}: cannot compensate this move: {m.group(2)} "
                         f"(line {mv.line + 1}: {prog.lines[mv.line].strip()[:60]})") from None
    text, changed, held = gcode.write_program(prog, comp.axes, min_decimals)
    written = np.array([held[a] if a != "S" else [spindle] * len(moves) for a in machine.axis_names]).T
    d = machine.directions_matrix(dirs, len(moves))
    real = _core.tool_poses(machine._core, machine.theta(errs), written, d)[0]
    return GcodeCompensation(text, len(moves), changed, prog.skipped, comp,
                             written_error=real - comp.points, lines=[mv.line + 1 for mv in moves])


def compensate_gcode_file(path: Union[str, os.PathLike], out: Union[str, os.PathLike], machine, errors,
                          **kwargs) -> GcodeCompensation:
    """:func:`compensate_gcode` from file to file. Bytes outside the changed
    numbers are copied unchanged (the file is read and written as Latin-1,
    which maps every byte to itself). The guards of :func:`compensate_gcode`
    (``force``, ``max_correction``, ``max_correction_deg``) apply before
    anything is written."""
    path = os.fspath(path)
    files.check_outputs([("program", path)], [("out", out)])
    text = files.read_bytes(path, "G-code program").decode("latin-1")
    res = compensate_gcode(text, machine, errors, name=path, **kwargs)
    files.write_bytes(out, res.text.encode("latin-1"))
    return res


# ---------------------------------------------------------------------------
# controller-neutral error table
# ---------------------------------------------------------------------------
SIGN_CONVENTION = [
    "Sign convention (fivecal machine model; `fivecal docs readme`, Sign conventions):",
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
        result = schema.validate(files.read_json(result, "result"), "errors", os.fspath(result))
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
        result = schema.validate(files.read_json(src, "result"), "errors", src)
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
        files.write_json(path, doc, ensure_ascii=False)
        return rows
    import csv
    import io

    cols = ["name", "kind", "axis", "component", "value", "std", "unit", "display_value", "display_std",
            "display_unit", "estimated", "description"]
    f = io.StringIO(newline="")
    for line in head + SIGN_CONVENTION:
        f.write(f"# {line}\n")
    w = csv.writer(f)
    w.writerow(cols)
    for r in rows:
        w.writerow(["" if r[c] is None else (repr(r[c]) if isinstance(r[c], float) else r[c])
                    for c in cols])
    files.write_text(path, f.getvalue())
    return rows
