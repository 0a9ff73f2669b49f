"""From identified errors to a LinuxCNC machine (docs/linuxcnc.md).

* ``absorb``: the values of the ``xyzac-trt-kins`` / ``xyzbc-trt-kins`` HAL
  pins (``x|y|z-rot-point``, ``x|y-offset``, ``z-offset``, ``tool-offset``)
  that best absorb the identified errors over a working volume, and the
  volumetric error LinuxCNC leaves after them (the kinematics model itself is
  in the C++ core: ``cpp/include/fivecal/controllers/linuxcnc_trt.h``).
* ``hal_text`` / ``ini_text``: the lines that set those pins, old and new side
  by side; ``check_change`` refuses implausibly large changes.
* ``comp_rows`` / ``comp_text``: joint compensation files (``COMP_FILE``,
  type 0: nominal, forward, reverse) for a linear axis's positioning error
  along itself (``EXX1..3`` for X) and its backlash (``EXXb``).
* ``export``: all of it into a folder, behind the usable-result guard.

Units: mm, degrees for rotary joints; error parameters in mm and rad.
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .. import _core, files
from ..compensation import usable_errors
from ..files import read_text as _read_text
from ..guards import CorrectionLimitError
from ..machine import Machine
from . import controllers as K
from . import hal
from . import nc_options as O
from .controllers import region_stats

KINS = ("xyzac-trt", "xyzbc-trt")
TILT = {"xyzac-trt": "A", "xyzbc-trt": "B"}
#: default plausibility limit on a pin change (mm): rotary pivots of a built
#: machine are off by tens of micrometres; a millimetre is a unit or sign slip
DEFAULT_MAX_CHANGE = 0.5
#: default plausibility limit on an angular change (rad) of a controller
#: model (``fivecal export kinematics``): axis directions of a built machine
#: are off by tens of microradians; a milliradian (1 mm/m) is a slip
DEFAULT_MAX_CHANGE_RAD = 1e-3
#: default working volume of the absorption fit
DEFAULT_VOLUME = {"linear": (-100.0, 100.0), "tilt": (-90.0, 90.0), "C": (-180.0, 180.0)}


def _kins(kins: str) -> str:
    k = kins[:-5] if kins.endswith("-kins") else kins
    if k not in KINS:
        raise ValueError(f"kins: '{kins}' (expected {' or '.join(KINS)})")
    return k


def pin_names(kins: str) -> List[str]:
    """The HAL input pins of ``<kins>-kins`` fivecal sets, in a fixed order."""
    return list(_core.trt_pin_names(_kins(kins)))


def match(machine: Machine, kins: str) -> dict:
    """How ``machine`` drives LinuxCNC's joints X Y Z tilt C: ``axes`` (the
    fivecal axis letters), ``sign`` (joint = sign * fivecal command) and
    ``origin`` (LinuxCNC world = workpiece point - origin - workpiece shift).
    ValueError says why when the machine does not fit the kinematics."""
    return dict(_core.trt_match(machine._core, _kins(kins)))


def joints(machine: Machine, kins: str, axes: Mapping) -> np.ndarray:
    """LinuxCNC joint values (N, 5: X Y Z tilt C) for fivecal axis commands."""
    return np.asarray(_core.trt_joints(machine._core, _kins(kins), machine.axes_matrix(axes)))


def commands(machine: Machine, kins: str, joint_values) -> dict:
    """fivecal axis commands (dict axis -> array) for LinuxCNC joint values (N, 5)."""
    j = np.atleast_2d(np.asarray(joint_values, dtype=float))
    return machine.axes_dict(np.asarray(_core.trt_commands(machine._core, _kins(kins), j)))


def inverse(kins: str, pins: Mapping[str, float], world) -> np.ndarray:
    """LinuxCNC's own inverse kinematics (LinuxCNC 2.9 trtfuncs.c): world rows
    (X Y Z mm, tilt C degrees) -> joint rows."""
    w = np.atleast_2d(np.asarray(world, dtype=float))
    return np.asarray(_core.trt_inverse(_kins(kins), dict(pins), w))


def forward(kins: str, pins: Mapping[str, float], joint_values) -> np.ndarray:
    """LinuxCNC's forward kinematics: joint rows -> world X Y Z rows (mm)."""
    j = np.atleast_2d(np.asarray(joint_values, dtype=float))
    return np.asarray(_core.trt_forward(_kins(kins), dict(pins), j))


def pose_grid(machine: Machine, kins: str, volume: Optional[Mapping[str, Tuple[float, float]]] = None,
              n_linear: int = 3, n_tilt: int = 7, n_c: int = 12) -> dict:
    """Poses over a working volume: a grid of linear positions times a grid of
    tilt and C angles (fivecal commands, dict axis -> array). ``volume`` maps
    axis letters to (min, max) in mm / degrees; missing axes take
    DEFAULT_VOLUME (linear +-100 mm, tilt -90..90 deg, C a full turn)."""
    k = _kins(kins)
    volume = dict(volume or {})
    tilt = TILT[k]
    unknown = [a for a in volume if a not in ("X", "Y", "Z", tilt, "C")]
    if unknown:
        raise ValueError(f"volume: axis {', '.join(unknown)} is not an axis of {k} (X Y Z {tilt} C)")

    def rng(a, default, n):
        lo, hi = (float(v) for v in volume.get(a, default))
        if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
            raise ValueError(f"volume.{a}: expected min <= max, got {lo}..{hi}")
        if a == "C" and hi - lo >= 360.0:
            return np.linspace(lo, hi, n, endpoint=False)
        return np.linspace(lo, hi, n)

    grids = [rng(a, DEFAULT_VOLUME["linear"], n_linear) for a in "XYZ"]
    grids.append(rng(tilt, DEFAULT_VOLUME["tilt"], n_tilt))
    grids.append(rng("C", DEFAULT_VOLUME["C"], n_c))
    mesh = [g.ravel() for g in np.meshgrid(*grids, indexing="ij")]
    return dict(zip(("X", "Y", "Z", tilt, "C"), mesh))


