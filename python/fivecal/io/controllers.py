"""What a controller's kinematic model can absorb of identified errors
(docs/controllers.md).

A controller model is the set of machine parameters a controller's own
kinematics can represent. Generic pivot models (what a 5-axis kinematics
table holds):

* ``table-table``, ``head-head``, ``table-head``: for each rotary axis the
  pivot (where its line runs: the two position components perpendicular to
  its direction), with ``directions=True`` also its direction (two small
  rotations perpendicular to it), and the tool length (along the tool axis).
  Linear axes stay ideal (no squareness, no error motions).

LinuxCNC modules (sources: src/emc/kinematics/trtfuncs.c and 5axiskins.c,
LinuxCNC 2.9 as packaged in Debian 12):

* ``xyzac-trt``, ``xyzbc-trt``: the rotary pivots only (the ``x|y|z-rot-point``
  and ``x|y-offset`` pins; tool-offset is held), the same fit as
  :func:`fivecal.io.linuxcnc.absorb`, whose residual it reproduces.
* ``5axiskins`` (a B-on-C spindle head whose axes meet at the pivot): only
  ``pivot-length``, i.e. the tool length.

Every model also takes a constant shift of the workpiece frame (probing the
part into the work offset absorbs it). :func:`absorb` fits the model's
parameters and that shift by least squares over a pose grid; what is left is
the tool-point error the controller leaves (:class:`Absorption`).
:func:`kinematics_table` gives the model as pivot points and axis directions
in the machine frame, and :func:`table_tool_points` is the kinematics such a
table describes (independent of fivecal's chain code), so the table's values
can be checked against the tool points they must reproduce. The numerics of
all of it are the C++ core's (``cpp/src/controllers/``: ``absorb.cc``,
``linuxcnc_5axis.cc``, ``kinematics_table.cc``); this module builds the
pose grids and writes the tables and reports.

Units: mm, degrees for rotary commands, rad for angular parameters.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import List, Mapping, Optional, Tuple

import numpy as np

from .. import _core, files
from ..compensation import compensate_poses
from ..machine import Machine

GENERIC = ("table-table", "head-head", "table-head")
LINUXCNC = ("xyzac-trt", "xyzbc-trt", "5axiskins")
MODELS = GENERIC + LINUXCNC
#: default working volume: linear axes +-100 mm, a rotary axis along z a full
#: turn, any other rotary axis -90..90 degrees
DEFAULT_LINEAR = (-100.0, 100.0)
DEFAULT_TILT = (-90.0, 90.0)
DEFAULT_TURN = (-180.0, 180.0)


def _rotaries(machine: Machine) -> List[dict]:
    return [a for a in machine.axes if a["type"] == "rotary" and a["name"] != "S"]


def _side(machine: Machine, axis: str) -> str:
    return "workpiece" if axis in machine.workpiece_chain else "tool"


@dataclass
class Parameter:
    """One controller parameter: a direction in fivecal's parameter space."""

    label: str           # e.g. "C pivot x", "A direction about z", "tool length"
    unit: str            # "mm" or "rad"
    column: np.ndarray = field(repr=False)   # (n_theta,) per unit of the parameter


def parameters(machine: Machine, model: str, directions: bool = False,
               tool_length: bool = True) -> List[Parameter]:
    """The parameters of ``model`` on ``machine`` (see the module text; the
    core's ``ControllerParameters``). ValueError when the machine's topology
    does not fit the model."""
    return [Parameter(p["label"], p["unit"], np.asarray(p["column"]))
            for p in _core.controller_parameters(machine._core, model, directions, tool_length)]


def absorbable(machine: Machine, model: str, directions: bool = False,
               tool_length: bool = True) -> List[str]:
    """fivecal error parameters the model can represent (fully or in part)."""
    names = machine.parameter_names()
    cols = [p.column for p in parameters(machine, model, directions, tool_length)]
    used = np.any(np.abs(np.array(cols)) > 1e-12, axis=0) if cols else np.zeros(len(names), bool)
    return [n for n, u in zip(names, used) if u]


