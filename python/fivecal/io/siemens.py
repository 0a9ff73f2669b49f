"""Siemens SINUMERIK 840D sl / ONE: the swivel data record as a part program
(docs/controllers.md, "Siemens SINUMERIK").

* ``write(exp, machine)``: the ``.MPF`` text of ``$TC_CARRk[n]=value``
  assignments a user runs on the controller, old value, change and its 1 sigma
  beside each, under a header saying what was absorbed and what is left.
* ``read(path)``: the assignments of such a program (or of a read-out of the
  record) as ``{name: value}``, for ``fivecal export siemens --old``.

The record's values, their meaning and the kinematics that checks them are the
C++ core's (``cpp/src/controllers/siemens.cc``); this module only formats and
parses text.
"""
from __future__ import annotations

import datetime
import math
import re
from typing import Dict, List, Mapping

from .. import files
from ..machine import Machine

#: decimals written: mm to 1 nm, the axis vectors' components to 1e-9 (a
#: direction rounded to 1e-6 would move a point 500 mm away by 0.5 um); the
#: variables are REAL (programming guide 04.00 §15.2 p. 15-512)
DECIMALS = {"mm": 6, "": 9}
#: $TC_CARR23: the kinematics type letter; Values carry its character code
TYPE_NAMES = {"T": "swivel head", "P": "swivel table", "M": "swivel head + swivel table (mixed)"}
#: variables whose value is an axis identifier or a string (programming guide
#: 04.00 §15.2: $TC_CARR21/22 AXIS; $TC_CARR34..36 names): read, not returned
_NOT_NUMBERS = {21, 22, 34, 35, 36}
#: rotary axis offsets and their fine offsets: fivecal's record assumes the
#: rotary axes' zero is the machine file's (W1 08/2005 §2.5: a value not 0
#: makes that position the initial state)
_ZERO_ASSUMED = {24, 25, 64, 65}
#: the record's geometry: I1 1..3, I2 4..6, V1 7..9, V2 10..12, I3 15..17,
#: I4 18..20, the type 23; what --old compares (the rest of a read-out is
#: left alone: angles, Hirth gearing, limits, names, fine offsets)
_GEOMETRY = set(range(1, 13)) | set(range(15, 21)) | {23}
#: the vectors a type does not use (the manual's TOOLCARRIER <=> TRAORI table,
#: commissioning manual 12/2017 §21.7 p. 572; as SiemensVendor::Vectors)
_UNUSED = {"T": {"I4": (18, 19, 20)}, "P": {"I1": (1, 2, 3)}, "M": {}}

_ASSIGN = re.compile(r"\$TC_CARR(\d+)\[(\d+)\]\s*=\s*(\"[^\"]*\"|'[^']*'|[^\s;]+)", re.IGNORECASE)
_BLOCK_NUMBER = re.compile(r"^N\d+\s*", re.IGNORECASE)
_END = re.compile(r"^M(2|17|30)$", re.IGNORECASE)


def _get(obj, name, default=None):
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def _fixed(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}"
    # a value that rounds to zero is written 0, not -0
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def _value_text(value: float, unit: str) -> str:
    return _fixed(value, DECIMALS.get(unit, 6))


def _change_text(change: float, sigma: float, unit: str) -> str:
    # reports show um (offsets) and 1e-6 (axis vector components ~ urad)
    scale, label = (1e3, "um") if unit == "mm" else (1e6, "e-6")
    c = _fixed(change * scale, 2)
    s = f"change {c if c.startswith('-') else '+' + c} {label}"
    if math.isfinite(sigma):
        return s + f" +- {_fixed(sigma * scale, 2)} {label} (1 sigma)"
    return s + ", 1 sigma not determined (no covariance)"


def _letter(code) -> str:
    """The kinematics type letter a $TC_CARR23 value codes ('?' for none)."""
    x = _num(code)
    return next((t for t in TYPE_NAMES if x == ord(t)), "?")


def _record_number(names: List[str]) -> str:
    found = {m.group(2) for m in (_ASSIGN.match(n + "=0") for n in names) if m}
    if len(found) != 1:
        raise ValueError(f"siemens: the values name {sorted(found) or 'no'} swivel data records; one expected")
    return found.pop()