@dataclass
class Absorption:
    """What LinuxCNC's trt kinematics absorbs of identified errors."""

    kins: str
    pins: Dict[str, float]               # new pin values (mm)
    old_pins: Dict[str, float]           # the pins before (the nominal geometry by default)
    solved: List[str]                    # pins fitted; the others are held at their old values
    workpiece_shift: np.ndarray          # (3,) mm: the part frame's offset; the work offset absorbs it
    residual: np.ndarray                 # (N, 3) mm: tool point error left with the new pins
    residual_old: np.ndarray             # (N, 3) mm: the same with the old pins
    poses: dict = field(repr=False)      # the fivecal commands the fit used
    rms: float = 0.0
    max: float = 0.0
    rms_old: float = 0.0
    max_old: float = 0.0
    rms_compensated: Optional[float] = None   # with fivecal's G-code compensation on top
    max_compensated: Optional[float] = None
    model: Optional[K.Absorption] = field(default=None, repr=False)  # the same pins in fivecal's parameters

    def changes(self) -> Dict[str, float]:
        return {n: self.pins[n] - self.old_pins.get(n, 0.0) for n in self.pins}

    def by_region(self, axis: str, bins: int = 4) -> List[Tuple[float, float, float, float]]:
        """Residual |e| by region of one axis: (lo, hi, rms, max) per bin, mm."""
        return region_stats(self.poses, self.residual, axis, bins)

    def report(self) -> str:
        lines = [f"LinuxCNC {self.kins}-kins: pins that best absorb the identified errors",
                 pins_table(self.old_pins, self.pins),
                 "workpiece shift (probe the part again into the work offset): "
                 + ", ".join(f"{a} {1000 * v:+.1f} um" for a, v in zip("XYZ", self.workpiece_shift)),
                 f"tool point error the pins leave over {len(self.residual)} poses: old pins rms "
                 f"{1000 * self.rms_old:.2f} um, max {1000 * self.max_old:.2f} um; new pins rms "
                 f"{1000 * self.rms:.2f} um, max {1000 * self.max:.2f} um",
                 *([f"with fivecal's G-code compensation on top (fivecal compensate): rms "
                    f"{1000 * self.rms_compensated:.3f} um, max {1000 * self.max_compensated:.3f} um"]
                   if self.rms_compensated is not None else []),
                 "what the pins cannot absorb (axis tilts, error motions, backlash) is left: "
                 "fivecal compensate removes it from a program"]
        return "\n".join(lines)


def tool_point_error(machine: Machine, kins: str, errors, pins: Mapping[str, float],
                     workpiece_shift, joint_values, world) -> np.ndarray:
    """(N, 3) mm: where the erroneous machine puts the tool when LinuxCNC
    commands ``joint_values`` (N, 5) for the world targets ``world`` (N, 3),
    minus the target in the workpiece frame (world + tool tip + workpiece shift).
    With ``joint_values = inverse(kins, pins, ...)`` this is the error fivecal
    predicts the controller leaves."""
    j = np.atleast_2d(np.asarray(joint_values, dtype=float))
    mp = match(machine, kins)
    p = machine.tool_point(commands(machine, kins, j), errors=errors)
    target = np.atleast_2d(np.asarray(world, dtype=float))[:, :3] + np.asarray(mp["origin"]) \
        + np.asarray(workpiece_shift, dtype=float)
    return p - target


def nominal_pins(machine: Machine, kins: str, held: Optional[Mapping[str, float]] = None,
                 poses: Optional[Mapping] = None) -> Dict[str, float]:
    """The pins of the machine's nominal geometry (z-offset and tool-offset
    held at ``held``, default 0)."""
    k = _kins(kins)
    poses = poses if poses is not None else pose_grid(machine, k)
    q = machine.axes_matrix(poses)
    fit = _core.trt_fit(machine._core, k, machine.theta(None), q, dict(held or {}))
    return {n: float(fit["pins"][n]) for n in pin_names(k)}


def absorb(machine: Machine, kins: str, errors=None, poses: Optional[Mapping] = None,
           old_pins: Optional[Mapping[str, float]] = None) -> Absorption:
    """Pins of ``<kins>-kins`` that best absorb ``errors`` (dict name -> mm/rad
    or a Result) over ``poses`` (fivecal commands; default :func:`pose_grid`).
    ``old_pins`` are the controller's current values (default: the machine's
    nominal geometry); z-offset and tool-offset keep their old values. One
    call of the core's controller absorber (:func:`fivecal.io.controllers.absorb`,
    which fits the pins through trtfuncs.c's kinematics and the same model
    in fivecal's parameters: :attr:`Absorption.model`)."""
    k = _kins(kins)
    poses = poses if poses is not None else pose_grid(machine, k)
    q = machine.axes_matrix(poses)
    if old_pins is None:
        old_pins = nominal_pins(machine, k, poses=poses)
    old = {n: float(old_pins.get(n, 0.0)) for n in pin_names(k)}
    kab = K.absorb(machine, k, errors, poses=poses, held_pins=old)
    fit = kab.pins_fit
    pins = {n: float(fit["pins"][n]) for n in pin_names(k)}
    return Absorption(kins=k, pins=pins, old_pins=old, solved=list(fit["solved"]),
                      workpiece_shift=np.asarray(fit["workpiece_shift"]),
                      residual=np.asarray(fit["residual"]), residual_old=np.asarray(fit["residual_held"]),
                      poses=machine.axes_dict(q), rms=fit["rms"], max=fit["max"],
                      rms_old=fit["rms_held"], max_old=fit["max_held"], model=kab)


# ---- pins: text, comparison, plausibility ---------------------------------

def pins_table(old: Mapping[str, float], new: Mapping[str, float]) -> str:
    """Old and new values side by side (mm)."""
    rows = [f"{'pin':<14}{'old mm':>16}{'new mm':>16}{'change um':>12}"]
    for n in new:
        o = float(old.get(n, 0.0))
        rows.append(f"{n:<14}{o:>16.6f}{new[n]:>16.6f}{1000 * (new[n] - o):>+12.2f}")
    return "\n".join(rows)


class ChangeLimitError(CorrectionLimitError):
    """A controller value would change by more than the plausibility limit
    (``--max-change``)."""

    def __init__(self, where: str, name: str, size: float, limit: float, unit: str):
        self.where, self.index, self.axis, self.size, self.limit, self.unit = where, 0, name, size, limit, unit
        ValueError.__init__(
            self, f"{where}: {name} would change by {size:.4g} {unit}, more than the plausibility limit of "
            f"{limit:g} {unit} (--max-change; 'off' switches it off); a change this large is more likely a unit "
            "or sign slip or a bad identification than the machine: check the result, or raise --max-change if "
            "the machine really is that far off")


