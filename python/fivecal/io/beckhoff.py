"""Beckhoff TwinCAT 3 CNC (ISG kernel): the files of a vendor export.

The values come from the C++ core (``cpp/src/controllers/beckhoff.cc``: the
universal kinematics TF5240 ID 91 and the TF5280 volumetric tables); this
module only writes and reads them (docs/controllers.md, "Beckhoff TwinCAT
CNC"):

* ``.lis`` -- the channel parameter list lines of the universal kinematics
  (``kinematik[91].*`` or ``trafo[j].*``), one ``name  value`` a line, the old
  value, the change and its 1 sigma in a ``#`` comment;
* ``_volcomp.csv`` -- the TF5280 tables in the ISG CSV layout (a header of
  the argument and the component errors, one record a row, ``//`` comments,
  ``#`` between the axes' blocks), when the export carries tables;
* ``_etalon.txt`` -- the same tables in the Etalon exchange format
  (``[EXX]`` blocks with ``Gridpoints = { argument value ... }``).

``read(path)`` reads any of the three back into ``{name: value}`` with the
export's value names (``kinematik[91].axis[3].point[2]``, ``X[4]``,
``EYX[4]``), for ``--old FILE``.
"""
from __future__ import annotations

import datetime as _dt
import math
import os
import re
from typing import Dict, List, Mapping, Optional, Tuple

from .. import files

COMPONENTS = ("X", "Y", "Z", "A", "B", "C")
_TABLE = re.compile(r"^E([XYZABC])([XYZABC])\[(\d+)\]$")
_GRID = re.compile(r"^([XYZABC])\[(\d+)\]$")
_LIS = re.compile(r"^(kinematik\[91\]|trafo\[\d+\])\.[A-Za-z_]+(\[\d+\])?(\.[A-Za-z_]+(\[\d+\])?)*$")


def _get(obj, name: str, default=None):
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _num(x: float) -> str:
    """Shortest text that reads back as the same float."""
    x = float(x)
    if x == 0:
        return "0"
    if x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _fmt(x, unit: str = "") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    return f"{float(x):.6g}" + (f" {unit}" if unit else "")


def _header(exp, machine, what: str, comment: str) -> List[str]:
    ab = _get(exp, "absorption")
    model = _get(ab, "model", "") if ab is not None else ""
    rms = _get(ab, "rms") if ab is not None else None
    mx = _get(ab, "max") if ab is not None else None
    name = _get(machine, "name", "") if not isinstance(machine, str) else machine
    trip = _get(exp, "round_trip_max")
    trip = _get(exp, "round_trip_max_mm") if trip is None else trip
    when = _get(exp, "date") or _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    lines = [
        f"fivecal export for Beckhoff TwinCAT 3 CNC: {what}",
        f"machine: {name}",
        f"result: {_get(exp, 'result_file') or _get(exp, 'result') or 'n/a'}",
        f"date: {when}",
        f"absorption model: {model or 'n/a'}",
        "error the kinematics cannot absorb (over the working volume): "
        + (f"rms {rms * 1e3:.3f} um, max {mx * 1e3:.3f} um" if rms is not None and mx is not None else "n/a"),
        "round trip through Beckhoff's own kinematics: " + (f"max {trip * 1e3:.3g} um" if trip is not None else "n/a"),
        "each value: new, then in the comment the old value, the change and its 1 sigma (from the "
        "identification's covariance)",
    ]
    return [f"{comment} {line}" for line in lines]


def _rows(exp) -> List[dict]:
    rows = list(_get(exp, "values") or [])
    for i, r in enumerate(rows):
        for key in ("name", "new"):
            if _get(r, key) is None:
                raise ValueError(f"export values[{i}]: no '{key}'")
    return rows


def _tables(rows: List[dict]) -> Dict[str, dict]:
    """axis -> {"grid": [rows], "E<c>": [rows]} for the tables the export carries."""
    out: Dict[str, dict] = {}
    for r in rows:
        name = _get(r, "name")
        g = _GRID.match(name)
        if g:
            out.setdefault(g.group(1), {}).setdefault("grid", []).append(r)
            continue
        t = _TABLE.match(name)
        if t:
            out.setdefault(t.group(2), {}).setdefault("E" + t.group(1), []).append(r)
    return out


