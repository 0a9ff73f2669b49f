"""Orientations as cameras, motion capture and trackers write them, for the
pose import (docs/import.md, "Rotations").

A pose table gives the measured orientation in one of four forms, told by
its columns (and, where the columns cannot tell, by the sidecar's
``rotation``):

* ``quaternion``: ``qw qx qy qz`` (any column order: the names say which is
  which), or ``q1 q2 q3 q4`` / ``q0 q1 q2 q3`` with ``rotation.order``
  ``wxyz`` (scalar first, Eigen, EuRoC, ROS 1 tf's w first writers) or
  ``xyzw`` (scalar last, ROS messages, TUM, Unity, SciPy);
* ``matrix``: ``r11 r12 r13 r21 ... r33`` (row by row);
* ``rotation_vector``: ``measured_rx measured_ry measured_rz`` (rad unless
  the header or ``rotation.unit`` says ``deg``);
* ``euler``: ``euler_1 euler_2 euler_3`` (the angles in the order of
  ``rotation.sequence``) or ``roll pitch yaw`` (about x, y, z), with the
  sequence named (``ZYX``: intrinsic, upper case; ``xyz``: extrinsic, lower
  case) and the unit.

The conversion is the core's (``_core.rotation_vectors``, Eigen): fivecal
keeps every orientation as a rotation vector in rad. A quaternion whose norm
is off 1, or a matrix that is not a rotation, by more than
``rotation.tolerance`` (default 1e-3) is refused naming its line.

Per-component noise of a pose: ``sigma_x sigma_y sigma_z`` (mm, or the
header's unit) and ``sigma_rx sigma_ry sigma_rz`` (rad, or the header's or
``rotation.unit``), all six or none; or the sidecar's ``sigma`` as six values.
"""
from __future__ import annotations

import math
from typing import Mapping, Optional

import numpy as np

from .. import _core

FORMS = ("quaternion", "matrix", "rotation_vector", "euler")
_ALIASES = {"quat": "quaternion", "quaternions": "quaternion", "rotation_matrix": "matrix", "dcm": "matrix",
            "rotvec": "rotation_vector", "rotation vector": "rotation_vector", "axis_angle": "rotation_vector",
            "euler_angles": "euler"}
ROTATION_VECTOR = ("measured_rx", "measured_ry", "measured_rz")
QUATERNION_NAMED = ("qw", "qx", "qy", "qz")
QUATERNION_NUMBERED = (("q1", "q2", "q3", "q4"), ("q0", "q1", "q2", "q3"))
MATRIX = tuple(f"r{i}{j}" for i in (1, 2, 3) for j in (1, 2, 3))
EULER = ("euler_1", "euler_2", "euler_3")
RPY = ("roll", "pitch", "yaw")
SIGMA_POSITION = ("sigma_x", "sigma_y", "sigma_z")
SIGMA_ROTATION = ("sigma_rx", "sigma_ry", "sigma_rz")
SIGMA = SIGMA_POSITION + SIGMA_ROTATION
#: every column the pose import takes for its orientation and its noise
FIELDS = frozenset(ROTATION_VECTOR + QUATERNION_NAMED + QUATERNION_NUMBERED[0] + ("q0",) + MATRIX + EULER + RPY
                   + SIGMA)
#: columns holding angles: a unit in their header converts them to rad
ANGLE_FIELDS = frozenset(ROTATION_VECTOR + EULER + RPY + SIGMA_ROTATION)
#: columns holding lengths (mm, or the header's unit, or --units)
LENGTH_FIELDS = frozenset(SIGMA_POSITION)
_KEYS = {"form", "order", "sequence", "unit", "tolerance"}
_RAD = {"rad": 1.0, "deg": math.pi / 180.0, "degree": math.pi / 180.0, "degrees": math.pi / 180.0}


class Spec:
    """How one pose table gives its orientation: the form, the fields in
    the order the core takes them, and the core's options."""

    def __init__(self, form: str, fields: tuple, order: str = "wxyz", sequence: str = "", unit: str = "rad",
                 tolerance: float = 1e-3):
        self.form, self.fields, self.order = form, fields, order
        self.sequence, self.unit, self.tolerance = sequence, unit, tolerance
        self.sigma = False  # per-row sigma_x ... sigma_rz columns