def default_max_change() -> Dict[str, float]:
    """The plausibility limits by unit when ``--max-change`` gives none."""
    return {"mm": DEFAULT_MAX_CHANGE, "rad": DEFAULT_MAX_CHANGE_RAD}


def parse_max_change(text: str, angular: bool = False) -> Optional[Dict[str, float]]:
    """``--max-change`` as limits by unit: ``MM`` (and, with ``angular``,
    ``MM,RAD``; the other keeps its default) or ``off`` (None)."""
    if str(text).strip().lower() == "off":
        return None
    parts = [t.strip() for t in str(text).split(",")]
    form = "MM,RAD" if angular else "MM"
    limits = default_max_change()
    if len(parts) > (2 if angular else 1):
        raise ValueError(f"--max-change: expected {form} or 'off', got '{text}'")
    for unit, t in zip(("mm", "rad"), parts):
        try:
            v = float(t)
        except ValueError:
            raise ValueError(f"--max-change: '{t}' is not a number of {unit} ({form} or 'off')") from None
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"--max-change: expected a positive number of {unit}, got {t}")
        limits[unit] = v
    return limits


def check_changes(where: str, changes: Sequence[Tuple[str, float, str]],
                  limits: Optional[Mapping[str, float]], force: bool = False) -> None:
    """The plausibility guard of every controller export: ChangeLimitError
    for the largest change (name, change, unit 'mm' or 'rad') beyond its
    unit's limit in ``limits``, unless ``force`` or ``limits`` is None. A
    change that is not a finite number is beyond any limit."""
    if force or limits is None:
        return
    over = [(math.inf if not math.isfinite(c) else abs(c) / limits[u], n, c, u) for n, c, u in changes
            if u in limits and not abs(c) <= limits[u]]
    if over:
        _, name, c, u = max(over, key=lambda o: o[0])
        raise ChangeLimitError(where, name, abs(c), limits[u], u)


def check_change(old: Mapping[str, float], new: Mapping[str, float],
                 limit: Optional[float] = DEFAULT_MAX_CHANGE, force: bool = False) -> None:
    """ChangeLimitError for the largest pin change beyond ``limit`` (mm),
    unless ``force`` or ``limit`` is None."""
    check_changes("LinuxCNC pins", [(n, new[n] - float(old.get(n, 0.0)), "mm") for n in new],
                  None if limit is None else {"mm": limit}, force)


def _number(v: float) -> str:
    return repr(float(v))  # shortest text that reads back as the same double


def _check_pins(k: str, pins: Mapping[str, float], what: str) -> None:
    """ValueError naming the pin for a name ``<k>-kins`` does not have or a
    value that is not a finite number: a HAL file must not say ``nan``, nor
    leave out a pin it was asked to set."""
    names = pin_names(k)
    for n, v in pins.items():
        if n not in names:
            raise ValueError(f"{what}: '{n}' is not a pin of {k}-kins fivecal sets ({', '.join(names)})")
        try:
            ok = math.isfinite(float(v))
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"{what}: {k}-kins.{n}: expected a finite number of mm, got {v!r}")


#: pins the fit holds at their old values: hal_text and ini_text leave them to
#: the machine's own configuration (tool-offset is usually netted to
#: motion.tooloffset.z, and a netted pin cannot be setp)
HELD = ("z-offset", "tool-offset")


def hal_text(kins: str, pins: Mapping[str, float], old: Optional[Mapping[str, float]] = None,
             header: str = "", held: Sequence[str] = HELD) -> str:
    """``setp`` lines for the fitted pins (a HAL file), each with the old value
    in its comment; the ``held`` pins are listed as comments only. Load it
    after the kinematics module (a HALFILE after the motion module); remove
    any other ``setp``/``sets``/``net`` of the pins it sets."""
    k = _kins(kins)
    _check_pins(k, pins, "pins")
    if old is not None:
        _check_pins(k, old, "old")
    out = [f"# fivecal: {k}-kins pins (mm){(' - ' + O.comment_text(header)) if header else ''}"]
    if old is not None:
        out += ["# " + line for line in pins_table(old, pins).splitlines()]
    for n in pin_names(k):
        if n not in pins:
            continue
        if n in held:
            out.append(f"# {k}-kins.{n} = {pins[n]:.6f} is held (set where your configuration sets it)")
            continue
        c = "" if old is None else f"  # old {float(old.get(n, 0.0)):.6f}"
        out.append(f"setp {k}-kins.{n} {_number(pins[n])}{c}")
    return "\n".join(out) + "\n"


def ini_text(kins: str, pins: Mapping[str, float], section: str = "FIVECAL_KINS",
             held: Sequence[str] = HELD) -> Tuple[str, str]:
    """The same values as an INI section plus the HAL lines that read it
    (``setp <kins>-kins.x-rot-point [FIVECAL_KINS]X_ROT_POINT``)."""
    k = _kins(kins)
    _check_pins(k, pins, "pins")
    if not re.fullmatch(r"[A-Za-z0-9_]+", str(section)):
        raise ValueError(f"section: expected an INI section name of letters, digits and '_', got {section!r}")
    ini = [f"[{section}]", f"# fivecal: {k}-kins pins (mm)"]
    hal = [f"# fivecal: {k}-kins pins from the INI section [{section}]"]
    for n in pin_names(k):
        if n in pins and n not in held:
            key = n.upper().replace("-", "_")
            ini.append(f"{key} = {_number(pins[n])}")
            hal.append(f"setp {k}-kins.{n} [{section}]{key}")
    return "\n".join(ini) + "\n", "\n".join(hal) + "\n"


#: every pin of LinuxCNC's <kins>-kins (trtfuncs.c; conventional-directions
#: from LinuxCNC 2.10): a name outside this list is a typo
MODULE_PINS = ("x-rot-point", "y-rot-point", "z-rot-point", "x-offset", "y-offset", "z-offset", "tool-offset",
               "conventional-directions")