def pose_grid(machine: Machine, volume: Optional[Mapping[str, Tuple[float, float]]] = None,
              n_linear: int = 3, n_tilt: int = 7, n_turn: int = 12) -> dict:
    """Poses over a working volume (dict axis -> array): a grid of the linear
    axes times the rotary axes. ``volume`` maps axis letters to (min, max);
    missing axes take +-100 mm, -90..90 degrees, or a full turn for a rotary
    axis along z."""
    volume = dict(volume or {})
    axes = [a for a in machine.axes if a["name"] != "S"]
    unknown = [k for k in volume if k not in [a["name"] for a in axes]]
    if unknown:
        raise ValueError(f"volume: {', '.join(unknown)} is not an axis of {machine.name} "
                         f"({' '.join(a['name'] for a in axes)})")
    grids = []
    for a in axes:
        n = a["name"]
        if a["type"] == "linear":
            default, count = DEFAULT_LINEAR, n_linear
        elif abs(abs(a["direction"][2]) - 1) < 1e-9:
            default, count = DEFAULT_TURN, n_turn
        else:
            default, count = DEFAULT_TILT, n_tilt
        lo, hi = (float(v) for v in volume.get(n, default))
        if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
            raise ValueError(f"volume.{n}: expected min <= max, got {lo}..{hi}")
        full = a["type"] == "rotary" and hi - lo >= 360.0
        grids.append(np.linspace(lo, hi, count, endpoint=not full))
    mesh = [g.ravel() for g in np.meshgrid(*grids, indexing="ij")]
    out = dict(zip([a["name"] for a in axes], mesh))
    if "S" in machine.axis_names:
        out["S"] = np.zeros_like(mesh[0])
    return out


def region_stats(poses: Mapping, residual: np.ndarray, axis: str,
                 bins: int = 4) -> List[Tuple[float, float, float, float]]:
    """|residual| by region of one axis: (lo, hi, rms, max) per bin, mm."""
    q = np.asarray(poses[axis], dtype=float)
    e = np.linalg.norm(residual, axis=1)
    edges = np.linspace(q.min(), q.max(), bins + 1)
    out = []
    for i in range(bins):
        sel = (q >= edges[i]) & ((q < edges[i + 1]) if i < bins - 1 else (q <= edges[i + 1]))
        if sel.any():
            out.append((float(edges[i]), float(edges[i + 1]), float(np.sqrt(np.mean(e[sel] ** 2))),
                        float(e[sel].max())))
    return out


def _stats(r: np.ndarray) -> Tuple[float, float]:
    n = np.linalg.norm(r, axis=1)
    return (float(np.sqrt(np.mean(n ** 2))), float(n.max())) if len(n) else (0.0, 0.0)


@dataclass
class Absorption:
    """What a controller model absorbs of identified errors over a pose grid."""

    model: str
    parameters: List[Parameter]
    values: np.ndarray                 # fitted parameter values (mm, rad)
    held: List[str]                    # labels the poses cannot tell from others (held at 0)
    theta: np.ndarray = field(repr=False)   # fivecal parameter vector of the controller's model
    workpiece_shift: np.ndarray = field(default_factory=lambda: np.zeros(3))
    residual: np.ndarray = field(default=None, repr=False)      # (N, 3) mm, after
    residual_old: np.ndarray = field(default=None, repr=False)  # (N, 3) mm, nominal model
    poses: dict = field(default=None, repr=False)
    rms: float = 0.0
    max: float = 0.0
    rms_old: float = 0.0
    max_old: float = 0.0
    rms_compensated: Optional[float] = None   # after absorption + fivecal's G-code compensation
    max_compensated: Optional[float] = None
    pins_fit: Optional[dict] = field(default=None, repr=False)  # LinuxCNC trt: the pins (core TrtFit)

    def value(self, label: str) -> float:
        return float(self.values[[p.label for p in self.parameters].index(label)])

    def by_region(self, axis: str, bins: int = 4):
        return region_stats(self.poses, self.residual, axis, bins)

    def report(self) -> str:
        um = lambda v: f"{1000 * v:.2f} um"  # noqa: E731
        lines = [f"controller model {self.model}: parameters that best absorb the identified errors"]
        for p, v in zip(self.parameters, self.values):
            s = f"{1000 * v:+.3f} um" if p.unit == "mm" else f"{1e6 * v:+.2f} urad"
            lines.append(f"  {p.label:<24}{s}{'  (held: not determined by the poses)' if p.label in self.held else ''}")
        lines.append("  workpiece shift (into the work offset): "
                     + ", ".join(f"{a} {1000 * v:+.1f} um" for a, v in zip("XYZ", self.workpiece_shift)))
        lines.append(f"tool point error over {len(self.residual)} poses: nominal model rms {um(self.rms_old)}, "
                     f"max {um(self.max_old)}; after absorption rms {um(self.rms)}, max {um(self.max)}")
        if self.rms_compensated is not None:
            lines.append(f"after absorption + fivecal G-code compensation: rms {um(self.rms_compensated)}, "
                         f"max {um(self.max_compensated)}")
        for a in [n for n in self.poses if n != "S" and np.ptp(self.poses[n]) > 0]:
            lines.append(f"  by {a}: " + "; ".join(f"{lo:g}..{hi:g} rms {um(r)} max {um(m)}"
                                                   for lo, hi, r, m in self.by_region(a)))
        return "\n".join(lines)