def read_spec(value, where: str) -> dict:
    """The sidecar's ``rotation`` checked: a dict with ``form`` and, as the
    form needs, ``order``, ``sequence``, ``unit``, ``tolerance``."""
    if not isinstance(value, Mapping):
        raise ValueError(f"{where}: expected {{\"form\": \"quaternion\", \"order\": \"xyzw\"}} (forms: "
                         f"{', '.join(FORMS)}), got {value!r}")
    unknown = sorted(set(value) - _KEYS)
    if unknown:
        raise ValueError(f"{where}.{unknown[0]}: unknown key (keys: {', '.join(sorted(_KEYS))})")
    out = dict(value)
    form = out.get("form")
    if form is not None:
        if not isinstance(form, str):
            raise ValueError(f"{where}.form: expected one of {', '.join(FORMS)}, got {form!r}")
        form = _ALIASES.get(form.strip().lower(), form.strip().lower())
        if form not in FORMS:
            raise ValueError(f"{where}.form: '{value['form']}' is not a rotation form ({', '.join(FORMS)})")
        out["form"] = form
    order = out.get("order")
    if order is not None:
        o = str(order).strip().lower().replace(",", "").replace(" ", "")
        if o not in ("wxyz", "xyzw"):
            raise ValueError(f"{where}.order: '{order}' is not a quaternion order: wxyz (scalar first) or xyzw "
                             "(scalar last)")
        out["order"] = o
    unit = out.get("unit")
    if unit is not None:
        if not isinstance(unit, str) or unit.strip().lower() not in _RAD:
            raise ValueError(f"{where}.unit: expected rad or deg, got {unit!r}")
        out["unit"] = "deg" if unit.strip().lower().startswith("deg") else "rad"
    seq = out.get("sequence")
    if seq is not None and not isinstance(seq, str):
        raise ValueError(f"{where}.sequence: expected three axis letters like ZYX (intrinsic) or xyz (extrinsic), "
                         f"got {seq!r}")
    tol = out.get("tolerance")
    if tol is not None and (isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0 < tol < 0.5):
        raise ValueError(f"{where}.tolerance: expected a number in (0, 0.5), got {tol!r}")
    for key, forms in (("order", ("quaternion",)), ("sequence", ("euler",)),
                       ("unit", ("rotation_vector", "euler"))):
        if out.get(key) is not None and out.get("form") is not None and out["form"] not in forms:
            raise ValueError(f"{where}.{key}: belongs to a {' or '.join(forms)}, not a {out['form']}")
    return out


def prepare(cols, side: Mapping, origin: Mapping, where: str) -> Spec:
    """Which orientation form the columns ``cols`` (the import's ``_Column``
    objects, with ``field``, ``header``, ``unit`` and ``factor``) give, checked
    against the sidecar's ``rotation``; sets the unit factor (to rad) of angle
    columns whose header names no unit. ValueError names the header."""
    rw = origin.get("rotation", "rotation")
    given = read_spec(side["rotation"], rw) if side.get("rotation") is not None else {}
    present = {c.field: c for c in cols}
    found = []
    if any(f in present for f in ROTATION_VECTOR):
        found.append(("rotation_vector", ROTATION_VECTOR))
    if any(f in present for f in QUATERNION_NAMED):
        found.append(("quaternion", QUATERNION_NAMED))
    numbered = [q for q in QUATERNION_NUMBERED if all(f in present for f in q)]
    if numbered or any(f in present for f in ("q0", "q1", "q2", "q3", "q4")):
        found.append(("quaternion", numbered[0] if numbered else QUATERNION_NUMBERED[0]))
    if any(f in present for f in MATRIX):
        found.append(("matrix", MATRIX))
    if any(f in present for f in EULER):
        found.append(("euler", EULER))
    if any(f in present for f in RPY):
        found.append(("euler", RPY))
    if not found:
        raise ValueError(f"{where}: no orientation columns; a pose import expects measured_rx measured_ry "
                         "measured_rz (rotation vector), qw qx qy qz (quaternion), r11 ... r33 (matrix) or "
                         "euler_1 euler_2 euler_3 / roll pitch yaw (Euler angles, with rotation.sequence in the "
                         "sidecar): `fivecal docs import`")
    if len(found) > 1:
        a, b = found[0][1], found[1][1]
        raise ValueError(f"{where}: columns '{_header(present, a)}' and '{_header(present, b)}' both give the "
                         f"orientation ({found[0][0]}, {found[1][0]}); keep one form (skip the others with --ignore)")
    form, fields = found[0]
    missing = [f for f in fields if f not in present]
    if missing:
        raise ValueError(f"{where}: no '{missing[0]}' column; a {form} needs the columns {' '.join(fields)}")
    if given.get("form") not in (None, form):
        raise ValueError(f"{rw}.form: says {given['form']}, but the columns ({' '.join(fields)}) give a {form}")
    spec = Spec(form, fields, tolerance=float(given.get("tolerance", 1e-3)))
    if form == "quaternion":
        if fields == QUATERNION_NAMED:
            # the names say which is the scalar; a sidecar order must agree with nothing: it is not needed
            spec.order = "wxyz"
        elif given.get("order") is None:
            raise ValueError(f"{where}: columns {' '.join(fields)} do not say which value is the scalar w: give "
                             "\"rotation\": {\"form\": \"quaternion\", \"order\": \"wxyz\"} (scalar first) or "
                             "\"xyzw\" (scalar last) in the sidecar, or name the columns qw qx qy qz")
        else:
            spec.order = given["order"]
    elif given.get("order") is not None:
        raise ValueError(f"{rw}.order: a quaternion order, but the columns give a {form}")
    if form == "euler":
        seq = given.get("sequence")
        if seq is None:
            raise ValueError(f"{where}: Euler angles need their sequence: give \"rotation\": {{\"form\": \"euler\", "
                             "\"sequence\": \"ZYX\", \"unit\": \"deg\"}} in the sidecar (upper case: intrinsic, "
                             "lower case: extrinsic)")
        spec.sequence = seq.strip()
        try:
            _core.rotation_vectors(np.zeros((0, 3)), "euler", sequence=spec.sequence)
        except ValueError as e:  # the core names the field; say which file gave it
            raise ValueError(f"{rw[:-len('rotation')]}{e}") from None
        if fields == RPY:
            letters = spec.sequence.lower()
            if sorted(letters) != ["x", "y", "z"]:
                raise ValueError(f"{rw}.sequence: roll, pitch and yaw are angles about x, y and z; sequence "
                                 f"'{spec.sequence}' turns about one axis twice: name the columns euler_1 euler_2 "
                                 "euler_3")
            spec.fields = tuple(RPY["xyz".index(a)] for a in letters)
    elif given.get("sequence") is not None:
        raise ValueError(f"{rw}.sequence: an Euler sequence, but the columns give a {form}")
    unit = given.get("unit", "rad")
    for c in cols:
        # angle columns whose header names no unit are in the rotation's unit
        if c.field in ANGLE_FIELDS and c.unit is None:
            c.factor = _RAD[unit]
    if form in ("rotation_vector", "euler"):
        spec.unit = "rad"  # the columns' factors made them rad
    sig = [f for f in SIGMA if f in present]
    if sig and len(sig) != len(SIGMA):
        lack = [f for f in SIGMA if f not in present]
        raise ValueError(f"{where}: column '{present[sig[0]].header}' gives part of a pose's noise; give all six "
                         f"sigma_x sigma_y sigma_z sigma_rx sigma_ry sigma_rz (no '{lack[0]}' column)")
    spec.sigma = bool(sig)
    return spec