def read_hal_pins(path: str, kins: str) -> Dict[str, float]:
    """The controller's current pin values from a HAL file, read as halcmd
    reads it (:mod:`fivecal.io.hal`): ``setp``, ``sets`` and ``net`` lines,
    comments, continuations. A pin whose value the file cannot give (an INI
    substitution, a line halcmd refuses, a signal another component drives)
    is refused naming the file and line, except ``tool-offset`` driven at run
    time (``motion.tooloffset.z``, the sample configs' way): the pins are for
    the tool fivecal was calibrated with, offset 0, so it is left out."""
    k = _kins(kins)
    names = pin_names(k)
    got = hal.pin_values(path, f"{k}-kins", MODULE_PINS, names + ["conventional-directions"])
    out: Dict[str, float] = {}
    for n, v in got.items():
        if v.problem is not None and n == "tool-offset" and v.runtime:
            continue
        if v.problem is not None:
            raise ValueError(f"{v.where}: {k}-kins.{n}: {v.problem}")
        if not math.isfinite(v.value):
            raise ValueError(f"{v.where}: {k}-kins.{n}: value is not finite")
        if n == "conventional-directions":
            if v.value != 0:
                raise ValueError(f"{v.where}: {k}-kins.conventional-directions is on; fivecal's model of "
                                 f"{k}-kins is that of the default directions (0)")
            continue
        out[n] = v.value
    if not out:
        raise ValueError(f"{path}: no value for a pin of {k}-kins (setp, sets or net lines of "
                         f"{', '.join(names)})")
    return out


# ---- joint compensation files ---------------------------------------------

def _joint_of(machine: Machine, kins: str, axis: str):
    m = match(machine, kins)
    if axis not in m["axes"]:
        raise ValueError(f"comp: axis {axis} drives no joint of {_kins(kins)} ({m['axes']})")
    j = m["axes"].index(axis)
    return j, m["sign"][j]


def comp_rows(machine: Machine, kins: str, errors: Mapping[str, float], axis: str,
              lo: float, hi: float, step: float) -> np.ndarray:
    """Rows (nominal, forward, reverse) of a LinuxCNC type-0 compensation file
    for the joint driven by ``axis``: where the joint really is when commanded
    to ``nominal`` approaching upward (forward) and downward (reverse), from the
    axis's error motion along itself (EXX1..3 for X, ECC1..3 for C) and its
    backlash (EXXb), in joint units (mm, degrees). LinuxCNC then commands the
    motor to nominal + (nominal - actual)."""
    if not (math.isfinite(lo) and math.isfinite(hi) and math.isfinite(step)) or step <= 0 or hi <= lo:
        raise ValueError(f"comp {axis}: expected min < max and a positive step, got {lo}:{hi}:{step}")
    n = int(math.floor((hi - lo) / step + 1e-9)) + 1
    if n > 10000:
        raise ValueError(f"comp {axis}: {n} points; LinuxCNC holds at most about 256 per joint")
    _, sign = _joint_of(machine, kins, axis)
    rotary = machine.is_rotary(axis)
    on_tool = axis in machine.tool_chain
    # The joint's own error along its direction: a workpiece-side linear axis
    # moves the table, so its error moves the tool the other way (-1).
    sigma = -1.0 if (not rotary and not on_tool) else 1.0
    coef = [float(errors.get(f"E{axis}{axis}{d}", 0.0)) for d in (1, 2, 3)]
    back = float(errors.get(f"E{axis}{axis}b", 0.0))
    nominal = lo + step * np.arange(n)
    q = nominal / sign  # fivecal command
    qv = np.radians(q) if rotary else q  # the polynomial's variable: mm or rad
    e = sigma * (coef[0] * qv + coef[1] * qv ** 2 + coef[2] * qv ** 3)
    scale = math.degrees(1.0) if rotary else 1.0
    fwd = nominal + scale * (e + back)
    rev = nominal + scale * (e - back)
    return np.column_stack([nominal, fwd, rev])


def comp_text(rows: np.ndarray, header: str = "") -> str:
    """A LinuxCNC COMP_FILE (COMP_FILE_TYPE = 0): 'nominal forward reverse' lines.
    LinuxCNC stops reading at the first line that is not three numbers, so the
    description goes into the INI, not into this file."""
    del header  # kept out of the file on purpose (see above)
    return "".join(f"{a:.9f} {b:.9f} {c:.9f}\n" for a, b, c in rows)


def comp_axes(errors: Mapping[str, float], machine: Machine, kins: str) -> List[str]:
    """Axes of the kinematics whose along-axis error motion or backlash is non-zero."""
    out = []
    for a in match(machine, kins)["axes"]:
        names = [f"E{a}{a}{d}" for d in (1, 2, 3)] + [f"E{a}{a}b"]
        if any(abs(float(errors.get(n, 0.0))) > 0 for n in names):
            out.append(a)
    return out


# ---- everything into a folder ---------------------------------------------

@dataclass
class Export:
    absorption: Absorption
    files: List[str]
    comp: Dict[str, str]        # axis -> file name
    not_exported: List[str]     # non-zero errors neither the pins nor a comp file carry
    replaced: List[str] = field(default_factory=list)  # files of an earlier export the folder held

    def summary(self) -> str:
        lines = [self.absorption.report()]
        for a, f in self.comp.items():
            lines.append(f"joint compensation for {a}: {f} (COMP_FILE_TYPE = 0)")
        if self.not_exported:
            lines.append("left to G-code compensation (no LinuxCNC parameter holds them): "
                         + ", ".join(self.not_exported))
        lines.append("written: " + ", ".join(self.files))
        return "\n".join(lines)


#: the files :func:`export` writes: a folder that holds only these (an
#: earlier export) is replaced as a whole
_EXPORT_FILE = re.compile(r"(fivecal-kins\.hal|fivecal-kins\.ini|fivecal-kins-ini\.hal|linuxcnc-report\.txt"
                          r"|comp-[A-Z]\.txt)\Z")


def _write_folder(out_dir: str, contents: Mapping[str, str]) -> List[str]:
    """``contents`` (name -> text) as the folder ``out_dir``, all or nothing:
    written into a new folder beside it, which then takes its place. A
    folder that exists must hold only files of an earlier export (they are
    replaced, stale comp files included: returned); anything else in it is
    refused, naming the file. On a failure the old folder stays as it was."""
    dest = os.path.realpath(out_dir)
    old: List[str] = []
    if os.path.lexists(dest):
        if not os.path.isdir(dest):
            raise ValueError(f"--out {out_dir}: exists and is not a folder")
        old = sorted(os.listdir(dest))
        foreign = [n for n in old if not _EXPORT_FILE.match(n)]
        if foreign:
            raise ValueError(f"--out {out_dir}: holds {foreign[0]}"
                             f"{f' and {len(foreign) - 1} more' if len(foreign) > 1 else ''}, which fivecal export "
                             "linuxcnc did not write; it replaces only a folder of its own files: choose a new or "
                             "empty folder")
    files.write_folder(dest, contents, f"--out {out_dir}")
    return old


