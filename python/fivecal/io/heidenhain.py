"""Heidenhain TNC kinematics description rows: the writer and reader of
``fivecal export heidenhain`` (docs/controllers.md, "Heidenhain TNC").

The rows, their values, the conventions and the round trip are the C++
core's (``cpp/src/controllers/heidenhain.cc``); this module only lays them
out. KinematicsDesign's own file format is not public, so the ``.tab`` file
is the description table's layout (``NR KEY AXIS COORD``, iTNC 530 HSCI
technical manual, July 2013, p. 722 and p. 670) with the old value, the
change and its 1 sigma in further columns: **values to enter** in the
machine's kinematics table, not a file to load. The ``.csv`` has the same
rows with the unit and the source of each.

``read(path)`` reads a ``.tab`` or ``.csv`` written here (possibly edited to
the values the control holds: ``--old FILE``) back to ``{name: value}``.
"""
from __future__ import annotations

import csv
import datetime as _dt
import io
import math
import re
from typing import Dict, List, Mapping, Optional, Tuple

from fivecal import files

NAME = "heidenhain"
TAB_NAME = "FIVECAL_KINEMATICS.TAB"

_ROW = re.compile(r"^row (\d+) (ToolAxis|Trans|MachAxis|MachBase)(?: ([XYZABC]))?$")
_COLUMNS = ["NR", "KEY", "AXIS", "COORD", "OLD", "CHANGE", "SIGMA_1", "UNIT"]


def _split(name: str) -> Tuple[int, str, str]:
    m = _ROW.match(name)
    if not m:
        raise ValueError(f"heidenhain: value {name!r} is not a row name 'row <NR> <KEY> [<AXIS>]'")
    return int(m.group(1)), m.group(2), m.group(3) or ""


def _has_coord(key: str) -> bool:
    return key == "Trans"


def _fmt(v: Optional[float], unit: str) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    # 1 nm in mm; 1e-9 deg (2e-11 rad) keeps a 500 mm lever below 1 nm.
    digits = 6 if unit == "mm" else 9
    text = f"{float(v):.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text


def _get(obj, name: str, default=None):
    if isinstance(obj, Mapping):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _header(exp, machine) -> List[str]:
    ab = _get(exp, "absorption")
    model = _get(ab, "model", "?")
    result = _get(exp, "result") or "-"
    lines = [
        "fivecal export heidenhain: kinematics description rows (VALUES TO ENTER, not a file to load:",
        "KinematicsDesign's file format is not public). Columns: the table's NR KEY AXIS COORD (iTNC 530 HSCI",
        "technical manual, July 2013, p. 722), then the old value, the change and its 1 sigma.",
        f"machine {machine.name} ({machine.topology}); result {result}; "
        f"written {_dt.datetime.now(_dt.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}",
        f"absorption model {model}; options " + ", ".join(f"{k}={v}" for k, v in
                                                          sorted((_get(exp, 'options') or {}).items())),
    ]
    if ab is not None:
        um = lambda v: f"{1000 * float(v):.2f} um"  # noqa: E731
        lines.append(f"tool point error over the working volume: before rms {um(_get(ab, 'rms_old', 0))} "
                     f"max {um(_get(ab, 'max_old', 0))} (Cycle 451's 'measured dispersion'); left after these "
                     f"values (the controller's model cannot absorb it) rms {um(_get(ab, 'rms', 0))} "
                     f"max {um(_get(ab, 'max', 0))} (its 'optimised dispersion')")
    rt = _get(exp, "round_trip_max")
    if rt is not None:
        lines.append(f"round trip: these rows through the TNC's kinematics reproduce fivecal's absorbed model "
                     f"to {1000 * float(rt):.4f} um")
    lines.append("The machine builder's table has its own row numbers and further rows (CMO, TOOLFILE, ...): "
                 "enter each value in the row of the same KEY and AXIS at the same place in the chain.")
    return lines


def _rows(exp) -> List[dict]:
    out = []
    for v in _get(exp, "values"):
        nr, key, axis = _split(v["name"])
        out.append(dict(v, nr=nr, key=key, axis=axis))
    return out


def tab_text(exp, machine) -> str:
    out = [f"; {line}" for line in _header(exp, machine)]
    out.append(f"BEGIN {TAB_NAME} MM")
    widths = [4, 9, 5, 16, 16, 14, 14, 4]
    out.append(" ".join(f"{c:<{w}}" for c, w in zip(_COLUMNS, widths)).rstrip())
    for r in _rows(exp):
        unit = r.get("unit", "")
        if _has_coord(r["key"]):
            cells = [str(r["nr"]), r["key"], r["axis"], _fmt(r.get("new"), unit), _fmt(r.get("old"), unit),
                     _fmt(r.get("change"), unit), _fmt(r.get("sigma"), unit), unit]
        else:
            cells = [str(r["nr"]), r["key"], r["axis"] or "-", "-", "-", "-", "-", "-"]
        out.append(" ".join(f"{c:<{w}}" for c, w in zip(cells, widths)).rstrip())
    out.append("[END]")
    return "\n".join(out) + "\n"