def lis_text(exp, machine) -> str:
    rows = _rows(exp)
    lines = _header(exp, machine, "universal kinematics (TF5240, kinematic ID 91), channel parameter list", "#")
    lines.append("# lengths in 0.1 um = 0.0001 mm (P-CHAN-00286, P-CHAN-00293); orientations are direction vectors")
    width = max([len(_get(r, "name")) for r in rows] + [10])
    for r in rows:
        name = _get(r, "name")
        if not _LIS.match(name):
            continue
        unit = _get(r, "unit", "") or ""
        if _get(r, "fixed"):
            note = "fixed by the machine's topology"
        else:
            note = (f"old {_num(_get(r, 'old', 0.0))}, change {_fmt(_get(r, 'change'))} "
                    f"+- {_fmt(_get(r, 'sigma'))}" + (f" {unit}" if unit else ""))
        lines.append(f"{name:<{width}}  {_num(_get(r, 'new')):>16}   # {note}")
    return "\n".join(lines) + "\n"


def _table_blocks(exp) -> List[Tuple[str, List[dict], List[str], Dict[str, List[dict]]]]:
    blocks = []
    for axis, t in _tables(_rows(exp)).items():
        grid = sorted(t.get("grid", []), key=lambda r: int(_GRID.match(_get(r, "name")).group(2)))
        comps = [f"E{c}{axis}" for c in COMPONENTS if f"E{c}" in t]
        cols = {c: sorted(t[c[:2]], key=lambda r: int(_TABLE.match(_get(r, "name")).group(3))) for c in comps}
        for c in comps:
            if len(cols[c]) != len(grid):
                raise ValueError(f"export: {c} has {len(cols[c])} values, its grid {axis} has {len(grid)}")
        blocks.append((axis, grid, comps, cols))
    return blocks


def csv_text(exp, machine) -> str:
    lines = _header(exp, machine, "volumetric compensation tables (TF5280), ISG CSV format", "//")
    for b, (axis, grid, comps, cols) in enumerate(_table_blocks(exp)):
        if b:
            lines.append("#")
        units = {c: _get(cols[c][0], "unit", "") for c in comps}
        lines.append(f"// component errors of the {axis} axis ({', '.join(f'{c} {u}' for c, u in units.items())}), "
                     f"argument {axis} in {_get(grid[0], 'unit', '')}")
        lines.append(" ".join([axis] + comps))
        for i, g in enumerate(grid):
            lines.append(" ".join([_num(_get(g, "new"))] + [_num(_get(cols[c][i], "new")) for c in comps]))
            lines.append("// old " + " ".join(_num(_get(cols[c][i], "old", 0.0)) for c in comps)
                         + " | 1 sigma " + " ".join(_fmt(_get(cols[c][i], "sigma")) for c in comps))
    return "\n".join(lines) + "\n"


def etalon_text(exp, machine) -> str:
    lines = _header(exp, machine, "volumetric compensation tables (TF5280), Etalon exchange format "
                    "(variant 'Vendor')", "//")
    for axis, grid, comps, cols in _table_blocks(exp):
        for c in comps:
            lines.append(f"[{c}]")
            lines.append(f"// {_get(cols[c][0], 'unit', '')} over {axis} in {_get(grid[0], 'unit', '')}")
            lines.append("Gridpoints = {")
            for g, r in zip(grid, cols[c]):
                lines.append(f"    {_num(_get(g, 'new'))} {_num(_get(r, 'new'))}   "
                             f"// old {_num(_get(r, 'old', 0.0))}, change {_fmt(_get(r, 'change'))} "
                             f"+- {_fmt(_get(r, 'sigma'))}")
            lines.append(f"}}  // end of {c}")
    return "\n".join(lines) + "\n"


def write(exp, machine) -> Dict[str, str]:
    """File name suffix -> text: ``.lis`` always, the tables when the export has them."""
    out = {".lis": lis_text(exp, machine)}
    if _tables(_rows(exp)):
        out["_volcomp.csv"] = csv_text(exp, machine)
        out["_etalon.txt"] = etalon_text(exp, machine)
    return out


def _float(text: str, path: str, lineno: int, what: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{path}:{lineno}: {what} '{text}' is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"{path}:{lineno}: {what} '{text}' is not finite")
    return v


def _strip(line: str, marks: Tuple[str, ...]) -> str:
    for m in marks:
        i = line.find(m)
        if i >= 0:
            line = line[:i]
    return line.strip()


def _read_lis(text: str, path: str) -> Dict[str, float]:
    out: Dict[str, float] = {}
    for n, raw in enumerate(text.splitlines(), 1):
        line = _strip(raw, ("#",))
        if not line:
            continue
        parts = line.split()
        if len(parts) != 2 or not _LIS.match(parts[0]):
            raise ValueError(f"{path}:{n}: expected 'kinematik[91].<name> <value>' or 'trafo[j].<name> <value>', "
                             f"got '{raw.strip()}'")
        if parts[0] in out:
            raise ValueError(f"{path}:{n}: {parts[0]} given twice")
        out[parts[0]] = _float(parts[1], path, n, parts[0])
    if not out:
        raise ValueError(f"{path}: no kinematik[91] / trafo[j] values")
    return out