def export(result, machine: Machine, kins: str, out_dir: str, old_pins: Optional[Mapping] = None,
           max_change: Optional[float] = DEFAULT_MAX_CHANGE, force: bool = False,
           volume: Optional[Mapping] = None, comp_step: float = 5.0,
           comp_range: Optional[Mapping[str, Tuple[float, float]]] = None,
           what: str = "this identification result") -> Export:
    """Write the LinuxCNC files for an identification ``result`` (path, dict
    or Result) into ``out_dir``: fivecal-kins.hal (setp lines, old values in
    comments), fivecal-kins.ini + fivecal-kins-ini.hal (the same through an INI
    section), comp-<axis>.txt per axis with an along-axis error motion or
    backlash, and linuxcnc-report.txt. Refuses a result that is not usable and
    pin changes beyond ``max_change`` mm unless ``force``. A folder of an
    earlier export is replaced as a whole (:attr:`Export.replaced` lists its
    files), all or nothing; a folder holding anything else is refused."""
    k = _kins(kins)
    errors = usable_errors(result, machine, force, what)
    match(machine, k)  # a clear refusal before any work
    poses = pose_grid(machine, k, volume)
    # one absorber: the pins and the same model in fivecal's parameters,
    # which leaves the same map (tested), so its G-code-compensated residual
    # is this controller's
    ab = absorb(machine, k, errors, poses=poses, old_pins=old_pins)
    check_change(ab.old_pins, ab.pins, max_change, force)
    ab.rms_compensated, ab.max_compensated = K.compensated_stats(machine, errors, ab.model)
    contents: Dict[str, str] = {}

    def write(name, text):
        contents[name] = text

    write("fivecal-kins.hal", hal_text(k, ab.pins, ab.old_pins, header=f"machine {machine.name}"))
    ini, ini_hal = ini_text(k, ab.pins)
    write("fivecal-kins.ini", ini)
    write("fivecal-kins-ini.hal", ini_hal)
    comp = {}
    for a in comp_axes(errors, machine, k):
        j, sign = _joint_of(machine, k, a)
        if comp_range and a in comp_range:
            lo, hi = comp_range[a]
        elif volume and a in volume:
            lo, hi = sorted(sign * float(v) for v in volume[a])
        else:
            lo, hi = (-180.0, 180.0) if machine.is_rotary(a) else DEFAULT_VOLUME["linear"]
        name = f"comp-{a}.txt"
        write(name, comp_text(comp_rows(machine, k, errors, a, lo, hi, comp_step)))
        comp[a] = name
    # pivot positions go into the pins, constant offsets into the work offset
    absorbed = {f"E{c}0{a}" for a in ("C", TILT[k], "X", "Y", "Z") for c in "XYZ"}
    carried = set(absorbed)
    for a in comp:
        carried |= {f"E{a}{a}{d}" for d in (1, 2, 3)} | {f"E{a}{a}b"}
    not_exported = sorted(n for n, v in errors.items() if abs(float(v)) > 0 and n not in carried
                          and not n.startswith("tip."))
    exp = Export(ab, list(contents) + ["linuxcnc-report.txt"], comp, not_exported)
    report = [exp.summary(), "", "INI lines for the compensation files:"]
    for a, name in comp.items():
        j, _ = _joint_of(machine, k, a)
        report += [f"[JOINT_{j}]", f"COMP_FILE = {name}", "COMP_FILE_TYPE = 0"]
    write("linuxcnc-report.txt", "\n".join(report) + "\n")
    exp.replaced = _write_folder(out_dir, contents)
    return exp


# ---- probing programs (G38.2) and LinuxCNC's probe log ---------------------

def _plane_touch() -> str:
    """The observation kind of a touch on one of the artefact's facets (a
    plane, what a G38.2 line of these programs probes): the registry's probe
    touch whose targets are the artefact's "facets"."""
    return next(k["name"] for k in _core.observation_kinds()
                if k["probe_touch"] and k["report"]["target_list"] == "facets")


def _facets(artefact: Mapping) -> Dict[str, dict]:
    facets = {f["id"]: f for f in (artefact or {}).get("facets", [])}
    if not facets:
        raise ValueError("artefact: no facets (a probing program needs facet targets)")
    return facets


def _touch_geometry(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                    tip_radius: float, workpiece_shift=(0.0, 0.0, 0.0)):
    """Per touch: (joint tilt, joint C, contact world point, facet normal,
    tool axis in world coordinates)."""
    k = _kins(kins)
    O.check_vector("workpiece_shift", workpiece_shift)
    mp = match(machine, k)
    tilt = TILT[k]
    facets = _facets(artefact)
    plane = _plane_touch()
    origin = np.asarray(mp["origin"], dtype=float) + np.asarray(workpiece_shift, dtype=float)
    out = []
    for i, t in enumerate(plan):
        if t.get("type") != plane:
            raise ValueError(f"plan[{i}]: type '{t.get('type')}': only facet touches become G38.2 moves")
        f = facets.get(t.get("target"))
        if f is None:
            raise ValueError(f"plan[{i}]: target '{t.get('target')}' is not a facet of the artefact")
        axes = t.get("axes", {})
        if tilt not in axes or "C" not in axes:
            raise ValueError(f"plan[{i}].axes: needs {tilt} and C (degrees)")
        n = np.asarray(f["normal"], dtype=float)
        n = n / np.linalg.norm(n)
        p = np.asarray(t.get("point", f["point"]), dtype=float)
        world = p + tip_radius * n - origin
        q = {a: 0.0 for a in machine.axis_names if a != "S"}
        q.update({tilt: float(axes[tilt]), "C": float(axes["C"])})
        v = machine.tool_pose(q)[1][0]
        out.append((mp["sign"][3] * float(axes[tilt]), mp["sign"][4] * float(axes["C"]), world, n, v))
    return out


