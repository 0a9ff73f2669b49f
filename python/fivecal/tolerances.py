"""Tolerances given by people: ``NAME=VALUE[unit]`` lists and single values
with an optional unit, read once, here, for every command and API that
takes them (docs/history.md, "Tolerances").

A value may carry its unit: ``12um``, ``0.012mm``, ``20urad``, ``0.001rad``,
``0.01deg``; the slopes of error motions ``5um/m`` (a linear axis) or
``10um/rad`` (a rotary axis), with ``^d`` for a degree-d coefficient. A bare
number is in the file unit of the quantity: mm, rad, or mm/mm^d etc. for a
parameter, mm for a length. A tolerance must be a finite number > 0, and a
bare one is refused when it is larger than :data:`BARE_LIMIT_FACTOR` times
the default prior σ of the parameter's class (1 mm for a pivot location,
1 mrad for an axis orientation, ...): such a number is nearly always µm or
µrad written without its unit (``EX0C=12`` meaning 12 µm would pass a
−108 µm error). Write the unit to give a tolerance that large.

One rule for every command: a bare number is in the file unit in
``identify``, ``history compare | trend``, ``rtest`` and ``export program``
alike (the last two read µm before; the implausibility refusal catches a
bare µm number left in a script). The names say what is graded:
:data:`VALUE_OPTION` a value (a parameter's |value|, a K test's range),
:data:`CHANGE_OPTION` the change between two calibrations,
:data:`PATH_OPTION` a program's path.
"""
from __future__ import annotations

import difflib
import math
import re
from functools import lru_cache
from typing import Dict, Iterable, Mapping, Optional, Sequence, Tuple

from . import _core
from .units import _BACKLASH, _LOCATION, _MOTION, _setup_unit

#: A bare tolerance above this many default prior σ of its parameter's class is refused.
BARE_LIMIT_FACTOR = 10.0

#: Largest bare volumetric tolerance (mm): the predicted tool-point error of a
#: machine in service is tens of µm; a bare 12 is 12 µm meant.
VOLUMETRIC_BARE_LIMIT = 1.0

#: Largest bare tolerance on the range of an R-test K test (mm): ranges of a
#: machine in service are tens of µm; a bare 20 is 20 µm meant.
RANGE_BARE_LIMIT = 1.0

#: Largest bare path tolerance of a ball bar program (mm): the change of the
#: nominal bar length between two blocks must stay below what the bar can
#: read (0.1 µm); a bare 0.02 is the old µm habit.
PATH_BARE_LIMIT = 0.01

#: The one spelling of each kind of tolerance on every command line
#: (docs/history.md, "Tolerances"): a value's, a change's, a path's.
VALUE_OPTION = "--tolerance"
CHANGE_OPTION = "--change-tolerance"
PATH_OPTION = "--path-tolerance"

LENGTH_UNITS = {"mm": 1.0, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "nm": 1e-6, "m": 1e3}
ANGLE_UNITS = {"rad": 1.0, "mrad": 1e-3, "urad": 1e-6, "µrad": 1e-6, "μrad": 1e-6, "deg": math.pi / 180,
               "°": math.pi / 180, "arcsec": math.pi / 648000}
_DEN = {"length": {"mm": 1.0, "m": 1e3}, "angle": {"rad": 1.0, "deg": math.pi / 180, "°": math.pi / 180}}
_POWER = {"": 1, "²": 2, "³": 3, "^1": 1, "^2": 2, "^3": 3}
_VALUE = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?:nan|inf|infinity))\s*(\S.*?)?\s*$",
                    re.IGNORECASE)
_FILE_UNIT = {"length": "mm", "angle": "rad"}


def dimension(name: str) -> Tuple[str, Optional[str], int]:
    """(``length`` or ``angle``: the kind of the value; the kind of the
    polynomial variable of an error motion, else None; its degree)."""
    m = _MOTION.match(name)
    if m:
        comp, axis, d = m.groups()
        return ("angle" if comp in "ABC" else "length"), ("angle" if axis in "ABCS" else "length"), int(d)
    m = _LOCATION.match(name)
    if m:
        return ("angle" if m.group(1) in "ABC" else "length"), None, 0
    m = _BACKLASH.match(name)
    if m:
        return ("angle" if m.group(2) in "ABCS" else "length"), None, 0
    return ("angle" if _setup_unit(name) == "rad" else "length"), None, 0