def write(exp, machine: Machine) -> Dict[str, str]:
    """The part program (``{".MPF": text}``) that sets the swivel data record
    to the export's new values. ``exp`` is a ``fivecal.io.controllers``
    vendor export: ``values`` (dicts name, unit, old, new, change, sigma,
    source, fixed), ``absorption`` (model, rms, max, rms_old, max_old, mm),
    ``round_trip_max`` (mm); ``result`` (the result file) and ``date`` when known."""
    values = list(_get(exp, "values", []))
    if not values:
        raise ValueError("siemens: the export has no values")
    n = _record_number([v["name"] for v in values])
    ab = _get(exp, "absorption")
    type_value = next((v for v in values if v["name"].upper().startswith("$TC_CARR23[")), None)
    if type_value is None:
        raise ValueError("siemens: the export has no kinematics type $TC_CARR23")
    letter = _letter(type_value["new"])
    if letter == "?":
        raise ValueError(f"siemens: {type_value['name']}: {type_value['new']!r} codes no kinematics type T, P or M")
    date = _get(exp, "date") or datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    um = lambda x: f"{1e3 * _num(x):.2f} um"  # noqa: E731
    lines = [
        f"; fivecal: swivel data record {n} for Siemens SINUMERIK 840D sl / ONE (TOOLCARRIER; CYCLE800, TRAORI)",
        f"; machine {machine.name} ({machine.topology}), kinematics type {letter} ({TYPE_NAMES.get(letter, '?')})",
        f"; identification result {_get(exp, 'result') or '(not named)'}, written {date}",
        f"; absorbed into the model {_get(ab, 'model', '?')}: the pivots and directions of both rotary axes",
        f"; error this record cannot absorb over the working volume: rms {um(_get(ab, 'rms'))}, "
        f"max {um(_get(ab, 'max'))} (with the nominal record: rms {um(_get(ab, 'rms_old'))}, "
        f"max {um(_get(ab, 'max_old'))})",
        f"; the record's own transformation with the new values reproduces the absorbed model "
        f"within {um(_get(exp, 'round_trip_max', _get(exp, 'round_trip_max_mm')))}",
        "; each line: the new value; the old one, the change and its 1 sigma from the identification",
        "; offset vectors I1..I4 in mm, rotary axis vectors V1, V2 (directions, unit length)",
        "; sources: SINUMERIK Operate commissioning manual 12/2017 (6FC5397-1DP40-6BA1) §21.7 pp. 568, 572;",
        ";   03/2013 (6FC5397-1DP40-3BA1) §22.6 p. 502; function manual W1 08/2005 (6FC5397-0BP10-0BA0) §2.5",
        "; fine offsets $TC_CARR41..60 (added when SD42974 $SC_TOCARR_FINE_CORRECTION = 1, W1 p. 2-91)",
        ";   are left as they are: new = old + change holds for the sum",
        "; the values take effect once this program has started (commissioning manual 12/2017 p. 568);",
        ";   then run the sphere check: `fivecal docs controllers`, 'Verify after loading'",
    ]
    for v in values:
        name, unit = v["name"], v.get("unit", "")
        if v["name"].upper().startswith("$TC_CARR23["):
            was = _letter(v.get("old"))
            lines.append(f'{name}="{letter}" ; kinematics type, old "{was}"')
            continue
        new, old = _num(v["new"]), _num(v.get("old"))
        if not math.isfinite(new):
            raise ValueError(f"siemens: {name}: the new value is not a number ({v['new']!r})")
        lines.append(f"{name}={_value_text(new, unit)} ; old {_value_text(old, unit)}, "
                     + _change_text(_num(v.get("change")), _num(v.get("sigma")), unit))
    lines.append("M30 ; end of program")
    return {".MPF": "\n".join(lines) + "\n"}


def parse(text: str, path: str = "<text>") -> Dict[str, float]:
    """The ``$TC_CARRk[n]`` assignments of a part program: ``{name: value}``
    (the kinematics type letter as its character code). A line that is not
    a comment, an assignment, a block number, a program header or its end
    is refused by number."""
    out: Dict[str, float] = {}
    where: Dict[str, int] = {}
    for i, raw in enumerate(text.splitlines(), start=1):
        line = raw.split(";", 1)[0].strip()
        if not line or line.startswith("%") or _END.match(line):
            continue
        line = _BLOCK_NUMBER.sub("", line)
        if not line:
            continue
        pos = 0
        found = False
        for m in _ASSIGN.finditer(line):
            if line[pos:m.start()].strip():
                break
            pos = m.end()
            found = True
            k, rec, value = int(m.group(1)), m.group(2), m.group(3)
            name = f"$TC_CARR{k}[{rec}]"
            if k in _NOT_NUMBERS:
                continue
            if value[0] in "\"'":
                letter = value[1:-1].upper()
                if k != 23 or letter not in TYPE_NAMES:
                    raise ValueError(f"{path}: line {i}: {name}={value}: expected a number"
                                     + (" or the kinematics type T, P or M" if k == 23 else ""))
                number = float(ord(letter))
            else:
                try:
                    number = float(value)
                except ValueError:
                    raise ValueError(f"{path}: line {i}: {name}={value}: not a number") from None
                if not math.isfinite(number):
                    raise ValueError(f"{path}: line {i}: {name}={value}: not a finite number")
            if k in _ZERO_ASSUMED and number != 0.0:
                raise ValueError(
                    f"{path}: line {i}: {name}={value}: a rotary axis offset other than 0; fivecal's record "
                    "takes the rotary axes' zero from the machine file (give a machine file whose zero is "
                    "this offset, and a file without it)")
            if name in out:
                raise ValueError(f"{path}: line {i}: {name} is set again (first on line {where[name]})")
            out[name] = number
            where[name] = i
        if not found or line[pos:].strip():
            raise ValueError(f"{path}: line {i}: '{raw.strip()}' is not an assignment $TC_CARRk[n]=value")
    if not out:
        raise ValueError(f"{path}: no $TC_CARRk[n]=value assignment")
    # a vector the record's type does not use is dropped when 0; another
    # value would be a kinematics fivecal's model of that type does not have
    for name, code in list(out.items()):
        m = _ASSIGN.match(name + "=0")
        if int(m.group(1)) != 23:
            continue
        rec, letter = m.group(2), chr(int(code))
        for vec, numbers in _UNUSED[letter].items():
            for k in numbers:
                key = f"$TC_CARR{k}[{rec}]"
                if out.get(key, 0.0) != 0.0:
                    raise ValueError(f"{path}: line {where[key]}: {key}={out[key]!r}: {vec} of a type {letter} "
                                     f"record is not 0; the manual names no {vec} for type {letter} "
                                     "(commissioning manual 12/2017 §21.7 p. 572), so fivecal has no model of it")
                out.pop(key, None)
    return {n: v for n, v in out.items() if int(_ASSIGN.match(n + "=0").group(1)) in _GEOMETRY}


def read(path) -> Dict[str, float]:
    """The values a ``.MPF`` of assignments (as :func:`write` writes, or as
    the controller reads the record out) sets: ``{name: value}``."""
    return parse(files.read_text(path, "swivel data record"), str(path))