def _header(present, fields) -> str:
    return next(present[f].header for f in fields if f in present)


def row_rotation(vals: Mapping, spec: Spec, where: str) -> list:
    """The row's measured orientation as a rotation vector (rad); ``vals``:
    field -> (value, where of the cell)."""
    v = np.array([[vals[f][0] for f in spec.fields]], dtype=float)
    if spec.form == "rotation_vector" and math.sqrt(float(np.sum(v * v))) > math.pi + 1e-9:
        # a rotation vector is at most half a turn long: longer ones are degrees read as rad
        raise ValueError(f"{where}: measured rotation {', '.join(f'{x:.6g}' for x in v[0])} is longer than π rad, "
                         "which no rotation vector is; degrees? name the columns measured_rx_deg ... or convert "
                         "to rad")
    out, problems = _core.rotation_vectors(v, spec.form, order=spec.order, sequence=spec.sequence,
                                           unit=spec.unit, tolerance=spec.tolerance)
    if problems[0]:
        raise ValueError(f"{where}: {problems[0]} (columns {' '.join(spec.fields)})")
    return [float(x) for x in out[0]]


def row_sigma(vals: Mapping, spec: Optional[Spec]) -> Optional[list]:
    """The row's six sigma cells (mm, mm, mm, rad, rad, rad), each > 0, or
    None when the table has none."""
    if spec is None or not spec.sigma:
        return None
    out = []
    for f in SIGMA:
        s, sw = vals[f]
        if not s > 0:
            raise ValueError(f"{sw}: {f} {s:g} {'mm' if f in SIGMA_POSITION else 'rad'} must be > 0")
        out.append(s)
    return out


def sidecar_sigma(value, kind: str, where: str):
    """The sidecar's (or --sigma's) ``sigma``: one number > 0, or one per
    residual row of the kind (the registry's ``row_units``: six for a 6D
    pose, whose rows are in mm and rad, so that one number cannot weigh
    them). Returns the list, or None for one number (checked by the caller)."""
    units = list({k["name"]: k for k in _core.observation_kinds()}.get(kind, {}).get("row_units") or [])
    mixed = len(set(units)) > 1
    if isinstance(value, (list, tuple)):
        if len(units) < 2:
            raise ValueError(f"{where}: expected one number > 0 (mm), got a list")
        try:
            v = [float(x) for x in value]
        except (TypeError, ValueError):
            raise ValueError(f"{where}: expected {len(units)} numbers > 0, got {value!r}") from None
        if len(v) != len(units):
            what = " ".join(f"{'xyz'[i % 3] if u == 'mm' else 'r' + 'xyz'[i % 3]}" for i, u in enumerate(units))
            raise ValueError(f"{where}: expected {len(units)} values, one per row ({what}: "
                             f"{', '.join(units)}), got {len(v)}")
        for i, x in enumerate(v):
            if not (math.isfinite(x) and x > 0):
                raise ValueError(f"{where}[{i}]: sigma {x:g} must be > 0")
        return v
    if mixed:
        raise ValueError(f"{where}: a {kind} observation's rows are in {' and '.join(sorted(set(units)))}, so one "
                         f"number cannot weigh them: give {len(units)} values ({', '.join(units)}), or "
                         "sigma_x ... sigma_rz columns")
    return None