def _read_csv(text: str, path: str) -> Dict[str, float]:
    out: Dict[str, float] = {}
    header: Optional[List[str]] = None
    row = 0
    for n, raw in enumerate(text.splitlines(), 1):
        if raw.strip().startswith("#"):
            header = None  # a file break: a new header follows
            continue
        line = _strip(raw, ("//",))
        if not line:
            continue
        parts = line.split()
        if header is None:
            arg = parts[0]
            bad = [p for p in parts[1:] if not re.match(rf"^E[XYZABC]{re.escape(arg)}$", p)]
            if arg not in COMPONENTS or len(parts) < 2 or bad:
                raise ValueError(f"{path}:{n}: expected a header '<axis> E<c><axis> ...' (e.g. 'X EXX EYX'), "
                                 f"got '{raw.strip()}'")
            header, row = parts, 0
            continue
        if len(parts) != len(header):
            raise ValueError(f"{path}:{n}: {len(parts)} values, the header names {len(header)}")
        for name, t in zip(header, parts):
            key = f"{name}[{row}]"
            if key in out:
                raise ValueError(f"{path}:{n}: {key} given twice")
            out[key] = _float(t, path, n, name)
        row += 1
    if not out:
        raise ValueError(f"{path}: no table records")
    return out


def _read_etalon(text: str, path: str) -> Dict[str, float]:
    out: Dict[str, float] = {}
    block: Optional[str] = None
    inside = False
    row = 0
    for n, raw in enumerate(text.splitlines(), 1):
        line = _strip(raw, ("//",))
        if not line:
            continue
        m = re.match(r"^\[(E([XYZABC])([XYZABC])|[XYZABC]0[XYZABC])\]$", line)
        if not inside and m:
            block, row = m.group(1), 0
            continue
        if block is None:
            raise ValueError(f"{path}:{n}: expected a block '[EXX]', got '{raw.strip()}'")
        if not inside and re.match(r"^Gridpoints\s*=\s*\{$", line):
            if not block.startswith("E"):
                raise ValueError(f"{path}:{n}: {block} is a position error, it takes 'VALUE = ...'")
            inside = True
            continue
        if not inside:
            v = re.match(r"^VALUE\s*=\s*(\S+)$", line)
            if not v:
                raise ValueError(f"{path}:{n}: expected 'Gridpoints = {{' or 'VALUE = ...' in [{block}], "
                                 f"got '{raw.strip()}'")
            out[block] = _float(v.group(1), path, n, block)
            continue
        if line == "}":
            inside = False
            continue
        parts = line.split()
        if len(parts) != 2:
            raise ValueError(f"{path}:{n}: expected '<argument> <value>' in [{block}], got '{raw.strip()}'")
        axis = block[2]
        arg = _float(parts[0], path, n, f"{axis} argument")
        key = f"{axis}[{row}]"
        if key in out and out[key] != arg:
            raise ValueError(f"{path}:{n}: [{block}] row {row} at {axis} = {parts[0]}, another block has "
                             f"{_num(out[key])} there")
        out[key] = arg
        out[f"{block}[{row}]"] = _float(parts[1], path, n, block)
        row += 1
    if inside:
        raise ValueError(f"{path}: [{block}] not closed with '}}'")
    if not out:
        raise ValueError(f"{path}: no Etalon blocks")
    return out


def _read_one(path) -> Dict[str, float]:
    text = files.read_text(path, "beckhoff file")
    body = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.strip().startswith(("#", "//"))]
    first = body[0] if body else ""
    p = os.fspath(path)
    if first.startswith(("kinematik[", "trafo[")):
        return _read_lis(text, p)
    if first.startswith("["):
        return _read_etalon(text, p)
    return _read_csv(text, p)


def read(path) -> Dict[str, float]:
    """The values a Beckhoff file states (a ``.lis`` channel list, an ISG CSV
    table file or an Etalon exchange file), by the export's value names. A
    ``.lis`` with the ISG CSV tables beside it (``NAME.lis`` and
    ``NAME_volcomp.csv``, as an export writes them) reads as both: the
    controller's current kinematics and tables (``--old``)."""
    out = _read_one(path)
    p = os.fspath(path)
    if p.endswith(".lis"):
        tables = p[: -len(".lis")] + "_volcomp.csv"
        if os.path.isfile(tables):
            out.update(_read_one(tables))
    return out