def probing_program(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                    tip_radius: float, clearance: float = 1.0, overtravel: float = 1.0,
                    feed: float = 60.0, retract: float = 10.0, safe: float = 300.0,
                    dwell: float = 0.0, arm: str = "", disarm: str = "",
                    log: str = "probe-log.txt",
                    tcp_on: str = "M428", workpiece_shift=(0.0, 0.0, 0.0),
                    before_probe: Optional[Sequence[Sequence[str]]] = None, sync: str = "") -> str:
    """An ISO G-code program for LinuxCNC that runs a fivecal facet plan
    (``{"type": "facet", "target": id, "axes": {tilt, C}, "point": [...]}``)
    with tool centre point kinematics: per touch, index the table, go to
    ``clearance`` mm off the contact point along the facet normal, ``G38.2``
    towards it (``overtravel`` mm beyond) at ``feed`` mm/min and back off.
    Between touches the probe leaves ``retract`` mm along the facet normal and
    then ``safe`` mm along the tool axis, re-indexes there and comes back the
    same way (straight G0 moves: check them against your fixtures); ``dwell``
    seconds (G4) after each re-indexing let the table settle; ``sync``, ``arm``
    and ``disarm`` are lines written at the start point before the G38.2 and
    after it: ``sync="M66 E0 L0"`` (an immediate input read, which makes the
    interpreter wait until the machine stands at the start point),
    ``arm="M64 P0"`` and ``disarm="M65 P0"`` switch a probe interface on only
    for the probing move, right there. (LinuxCNC checks the probe input when
    it queues a G38.2, so arming while the stylus still sits on the previous
    contact fails; and an output "synchronised with the next move", M62,
    written before a G38.2 comes on while the probe move already runs, late
    on a busy computer.)
    The probed positions go to ``log`` (``PROBEOPEN``); read them back with
    :func:`read_probe_log`. Coordinates: workpiece point - tool tip at the zero
    pose (the pins' convention); ``tcp_on`` is the line that switches the
    controller to its tool-centre-point kinematics (``M428`` in LinuxCNC's
    sample configs). ``before_probe``: per touch, lines written just before
    its ``arm`` line (the simulator's probe planes: :func:`probe_sim_lines`)."""
    k = _kins(kins)
    tilt = TILT[k]
    O.check(tip_radius=tip_radius, clearance=clearance, overtravel=overtravel, feed=feed, retract=retract,
            safe=safe, dwell=dwell)
    O.check_probe_lines(log, arm, disarm, sync, tcp_on, before_probe)
    spheres = artefact.get("spheres") or []
    if spheres:
        # its straight lifts know nothing of spheres: on TANGO they ran 4 mm
        # through the scale bar's balls
        raise ValueError(f"probing_program: the artefact has {len(spheres)} sphere(s) this facet cycle's moves "
                         "do not avoid; use fivecal.io.nc_programs.touch_program, whose moves keep clear of "
                         "every sphere (fivecal export program chooses it)")
    touches = _touch_geometry(machine, k, plan, artefact, tip_radius, workpiece_shift)
    if before_probe is not None and len(before_probe) != len(touches):
        raise ValueError(f"before_probe: {len(before_probe)} entries for {len(touches)} touches")
    f = lambda v: f"{v:.6f}"  # noqa: E731
    out = [f"(fivecal probing program: {len(touches)} touches, machine {O.comment_text(machine.name)}, "
           f"{k}-kins)",
           "(units mm and degrees; world coordinates = workpiece point - tool tip at the zero pose)",
           # G61 exact stop: no move blends into the next, so every G38.2
           # starts from its start point at rest
           "G21 G90 G94 G17 G40 G49 G54 G61"]
    if tcp_on:
        out.append(f"{tcp_on} (tool centre point kinematics on)")
    out.append(f"(PROBEOPEN {log})")
    xyz = lambda p: f"X{f(p[0])} Y{f(p[1])} Z{f(p[2])}"  # noqa: E731
    last = None
    for i, (t, c, w, n, v) in enumerate(touches):
        start, end = w + clearance * n, w - overtravel * n
        off = start + retract * n
        up = off + safe * v
        out.append(f"(touch {i + 1}: {O.comment_text(plan[i]['target'])})")
        out.append(f"G0 {xyz(up)} {tilt}{f(t)} C{f(c)}")
        if dwell > 0 and last != (t, c):
            out.append(f"G4 P{dwell:g}")
        last = (t, c)
        out += [f"G0 {xyz(off)}", f"G0 {xyz(start)}"]
        # ``sync`` stops the read-ahead at the start point, so immediate
        # outputs (M64, M68) act there, before the G38.2 is queued. Outputs
        # "synchronised with the next move" (M62, M67) written before a G38.2
        # came on while the probe move already ran, later the busier the
        # computer: the stylus could be past the surface when armed
        out += [sync] if sync else []
        out += list(before_probe[i]) if before_probe is not None else []
        out += [arm] if arm else []
        out.append(f"G38.2 {xyz(end)} F{feed:g}")
        out += [disarm] if disarm else []
        out += [f"G0 {xyz(start)}", f"G0 {xyz(off)}", f"G0 {xyz(up)}"]
    out += ["(PROBECLOSE)", "M2"]
    return O.check_positions("\n".join(out) + "\n", "probing program")


#: how far a logged rotary position may be from the plan's command (degrees):
#: the rotary joints stand still during a G38.2, so only the log's rounding
PROBE_ROTARY_TOLERANCE = 1e-3
#: how far a logged position may be from its touch's G38.2 line (mm): the
#: controller follows the programmed straight line, so a log's rounding and
#: following error, never another touch
PROBE_LINE_TOLERANCE = 0.05


def _touch_fits(row, rot, touch) -> Optional[str]:
    """Why the logged row (world x y z, tilt, C) is not the planned touch
    (``rot``: its tilt and C joint command; ``touch``: (contact point, normal)
    of its probe line, or None), None when it is."""
    dt = row[3] - rot[0]
    dc = (row[4] - rot[1] + 180.0) % 360.0 - 180.0  # a wrapped C logs its angle modulo a turn
    if abs(dt) > PROBE_ROTARY_TOLERANCE or abs(dc) > PROBE_ROTARY_TOLERANCE:
        return f"rotary position {row[3]:.6g} {row[4]:.6g}, the plan commands {rot[0]:.6g} {rot[1]:.6g}"
    if touch is None:
        return None
    w, n = touch
    d = np.asarray(row[:3]) - w
    s = float(d @ n)
    off = float(np.linalg.norm(d - s * n))
    lo, hi = -O.RULES["overtravel"].high, O.RULES["clearance"].high
    if off > PROBE_LINE_TOLERANCE or not lo - PROBE_LINE_TOLERANCE <= s <= hi + PROBE_LINE_TOLERANCE:
        return (f"position {row[0]:.6g} {row[1]:.6g} {row[2]:.6g} is {off:.3g} mm off and {s:.3g} mm along the "
                f"probe line of the touch")
    return None