def csv_text(exp, machine) -> str:
    buf = io.StringIO()
    for line in _header(exp, machine):
        buf.write(f"# {line}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["nr", "key", "axis", "coord", "old", "change", "sigma", "unit", "source"])
    for r in _rows(exp):
        unit = r.get("unit", "")

        def num(x):
            text = _fmt(x, unit)
            return "" if text == "-" else text
        if _has_coord(r["key"]):
            w.writerow([r["nr"], r["key"], r["axis"], num(r.get("new")), num(r.get("old")), num(r.get("change")),
                        num(r.get("sigma")), unit, r.get("source", "")])
        else:
            w.writerow([r["nr"], r["key"], r["axis"], "", "", "", "", "", r.get("source", "")])
    return buf.getvalue()


def write(exp, machine) -> Dict[str, str]:
    """File name suffix -> text: ``.tab`` (the table's layout) and ``.csv``."""
    return {".tab": tab_text(exp, machine), ".csv": csv_text(exp, machine)}


def _number(text: str, where: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"{where}: expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{where}: expected a finite number, got {text!r}")
    return v


def _read_tab(text: str, path: str) -> Dict[str, float]:
    values: Dict[str, float] = {}
    columns: Optional[List[str]] = None
    begun = ended = False
    for n, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        where = f"{path}: line {n}"
        if not line or line.startswith(";"):
            continue
        if ended:
            raise ValueError(f"{where}: text after [END]")
        if not begun:
            if not re.match(r"^BEGIN \S+ (MM|INCH)$", line):
                raise ValueError(f"{where}: expected 'BEGIN <name>.TAB MM', got {line!r}")
            if line.endswith("INCH"):
                raise ValueError(f"{where}: the table is in inch; fivecal reads mm tables")
            begun = True
            continue
        if columns is None:
            columns = line.split()
            for c in ("NR", "KEY", "AXIS", "COORD"):
                if c not in columns:
                    raise ValueError(f"{where}: the column line has no {c} column ({' '.join(columns)})")
            continue
        if line == "[END]":
            ended = True
            continue
        cells = line.split()
        if len(cells) < 4:
            raise ValueError(f"{where}: expected NR KEY AXIS COORD, got {line!r}")
        row = dict(zip(columns, cells))
        nr, key, axis = row["NR"], row["KEY"], row["AXIS"]
        if not nr.isdigit():
            raise ValueError(f"{where}: NR {nr!r} is not a row number")
        if key not in ("ToolAxis", "Trans", "MachAxis", "MachBase"):
            raise ValueError(f"{where}: KEY {key!r}: fivecal reads ToolAxis, Trans, MachAxis, MachBase rows")
        if key == "Trans":
            if axis not in tuple("XYZABC"):
                raise ValueError(f"{where}: AXIS {axis!r}: a Trans row takes X, Y, Z, A, B or C")
            name = f"row {int(nr)} Trans {axis}"
            if name in values:
                raise ValueError(f"{where}: row {int(nr)} given twice")
            values[name] = _number(row["COORD"], f"{where} COORD")
    if not begun:
        raise ValueError(f"{path}: no 'BEGIN <name>.TAB MM' line")
    if not ended:
        raise ValueError(f"{path}: no [END] line")
    return values


def _read_csv(text: str, path: str) -> Dict[str, float]:
    values: Dict[str, float] = {}
    lines = [(n, line) for n, line in enumerate(text.splitlines(), start=1) if line and not line.startswith("#")]
    if not lines:
        raise ValueError(f"{path}: no rows")
    reader = csv.reader([line for _, line in lines])
    header = next(reader)
    for c in ("nr", "key", "axis", "coord"):
        if c not in header:
            raise ValueError(f"{path}: line {lines[0][0]}: the header has no {c!r} column")
    for (n, _), cells in zip(lines[1:], reader):
        where = f"{path}: line {n}"
        if len(cells) != len(header):
            raise ValueError(f"{where}: {len(cells)} fields, the header has {len(header)}")
        row = dict(zip(header, cells))
        if row["key"] != "Trans":
            continue
        if row["axis"] not in tuple("XYZABC") or not row["nr"].isdigit():
            raise ValueError(f"{where}: expected a row number and an axis X Y Z A B C, got "
                             f"{row['nr']!r} {row['axis']!r}")
        values[f"row {int(row['nr'])} Trans {row['axis']}"] = _number(row["coord"], f"{where} coord")
    return values


def read(path: str) -> Dict[str, float]:
    """The rows' values of a ``.tab`` or ``.csv`` written by :func:`write`
    (``{"row 12 Trans Z": -120.0, ...}``); a malformed line is refused by number."""
    text = files.read_text(path)
    if str(path).lower().endswith(".csv"):
        return _read_csv(text, str(path))
    return _read_tab(text, str(path))