def absorb(machine: Machine, model: str, errors=None, poses: Optional[Mapping] = None,
           directions: bool = False, tool_length: bool = True,
           compensation: bool = False, held_pins: Optional[Mapping[str, float]] = None) -> Absorption:
    """Least-squares values of ``model``'s parameters (and a workpiece shift)
    that best reproduce the tool points of the machine with ``errors`` over
    ``poses`` (default :func:`pose_grid`): the core's ``Absorb``, one
    absorber for every model. With ``compensation`` also the error left when
    fivecal's G-code compensation runs on top of the absorbed model (inverse
    kinematics of the identified machine, targets the absorbed model's tool
    points: :func:`fivecal.compensation.compensate_poses`). For the LinuxCNC
    trt models :attr:`Absorption.pins_fit` holds the pins (``held_pins``:
    the z-offset and tool-offset held, and the "before" pins)."""
    poses = poses if poses is not None else pose_grid(machine)
    q = machine.axes_matrix(poses)
    fit = _core.controller_absorb(machine._core, model, machine.theta(errors), q, directions, tool_length,
                                  dict(held_pins or {}))
    params = [Parameter(p["label"], p["unit"], np.asarray(p["column"])) for p in fit["parameters"]]
    ab = Absorption(model=model, parameters=params, values=np.asarray(fit["values"]), held=list(fit["held"]),
                    theta=np.asarray(fit["theta"]), workpiece_shift=np.asarray(fit["workpiece_shift"]),
                    residual=np.asarray(fit["residual"]), residual_old=np.asarray(fit["residual_old"]),
                    poses=machine.axes_dict(q), rms=fit["rms"], max=fit["max"], rms_old=fit["rms_old"],
                    max_old=fit["max_old"], pins_fit=fit["trt"])
    if compensation:
        ab.rms_compensated, ab.max_compensated = compensated_stats(machine, errors, ab)
    return ab


def compensated_stats(machine: Machine, errors, ab: Absorption) -> Tuple[float, float]:
    """(rms, max) mm of :func:`compensated_residual`."""
    return _stats(compensated_residual(machine, errors, ab))


def compensated_residual(machine: Machine, errors, ab: Absorption) -> np.ndarray:
    """(N, 3) mm: tool point error left at ``ab.poses`` when the controller
    runs the absorbed model and the program is compensated by fivecal on top
    (targets: the absorbed model's tool points plus the workpiece shift)."""
    names = machine.parameter_names()
    errs = {n: float(v) for n, v in zip(names, machine.theta(errors) - machine.theta(None)) if v != 0.0}
    cp = compensate_poses(machine, errs, ab.poses, reference_theta=ab.theta,
                          reference_shift=ab.workpiece_shift,
                          progress=False, max_correction=None, max_correction_deg=None, force=True)
    return cp.remaining


# ---- LinuxCNC 5axiskins ----------------------------------------------------

def _match_5axis(machine: Machine) -> dict:
    """How ``machine`` drives 5axiskins's joints X Y Z B C (the core's
    ``MatchFiveAxis``): ``sign`` (joint = sign * command, per axis letter),
    ``pivot_length`` (mm) and ``origin``. ValueError says why a machine does
    not fit."""
    m = _core.fiveaxis_match(machine._core)
    return {"sign": {a: float(v) for a, v in m["sign"].items()}, "pivot_length": float(m["pivot_length"]),
            "origin": np.asarray(m["origin"])}


def fiveaxis_forward(pivot_length: float, joints) -> np.ndarray:
    """5axiskins.c forward kinematics (W = 0): joints (N, 5: X Y Z B C, mm and
    degrees) -> world X Y Z."""
    return np.asarray(_core.fiveaxis_forward(float(pivot_length), np.atleast_2d(np.asarray(joints, float))))


def fiveaxis_inverse(pivot_length: float, world) -> np.ndarray:
    """5axiskins.c inverse kinematics: world rows (X Y Z B C) -> joints."""
    return np.asarray(_core.fiveaxis_inverse(float(pivot_length), np.atleast_2d(np.asarray(world, float))))


def fiveaxis_joints(machine: Machine, axes: Mapping) -> np.ndarray:
    """5axiskins joints (N, 5) for fivecal axis commands."""
    return np.asarray(_core.fiveaxis_joints(machine._core, machine.axes_matrix(axes)))


# ---- neutral kinematics table ------------------------------------------------

