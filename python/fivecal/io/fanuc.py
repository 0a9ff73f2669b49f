"""FANUC Series 30i/31i/32i tool centre point parameters as a parameter list
(docs/controllers.md, "FANUC").

:func:`write` turns a vendor export (``fivecal.io.controllers.vendor_export``
for the vendor ``fanuc``: the values the C++ core's ``FanucVendor`` maps,
old beside new, the change's 1σ, the absorption) into a parameter list a
user keys in at the control's parameter screen: one line per parameter
(number, path, new value in the input unit, old value, change ± 1σ, unit,
what the manual calls it and where). :func:`read` reads such a list back
(``fivecal export fanuc --old FILE``: the control's current values).

The list is a fivecal layout, not a FANUC file: the public copies of the
parameter manual found (B-63950EN/02 §3.3) give the reader/puncher format
of bit and axis parameters but not of the real path parameters these are,
so no ``N19703...`` memory-card file is written (docs/controllers.md).
Numbers are computed in the C++ core; this module only formats and parses.
"""
from __future__ import annotations

import datetime
import math
from typing import Any, Dict, List, Mapping

from ..files import read_text

__all__ = ["write", "read", "resolution", "SUFFIX", "DECIMALS"]

#: The file the export writes: DIR/fanuc.txt.
SUFFIX = ".txt"

#: Decimals of a length in mm at the least input increment (A-79348E sheets
#: 82-84: "Depend on the increment system of the applied axis"; IS-B 0.001
#: mm, IS-C 0.0001 mm).
DECIMALS = {"IS-B": 3, "IS-C": 4}

def resolution(options: Mapping[str, str]) -> float:
    """The least input increment (mm) the list is written to: a value read
    back differs from the export's by up to half of it."""
    return 10.0 ** -DECIMALS[dict(options or {}).get("increment", "IS-B")]


_HEAD = ("No.", "path", "new", "old", "change ± 1σ", "unit", "meaning; source")


def _get(obj: Any, name: str, default: Any = None) -> Any:
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _num(v: Any, unit: str, decimals: int) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    if unit == "":
        return f"{int(round(float(v)))}"
    return f"{float(v):.{decimals}f}"


def _um(v: Any) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{1000 * float(v):.2f} µm"


def write(exp: Any, machine: Any) -> Dict[str, str]:
    """The parameter list of a FANUC export: ``{".txt": text}``.

    ``exp`` is a ``VendorExport`` (attributes or keys ``values``: dicts with
    name, unit, old, new, change, sigma, source, fixed; ``absorption`` with
    ``model``, ``rms``, ``max``; ``options``; optionally ``round_trip_max``
    and ``result`` (the result file's name)).
    """
    options = dict(_get(exp, "options", None) or {})
    increment = options.get("increment")
    if increment not in DECIMALS:
        raise ValueError(f"fanuc: option increment={increment!r}: expected IS-B or IS-C (--set increment=IS-B)")
    decimals = DECIMALS[increment]
    path = options.get("path", "1")
    values: List[Mapping[str, Any]] = list(_get(exp, "values", []))
    ab = _get(exp, "absorption")
    model = _get(ab, "model", "?")
    code = next((v.get("new") for v in values if v.get("name") == "19680"), None)
    name = _get(machine, "name", "")
    topology = _get(machine, "topology", "")
    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        "# FANUC Series 30i/31i/32i, tool centre point control for 5-axis machining: parameters by fivecal",
        "# source: FANUC A-79348E, Series 30i-MODEL A, Tool center point control for 5-axis machining, "
        "Additional manual (sheets n/88)",
        f"# machine: {name} ({topology})   result: {_get(exp, 'result', None) or '-'}   written: {now}",
        f"# model: {model} (No. 19680 = {_num(code, '', 0)})   path: {path}   "
        f"increment: {increment} ({10.0 ** -decimals:.{decimals}f} mm)",
        f"# tool-point error these parameters cannot absorb, over the working volume: rms {_um(_get(ab, 'rms'))}, "
        f"max {_um(_get(ab, 'max'))}",
    ]
    rt = _get(exp, "round_trip_max", _get(exp, "round_trip_max_mm"))
    if rt is not None:
        lines.append(f"# round trip, the manual's transformation with the new values against fivecal's model: "
                     f"max {_um(rt)} (before rounding to the increment)")
    lines += [
        "# Key in the new values (parameter screen, parameter input); the codes (unit 'code') are the mechanism",
        "# as fivecal's machine file has it and must already stand so: they are never changed by an export.",
        "# Then run the check of `fivecal docs controllers`, 'Verify after loading'.",
        "# " + " | ".join(_HEAD),
    ]
    for v in values:
        unit = v.get("unit", "")
        fixed = bool(v.get("fixed", False))
        change = v.get("change")
        sigma = v.get("sigma")
        if fixed:
            delta = "(code)" if unit == "" else "(unchanged)"
        else:
            # σ is often below the increment: two more decimals, so it is not shown as 0
            delta = f"{float(change):+.{decimals}f} ± {_num(sigma, unit, decimals + 2)}"
        lines.append(" | ".join([
            str(v["name"]), str(path), _num(v.get("new"), unit, decimals), _num(v.get("old"), unit, decimals),
            delta, unit or "code", str(v.get("source", "")).replace("|", "/"),
        ]))
    return {SUFFIX: "\n".join(lines) + "\n"}


def read(path: str) -> Dict[str, float]:
    """The values of a FANUC parameter list (the ``new`` column): name -> value.

    A line is ``name | path | value [| ...]``; ``#`` starts a comment line.
    A malformed line or a name given twice is a ``ValueError`` naming the
    file and line.
    """
    out: Dict[str, float] = {}
    for n, raw in enumerate(read_text(path, "FANUC parameter list").splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = [f.strip() for f in line.split("|")]
        if len(fields) < 3 or not fields[0]:
            raise ValueError(f"{path}:{n}: expected 'No. | path | value | ...', got {raw.strip()!r}")
        try:
            value = float(fields[2])
        except ValueError:
            raise ValueError(f"{path}:{n}: parameter {fields[0]}: value {fields[2]!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"{path}:{n}: parameter {fields[0]}: value {fields[2]!r} is not finite")
        if fields[0] in out:
            raise ValueError(f"{path}:{n}: parameter {fields[0]} given twice")
        out[fields[0]] = value
    if not out:
        raise ValueError(f"{path}: no parameter lines (expected 'No. | path | value | ...')")
    return out