def file_unit(name: str) -> str:
    """The unit a bare tolerance of ``name`` is read in (``mm``, ``rad``, ``mm/mm^2``, ``rad/rad``, ...)."""
    kind, den, d = dimension(name)
    unit = _FILE_UNIT[kind]
    if den:
        unit += "/" + _FILE_UNIT[den] + ("" if d == 1 else f"^{d}")
    return unit


def prior_class(name: str) -> Optional[str]:
    """The default prior class of a machine error (docs/identification.md), None for a set-up parameter."""
    m = _LOCATION.match(name)
    if m:
        return "location_angle" if m.group(1) in "ABC" else "location_offset"
    m = _MOTION.match(name)
    if m:
        comp, axis, d = m.groups()
        if axis in "XYZ":
            if comp == axis and d == "1":
                return "scale_gain"
            return f"linear_{'tilt' if comp in 'ABC' else 'motion'}_{d}"
        return f"rotary_{'tilt' if comp in 'ABC' else 'motion'}_{d}"
    m = _BACKLASH.match(name)
    if m:
        return "backlash_rotary" if m.group(2) in "ABCS" else "backlash_linear"
    if name.startswith("tip."):
        return "tip"
    return None


@lru_cache(maxsize=None)
def _class_sigma() -> Dict[str, float]:
    return {c["name"]: float(c["sigma"]) for c in _core.prior_classes()}


def bare_limit(name: str) -> float:
    """Largest bare tolerance of ``name`` accepted (file unit): :data:`BARE_LIMIT_FACTOR`
    default prior σ of its class; 10 mm / 0.01 rad for a set-up parameter without one."""
    sigma = _class_sigma().get(prior_class(name) or "")
    if sigma is None:
        return 1e-2 if dimension(name)[0] == "angle" else 10.0
    return BARE_LIMIT_FACTOR * sigma


def _unit_factor(unit: str, kind: str, den: Optional[str], degree: int) -> Optional[float]:
    """Factor from ``unit`` to the file unit, None when it is not a unit of this quantity."""
    num_units = LENGTH_UNITS if kind == "length" else ANGLE_UNITS
    u = unit.replace(" ", "")
    if "/" not in u:
        return num_units.get(u) if den is None else None
    if den is None:
        return None
    num, rest = u.split("/", 1)
    m = re.match(r"^(.*?)(\^[123]|²|³)?$", rest)
    base, power = m.group(1), _POWER[m.group(2) or ""]
    if num not in num_units or base not in _DEN[den] or power != degree:
        return None
    return num_units[num] / _DEN[den][base] ** degree


def _units_text(kind: str, den: Optional[str], degree: int) -> str:
    if den is None:
        return "um, mm" if kind == "length" else "urad, mrad, rad, deg"
    p = "" if degree == 1 else f"^{degree}"
    n = "um" if kind == "length" else "urad"
    return f"{n}/m{p}, {n}/mm{p}" if den == "length" else f"{n}/rad{p}, {n}/deg{p}"


def parse_value(text, where: str, kind: str = "length", den: Optional[str] = None, degree: int = 0,
                bare_unit: Optional[str] = None, bare_limit: Optional[float] = None,
                limit_hint: str = "") -> float:
    """A tolerance (text with an optional unit, or a number) in the file
    unit of its quantity. ``bare_unit``: the unit of a bare number (default
    the file unit); ``bare_limit``: the largest bare value accepted (file
    unit). ValueError naming ``where`` for anything else."""
    if isinstance(text, bool):
        raise ValueError(f"{where}: expected a number, got {text}")
    if isinstance(text, (int, float)):
        x, unit = float(text), ""
    else:
        m = _VALUE.match(str(text))
        if not m:
            raise ValueError(f"{where}: '{str(text).strip()}' is not a number with an optional unit "
                             f"(e.g. 12um, 0.012mm, 20urad)")
        x, unit = float(m.group(1)), (m.group(2) or "").strip()
    if not math.isfinite(x) or x <= 0:
        raise ValueError(f"{where}: a tolerance must be a positive, finite number, got '{str(text).strip()}'")
    if unit:
        f = _unit_factor(unit, kind, den, degree)
        if f is None:
            raise ValueError(f"{where}: unknown or wrong unit '{unit}' (this tolerance takes "
                             f"{_units_text(kind, den, degree)})")
        return x * f
    if bare_unit:
        x *= _unit_factor(bare_unit, kind, den, degree)
    if bare_limit is not None and x > bare_limit:
        fu = _FILE_UNIT[kind] + (f"/{_FILE_UNIT[den]}" + ("" if degree == 1 else f"^{degree}") if den else "")
        t = str(text).strip()
        small = ("um" if kind == "length" else "urad") + ("" if den is None else "/" + ("m" if den == "length"
                                                                                          else "rad"))
        raise ValueError(f"{where}: {t} {bare_unit or fu} is implausibly large (above {bare_limit:g} {fu}"
                         f"{limit_hint}); a bare number is in {bare_unit or fu}: if you meant "
                         f"{'µm' if kind == 'length' else 'µrad'}, write the unit ({t}{small})")
    return x