def kinematics_table(machine: Machine, theta=None) -> dict:
    """The machine (with the location errors and tip offsets in ``theta``, a
    parameter vector or dict; default nominal) as a neutral kinematics table:
    per axis its chain (``workpiece``: carries the part, ``tool``: carries the
    spindle; each listed from the foundation outward), unit direction and, for
    a rotary axis, the point of its line nearest the nominal pivot, all in the
    machine frame at the zero pose; ``tool_tip`` and ``tool_axis`` at the
    zero pose; ``part_origin`` / ``part_rotation``: where the part frame sits
    at the zero pose (moved by the table axes' location errors; probing the
    part into the work offset measures it). Sign convention: a positive linear
    command moves the axis's carriage by +direction; a positive rotary command
    turns its carriage right-handed about +direction (ISO 841 for a part-side
    table axis is the opposite rotation of the part: use a direction reversed
    against the nominal machine axis there). Error motions are not in a table."""
    th = machine.theta(theta) if not isinstance(theta, np.ndarray) else theta
    t = _core.kinematics_table(machine._core, np.asarray(th, dtype=float))
    return {"machine": machine.name, "topology": machine.topology, "axes": list(t["axes"]),
            "tool_tip": np.asarray(t["tool_tip"]), "tool_axis": np.asarray(t["tool_axis"]),
            "part_origin": np.asarray(t["part_origin"]), "part_rotation": np.asarray(t["part_rotation"])}


def table_tool_points(table: Mapping, axes: Mapping) -> np.ndarray:
    """(N, 3) mm: the tool points in the workpiece frame that a kinematics
    table describes, for axis commands ``axes`` (mm, degrees): each axis a
    screw about its line, tool = S_tool(q) tip, part = S_workpiece(q), in the
    part frame (``part_origin``, ``part_rotation``)."""
    rows = list(table["axes"])
    names = [r["axis"] for r in rows]
    qs = {n: np.atleast_1d(np.asarray(axes.get(n, 0.0), dtype=float)) for n in names}
    n = max(len(v) for v in qs.values())
    q = np.column_stack([np.broadcast_to(qs[a], (n,)) for a in names]) if rows else np.zeros((n, 0))
    return np.asarray(_core.table_tool_points(
        names, [r["chain"] for r in rows], [r["type"] for r in rows],
        np.array([np.asarray(r["direction"], float) for r in rows]).reshape(-1, 3),
        np.array([np.asarray(r.get("point", (0.0, 0.0, 0.0)), float) for r in rows]).reshape(-1, 3),
        np.asarray(table["tool_tip"], float), np.asarray(table.get("part_origin", np.zeros(3)), float),
        np.asarray(table.get("part_rotation", np.eye(3)), float), q))


def table_rows(old: Mapping, new: Mapping) -> List[dict]:
    """Old and new table side by side, one row per value (CSV/JSON export)."""
    rows = []
    for ro, rn in zip(old["axes"], new["axes"]):
        for what in ("point", "direction"):
            if what not in rn:
                continue
            for c in range(3):
                rows.append({"axis": rn["axis"], "chain": rn["chain"], "value": f"{what}.{'xyz'[c]}",
                             "old": float(ro[what][c]), "new": float(rn[what][c])})
    for what in ("tool_tip", "tool_axis"):
        for c in range(3):
            rows.append({"axis": "tool", "chain": "tool", "value": f"{what}.{'xyz'[c]}",
                         "old": float(old[what][c]), "new": float(new[what][c])})
    return rows


# ---- names the values carry in vendor documentation -------------------------

SIGN_CONVENTION = ("machine frame at the zero pose (the part frame: part_origin, part_rotation); a positive linear "
                   "command moves its carriage by +direction, a positive rotary command turns its "
                   "carriage right-handed about +direction; points are on the rotary axis line, "
                   "nearest the nominal pivot; mm")