def _check_log_order(rows, nos, where, plan, rots, touches) -> None:
    """Refuse, naming the line, a log whose positions are not the plan's
    touches one by one: in another order, with lines missing or added, or of
    another plan. A log that lines up wrongly gives touches at other rotary
    positions than the fit believes, a confident wrong answer."""
    t = lambda i: None if touches is None else touches[i]  # noqa: E731
    fits = lambda r, i: _touch_fits(r, rots[i], t(i)) is None  # noqa: E731
    n = len(plan)
    for k, (row, no) in enumerate(zip(rows, nos)):
        if k >= n:
            raise ValueError(f"{where}:{no}: more probed positions ({len(rows)}) than the {n} planned touches of "
                             "the plan (a log of another plan, or of two runs?)")
        why = _touch_fits(row, rots[k], t(k))
        if why is None:
            continue
        target = plan[k].get("target", "?")
        if len(rows) == n and n > 1 and all(fits(r, n - 1 - i) for i, r in enumerate(rows)):
            raise ValueError(f"{where}:{no}: this line is touch {n - k} of the plan, not touch {k + 1}: the log "
                             f"runs in reverse order of the plan's {n} planned touches (sorted or reversed "
                             "after the run?)")
        later = [i for i in range(k + 1, n) if fits(row, i)]
        # lines missing: the log goes on from a later touch in the plan's order
        j = later[0] if later else n
        if later and (k + 1 >= len(rows) or j + 1 >= n or fits(rows[k + 1], j + 1)):
            miss = f"touch {k + 1}" if j == k + 1 else f"touches {k + 1}..{j}"
            raise ValueError(f"{where}:{no}: this line is touch {j + 1} of the plan, not touch {k + 1} "
                             f"({target}): {miss} missing before it ({len(rows)} probed positions for {n} "
                             "planned touches)")
        earlier = [i for i in range(n) if i != k and fits(row, i)]
        if earlier:
            raise ValueError(f"{where}:{no}: this line is touch {earlier[0] + 1} of the plan, not touch {k + 1} "
                             f"({target}): the log is not in the plan's order")
        raise ValueError(f"{where}:{no}: not touch {k + 1} of the plan ({target}): {why}; no touch of the plan "
                         "was probed there (a log of another plan or kinematics, or the program edited?)")
    if len(rows) < n:
        raise ValueError(f"{where}:{nos[-1] if nos else 0}: the log ends here, after {len(rows)} probed positions "
                         f"for {n} planned touches: touch {len(rows) + 1} ({plan[len(rows)].get('target', '?')}) "
                         "and after missing (LinuxCNC skips a position equal to the previous one; a touch that "
                         "did not trip stops the program)")


def read_probe_log(source: str, machine: Machine, kins: str, plan: Sequence[Mapping],
                   pins: Mapping[str, float], touches: Optional[Sequence[Tuple[object, object]]] = None
                   ) -> List[dict]:
    """Facet or sphere observations (dataset JSON, the type and target of
    each plan entry) from LinuxCNC's probe log (the
    ``PROBEOPEN`` file: one line 'x y z a b c u v w' per probe, in program
    coordinates) of a program :func:`probing_program` (or
    :func:`fivecal.io.nc_programs.sphere_program`, or
    :func:`fivecal.io.nc_programs.touch_program` for a plan that mixes facet
    and sphere touches) wrote for ``plan``, one line per touch in plan order:
    each world position goes through LinuxCNC's inverse kinematics with the
    ``pins`` the controller ran with to the joints, then to fivecal's axis
    readings. ``source`` is a path or the log text.

    Every line is checked against its touch of the plan: its rotary
    positions are the plan's commands, and with ``touches`` (per touch the
    nominal contact point of the stylus centre in program coordinates and
    the touch direction, as the program writers compute them:
    :func:`fivecal.io.plan_readings.probe_log_dataset` passes them) its
    position lies on that touch's probe line. A log in another order, with
    lines missing or added, or of another plan is refused naming the line."""
    k = _kins(kins)
    if "\n" not in source and os.path.exists(source):
        text, where = _read_text(source, "probe log"), source
    else:
        text, where = source, "probe log"
    rows, nos = [], []
    for no, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        parts = line.split()
        try:
            vals = [float(v) for v in parts]
        except ValueError:
            got = line.strip() if len(line.strip()) <= 80 else line.strip()[:80] + "…"
            raise ValueError(f"{where}:{no}: expected 9 numbers 'x y z a b c u v w', got '{got}'") from None
        if len(vals) != 9 or not all(math.isfinite(v) for v in vals):
            raise ValueError(f"{where}:{no}: expected 9 finite numbers 'x y z a b c u v w', got {len(vals)}")
        rows.append(vals)
        nos.append(no)
    if touches is not None and len(touches) != len(plan):
        raise ValueError(f"touches: {len(touches)} probe lines for {len(plan)} planned touches")
    ti = 3 if TILT[k] == "A" else 4
    world = np.array([[*r[:3], r[ti], r[5]] for r in rows]).reshape(-1, 5)
    mp = match(machine, k)
    tilt = TILT[k]
    rots = []
    for i, t in enumerate(plan):
        axes = t.get("axes") or {}
        if tilt not in axes or "C" not in axes:
            raise ValueError(f"plan[{i}].axes: needs {tilt} and C (degrees)")
        rots.append((mp["sign"][3] * float(axes[tilt]), mp["sign"][4] * float(axes["C"])))
    lines = None if touches is None else [(np.asarray(w, float), np.asarray(n, float) / np.linalg.norm(n))
                                          for w, n in touches]
    _check_log_order(world, nos, where, plan, rots, lines)
    j = inverse(k, pins, world)
    q = commands(machine, k, j)
    obs = []
    plane = _plane_touch()
    for i, t in enumerate(plan):
        axes = {a: float(q[a][i]) for a in machine.axis_names}
        o = {"type": t.get("type", plane), "target": t["target"], "axes": axes, "id": f"touch{i + 1}"}
        if t.get("direction"):  # the side each rotary axis was approached from (reversal errors)
            o["direction"] = dict(t["direction"])
        obs.append(o)
    return obs