def parameter_tolerance(name: str, value, where: Optional[str] = None) -> float:
    """The tolerance of parameter ``name`` (a number in its file unit, or text with a unit)."""
    kind, den, d = dimension(name)
    cls = prior_class(name)
    hint = f", {BARE_LIMIT_FACTOR:g} × the default prior σ of its class {cls}" if cls else ""
    return parse_value(value, where or name, kind, den, d, bare_limit=bare_limit(name), limit_hint=hint)


def check_names(tolerances: Mapping[str, float], names: Iterable[str], what: str, option: str = "--tolerance") -> None:
    """ValueError naming ``option`` and the first tolerance name not in ``names`` (``what``: whose names)."""
    allowed = set(names)
    for n in tolerances:
        if n not in allowed:
            near = difflib.get_close_matches(n, sorted(allowed), 1)
            raise ValueError(f"{option}: {n} is not a parameter of {what}"
                             + (f" (did you mean {near[0]}?)" if near else ""))


def parse_tolerances(items: Optional[Sequence[str]], option: str = "--tolerance",
                     names: Optional[Iterable[str]] = None, what: str = "the machine") -> Dict[str, float]:
    """``NAME=VALUE[unit]`` items (repeated options, each comma separated) as
    name -> tolerance in the parameter's file unit. ``names``: the allowed
    names (the machine's parameters), checked when given."""
    out: Dict[str, float] = {}
    for text in items or ():
        for item in [t for t in str(text).split(",") if t.strip()]:
            if "=" not in item:
                raise ValueError(f"{option}: expected NAME=VALUE (e.g. EX0C=12um or EX0C=0.012), "
                                 f"got '{item.strip()}'")
            k, v = (s.strip() for s in item.split("=", 1))
            if not k:
                raise ValueError(f"{option}: a name is missing before '=' in '{item.strip()}'")
            if k in out:
                raise ValueError(f"{option}: {k} is given twice")
            out[k] = parameter_tolerance(k, v, f"{option} {k}")
    if names is not None:
        check_names(out, names, what, option)
    return out


def check_tolerances(tolerances: Optional[Mapping[str, object]], where: str = "tolerance") -> Dict[str, float]:
    """The Python API's tolerances (name -> number in the file unit, or text with a
    unit) checked as the command line's are."""
    return {str(n): parameter_tolerance(str(n), v, f"{where} {n}") for n, v in (tolerances or {}).items()}


def range_tolerance(value, where: str = VALUE_OPTION) -> Optional[float]:
    """The largest range of an R-test K test (mm; text may carry a length
    unit), None for None; a bare number above :data:`RANGE_BARE_LIMIT` is
    refused as probably µm."""
    if value is None:
        return None
    return parse_value(value, where, "length", bare_limit=RANGE_BARE_LIMIT,
                       limit_hint=" for the range of an R-test K test")


def path_tolerance(value, where: str = PATH_OPTION) -> float:
    """The largest change of the nominal ball bar length between two blocks
    of a program (mm; text may carry a length unit); a bare number above
    :data:`PATH_BARE_LIMIT` is refused as probably µm."""
    return parse_value(value, where, "length", bare_limit=PATH_BARE_LIMIT,
                       limit_hint=" for a bar-length change between two blocks")


def volumetric_tolerance(value, where: str = "--volumetric-tolerance") -> Optional[float]:
    """A volumetric tolerance (mm; text may carry a length unit), None for None."""
    if value is None:
        return None
    return parse_value(value, where, "length", bare_limit=VOLUMETRIC_BARE_LIMIT,
                       limit_hint=" for a predicted tool-point error")