def vendor_names(machine: Machine, axis: str, value: str) -> Tuple[str, str]:
    """(Siemens, Heidenhain) names of a table value, from the public manuals
    cited in docs/controllers.md. Siemens numbers the rotary axes of a swivel
    data record (CYCLE800 / TRAORI, $TC_CARR) 1 and 2, 1 nearer the machine
    base (for mixed kinematics 1 is the head axis); I-vectors are differences
    of the points given here, V-vectors the directions; with the TRAORI
    machine data each replaces. Heidenhain's KinematicsOpt (Cycle 451) saves
    the rotary axes' positions in the kinematics description, whose rows
    shift (KEY Trans, AXIS X/Y/Z) or rotate (AXIS A/B/C) by COORD before an
    axis becomes effective (KEY MachAxis); which rows a machine builder uses
    is his, so the row kind is named, not a row."""
    rot = [a["name"] for a in _rotaries(machine)]
    if axis not in rot:
        if axis == "tool" and value.startswith("tool_tip"):
            return ("tool length / I3 (head) or tool adapter reference", "tool length (tool table)")
        return ("", "")
    order = sorted(rot, key=lambda r: (0 if _side(machine, r) == "tool" else 1,
                                       (machine.tool_chain if _side(machine, r) == "tool"
                                        else machine.workpiece_chain).index(r)))
    sides = {_side(machine, r) for r in rot}
    if sides == {"workpiece"}:  # swivel table: 1 nearer the base
        order = sorted(rot, key=machine.workpiece_chain.index)
    n = order.index(axis) + 1
    kind = "table" if sides == {"workpiece"} else "head" if sides == {"tool"} else "mixed"
    # The commissioning manual's table of swivel data record components and
    # the TRAORI machine data each replaces (docs/controllers.md)
    md = {("table", 2): "MD24550 $MC_TRAFO5_BASE_TOOL_1", ("table", 3): "MD24558",
          ("head", 2): "MD24560 $MC_TRAFO5_JOINT_OFFSET_1", ("head", 3): "MD24550 $MC_TRAFO5_BASE_TOOL_1",
          ("mixed", 2): "MD24550 $MC_TRAFO5_BASE_TOOL_1", ("mixed", 3): "MD24558 $MC_TRAFO5_JOINT_OFFSET_PART_1"}
    carr = {2: "$TC_CARR4..6", 3: "$TC_CARR15..17"}
    hh = (f"KEY Trans rows (AXIS X/Y/Z, COORD mm) before the MachAxis {axis} row of the kinematics "
          "description; Cycle 451")
    if value.startswith("direction"):
        return (f"V{n} (rotary axis {n} vector, $TC_CARR{7 + 3 * (n - 1)}..{9 + 3 * (n - 1)}; TRAORI "
                f"MD{24570 + 2 * (n - 1)} $MC_TRAFO5_AXIS{n}_1)",
                f"rotary axis {axis} orientation: KEY Trans rows (AXIS A/B/C, COORD deg) before the "
                f"MachAxis {axis} row; Cycle 451")
    if kind == "table":
        s = "I2 = point (from the machine reference)" if n == 1 else "I3 = point - point of rotary axis 1"
        i = 2 if n == 1 else 3
    elif kind == "head":
        s = "I3 = this point - tool adapter; I2 = point of axis 1 - this point" if n == 2 else \
            "I1 closes the chain (-(I2+I3))"
        i = 3 if n == 2 else None
    else:
        s = "I2 = point - tool adapter" if n == 1 else "I3 = point (from the machine reference)"
        i = 2 if n == 1 else 3
    where = f", {carr[i]}; TRAORI {md[(kind, i)]}" if i else ""
    return (f"{s} ($TC_CARR, swivel data record{where})", f"rotary axis {axis} position: {hh}")


def export_rows(machine: Machine, ab: Absorption) -> List[dict]:
    """Old (nominal) and new (absorbed) table rows with vendor names."""
    rows = table_rows(kinematics_table(machine), kinematics_table(machine, ab.theta))
    for r in rows:
        r["change"] = r["new"] - r["old"]
        r["siemens"], r["heidenhain"] = vendor_names(machine, r["axis"], r["value"])
    return rows


def export_dict(machine: Machine, ab: Absorption) -> dict:
    new_table = kinematics_table(machine, ab.theta)
    by = {a: [{"lo": lo, "hi": hi, "rms_mm": r, "max_mm": mx} for lo, hi, r, mx in ab.by_region(a)]
          for a in ab.poses if a != "S" and np.ptp(ab.poses[a]) > 0}
    return {"machine": machine.name, "model": ab.model, "sign_convention": SIGN_CONVENTION,
            "parameters": {p.label: {"value": float(v), "unit": p.unit}
                           for p, v in zip(ab.parameters, ab.values)},
            "held": ab.held, "absorbable": [n for n in absorbable(machine, ab.model)],
            "linuxcnc": linuxcnc_lines(machine, ab),
            "workpiece_shift_mm": [float(v) for v in ab.workpiece_shift],
            "residual": {"poses": len(ab.residual), "rms_old_mm": ab.rms_old, "max_old_mm": ab.max_old,
                         "rms_mm": ab.rms, "max_mm": ab.max, "rms_compensated_mm": ab.rms_compensated,
                         "max_compensated_mm": ab.max_compensated, "by_region": by},
            "table": export_rows(machine, ab),
            "map": {"axes": {a: [float(v) for v in ab.poses[a]] for a in ab.poses if a != "S"},
                    "residual_mm": [[float(v) for v in r] for r in ab.residual]},
            "part_frame": {"origin_mm": [float(v) for v in new_table["part_origin"]],
                           "rotation": [[float(v) for v in r] for r in new_table["part_rotation"]]}}


def linuxcnc_lines(machine: Machine, ab: Absorption) -> List[str]:
    """For the LinuxCNC models, what to set: the 5axiskins pin line, or where
    the trt pins come from."""
    if ab.model == "5axiskins":
        mp = _match_5axis(machine)
        old, new = mp["pivot_length"], mp["pivot_length"] + ab.value("tool length")
        return [f"setp 5axiskins.pivot-length {new!r}  # old {old!r} (mm; 5axiskins.c: add the "
                "tool's z offset, motion.tooloffset.z, where your configuration nets the pin)"]
    if ab.model in ("xyzac-trt", "xyzbc-trt"):
        return [f"LinuxCNC {ab.model}-kins pins, COMP_FILEs and the recipe: fivecal export linuxcnc "
                f"--kins {ab.model}"]
    return []