def probe_sim_hal() -> str:
    """HAL lines of a simulated touch probe for the headless simulator:
    ``motion.probe-input`` is on while the program arms it
    (``motion.digital-out-00``) and gx*X + gy*Y + gz*Z + h < 0 for the joint
    feedback X Y Z, i.e. the stylus ball is inside the plane of the facet
    being touched. The program itself loads gx gy gz and -h into
    ``motion.analog-out-04..07`` with ``M68`` at the start point, after
    ``sync`` and before the ``M64 P0`` that arms it: :func:`probe_sim_lines`. Every
    part of the trigger thus runs in the servo thread and changes only at
    segment starts, so the trip point does not depend on how fast any
    non-realtime process (task, a Python helper) keeps up with the motion.
    The configuration needs 8 analog outputs (``[EMCMOT] EMCMOT = motmod
    num_aio=8``; 00-03 are often taken, e.g. 03 by the kinematics switch)."""
    out = ["# fivecal simulated touch probe (see fivecal.io.linuxcnc.probe_sim_hal)",
           "loadrt mult2 names=fcm0,fcm1,fcm2",
           "loadrt sum2 names=fcs0,fcs1",
           "loadrt comp names=fcc0",
           "loadrt and2 names=fca0"]
    for f in ("fcm0", "fcm1", "fcm2", "fcs0", "fcs1", "fcc0", "fca0"):
        out.append(f"addf {f} servo-thread")
    out += ["setp fcc0.hyst 0",
            "net fcp-x joint.0.pos-fb => fcm0.in0",
            "net fcp-y joint.1.pos-fb => fcm1.in0",
            "net fcp-z joint.2.pos-fb => fcm2.in0",
            "net fcp-gx motion.analog-out-04 => fcm0.in1",
            "net fcp-gy motion.analog-out-05 => fcm1.in1",
            "net fcp-gz motion.analog-out-06 => fcm2.in1",
            "net fcp-mx fcm0.out => fcs0.in0",
            "net fcp-my fcm1.out => fcs0.in1",
            "net fcp-mxy fcs0.out => fcs1.in0",
            "net fcp-mz fcm2.out => fcs1.in1",
            # comp.out = in1 > in0: -h > g.X, the ball inside the facet's plane
            "net fcp-s fcs1.out => fcc0.in0",
            "net fcp-h motion.analog-out-07 => fcc0.in1",
            "net fcp-inside fcc0.out => fca0.in0",
            "net fcp-arm motion.digital-out-00 => fca0.in1",
            "net fcp-probe fca0.out => motion.probe-input"]
    return "\n".join(out) + "\n"


def probe_sim_lines(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                    tip_radius: float, errors=None) -> List[List[str]]:
    """Per touch of ``plan``, the ``M68`` lines that load the simulated probe
    of :func:`probe_sim_hal` with the plane of the touched facet on the
    machine with ``errors`` (``probing_program(..., before_probe=..., sync="M66 E0 L0")``:
    immediate outputs, acting where the program stands)."""
    k = _kins(kins)
    model = probe_trigger_model(machine, k, plan, artefact, tip_radius, errors=errors)
    index = {tuple(p["rot"]): p for p in model}
    ids = list(_facets(artefact))
    out = []
    for t, (tt, c, _, _, _) in zip(plan, _touch_geometry(machine, k, plan, artefact, tip_radius)):
        p = index[(tt, c)]
        i = ids.index(t["target"])
        g, h = p["g"][i], p["h"][i]
        out.append([f"M68 E{e} Q{v:.12f}" for e, v in enumerate((g[0], g[1], g[2], -h), 4)])
    return out


def _touch_residuals(machine: Machine, artefact: Mapping, tip_radius: float, touches: Sequence[Mapping],
                     errors=None) -> np.ndarray:
    """(N,) mm: the core's residual of each touch (dataset observations of
    the artefact's facets or spheres) on the machine with ``errors``, the
    set-up parameters at 0: for a facet how far the stylus ball is outside
    (> 0) or inside (< 0) it. Built without the loader's plausibility check:
    a touch far off its target is what the caller measures."""
    doc = {"machine": machine.to_dict(), "probe": {"tip_radius": float(tip_radius)},
           "artefact": dict(artefact), "observations": list(touches)}
    ds = _core.Dataset.from_json(json.dumps(doc))
    values = {n: float(v) for n, v in zip(machine.parameter_names(), machine.theta(errors)) if v != 0.0}
    r, _ = _core.predict_residuals(ds, values)
    return np.asarray(r, dtype=float)


def probe_depths(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                 tip_radius: float, log: str, pins: Mapping[str, float], errors=None) -> np.ndarray:
    """(N,) mm: for each logged probe position, how far the stylus ball was
    outside (> 0) or inside (< 0) the touched facet on the machine with
    ``errors``. A simulated probe that tripped on time gives 0 to -(one servo
    cycle's feed); anything else means the trip was early or late."""
    obs = read_probe_log(log, machine, kins, plan, pins)
    facets = _facets(artefact)
    plane = _plane_touch()
    for o in obs:
        if o["type"] != plane or o["target"] not in facets:
            raise ValueError(f"{o['id']}: probe depths are of facet touches, got {o['type']} {o['target']!r}")
    return _touch_residuals(machine, artefact, tip_radius, obs, errors)


def probe_trigger_model(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                        tip_radius: float, errors=None) -> List[dict]:
    """For a simulated probe input (:func:`probe_sim_lines`): per rotary
    pose of the plan, the rows g, h with the stylus ball touching or inside
    the (convex) artefact when every g . (joint X, Y, Z) + h <= 0, on the
    machine with ``errors``. At fixed rotary joints the ball centre is affine
    in the linear joints, so four evaluations give it exactly (location
    errors; error motions make it only nearly affine)."""
    k = _kins(kins)
    poses = []
    for t, c, _, _, _ in _touch_geometry(machine, k, plan, artefact, tip_radius):
        if (t, c) not in poses:
            poses.append((t, c))
    ids = list(_facets(artefact))
    plane = _plane_touch()
    out = []
    for t, c in poses:
        jj = np.array([[0, 0, 0, t, c], [1, 0, 0, t, c], [0, 1, 0, t, c], [0, 0, 1, t, c]], float)
        q = commands(machine, k, jj)
        # the core's facet residual at the four joint points: h at the first,
        # its differences d(residual)/d(joint xyz) the rows g
        touches = [{"type": plane, "target": f, "axes": {a: float(q[a][i]) for a in machine.axis_names}}
                   for i in range(4) for f in ids]
        r = _touch_residuals(machine, artefact, tip_radius, touches, errors).reshape(4, len(ids))
        g = (r[1:] - r[0]).T
        out.append({"rot": [t, c], "g": g.tolist(), "h": [float(v) for v in r[0]]})
    return out