def export_text(machine: Machine, ab: Absorption) -> str:
    lines = [ab.report()]
    extra = linuxcnc_lines(machine, ab)
    if extra:
        lines += [""] + extra
    lines += ["", "kinematics table, " + SIGN_CONVENTION + ":",
             f"{'axis':<5}{'value':<14}{'old':>14}{'new':>14}{'change um':>11}  Siemens / Heidenhain"]
    for r in export_rows(machine, ab):
        lines.append(f"{r['axis']:<5}{r['value']:<14}{r['old']:>14.6f}{r['new']:>14.6f}"
                     f"{1000 * r['change']:>+11.3f}  {r['siemens']} / {r['heidenhain']}")
    return "\n".join(lines) + "\n"


def export_csv(machine: Machine, ab: Absorption) -> str:
    import csv
    import io
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["axis", "chain", "value", "old", "new", "change", "siemens", "heidenhain"])
    for r in export_rows(machine, ab):
        w.writerow([r["axis"], r["chain"], r["value"], repr(r["old"]), repr(r["new"]), repr(r["change"]),
                    r["siemens"], r["heidenhain"]])
    return buf.getvalue()


# ---- controller vendors: one export path for every vendor --------------------

def code_text(value: float, unit: str) -> str:
    """A fixed value as the controller shows it: a ``letter`` (unit of a
    code that is a letter, stored as its character code) as the letter."""
    if unit == "letter":
        code = int(round(value))
        return chr(code) if 32 < code < 127 else f"? (code {value:g})"
    return f"{value:g}"


def vendors() -> List[str]:
    """The controller vendors fivecal exports to (``fivecal export <vendor>``)."""
    return list(_core.vendor_names())


def vendor_info(vendor: str) -> dict:
    """A vendor's title and the convention options it reads (key -> help)."""
    return dict(_core.vendor_info(vendor))


def result_covariance(source, machine: Machine) -> np.ndarray:
    """(P, P) covariance of the machine's parameters (``machine.parameter_names()``
    order) from a result document (path, dict or :class:`fivecal.Result`): the
    estimated parameters' ``std`` and ``correlation``; rows of parameters not
    estimated, and of set-up parameters the machine does not have, are 0 (what
    a controller export propagates is the identification's uncertainty of
    what was estimated). A document without std or correlation is a
    ValueError naming what is missing."""
    names = machine.parameter_names()
    index = {n: i for i, n in enumerate(names)}
    if hasattr(source, "estimated") and hasattr(source, "std") and hasattr(source, "correlation"):
        estimated, std, corr = list(source.estimated), dict(source.std), np.asarray(source.correlation, float)
        where = "result"
    else:
        where = os.fspath(source) if isinstance(source, (str, os.PathLike)) else "result"
        doc = files.read_json(where, "result") if isinstance(source, (str, os.PathLike)) else source
        if not isinstance(doc, Mapping):
            raise ValueError(f"{where}: expected a result document (a JSON object)")
        estimated = list(doc.get("estimated") or [])
        params = doc.get("parameters") or {}
        std = {n: p.get("std") for n, p in params.items() if isinstance(p, Mapping)}
        raw = doc.get("correlation")
        if not estimated or raw is None:
            raise ValueError(f"{where}: no 'estimated' parameters with a 'correlation' matrix: the change's "
                             "uncertainty needs the identification's covariance (a result document of "
                             "fivecal identify or of a procedure that writes one)")
        corr = np.array([[np.nan if v is None else v for v in row] for row in raw], dtype=float)
    n = len(estimated)
    if corr.shape != (n, n):
        raise ValueError(f"{where}: correlation is {corr.shape[0]} x {corr.shape[1] if corr.ndim > 1 else 0}, "
                         f"but {n} parameters are estimated")
    s = np.array([np.nan if std.get(e) is None else float(std[e]) for e in estimated])
    cov = np.zeros((len(names), len(names)))
    keep = [k for k, e in enumerate(estimated) if e in index]
    for k in keep:
        if not (math.isfinite(s[k]) and s[k] >= 0):
            raise ValueError(f"{where}: parameters.{estimated[k]}.std: expected a finite std, got {std.get(estimated[k])!r}")
    sub = corr[np.ix_(keep, keep)] * np.outer(s[keep], s[keep])
    if not np.all(np.isfinite(sub)):
        raise ValueError(f"{where}: correlation: not all finite for the machine's parameters")
    idx = [index[estimated[k]] for k in keep]
    cov[np.ix_(idx, idx)] = sub
    return cov


@dataclass
class VendorExport:
    """The identified kinematics in a controller vendor's own terms (the
    core's ``ExportToVendor``): the vendor's values old / new / change with
    the change's 1σ, the absorption (what the controller's model leaves),
    the round trip through the vendor's own kinematics, and the fivecal
    parameters the new values compensate (``absorbed``, for verification
    after loading)."""

    vendor: str
    title: str
    machine: str
    model: str
    options: dict
    values: List[dict]                 # name, unit, source, fixed, motion_table, old, new, change, sigma
    absorption: Absorption
    # of the change of the values covariance_names lists: all but the
    # error-motion table entries (their σ is in values; their values x values
    # covariance, hundreds of MB on a fine grid, is not kept)
    covariance: np.ndarray = field(repr=False)
    covariance_names: List[str] = field(default_factory=list, repr=False)
    round_trip_max: float = 0.0                  # mm
    absorbed: dict = field(default_factory=dict, repr=False)  # names, change, covariance
    old_minus_nominal: np.ndarray = field(default=None, repr=False)
    result: str = ""                             # the result document it came from (for the files' headers)

    def value(self, name: str) -> dict:
        for v in self.values:
            if v["name"] == name:
                return v
        raise KeyError(name)

    def record(self) -> dict:
        """The common export record (``DIR/export.json``) that verification
        after loading reads (``fivecal sphere-check --expect``)."""
        ab = self.absorption
        by = {a: [{"lo": lo, "hi": hi, "rms_mm": r, "max_mm": mx} for lo, hi, r, mx in ab.by_region(a)]
              for a in ab.poses if a != "S" and np.ptp(ab.poses[a]) > 0}
        clean = lambda x: None if x is None or not math.isfinite(x) else float(x)  # noqa: E731
        return {"kind": "fivecal controller export", "vendor": self.vendor, "title": self.title,
                "machine": self.machine, "result": self.result, "model": self.model, "options": dict(self.options),
                "values": [{k: (clean(v[k]) if isinstance(v[k], float) else v[k]) for k in v}
                           for v in self.values],
                "absorbed": {"names": list(self.absorbed["names"]),
                             "change": [float(v) for v in self.absorbed["change"]],
                             "covariance": [[clean(x) for x in row] for row in self.absorbed["covariance"]]},
                "workpiece_shift_mm": [float(v) for v in ab.workpiece_shift],
                "residual": {"poses": len(ab.residual), "rms_old_mm": ab.rms_old, "max_old_mm": ab.max_old,
                             "rms_mm": ab.rms, "max_mm": ab.max, "by_region": by},
                "round_trip_max_mm": float(self.round_trip_max),
                "sphere_check": self.sphere_check()}

    def sphere_check(self) -> dict:
        """What ``fivecal sphere-check --expect`` can verify of this export:
        the kinematics (``absorbed``); never the error-motion tables."""
        tables = sum(1 for v in self.values if v.get("motion_table"))
        return {"verifies": "kinematics", "unverifiable_values": tables,
                "unverifiable": None if not tables else
                f"the {tables} error-motion table values (values[].motion_table): a sphere check does not see "
                "linear-axis error motions; verify them with a volumetric test (R-test, ball bar, tracker)"}

    def report(self) -> str:
        """Text summary: values old / new / change ± 1σ, then what the
        controller's model leaves (the absorption's report)."""
        lines = [f"{self.title} ({self.machine}; fivecal model {self.model})",
                 f"{'value':<34}{'unit':<6}{'old':>14}{'new':>14}{'change':>12}{'± 1σ':>10}"]
        for v in self.values:
            if v["fixed"]:
                unit = "" if v["unit"] == "letter" else v["unit"]
                lines.append(f"{v['name']:<34}{unit:<6}{code_text(v['new'], v['unit']):>14}{'(code)':>26}")
                continue
            sig = "" if v["sigma"] is None or not math.isfinite(v["sigma"]) else f"{v['sigma']:.3g}"
            lines.append(f"{v['name']:<34}{v['unit']:<6}{v['old']:>14.6f}{v['new']:>14.6f}"
                         f"{v['change']:>+12.6f}{sig:>10}")
        lines.append(f"round trip through the controller's own kinematics: {1000 * self.round_trip_max:.3g} um "
                     "at most over the poses")
        lines.append(self.absorption.report())
        return "\n".join(lines)


def vendor_export(machine: Machine, vendor: str, errors=None, covariance: Optional[np.ndarray] = None,
                  poses: Optional[Mapping] = None, options: Optional[Mapping[str, str]] = None,
                  old: Optional[Mapping[str, float]] = None) -> VendorExport:
    """The identified errors in ``vendor``'s own terms (``fivecal export
    <vendor>``; docs/controllers.md): the core's one export path (absorb into
    the model the vendor's kinematics represents over ``poses``, default
    :func:`pose_grid`; the vendor's values old / new / change; the change's
    covariance from ``covariance``, the identification's (P, P), see
    :func:`result_covariance`; the round trip through the vendor's own
    kinematics). ``options``: the conventions the user states (``--set``);
    ``old``: the controller's current values by name (default: the nominal
    machine's), a name the vendor does not have, or a missing one, is a
    ValueError naming it."""
    poses = poses if poses is not None else pose_grid(machine)
    q = machine.axes_matrix(poses)
    opts = {str(k): str(v) for k, v in (options or {}).items()}
    theta = machine.theta(errors)
    cov = np.zeros((0, 0)) if covariance is None else np.asarray(covariance, dtype=float)
    old_vec = np.zeros(0)
    if old is not None:
        info = _core.vendor_values(vendor, machine._core, np.zeros(len(theta)), opts)
        names = [v["name"] for v in info["values"]]
        unknown = [n for n in old if n not in names]
        if unknown:
            raise ValueError(f"old values: '{unknown[0]}' is not a {vendor} value for machine '{machine.name}' "
                             f"(its values: {', '.join(names)})")
        missing = [v["name"] for v in info["values"] if v["name"] not in old and not v["fixed"]]
        if missing:
            raise ValueError(f"old values: '{missing[0]}' missing (the controller's current value is needed for "
                             f"every value it changes{f'; {len(missing) - 1} more' if len(missing) > 1 else ''})")
        old_vec = np.array([float(old.get(n, info["map"][k])) for k, n in enumerate(names)])
    d = _core.vendor_export(vendor, machine._core, theta, cov, q, opts, old_vec)
    a = d["absorption"]
    params = [Parameter(p["label"], p["unit"], np.asarray(p["column"])) for p in a["parameters"]]
    ab = Absorption(model=a["model"], parameters=params, values=np.asarray(a["values"]), held=list(a["held"]),
                    theta=np.asarray(a["theta"]), workpiece_shift=np.asarray(a["workpiece_shift"]),
                    residual=np.asarray(a["residual"]), residual_old=np.asarray(a["residual_old"]),
                    poses=machine.axes_dict(q), rms=a["rms"], max=a["max"], rms_old=a["rms_old"],
                    max_old=a["max_old"])
    values = []
    for k, v in enumerate(d["values"]):
        values.append({"name": v["name"], "unit": v["unit"], "source": v["source"], "fixed": bool(v["fixed"]),
                       "motion_table": bool(v["motion"]), "old": float(d["old"][k]), "new": float(d["new"][k]),
                       "change": float(d["change"][k]), "sigma": float(d["sigma"][k])})
    names = machine.parameter_names()
    theta_abs = np.asarray(a["theta"])
    moved = [i for i in range(len(names)) if any(abs(p.column[i]) > 0 for p in params)]
    acov = np.asarray(d["absorbed_covariance"])
    absorbed = {"names": [names[i] for i in moved], "change": theta_abs[moved],
                "covariance": acov[np.ix_(moved, moved)] if acov.size else np.full((len(moved), len(moved)), np.nan)}
    return VendorExport(vendor=vendor, title=d["title"], machine=machine.name, model=a["model"], options=opts,
                        values=values, absorption=ab, covariance=np.asarray(d["covariance"]),
                        covariance_names=[values[int(i)]["name"] for i in d["covariance_index"]],
                        round_trip_max=float(d["round_trip_max"]), absorbed=absorbed,
                        old_minus_nominal=np.asarray(d["old_minus_nominal"]))


def vendor_tool_points(machine: Machine, vendor: str, values, axes: Mapping,
                       options: Optional[Mapping[str, str]] = None) -> np.ndarray:
    """(N, 3) mm: the tool points the controller's own kinematics gives with
    ``values`` (in the order of its values) for the axis commands ``axes``, in
    the controller's workpiece frame (docs/controllers.md)."""
    return np.asarray(_core.vendor_tool_points(vendor, machine._core, np.asarray(values, float),
                                               machine.axes_matrix(axes),
                                               {str(k): str(v) for k, v in (options or {}).items()}))


def vendor_to_theta(machine: Machine, vendor: str, values, poses: Optional[Mapping] = None,
                    options: Optional[Mapping[str, str]] = None) -> dict:
    """What a controller running ``values`` does in fivecal's terms: the
    errors (name -> value) of the model its kinematics represents, fitted to
    its own tool points over ``poses``; ``rms_mm`` / ``max_mm``: what that
    model cannot represent of them (0 for values a fivecal export wrote)."""
    poses = poses if poses is not None else pose_grid(machine)
    d = _core.vendor_to_theta(vendor, machine._core, np.asarray(values, float), machine.axes_matrix(poses),
                              {str(k): str(v) for k, v in (options or {}).items()})
    names = machine.parameter_names()
    th = np.asarray(d["theta"])
    return {"errors": {n: float(v) for n, v in zip(names, th) if v != 0.0}, "theta": th,
            "workpiece_shift": np.asarray(d["workpiece_shift"]), "rms_mm": float(d["rms"]),
            "max_mm": float(d["max"]), "held": list(d["held"])}
