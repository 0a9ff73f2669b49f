"""Instrument tables (CSV or whitespace text) to fivecal datasets.

One row per observation, a header row naming the columns. The kinds:

* ``probing``: a probing log, axis positions at the trigger, the ``target``
  touched (a facet or sphere of the artefact) and the approach direction;
* ``dbb``: a ball bar trace, axis positions and the ``reading``;
* ``ball3d`` (alias ``rtest``): R-test / 3D ball triples, axes and ``dx dy dz``;
* ``point`` (alias ``tracker``): a fixed instrument (laser tracker, camera,
  CMM) measuring a target on the machine, axes and ``measured_x|y|z``; the
  axes may also come as a joint layout (``joint``, ``position``: one joint
  moved, the others at home), and the instrument's nominal pose from a rigid
  alignment (:mod:`fivecal.io.alignment`) when none is given;
* ``pose`` (alias ``6d``): a 6D tracker or camera fiducial, as ``point``
  plus the measured orientation ``measured_rx|ry|rz`` (rotation vector, rad
  unless the header names ``deg``);
* ``distance`` (alias ``tracer``): a tracking interferometer or laser
  tracer at one or more stations, axes, ``reading`` and ``station``; each
  station's nominal position and dead length from the sidecar;
* ``machined`` (alias ``cmm``): a CMM report of a machined test part, one
  face per row: the axes of the cut, ``point_x|y|z``, ``normal_x|y|z``,
  ``measured`` (the deviation), optionally the reference cut of a step;
* ``fivecal``: rows already in fivecal's terms, with a ``type`` column: any
  registered kind, its columns named after its dataset keys (the registry's
  ``json_keys``); :func:`write_table` writes such a table.

Units come from the header (``reading_um``, ``B_rad``, ``dx [um]``) through
:func:`fivecal.units.column_unit`, else from the options. Every bad cell is
refused naming the file, the line and the column. The user documentation is
docs/import.md (machined reports and the generic table: docs/formats.md).
"""
from __future__ import annotations

import csv
import difflib
import inspect
import io
import math
import os
import re
import sys
import warnings
from typing import Iterable, Mapping, Optional, Sequence, Union

from .. import _core, files, plausibility, schema, simulation
from .. import units as _units
from ..dataset import Dataset
from ..machine import Machine, RadiansWarning
from ..units import looks_like_radians, radians_message
from . import alignment
from . import rotations as _rot

#: the import of rows in fivecal's own terms (a ``type`` column, any
#: registered kind): the one table that is no kind's
GENERIC = "fivecal"
#: what a generic table's rows need besides their type
_GENERIC_EXPECTED = "type and the keys of each row's type (target, setup, reading, measured_x ...) [id]"
#: a circle-point-analysis layout: one joint moved per row, the others at home
_JOINT_FIELDS = {"joint", "position", "home", "joint_type"}
_JOINT_TYPES = {"prismatic": "linear", "linear": "linear", "translational": "linear",
                "revolute": "rotary", "rotary": "rotary", "rotational": "rotary"}
#: sidecar keys and options every import takes
_COMMON_OPTIONS = {"probe", "artefact", "setup", "sigma", "header"}


def _imports() -> dict:
    """import name -> its table, from the registry (each kind's ``table``:
    layout, columns, the sidecar options it takes; kinds of one name share
    it, ``kinds`` lists them), in registry order, then the generic table.
    Read at each call: a kind may register itself after this module loads."""
    out: dict = {}
    for k in _core.observation_kinds():
        t = k["table"]
        out.setdefault(t["name"], dict(t, kinds=[]))["kinds"].append(k["name"])
    every = [n for t in out.values() for n in t["kinds"]]
    out[GENERIC] = {"name": GENERIC, "aliases": ["generic"], "row_aliases": [], "layout": "generic",
                    "columns": [], "expected": _GENERIC_EXPECTED, "options": ["length", "tool_ball", "table_ball"],
                    "header_aliases": {}, "directions": {}, "rules": [], "kinds": every}
    return out


def _aliases(imports: Mapping) -> dict:
    """Other name of an import -> its name."""
    return {a: name for name, t in imports.items() for a in t["aliases"]}


def _spec(table: Mapping) -> dict:
    """A table's columns by header name."""
    return {c["name"]: c for c in table["columns"]}


def _orientation(table: Mapping) -> Optional[str]:
    """The file key a table's ``rotation`` columns fill other than the noise
    (an orientation, read by io/rotations.py in whichever form the columns
    give: rotation vector, quaternion, matrix, Euler angles), or None."""
    return next((c["field"] for c in table["columns"] if c["quantity"] == "rotation" and c["field"] != "sigma"),
                None)


#: what a message says a sidecar key is, where its name does not say it
_OPTION_WHAT = {"rotation": " (how the orientation is written)", "instruments": " (noise per instrument)"}


def _touch_kinds() -> dict:
    """The probe-touch kinds (a probing log's rows) -> their artefact list."""
    return {k["name"]: k["report"]["target_list"] for k in _core.observation_kinds() if k["probe_touch"]}


def _either(names: Sequence[str], word: str = "or") -> str:
    """``a, b or c``."""
    names = list(names)
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} {word} {names[-1]}"


KINDS = tuple(_imports())
ALIASES = _aliases(_imports())


def _axis_list(machine: Machine, skip_s: bool = False) -> str:
    """The machine's axes in the usual X Y Z A B C S order."""
    order = "XYZABCS"
    return " ".join(a for a in sorted(machine.axis_names, key=order.index) if not (skip_s and a == "S"))


class _Column:
    """One header cell: the fivecal field it feeds, its unit factor and the
    registry's record of its column (None for an axis or direction column)."""

    def __init__(self, index: int, header: str, field: str, unit: Optional[str]):
        self.index, self.header, self.field, self.unit = index, header, field, unit
        self.factor = 1.0
        self.spec: Optional[dict] = None


def canonical_kind(kind: str) -> str:
    imports = _imports()
    k = _aliases(imports).get(kind.strip().lower(), kind.strip().lower())
    if k not in imports:
        others = ", ".join(f"{t['aliases'][0]} = {n}" for n, t in imports.items() if t["aliases"] and n != GENERIC)
        raise ValueError(f"import: unknown kind '{kind}' (kinds: {', '.join(imports)}; {others})")
    return k


# --------------------------------------------------------------------------
# Text to cells
# --------------------------------------------------------------------------
def _lines(text: str):
    """(line number, text) of the lines that are neither blank nor ``#`` comments."""
    for n, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if s and not s.startswith("#"):
            yield n, line


def _delimiter(header: str, option: Optional[str]) -> Optional[str]:
    """None means runs of spaces or tabs (a text table)."""
    if option:
        o = {"tab": "\t", "\\t": "\t", "space": None, "whitespace": None, "comma": ",",
             "semicolon": ";"}.get(option.lower(), option)
        if o is not None and len(o) != 1:
            raise ValueError(f"import: delimiter '{option}': expected one character, tab, space, comma or semicolon")
        return o
    for d in (";", "\t", ","):
        if d in header:
            return d
    return None


#: characters: no cell of an instrument table (a number, an id, a name) is
#: longer; a longer one is a broken file, refused before it fills a message
_MAX_CELL = 4096


def _split(line: str, delim: Optional[str], where: str) -> list:
    """The cells of a line (``where``: its file and line, for the message)."""
    if delim is None:
        cells = line.split()
    else:
        try:
            cells = [c.strip() for c in next(csv.reader([line], delimiter=delim))]
        except csv.Error as e:
            if "field limit" in str(e):  # the csv module's own cap, 128 KiB
                raise ValueError(f"{where}: a cell holds more than {csv.field_size_limit()} characters (at most "
                                 f"{_MAX_CELL} are read); is the separator or a quote missing?") from None
            raise ValueError(f"{where}: not a valid CSV line ({e})") from None
    for i, c in enumerate(cells):
        if len(c) > _MAX_CELL:
            raise ValueError(f"{where}: cell {i + 1} holds {len(c)} characters (at most {_MAX_CELL} are read); "
                             f"it starts '{_shown(c)}': is the separator or a quote missing?")
    return cells


def _shown(cell: str, n: int = 40) -> str:
    """A cell for a message: its start when it is long."""
    c = cell.strip()
    return c if len(c) <= n else c[:n] + "…"


def _number(cell: str, decimal_comma: bool, where: str) -> float:
    s = cell.strip()
    if not s:
        raise ValueError(f"{where}: empty cell (a number is expected)")
    if decimal_comma:
        s = s.replace(",", ".")
    try:
        v = float(s)
    except ValueError:
        hint = ""
        if "," in s and not decimal_comma:
            hint = " (a decimal comma needs ';', tab or space separators, or --decimal comma)"
        raise ValueError(f"{where}: '{_shown(cell)}' is not a number{hint}") from None
    if not math.isfinite(v):
        raise ValueError(f"{where}: '{_shown(cell)}' is not a finite number (NaN or infinity is not a measurement)")
    return v


def _split_unit(header: str):
    """(name, unit or None): ``reading_um`` -> (reading, um), ``dx [um]`` -> (dx, um),
    ``table_ball_x`` -> (table_ball_x, None)."""
    return _units.split_unit(header)


# --------------------------------------------------------------------------
# Header to columns
# --------------------------------------------------------------------------
def _field(name: str, machine: Machine, kind: str, where: str, imports: Mapping) -> str:
    """The fivecal field of a column name (case-insensitive); ValueError when unknown."""
    axes = machine.axis_names
    low = name.strip().lower()
    up = name.strip().upper()
    if up == "C1":
        up = "S"
    if len(up) == 1 and up.isalpha():
        if up in axes:
            return up
        raise ValueError(f"{where}: unknown axis letter '{name}' (the machine's axes: {_axis_list(machine)})")
    m = re.match(r"^(?:dir_?([a-z]\d?)|([a-z]\d?)_?dir)$", low)
    if m:
        letter = (m.group(1) or m.group(2)).upper()
        letter = "S" if letter == "C1" else letter
        if letter not in axes:
            raise ValueError(f"{where}: direction column of unknown axis '{letter}' "
                             f"(the machine's axes: {_axis_list(machine)})")
        return "dir_" + letter
    fields = _spec(imports[kind])
    short = {c["alias"]: c["name"] for c in fields.values() if c["alias"]}
    short.update(imports[kind]["header_aliases"])
    if low in short:
        return short[low]
    if low in fields:
        return low
    known = sorted(fields) + list(axes) + [f"dir_{a}" for a in axes]
    close = difflib.get_close_matches(low, known, n=1)
    other = [k for k, t in imports.items() if t["layout"] != "generic" and low in _spec(t)]
    hint = f"; did you mean '{close[0]}'?" if close else ""
    if other and not close:
        hint = f"; it belongs to a {other[0]} import"
    raise ValueError(f"{where}: unknown column '{name}' for a {kind} import{hint} (rename it with "
                     f"--column FIELD=HEADER or skip it with --ignore '{name}')")


def _once(headers: Sequence[str], where: str, ignored) -> None:
    """Refuse a header naming a kept column twice (names are case-insensitive):
    which of the two a reader keyed by name would use is arbitrary."""
    first = {}
    for i, h in enumerate(headers):
        key = h.strip().lower()
        if key and key in first and key not in ignored:
            raise ValueError(f"{where}: column '{h.strip()}' appears twice in the header (columns {first[key] + 1} "
                             f"and {i + 1}); rename one, or skip both with --ignore '{h.strip()}'")
        first.setdefault(key, i)


def _named_headers(headers: Sequence[str], where: str, rename: Mapping[str, str], ignore: Iterable[str]):
    """The columns a table keeps, as (index, header, name, unit, where of the
    column): ``--ignore``d ones left out, ``--column FIELD=HEADER`` renames
    applied (the file's header still names the unit when it ends in one), an
    unnamed column or a rename/ignore of a column the header lacks refused."""
    by_header = {}
    for field, header in rename.items():
        by_header.setdefault(header.strip().lower(), field.strip())
    ignored = {i.strip().lower() for i in ignore}
    known = {h.strip().lower() for h in headers}
    for h in list(by_header) + sorted(ignored):
        if h not in known:
            raise ValueError(f"{where}: no column '{h}' in the header (columns: {', '.join(headers)})")
    _once(headers, where, ignored)
    for i, h in enumerate(headers):
        key = h.strip().lower()
        if key in ignored:
            continue
        if not key:
            raise ValueError(f"{where}: column {i + 1} has no name")
        name, unit = _split_unit(h)
        yield i, h.strip(), by_header.get(key, name), unit, f"{where}: column '{h.strip()}'"


def _columns(headers: Sequence[str], machine: Machine, kind: str, where: str, rename: Mapping[str, str],
             ignore: Iterable[str], length_unit: Optional[str], angle_unit: Optional[str], imports: Mapping) -> list:
    spec = _spec(imports[kind])
    cols, seen = [], {}
    for i, h, name, unit, cw in _named_headers(headers, where, rename, ignore):
        field = _field(name, machine, kind, cw, imports)
        if field in seen:
            raise ValueError(f"{where}: columns '{seen[field]}' and '{h}' both give {field}")
        seen[field] = h
        c = _Column(i, h, field, unit)
        c.spec = spec.get(field)
        q = c.spec["quantity"] if c.spec else None
        rotation = q == "rotation"
        quantity = "angle" if (len(field) == 1 and machine.is_rotary(field)) or rotation else \
            "length" if q == "length" or len(field) == 1 else None
        if quantity and unit is not None:
            c.factor, _ = _units.column_unit(h, quantity, where)
            if rotation:
                c.factor *= math.pi / 180.0  # angle columns scale to degrees; orientations are in rad
        elif rotation:
            c.factor = 1.0  # rad unless its header (or the sidecar's rotation.unit) says otherwise
        elif quantity == "angle":
            c.factor = _units.ANGLE_SUFFIXES[angle_unit or "deg"]
        elif quantity == "length":
            measured = bool(c.spec and c.spec["measured"])
            c.factor = _units.LENGTH_SUFFIXES[(length_unit if measured else None) or "mm"]
        elif unit is not None and q == "joint":
            raise ValueError(f"{cw}: {field} takes the unit of the moving joint (mm for a linear one, degrees "
                             "or --angle-units for a rotary one); name the column without a unit")
        elif unit is not None:
            raise ValueError(f"{cw}: {field} has no unit, got '{unit}'")
        cols.append(c)
    joint_fields = sorted(f for f in _JOINT_FIELDS if f in seen)
    if joint_fields:
        # one joint per row: the axis values come from joint and position
        if "joint" not in seen or "position" not in seen:
            raise ValueError(f"{where}: column '{seen[joint_fields[0]]}' belongs to a joint layout, which needs "
                             "both a 'joint' column (the moving joint) and a 'position' column (its position)")
        axis_cols = [seen[a] for a in machine.axis_names if a in seen]
        if axis_cols:
            raise ValueError(f"{where}: column '{axis_cols[0]}': axis columns and a joint layout (joint, "
                             "position) cannot be mixed; give one or the other")
        missing = []
    else:
        missing = [a for a in machine.axis_names if a != "S" and a not in seen]
    if missing:
        raise ValueError(f"{where}: no column for axis {', '.join(missing)} (expected a column per machine "
                         f"axis: {_axis_list(machine)}; S may be left out)")
    for r in (c["name"] for c in imports[kind]["columns"] if c["required"]):
        if r not in seen:
            raise ValueError(f"{where}: no '{r}' column; a {kind} import expects "
                             f"{_expected(machine, kind, imports)}")
    return cols


def _expected(machine: Machine, kind: str, imports: Mapping) -> str:
    axes = _axis_list(machine, skip_s=True)
    t = imports[kind]
    rest = t["expected"] or " ".join(
        [f"{k}" for k in _generic_keys(t)] + ["[id]"])
    return f"the columns {axes} {rest}"


def _generic_keys(table: Mapping) -> list:
    """A kind's own file keys (a table without an ``expected`` text: the
    generic reader's columns, named after them)."""
    keys = []
    for k in _core.observation_kinds():
        if k["name"] in table["kinds"]:
            keys += [x for x in k["json_keys"] if x not in ("type", "axes", "direction", "id") and x not in keys]
    return keys


# --------------------------------------------------------------------------
# Rows to observations
# --------------------------------------------------------------------------
def _approach(text: str, machine: Machine, where: str) -> dict:
    """``-Z``, ``Z-``, ``+X-Y``, ``X+Y-``: the axes that moved into the touch and their signs."""
    s = text.replace(" ", "")
    pat = r"([+-])([A-Za-z]1?)" if s[:1] in "+-" else r"([A-Za-z]1?)([+-])"
    parts = re.findall(pat, s)
    if not parts or "".join("".join(p) for p in parts) != s:
        raise ValueError(f"{where}: approach '{text}' is not like -Z, X+ or -X+Y-Z")
    out = {}
    for p in parts:
        sign, letter = (p[0], p[1]) if s[:1] in "+-" else (p[1], p[0])
        letter = "S" if letter.upper() == "C1" else letter.upper()
        if letter not in machine.axis_names:
            raise ValueError(f"{where}: approach '{text}': unknown axis letter '{letter}' "
                             f"(the machine's axes: {_axis_list(machine)})")
        if letter in out:
            raise ValueError(f"{where}: approach '{text}': axis {letter} given twice")
        out[letter] = 1 if sign == "+" else -1
    return out


def _vector3(value, what: str) -> list:
    if isinstance(value, str):
        value = [t for t in value.replace(";", ",").split(",") if t.strip()]
    try:
        v = [float(x) for x in value]
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected three numbers x,y,z (mm), got {value!r}") from None
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise ValueError(f"{what}: expected three finite numbers x,y,z (mm), got {value!r}")
    return v


def read_sidecar(path: Union[str, os.PathLike]) -> dict:
    """A small JSON file of what a table does not hold: ``probe``, ``artefact``
    (as in a dataset), ``setup``, ``length``, ``tool_ball``, ``table_ball``,
    ``sigma`` (mm); checked against ``import.schema.json``."""
    path = os.fspath(path)
    return schema.validate(files.read_json(path, "import sidecar"), "import", path)


def read_table(path: Union[str, os.PathLike], kind: str, machine: Union[Machine, Mapping, str], *,
               sidecar: Union[None, str, os.PathLike, Mapping] = None, units: Optional[str] = None,
               angle_units: Optional[str] = None, columns: Optional[Mapping[str, str]] = None,
               ignore: Sequence[str] = (), delimiter: Optional[str] = None, decimal: Optional[str] = None,
               setup: Optional[str] = None, length: Optional[float] = None, tool_ball=None, table_ball=None,
               sigma: Optional[float] = None, header: Optional[Sequence[str]] = None,
               instrument: Optional[str] = None, target: Optional[str] = None, target_point=None,
               instrument_origin=None, instrument_angles=None, align: Optional[bool] = None,
               target_rotation=None, station: Optional[str] = None) -> dict:
    """Read an instrument table into a dataset dict (docs/formats.md); see
    docs/import.md for each kind's columns.

    ``kind``: ``probing``, ``dbb``, ``ball3d`` (or ``rtest``), ``point`` (or
    ``tracker``), ``fivecal``.
    ``machine``: a :class:`fivecal.Machine`, a machine dict or a machine JSON
    path. ``sidecar``: a dict or JSON path with ``probe``, ``artefact``,
    ``setup``, ``length``, ``tool_ball``, ``table_ball``, ``sigma``,
    ``header``, and for ``point`` ``instrument``, ``target``,
    ``target_point``, ``instrument_origin``, ``instrument_angles`` (deg),
    ``align`` and ``joints``, for ``pose`` also ``target_rotation`` (rad);
    for ``distance`` ``stations`` (name -> ``{"position", "dead_length"}``),
    ``station``, ``instrument`` (the tracer), ``target``, ``target_point``;
    the keyword arguments of the same names
    override it. ``units``: the unit of
    measured columns whose header names none (``um`` or ``mm``, the
    default); ``angle_units``: of rotary axis columns (``deg``, the default,
    or ``rad``). ``columns``: field -> header, for headers that are not
    fivecal names (``{"reading": "dL_um"}``); ``ignore``: headers to skip.
    ``delimiter``: default from the header line (``;``, tab, ``,``, else
    spaces); ``decimal``: ``comma`` or ``point`` (default: a comma is the
    decimal mark unless it separates the columns). ``header``: the column
    names of a file without a header row.

    ``point``: without ``instrument_origin`` / ``instrument_angles`` (or with
    ``align=True``) the instrument's nominal pose is the rigid alignment of
    the measured points to the nominal machine's; ``align=False`` keeps the
    identity. The returned dict's ``_comment`` says which was done.

    Each observation's ``id`` is its ``id`` cell, or ``<file name>:<line>``.
    ValueError names the file, line and column of the first bad cell."""
    return _read(path, kind, machine, sidecar=sidecar, units=units, angle_units=angle_units, columns=columns,
                 ignore=ignore, delimiter=delimiter, decimal=decimal, setup=setup, length=length,
                 tool_ball=tool_ball, table_ball=table_ball, sigma=sigma, header=header, instrument=instrument,
                 target=target, target_point=target_point, instrument_origin=instrument_origin,
                 instrument_angles=instrument_angles, align=align, target_rotation=target_rotation,
                 station=station)[0]


def _read(path, kind, machine, *, sidecar=None, units=None, angle_units=None, columns=None, ignore=(),
          delimiter=None, decimal=None, setup=None, length=None, tool_ball=None, table_ball=None, sigma=None,
          header=None, instrument=None, target=None, target_point=None, instrument_origin=None,
          instrument_angles=None, align=None, target_rotation=None, station=None):
    """(dataset dict, the line of each observation)."""
    kind = canonical_kind(kind)
    imports = _imports()
    table = imports[kind]
    layout = table["layout"]
    path = os.fspath(path)
    if not isinstance(machine, Machine):
        machine = Machine.load(machine) if isinstance(machine, (str, os.PathLike)) else Machine.from_dict(machine)
    side_where = f"{os.fspath(sidecar)}: " if isinstance(sidecar, (str, os.PathLike)) else "sidecar "
    side = dict(read_sidecar(sidecar) if isinstance(sidecar, (str, os.PathLike)) else (sidecar or {}))
    origin = {k: f"{side_where}{k}" for k in side}
    for key, value in (("setup", setup), ("length", length), ("tool_ball", tool_ball),
                       ("table_ball", table_ball), ("sigma", sigma), ("header", header),
                       ("instrument", instrument), ("target", target), ("target_point", target_point),
                       ("instrument_origin", instrument_origin), ("instrument_angles", instrument_angles),
                       ("align", align), ("target_rotation", target_rotation), ("station", station)):
        if value is not None:
            side[key] = value
            origin[key] = f"--{key.replace('_', '-')}"
    # an option of another import: each table says which it takes
    for key in side:
        owners = [n for n, t in imports.items() if n != GENERIC and key in t["options"]]
        if owners and key not in _COMMON_OPTIONS and key not in table["options"] and side[key] is not None:
            raise ValueError(f"{origin[key]}: {key}{_OPTION_WHAT.get(key, '')} belongs to a {_either(owners)} "
                             f"import, not {kind}")
    if side.get("sigma") is not None:
        # one number, or one per residual row of a kind whose rows differ in unit
        listed = _rot.sidecar_sigma(side["sigma"], kind, origin["sigma"])
        if listed is not None:
            side["sigma"] = listed
    # checked once here, so that a bad value is named where it was given
    for key in ("tool_ball", "table_ball", "target_point", "instrument_origin", "instrument_angles",
                "target_rotation"):
        if side.get(key) is not None:
            side[key] = _vector3(side[key], origin[key])
    for key in ("length", "sigma"):
        if side.get(key) is not None and not isinstance(side[key], list):
            side[key] = _positive(side[key], origin[key])
    if side.get("setup") is not None and (not isinstance(side["setup"], str) or "." in side["setup"]):
        raise ValueError(f"{origin['setup']}: expected a mounting name without '.', got {side['setup']!r}")
    if units is not None and units.lower() not in _units.LENGTH_SUFFIXES:
        raise ValueError(f"import: --units '{units}': expected um or mm (length units: "
                         f"{_units.unit_list('length')})")
    if angle_units is not None and angle_units.lower() not in _units.ANGLE_SUFFIXES:
        raise ValueError(f"import: --angle-units '{angle_units}': expected deg or rad (angle units: "
                         f"{_units.unit_list('angle')})")
    if decimal not in (None, "comma", "point"):
        raise ValueError(f"import: decimal '{decimal}': expected comma or point")
    if layout == "instrument":
        _point_setup(side, origin, machine)
    if layout == "station":
        _distance_setup(side, origin, machine)
    _sidecar_sizes(side, origin, machine)

    text = files.read_text(path, f"{kind} table")
    lines = list(_lines(text))
    given = side.get("header")
    if given is not None:
        given = _header_names(given, origin["header"])
    if not lines:
        raise ValueError(f"{path}: no header and no data; a {kind} table needs a header row naming "
                         f"{_expected(machine, kind, imports)}")
    if given is not None:
        # the names come from the option: every line of the file is data
        hline, first = lines[0]
        delim = _delimiter(first, delimiter)
        headers = given
        if not any(_is_number(h) for h in _split(first, delim, f"{path}:{hline}")):
            raise ValueError(f"{path}:{hline}: this line holds names, not numbers, like a header row, but the "
                             f"column names were given ({origin['header']}); a file with a header row needs no "
                             "'header'")
        hwhere, hdesc = origin["header"], origin["header"]
        lines = [(None, "")] + lines
    else:
        hline, first = lines[0]
        delim = _delimiter(first, delimiter)
        headers = _split(first, delim, f"{path}:{hline}")
        hwhere, hdesc = f"{path}:{hline}", f"line {hline}"
    if all(_is_number(h) for h in headers):
        raise ValueError(f"{hwhere}: no header row (this line holds numbers); the first line must name "
                         f"the columns: {_expected(machine, kind, imports)}, or give the names with --header / "
                         "'header' in the sidecar")
    generic = layout == "generic"
    if generic:
        registry, text_keys = _registered(), _text_keys()
        cols = _generic_columns(headers, machine, kind, hwhere, columns or {}, ignore, units and units.lower(),
                                angle_units and angle_units.lower(), registry, text_keys, imports)
    else:
        cols = _columns(headers, machine, kind, hwhere, columns or {}, ignore,
                        units and units.lower(), angle_units and angle_units.lower(), imports)
    if _orientation(table):
        # the orientation in whichever form the columns give (io/rotations.py)
        side["_rotation"] = _rot.prepare(cols, side, origin, hwhere)
    decimal_comma = decimal == "comma" or (decimal is None and delim != ",")
    if decimal == "comma" and delim == ",":
        raise ValueError(f"{path}: a decimal comma needs another column separator than ',' (';', tab or spaces)")
    artefact = side.get("artefact") or {}
    targets = {}
    touch_kinds = _touch_kinds()
    if isinstance(artefact, Mapping):
        for typ, key in touch_kinds.items():
            for t in artefact.get(key) or []:
                if isinstance(t, Mapping) and "id" in t:
                    targets[str(t["id"])] = typ
    base = os.path.basename(path)
    obs, lineno_of, ids = [], [], {}
    for lineno, line in lines[1:]:
        cells = _split(line, delim, f"{path}:{lineno}")
        if len(cells) != len(headers):
            raise ValueError(f"{path}:{lineno}: {len(cells)} cells, the header ({hdesc}) has "
                             f"{len(headers)} columns ({', '.join(headers)})")
        if layout == "instrument":
            o = _point_row(cells, cols, machine, table, side, decimal_comma, angle_units, f"{path}:{lineno}")
        elif layout == "station":
            o = _distance_row(cells, cols, machine, table, side, decimal_comma, f"{path}:{lineno}")
        elif generic:
            o = _generic_row(cells, cols, machine, kind, side, decimal_comma, f"{path}:{lineno}", registry,
                             text_keys, imports)
        else:
            o = _row(cells, cols, machine, table, side, targets, decimal_comma, f"{path}:{lineno}", imports)
        oid = o.get("id") or f"{base}:{lineno}"
        if oid in ids:
            raise ValueError(f"{path}:{lineno}: id '{oid}' already used on line {ids[oid]}")
        ids[oid] = lineno
        o["id"] = oid
        obs.append(o)
        lineno_of.append(lineno)
    if not obs:
        raise ValueError(f"{path}: a header but no data rows")
    _rotary_units(_rotary_columns(obs, cols, machine, lineno_of, angle_units), path)
    if generic:
        _angle_checks(obs, cols, machine, path, lineno_of)
    d = {"machine": machine.to_dict(), "observations": obs}
    if layout == "instrument":
        _joint_homes(obs, machine, side, origin)
        d["_comment"] = _place_instrument(obs, machine, side, origin, path)
    touches = any(o["type"] in touch_kinds for o in obs)
    if touches and "probe" not in side:
        raise ValueError(f"{path}: probe touches need the probe tip radius: give 'probe': "
                         '{"tip_radius": R} (mm) in the sidecar')
    if "probe" in side:
        d["probe"] = side["probe"]
    if side.get("instruments") is not None:
        d["instruments"] = side["instruments"]  # checked with the dataset, naming the field
    if artefact:
        d["artefact"] = artefact
    return d, lineno_of



# --------------------------------------------------------------------------
# point: a fixed instrument following a target
# --------------------------------------------------------------------------
def _header_names(value, where: str) -> list:
    if isinstance(value, str):
        value = [t.strip() for t in value.split(",")]
    if not isinstance(value, Sequence) or not value or not all(isinstance(h, str) and h.strip() for h in value):
        raise ValueError(f"{where}: expected the column names, like joint,measured_x,measured_y,measured_z,"
                         f"position, got {value!r}")
    return [h.strip() for h in value]


def _point_setup(side: dict, origin: dict, machine: Machine) -> None:
    """Check and complete the point options in ``side`` (instrument, target,
    target_point, pose, align, joints), naming where a bad value was given."""
    inst = side.get("instrument", "T1")
    if not isinstance(inst, str) or not inst.strip() or "." in inst:
        raise ValueError(f"{origin.get('instrument', 'instrument')}: expected an instrument name without '.', "
                         f"got {inst!r}")
    side["instrument"] = inst.strip()
    target = side.get("target")
    if target is None:
        if not machine.tool_chain:
            target = "work"
        elif not machine.workpiece_chain:
            target = "tool"
        else:
            raise ValueError(f"point import: machine {machine.topology} has axes on both sides; say which side "
                             "carries the target: --target tool|work or 'target' in the sidecar")
    if target not in ("tool", "work"):
        raise ValueError(f"{origin.get('target', 'target')}: expected tool or work, got {target!r}")
    side["target"] = target
    if side.get("target_point") is None:
        side["target_point"] = [float(x) for x in machine.tip] if target == "tool" else [0.0, 0.0, 0.0]
    align = side.get("align")
    if align is not None and not isinstance(align, bool):
        raise ValueError(f"{origin['align']}: expected true or false, got {align!r}")
    posed = [k for k in ("instrument_origin", "instrument_angles") if side.get(k) is not None]
    if align and posed:
        raise ValueError(f"{origin['align']}: align asks for the pose from the data, but {origin[posed[0]]} "
                         "gives it; keep one")
    joints = side.get("joints")
    if joints is not None:
        jw = origin.get("joints", "joints")
        if not isinstance(joints, Mapping) or set(joints) - {"axes", "home"}:
            raise ValueError(f"{jw}: expected {{\"axes\": [axis letter of joint 1, 2, ...], \"home\": "
                             f"{{axis: position}}}}, got {joints!r}")
        axes = joints.get("axes") or []
        if not isinstance(axes, Sequence) or isinstance(axes, str):
            raise ValueError(f"{jw}.axes: expected a list of axis letters, joint 1 first, got {axes!r}")
        for i, a in enumerate(axes):
            if a not in machine.axis_names:
                raise ValueError(f"{jw}.axes[{i}]: {a!r} is not an axis of the machine "
                                 f"({_axis_list(machine)})")
            if list(axes).index(a) != i:
                raise ValueError(f"{jw}.axes[{i}]: axis {a} given twice")
        home = joints.get("home") or {}
        if not isinstance(home, Mapping):
            raise ValueError(f"{jw}.home: expected {{axis letter: home position}}, got {home!r}")
        for a, v in home.items():
            if a not in machine.axis_names:
                raise ValueError(f"{jw}.home.{a}: not an axis of the machine ({_axis_list(machine)})")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{jw}.home.{a}: expected a number (mm or degrees), got {v!r}")


def _instrument_cells(cells, cols, machine: Machine, decimal_comma: bool, where: str) -> tuple:
    """The cells of a point, pose or distance row: ``(axes, direction, vals,
    text)``; ``vals`` and ``text`` map a field to ``(value, where)``. Axis
    positions that look like µm are refused; a joint layout's ``position`` and
    ``home`` stay in the moving joint's unit, known only later."""
    axes, direction, vals, text = {}, {}, {}, {}
    for c in cols:
        cw = f"{where}: column '{c.header}'"
        cell = cells[c.index]
        if c.field in ("id", "joint", "joint_type", "station"):
            s = cell.strip()
            if not s:
                raise ValueError(f"{cw}: empty cell (a {c.field.replace('_', ' ')} is expected)")
            text[c.field] = (s, cw)
            continue
        v = _number(cell, decimal_comma, cw)
        if c.field.startswith("dir_"):
            if v not in (-1.0, 0.0, 1.0):
                raise ValueError(f"{cw}: direction {cell.strip()} is not -1, 0 or +1")
            if v:
                direction[c.field[4:]] = int(v)
            continue
        if c.field in ("position", "home"):
            vals[c.field] = (v, cw)  # the unit is the moving joint's, known below
            continue
        v *= c.factor
        if len(c.field) == 1:
            if not machine.is_rotary(c.field) and abs(v) > plausibility.REFUSE_POSITION:
                raise ValueError(f"{cw}: {v:.6g} mm is beyond any machine tool "
                                 f"({plausibility.REFUSE_POSITION / 1e3:g} m); positions look like µm: "
                                 f"name the column {c.field}_um")
            axes[c.field] = v
        else:
            vals[c.field] = (v, cw)
    return axes, direction, vals, text


def _row_sigma(o: dict, vals: Mapping, side: Mapping) -> None:
    """The row's declared noise: its ``sigma`` cell (> 0), else the sidecar's or
    option's, else none (the kind's or instrument's default)."""
    if "sigma" in vals:
        s, sw = vals["sigma"]
        if not s > 0:
            raise ValueError(f"{sw}: sigma {s:g} mm must be > 0")
        o["sigma"] = s
    elif side.get("sigma") is not None:
        o["sigma"] = side["sigma"]


def _point_row(cells, cols, machine: Machine, table: Mapping, side: Mapping, decimal_comma: bool, angle_units,
               where: str) -> dict:
    axes, direction, vals, text = _instrument_cells(cells, cols, machine, decimal_comma, where)
    o = {"type": table["kinds"][0], "instrument": side["instrument"], "target": side["target"],
         "target_point": list(side["target_point"]), "axes": axes}
    _fill(o, vals, table, side, where, o["type"])
    orientation = _orientation(table)
    if orientation:
        o[orientation] = _rot.row_rotation(vals, side["_rotation"], where)
        if "target_rotation" in table["options"] and side.get("target_rotation") is not None:
            o["target_rotation"] = list(side["target_rotation"])
    if "id" in text:
        o["id"] = text["id"][0]
    if direction:
        o["direction"] = direction
    _row_sigma(o, vals, side)
    sigmas = _rot.row_sigma(vals, side.get("_rotation"))
    if sigmas is not None:
        o["sigma"] = sigmas
    if "joint" in text:
        o["_joint"] = _joint_of(text, vals, machine, side, angle_units)
    return o


# --------------------------------------------------------------------------
# distance: a tracking interferometer or laser tracer at its stations
# --------------------------------------------------------------------------
def _distance_setup(side: dict, origin: dict, machine: Machine) -> None:
    """Check the distance options: the target as for a point import, and
    ``stations``: id -> {"position": [x, y, z] mm in F, "dead_length": mm}."""
    tracer = side.get("instrument")
    side["instrument"] = "T1" if tracer is None else tracer
    _point_setup(side, origin, machine)
    if tracer is None:
        del side["instrument"]  # the kind's own default tracer name
    stations = side.get("stations")
    sw = origin.get("stations", "stations")
    if not isinstance(stations, Mapping) or not stations:
        raise ValueError(f"{sw}: a distance import needs each station's nominal place: 'stations': "
                         '{"L1": {"position": [x, y, z], "dead_length": d}, ...} (mm) in the sidecar')
    for sid, st in stations.items():
        w = f"{sw}.{sid}"
        if not isinstance(sid, str) or not sid or "." in sid:
            raise ValueError(f"{w}: a station name without '.' is expected")
        if not isinstance(st, Mapping) or set(st) - {"position", "dead_length"} or "position" not in st:
            raise ValueError(f"{w}: expected {{\"position\": [x, y, z], \"dead_length\": d}} (mm), got {st!r}")
        st = dict(st)
        st["position"] = _vector3(st["position"], f"{w}.position")
        if st.get("dead_length") is not None:
            d = st["dead_length"]
            if isinstance(d, bool) or not isinstance(d, (int, float)) or not math.isfinite(d):
                raise ValueError(f"{w}.dead_length: expected a number (mm), got {d!r}")
        stations[sid] = st
    if side.get("station") is not None and side["station"] not in stations:
        raise ValueError(f"{origin['station']}: station {side['station']!r} is not in 'stations' "
                         f"({', '.join(stations)})")


def _distance_row(cells, cols, machine: Machine, table: Mapping, side: Mapping, decimal_comma: bool,
                  where: str) -> dict:
    axes, direction, vals, text = _instrument_cells(cells, cols, machine, decimal_comma, where)
    stations = side["stations"]
    if "station" in text:
        sid, sw = text["station"]
        if sid not in stations:
            close = difflib.get_close_matches(sid, sorted(stations), n=1)
            raise ValueError(f"{sw}: station '{sid}' is not in the sidecar's stations ({', '.join(stations)})"
                             + (f"; did you mean '{close[0]}'?" if close else ""))
    elif side.get("station") is not None or len(stations) == 1:
        sid = side.get("station") or next(iter(stations))
    else:
        raise ValueError(f"{where}: no station column and {len(stations)} stations in the sidecar; add a "
                         "'station' column or give --station")
    st = stations[sid]
    o = {"type": table["kinds"][0], "station": sid, "target": side["target"],
         "target_point": list(side["target_point"]), "axes": axes}
    _fill(o, vals, table, side, where, o["type"])
    o["station_position"] = list(st["position"])
    if st.get("dead_length") is not None:
        o["dead_length"] = float(st["dead_length"])
    if side.get("instrument") is not None:
        o["instrument"] = side["instrument"]
    if "id" in text:
        o["id"] = text["id"][0]
    if direction:
        o["direction"] = direction
    _row_sigma(o, vals, side)
    return o


def _joint_of(text, vals, machine: Machine, side: Mapping, angle_units) -> tuple:
    """(axis, position, home or None, where) of a joint-layout row."""
    j, jw = text["joint"]
    listed = list((side.get("joints") or {}).get("axes") or [])
    letter = "S" if j.upper() == "C1" else j.upper()
    if letter in machine.axis_names:
        axis = letter
    else:
        try:
            k = int(float(j.replace(",", ".")))
        except ValueError:
            k = None
        if k is None or float(j.replace(",", ".")) != k:
            raise ValueError(f"{jw}: '{j}' is neither an axis letter ({_axis_list(machine)}) nor a joint number")
        if not listed:
            raise ValueError(f"{jw}: joint {k}: which axis is it? give the axes of joints 1, 2, ... as "
                             "'joints': {\"axes\": [...]} in the sidecar (or write axis letters in the column)")
        if not 1 <= k <= len(listed):
            raise ValueError(f"{jw}: joint {k}: the sidecar's joints.axes names joints 1 to {len(listed)}")
        axis = listed[k - 1]
    if "joint_type" in text:
        t, tw = text["joint_type"]
        kind = _JOINT_TYPES.get(t.lower())
        if kind is None:
            raise ValueError(f"{tw}: '{t}' is not a joint type (prismatic, revolute, linear, rotary)")
        actual = "rotary" if machine.is_rotary(axis) else "linear"
        if kind != actual:
            raise ValueError(f"{tw}: '{t}', but joint {j} is axis {axis} of the machine, which is {actual}")
    factor = _units.ANGLE_SUFFIXES[(angle_units or "deg").lower()] if machine.is_rotary(axis) else 1.0
    pos, pw = vals["position"]
    pos *= factor
    if not machine.is_rotary(axis) and abs(pos) > plausibility.REFUSE_POSITION:
        raise ValueError(f"{pw}: {pos:.6g} mm is beyond any machine ({plausibility.REFUSE_POSITION / 1e3:g} m)")
    home = None
    if "home" in vals:
        home = (vals["home"][0] * factor, vals["home"][1])
    return axis, pos, home, jw


def _joint_homes(obs: list, machine: Machine, side: Mapping, origin: Mapping) -> None:
    """Axis values of joint-layout rows: the moving joint at its position, every
    other axis at its home (the home cells of its own rows, the sidecar's
    joints.home, else 0)."""
    if not any("_joint" in o for o in obs):
        return
    given = dict((side.get("joints") or {}).get("home") or {})
    home, seen = {}, {}
    for o in obs:
        axis, _, h, jw = o["_joint"]
        if h is None:
            continue
        value, hw = h
        if axis in home and abs(home[axis] - value) > 1e-9 * max(1.0, abs(value)):
            raise ValueError(f"{hw}: home {value:g} of axis {axis}, but {seen[axis]} gives {home[axis]:g}; "
                             "an axis has one home")
        if axis in given and abs(given[axis] - value) > 1e-9 * max(1.0, abs(value)):
            raise ValueError(f"{hw}: home {value:g} of axis {axis}, but {origin['joints']}.home gives "
                             f"{given[axis]:g}")
        home.setdefault(axis, value)
        seen.setdefault(axis, hw)
    for a, v in given.items():
        home.setdefault(a, float(v))
    for o in obs:
        axis, pos, _, _ = o.pop("_joint")
        o["axes"] = {a: float(home.get(a, 0.0)) for a in machine.axis_names if a != "S" or a in home}
        o["axes"][axis] = pos


def _place_instrument(obs: list, machine: Machine, side: Mapping, origin: Mapping, path: str) -> str:
    """Set each observation's instrument_origin / instrument_angles and say how
    they were found (the dataset's ``_comment``, printed by ``fivecal import``)."""
    inst = side["instrument"]
    pose = [side.get("instrument_origin"), side.get("instrument_angles")]
    if any(v is not None for v in pose):
        o_, a_ = [list(v) if v is not None else [0.0, 0.0, 0.0] for v in pose]
        note = (f"instrument {inst}: nominal pose as given: origin {_fmt(o_)} mm, angles a b c {_fmt(a_)} deg")
    elif side.get("align") is False:
        o_, a_ = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        note = (f"instrument {inst}: nominal pose the identity (align off): its frame is taken as the machine "
                "frame, the fit must find the whole pose")
    else:
        # the nominal machine's view of each target through an identity pose
        plan = [{"type": o["type"], "instrument": inst, "target": o["target"], "target_point": o["target_point"],
                 "axes": o["axes"], "instrument_origin": [0.0, 0.0, 0.0], "instrument_angles": [0.0, 0.0, 0.0]}
                for o in obs]
        nominal = [p["measured"] for p in simulation.simulate(machine, plan).to_dict()["observations"]]
        try:
            o_, a_, rms = alignment.instrument_pose([o["measured"] for o in obs], nominal)
        except ValueError as e:
            raise ValueError(f"{path}: instrument {inst}: no pose given, and {e}") from None
        o_, a_ = [round(x, 6) for x in o_], [round(x, 6) for x in a_]
        why = "align on" if side.get("align") else "no pose given"
        note = (f"instrument {inst}: nominal pose from a rigid alignment ({why}) of the {len(obs)} measured "
                f"points to the nominal machine's (rms {rms:.3g} mm): origin {_fmt(o_)} mm, angles a b c "
                f"{_fmt(a_)} deg")
    for o in obs:
        o["instrument_origin"], o["instrument_angles"] = list(o_), list(a_)
    return note


def _fmt(v) -> str:
    return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"


def _is_number(cell: str) -> bool:
    try:
        float(cell.replace(",", "."))
        return True
    except ValueError:
        return False


def _row(cells, cols, machine: Machine, table: Mapping, side: Mapping, targets: Mapping, decimal_comma: bool,
         where: str, imports: Mapping) -> dict:
    """One row of a probing log (its target says the kind) or of a ball
    mounting's table."""
    axes, direction, vals, text, empty = {}, {}, {}, {}, {}
    for c in cols:
        cw = f"{where}: column '{c.header}'"
        cell = cells[c.index]
        if c.spec and c.spec["quantity"] == "text":
            s = cell.strip()
            if not s:
                if c.field == "approach":
                    continue
                raise ValueError(f"{cw}: empty cell (a {c.field} is expected)")
            text[c.field] = s.lower() if c.field == "type" else s
            continue
        v = _number(cell, decimal_comma, cw)
        if c.field.startswith("dir_"):
            if v not in (-1.0, 0.0, 1.0):
                raise ValueError(f"{cw}: direction {cell.strip()} is not -1, 0 or +1")
            if v:
                direction[c.field[4:]] = int(v)
            continue
        v *= c.factor
        if len(c.field) == 1:
            if not machine.is_rotary(c.field) and abs(v) > plausibility.REFUSE_POSITION:
                raise ValueError(f"{cw}: {v:.6g} mm is beyond any machine tool "
                                 f"({plausibility.REFUSE_POSITION / 1e3:g} m); positions look like µm: "
                                 f"name the column {c.field}_um")
            axes[c.field] = v
        else:
            vals[c.field] = (v, cw)
    touch = table["layout"] == "touch"
    typ = _touch_type(text, text.get("type"), targets, where) if touch else table["kinds"][0]
    own = imports[_table_of(typ, imports)]
    used = {c["name"] for c in own["columns"] if c["quantity"] != "text"}
    for f, (v, fw) in vals.items():
        if f not in used:
            raise ValueError(f"{fw}: a {typ} row has no {f} (leave the cell empty)")
        if f in _SIZES:
            _size(f, v, fw)
    for key in ("dir_" + a for a in machine.axis_names):
        if key in empty:
            raise ValueError(f"{empty[key]}: empty cell (a direction -1, 0 or +1 is expected)")
    o = {"type": typ, "axes": axes}
    if "id" in text:
        o["id"] = text["id"]
    if text.get("approach"):
        direction.update(_approach(text["approach"], machine, f"{where}: column 'approach'"))
    if direction:
        o["direction"] = direction
    if touch:
        o["target"] = text["target"]
    else:
        setup = text.get("setup", side.get("setup"))
        if setup:
            o["setup"] = str(setup)
        _fill(o, vals, own, side, where, typ)
    _row_sigma(o, vals, side)
    return o


def _table_of(typ: str, imports: Mapping) -> str:
    """The import whose table reads rows of kind ``typ``."""
    return next(n for n, t in imports.items() if n != GENERIC and typ in t["kinds"])


def _fill(o: dict, vals: Mapping, table: Mapping, side: Mapping, where: str, typ: str) -> None:
    """The observation's measured and set-up values from the row's number
    cells (``vals``: column name -> (value, where)) as the table's columns
    say: a column per value or per entry of a vector, else the sidecar's (or
    option's) value, else the column's message; each value within its
    column's range (beyond it the unit is wrong)."""
    groups: dict = {}
    orientation = _orientation(table)
    for c in table["columns"]:
        if c["quantity"] not in ("text", "joint") and c["field"] not in ("sigma", orientation):
            groups.setdefault(c["field"], []).append(c)
    for field, cs in groups.items():
        names = [c["name"] for c in cs]
        vector = cs[0]["index"] is not None
        given = [n for n in names if n in vals]
        if vector and given and len(given) < len(names):
            raise ValueError(f"{where}: {field} needs the three columns {', '.join(names)}")
        if not given:
            key = cs[0]["sidecar"]
            if key and side.get(key) is not None:
                o[field] = side[key]
                continue
            if cs[0]["missing"]:
                raise ValueError(f"{where}: {cs[0]['missing']}")
            if key:
                raise ValueError(f"{where}: no {field} for this {typ} sample: give --{key.replace('_', '-')} "
                                 f"X,Y,Z (mm), '{key}' in the sidecar, or the columns {', '.join(names)}")
            if not cs[0]["required"]:
                continue
        values = []
        for c in cs:
            v, vw = _value(vals, c["name"], where, typ)
            _in_range(c, v, vw)
            values.append(v)
        o[field] = values if vector else values[0]


def _in_range(column: Mapping, value: float, where: str) -> None:
    """Refuse a value beyond its column's range with the column's message."""
    limit = column["range"]
    if limit and abs(value) > limit:
        raise ValueError(f"{where}: " + column["range_message"].format(value=value, limit=limit,
                                                                        limit_m=limit / 1e3,
                                                                        column=column["name"]))


def _touch_type(text, typ, targets, where) -> str:
    """The kind of a probe touch: its target's (the artefact list that holds
    it); a ``type`` cell naming another touch kind is refused."""
    kinds = _touch_kinds()
    t = text.get("target")
    if not t:
        raise ValueError(f"{where}: no target for a probe touch (a 'target' column naming a {_either(kinds)})")
    known = targets.get(t)
    if known is None:
        if not targets:
            raise ValueError(f"{where}: target '{t}': no artefact given; a probing import needs the artefact's "
                             f"{_either(list(kinds.values()))} and the probe tip radius in a sidecar "
                             "(--sidecar FILE)")
        close = difflib.get_close_matches(t, sorted(targets), n=1)
        raise ValueError(f"{where}: column 'target': '{t}' is not a {_either(kinds)} of the artefact "
                         f"({', '.join(sorted(targets))})" + (f"; did you mean '{close[0]}'?" if close else ""))
    if typ in kinds and typ != known:
        raise ValueError(f"{where}: column 'type': '{typ}' but target '{t}' is a {known}")
    return known


def _value(vals, key, where, typ, empty=None):
    if empty and key in empty:
        raise ValueError(f"{empty[key]}: empty cell (a number is expected for a {typ} row)")
    if key not in vals:
        raise ValueError(f"{where}: no '{key}' for this {typ} row")
    return vals[key]


#: The length-like values of a sidecar, the options and the columns (key ->
#: the size in mm beyond which the value is µm typed as mm, what has that
#: size); readings and axis positions have their own checks.
_SIZES = {"length": (plausibility.BAR_LENGTH, "no ball bar is that long"),
          "tip_radius": (plausibility.TIP_RADIUS, "no probe tip is that large"),
          "radius": (plausibility.ARTEFACT_RADIUS, "no reference sphere or cylinder is that large"),
          "scale_bar": (plausibility.LOCAL_POSITION, "no scale bar is that long"),
          "dead_length": (plausibility.LOCAL_POSITION, "no tracer station is that far from its target"),
          "tool_ball": (plausibility.LOCAL_POSITION, "no tool ball sits that far from the origin at the zero pose"),
          "table_ball": (plausibility.LOCAL_POSITION, "no table ball is that far from the workpiece origin"),
          "target_point": (plausibility.LOCAL_POSITION, "no target is that far from its frame's origin"),
          "instrument_origin": (plausibility.REFUSE_POSITION, "no instrument is that far from the machine"),
          "station_position": (plausibility.REFUSE_POSITION, "no station is that far from the machine"),
          "axis": (plausibility.REFUSE_POSITION, "beyond any machine tool")}
for _k in ("tool_ball", "table_ball"):
    _SIZES.update({f"{_k}_{c}": _SIZES[_k] for c in "xyz"})


def _size(key: str, value, where: str) -> None:
    """Refuse a length-like value (mm) of ``key`` beyond its plausible size
    (:data:`_SIZES`), naming where it was given; a list: each entry."""
    if isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _size(key, v, f"{where}[{i}]")
        return
    limit, why = _SIZES[key]
    if isinstance(value, (int, float)) and not isinstance(value, bool) and abs(value) > limit:
        raise ValueError(f"{where}: {value:.6g} mm: {why} (refused beyond {limit:g} mm); it looks like µm: "
                         f"give {value / 1000:.6g} (mm)")


def _sidecar_sizes(side: Mapping, origin: Mapping, machine: Machine) -> None:
    """The length-like values of the sidecar and the options, named where given."""
    for key in ("length", "tool_ball", "table_ball", "target_point", "instrument_origin"):
        if side.get(key) is not None:
            _size(key, side[key], origin.get(key, key))
    probe = side.get("probe")
    if isinstance(probe, Mapping):
        _size("tip_radius", probe.get("tip_radius"), f"{origin.get('probe', 'probe')}.tip_radius")
    art = side.get("artefact")
    if isinstance(art, Mapping):
        for group, key, size in (("spheres", "radius", "radius"), ("cylinders", "radius", "radius"),
                                 ("scale_bars", "length", "scale_bar")):
            for k, x in enumerate(art.get(group) or []):
                if isinstance(x, Mapping):
                    _size(size, x.get(key), f"{origin.get('artefact', 'artefact')}.{group}[{k}].{key}")
    for sid, st in (side.get("stations") or {}).items() if isinstance(side.get("stations"), Mapping) else ():
        if isinstance(st, Mapping):
            _size("station_position", st.get("position"), f"{origin.get('stations', 'stations')}.{sid}.position")
            _size("dead_length", st.get("dead_length"), f"{origin.get('stations', 'stations')}.{sid}.dead_length")
    joints = side.get("joints")
    if isinstance(joints, Mapping) and isinstance(joints.get("home"), Mapping):
        for a, v in joints["home"].items():
            if a in machine.axis_names and not machine.is_rotary(a):
                _size("axis", v, f"{origin.get('joints', 'joints')}.home.{a}")


def _positive(value, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a number (mm), got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{what}: expected a finite number > 0 (mm), got {value!r}")
    return v



# --------------------------------------------------------------------------
# fivecal (generic) and machined: columns named after the dataset file's keys
# --------------------------------------------------------------------------
# The generic table's columns come from the registered observation kinds'
# file keys (``_core.observation_kinds()``), so a new kind is read and written
# without an edit here. A key's columns follow its value's shape:
#   a number or text        -> the key itself (``reading``, ``setup``);
#   a list of three         -> ``<key>_x _y _z`` (``tool_ball_x``);
#   a list of another length -> ``<key>_1 ... _n`` (``sigma_1`` .. ``sigma_6``);
#   ``axes``                -> the axis letters; ``direction`` -> ``dir_<letter>``;
#   another axes object ``<p>_axes`` -> ``<p>_<letter>`` (``reference_A``).
_XYZ = "xyz"


def _entry_names(imports: Mapping) -> dict:
    """A kind table's own name of a vector entry (``dx``: the first entry of
    ``measured``) -> (key, index): the generic table reads them too."""
    out = {}
    for t in imports.values():
        for c in t["columns"]:
            i = c["index"]
            if i is not None and i < 3 and c["name"] != f"{c['field']}_{_XYZ[i]}":
                out.setdefault(c["name"], (c["field"], i))
    return out


def _measured_keys(imports: Mapping) -> set:
    """Keys whose numbers are what an instrument measured: ``--units`` applies to them."""
    return {c["field"] for t in imports.values() for c in t["columns"] if c["measured"]}


def _row_aliases(imports: Mapping) -> dict:
    """Other names a row's type cell may give a kind -> the kind."""
    return {a: t["kinds"][0] for t in imports.values() for a in t["row_aliases"]}


def _registered() -> dict:
    """name -> the registry's record of each observation kind."""
    return {k["name"]: k for k in _core.observation_kinds()}


class _Keys(set):
    """The file keys whose values are text in the dataset schema (names, ids,
    sides); ``typed``: the keys the schema describes at all. A key of a kind
    the schema file does not describe is text when its cell is not a number."""
    typed: set


def _text_keys() -> _Keys:
    s = schema.load_schema("dataset")
    common = schema.load_schema("common")["$defs"]
    out = _Keys({"id", "type"})
    out.typed = set(out)
    for block in s["$defs"]["observation"].get("allOf", []):
        for key, prop in block["then"].get("properties", {}).items():
            ref = prop.get("$ref", "")
            if ref.startswith("common.schema.json#/$defs/"):
                prop = common.get(ref.rsplit("/", 1)[1], {})
            if prop:
                out.typed.add(key)
            if prop.get("type") == "string" or (prop.get("enum") and all(isinstance(e, str) for e in prop["enum"])):
                out.add(key)
    return out


class _GColumn:
    """One column of a generic table: the key it feeds, its place in the
    key's value (None: the value; int: a list index; letter: an axes-object
    entry), and its unit factor."""

    def __init__(self, index: int, header: str, key: str, part, factor: float = 1.0):
        self.index, self.header, self.key, self.part, self.factor = index, header, key, part, factor


def _generic_columns(headers, machine: Machine, kind: str, where: str, rename: Mapping[str, str],
                     ignore: Iterable[str], length_unit: Optional[str], angle_unit: Optional[str],
                     registry: Mapping, text_keys: set, imports: Mapping) -> list:
    table = imports[kind]
    generic = kind == GENERIC
    keys = set()
    for k in (registry.values() if generic else [registry[n] for n in table["kinds"]]):
        keys |= set(k["json_keys"])
    keys -= {"axes", "direction"}
    axes = machine.axis_names
    entries, measured = _entry_names(imports), _measured_keys(imports)
    # a table's own other names: a whole name, or a prefix (a name ending in _)
    renames = {a: b for a, b in table["header_aliases"].items() if not a.endswith("_")}
    prefixes = {a: b for a, b in table["header_aliases"].items() if a.endswith("_")}

    def resolve(name: str, cw: str):
        low, up = name.strip().lower(), name.strip().upper()
        up = "S" if up == "C1" else up
        if len(up) == 1 and up.isalpha():
            if up in axes:
                return "axes", up
            raise ValueError(f"{cw}: unknown axis letter '{name}' (the machine's axes: {_axis_list(machine)})")
        m = re.match(r"^(?:dir_?([a-z]\d?)|([a-z]\d?)_?dir)$", low)
        if m:
            letter = (m.group(1) or m.group(2)).upper()
            letter = "S" if letter == "C1" else letter
            if letter not in axes:
                raise ValueError(f"{cw}: direction column of unknown axis '{letter}' "
                                 f"(the machine's axes: {_axis_list(machine)})")
            return "direction", letter
        if low == "approach":
            return "approach", None
        low = renames.get(low, low)
        for a, b in prefixes.items():
            if low.startswith(a):
                low = b + low[len(a):]
        if low in keys or (generic and low == "type"):
            return low, None
        if low in entries and entries[low][0] in keys:
            return entries[low]
        if "_" in low:
            base, suffix = low.rsplit("_", 1)
            if base in keys and len(suffix) == 1 and suffix in _XYZ:
                return base, _XYZ.index(suffix)
            if base in keys and suffix.isdigit() and int(suffix) >= 1:
                return base, int(suffix) - 1
            letter = "S" if suffix.upper() == "C1" else suffix.upper()
            if base + "_axes" in keys and letter in axes:
                return base + "_axes", letter
        names = sorted(keys | ({"type"} if generic else set())) + list(axes) + \
            [f"dir_{a}" for a in axes]
        close = difflib.get_close_matches(low, names, n=1)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        what = f"a {GENERIC} table (a key of a registered observation kind)" if generic else \
            f"a {kind} import"
        raise ValueError(f"{cw}: unknown column '{name}' for {what}{hint} (rename it with --column FIELD=HEADER "
                         f"or skip it with --ignore '{name}')")

    cols, seen = [], {}
    for i, h, name, unit, cw in _named_headers(headers, where, rename, ignore):
        field, part = resolve(name, cw)
        if (field, part) in seen:
            raise ValueError(f"{where}: columns '{seen[(field, part)]}' and '{h}' both give "
                             f"{field}{'' if part is None else f' {part}'}")
        seen[(field, part)] = h
        factor = 1.0
        letter = part if field == "axes" or field.endswith("_axes") else None
        if letter is not None and machine.is_rotary(letter):
            factor = _units.column_unit(h, "angle", where)[0] if unit is not None else \
                _units.ANGLE_SUFFIXES[angle_unit or "deg"]
        elif letter is not None:
            factor = _units.column_unit(h, "length", where)[0] if unit is not None else 1.0
        elif field in text_keys or field in ("type", "approach", "direction"):
            if unit is not None:
                raise ValueError(f"{cw}: {field} has no unit, got '{unit}'")
        elif field in table["directions"]:
            if unit is not None:
                raise ValueError(f"{cw}: {table['directions'][field]} is a direction and has no unit, "
                                 f"got '{unit}'")
        elif unit is not None:
            try:
                factor = _units.column_unit(h, "length", where)[0]
            except ValueError:
                raise ValueError(f"{cw}: only axis columns take an angle unit here; give {field} in the unit "
                                 "of the dataset file (`fivecal docs formats`)") from None
        elif field in measured:
            factor = _units.LENGTH_SUFFIXES[length_unit or "mm"]
        cols.append(_GColumn(i, h.strip(), field, part, factor))
    fields = {f for f, _ in seen}
    missing = [a for a in axes if a != "S" and ("axes", a) not in seen]
    if missing:
        raise ValueError(f"{where}: no column for axis {', '.join(missing)} (expected a column per machine "
                         f"axis: {_axis_list(machine)}; S may be left out)")
    if generic and "type" not in fields:
        raise ValueError(f"{where}: no 'type' column; a {kind} import expects {_expected(machine, kind, imports)}")
    for r in (c["name"] for c in table["columns"] if c["required"]):
        if r not in fields:
            raise ValueError(f"{where}: no '{r}' column; a {kind} import expects "
                             f"{_expected(machine, kind, imports)}")
    return cols


def _generic_row(cells, cols, machine: Machine, kind: str, side: Mapping, decimal_comma: bool, where: str,
                 registry: Mapping, text_keys: set, imports: Mapping) -> dict:
    """One observation of the generic (``fivecal``) table, or of a kind's
    table read by the generic reader (its columns named after its file keys)."""
    table = imports[kind]
    aliases = _row_aliases(imports)
    text, parts, empty = {}, {}, {}
    for c in cols:
        cw = f"{where}: column '{c.header}'"
        cell = cells[c.index].strip()
        if not cell:
            empty[(c.key, c.part)] = cw
            continue
        if c.key in text_keys or c.key in ("type", "approach") or (
                c.part is None and c.key not in text_keys.typed and not _is_number(cell)):
            text[c.key] = (cell.lower() if c.key == "type" else cell, cw)
            continue
        v = _number(cell, decimal_comma, cw)
        if c.key == "direction":
            if v not in (-1.0, 0.0, 1.0):
                raise ValueError(f"{cw}: direction {cell} is not -1, 0 or +1")
            v = int(v)
        else:
            v *= c.factor
        parts.setdefault(c.key, {})[c.part] = (v, cw)
    # the row's kind
    if kind == GENERIC:
        if "type" not in text:
            raise ValueError(f"{empty.get(('type', None), where)}: empty cell (the row's observation type is "
                             f"expected: {', '.join(registry)})")
        typ, tw = text.pop("type")
        typ = aliases.get(typ, typ)
        if typ not in registry:
            close = difflib.get_close_matches(typ, sorted(registry), n=1)
            raise ValueError(f"{tw}: '{typ}' is not an observation type ({', '.join(registry)})"
                             + (f"; did you mean '{close[0]}'?" if close else ""))
    else:
        typ = table["kinds"][0]
        if "type" in text and aliases.get(text["type"][0], text["type"][0]) != typ:
            raise ValueError(f"{text['type'][1]}: '{text['type'][0]}' in a {kind} import (a table of several "
                             f"kinds is a {GENERIC} import)")
        text.pop("type", None)
    keys = set(registry[typ]["json_keys"])
    for key, (_, cw) in list(text.items()):
        if key not in keys and key != "approach":
            raise ValueError(f"{cw}: a {typ} row has no {key} (leave the cell empty)")
    for key, got in parts.items():
        if key not in keys:
            raise ValueError(f"{next(iter(got.values()))[1]}: a {typ} row has no {key} (leave the cell empty)")
        if key in _SIZES:
            for v, cw in got.values():
                _size(key, v, cw)
    # every axis of the machine but S in every row; an empty direction cell is an axis not recorded
    for (key, part), cw in empty.items():
        if key == "axes" and part != "S":
            raise ValueError(f"{cw}: empty cell (a number is expected)")
    o = {"type": typ}
    for key, got in parts.items():
        if key == "axes" or key == "direction" or key.endswith("_axes"):
            o[key] = {p: v for p, (v, _) in got.items()}
            if key != "direction":
                # another axes object (``<p>_axes``) is read from ``<p>_<letter>`` columns
                prefix = key[:-len("axes")]
                for a, v in o[key].items():
                    if not machine.is_rotary(a) and abs(v) > plausibility.REFUSE_POSITION:
                        cw = got[a][1]
                        raise ValueError(f"{cw}: {v:.6g} mm is beyond any machine tool "
                                         f"({plausibility.REFUSE_POSITION / 1e3:g} m); positions look like µm: "
                                         f"name the column {prefix}{a}_um")
            continue
        if None in got and len(got) > 1:
            other = next(cw for p, (_, cw) in got.items() if p is not None)
            raise ValueError(f"{other}: {key} is given whole by column '{got[None][1].split(chr(39))[1]}' and "
                             "in parts; leave one empty")
        if None in got:
            o[key] = got[None][0]
            continue
        n = max(got) + 1
        for i in range(n):
            if i not in got:
                cw = empty.get((key, i))
                raise ValueError(f"{cw or where}: " + ("empty cell " if cw else f"no column for {key} entry {i + 1} ")
                                 + f"(a number is expected for a {typ} row)")
        o[key] = [got[i][0] for i in range(n)]
    # an axes object given in part (a step's reference cut): name the empty cell
    for key in [k for k in o if k.endswith("_axes")]:
        for (k, part), cw in empty.items():
            if k == key and part != "S":
                raise ValueError(f"{cw}: empty cell ({key} needs every axis: {_axis_list(machine, skip_s=True)})")
    if "axes" not in o:
        o["axes"] = {}
    for key, (value, _) in text.items():
        if key != "approach":
            o[key] = value
    if "approach" in text:
        o.setdefault("direction", {}).update(_approach(text["approach"][0], machine, text["approach"][1]))
    # what the table does not hold, from the sidecar or the options
    for key in registry[typ]["json_keys"]:
        if key not in o and side.get(key) is not None:
            o[key] = list(side[key]) if isinstance(side[key], (list, tuple)) else side[key]
    if isinstance(o.get("sigma"), (int, float)) and not o["sigma"] > 0:
        raise ValueError(f"{parts['sigma'][None][1]}: sigma {o['sigma']:g} mm must be > 0")
    own = imports[_table_of(typ, imports)]
    _apply_rules(o, parts, text, side, machine, where, own["rules"])
    if kind != GENERIC:
        # the instrument's range: a table of the kind's own (a fivecal table's
        # rows go to the dataset's checks as they are)
        for c in own["columns"]:
            got = parts.get(c["field"], {})
            if c["index"] in got:
                _in_range(c, *got[c["index"]])
    return o


def _cell(parts, text, key: str, where: str) -> str:
    """Where a row's value of ``key`` was given: its (first) cell, else the line."""
    if key in text:
        return text[key][1]
    if parts.get(key):
        return next(iter(parts[key].values()))[1]
    return where


def _entry(key: str, i: int, n: int) -> str:
    """The column of entry ``i`` of an ``n``-vector ``key`` (``point_y``), without unit."""
    return f"{key}_{_XYZ[i]}" if n == 3 else f"{key}_{i + 1}"


def _apply_rules(o: dict, parts, text, side: Mapping, machine: Machine, where: str, rules) -> None:
    """The rules a kind's table declares (the registry's ``table.rules``:
    defaults, allowed values, keys that must or must not come together,
    vector sizes, nonzero vectors, plausible sizes), in order, each refusal
    naming the cell (else the line) it is about."""
    for r in rules:
        keys, rule, message = r["keys"], r["rule"], r["message"]
        if rule == "default":
            key = keys[0]
            if key in o:
                continue
            if r["option"] and side.get(r["option"]):
                o[key] = str(side[r["option"]])
            else:
                o[key] = r["then"] if r["if_key"] and r["if_key"] in o else r["value"]
        elif rule == "no_char":
            key = keys[0]
            if key in o and any(ch in str(o[key]) for ch in r["chars"]):
                raise ValueError(f"{_cell(parts, text, key, where)}: " + message.format(value=o[key]))
        elif rule == "one_of":
            key = keys[0]
            if key in o and o[key] not in r["values"]:
                close = difflib.get_close_matches(str(o[key]), r["values"], n=1)
                allowed = f"neither {_either(r['values'], 'nor')}" if len(r["values"]) == 2 else \
                    f"not one of {', '.join(r['values'])}"
                raise ValueError(f"{_cell(parts, text, key, where)}: '{o[key]}' is {allowed}"
                                 + (f"; did you mean '{close[0]}'?" if close else ""))
        elif rule in ("excludes", "requires"):
            if o.get(r["if_key"]) != r["value"]:
                continue
            given = [k for k in keys if k in o]
            if rule == "excludes" and given:
                raise ValueError(f"{_cell(parts, text, given[0], where)}: " + message.format(value=r["value"]))
            if rule == "requires" and len(given) < len(keys):
                raise ValueError(f"{where}: " + message.format(axes=_axis_list(machine, skip_s=True)))
        elif rule == "size":
            for key in keys:
                if key in o and len(o[key]) != r["size"]:
                    count = "three" if r["size"] == 3 else str(r["size"])
                    names = " ".join(_entry(key, i, r["size"]) for i in range(r["size"]))
                    raise ValueError(f"{where}: {key} needs the {count} columns {names}")
        elif rule == "nonzero":
            for key in keys:
                if key in o and not math.sqrt(sum(v * v for v in o[key])) > 1e-9:
                    raise ValueError(f"{_cell(parts, text, key, where)}: " + message.format(value=_fmt(o[key])))
        elif rule == "limit":
            for key in keys:
                value = o.get(key, ())
                for i, v in enumerate(value if isinstance(value, (list, tuple)) else [value]):
                    if abs(v) > r["limit"]:
                        cw = parts.get(key, {}).get(i if isinstance(value, (list, tuple)) else None, (0, where))[1]
                        column = _entry(key, i, len(value)) if isinstance(value, (list, tuple)) else key
                        raise ValueError(f"{cw}: " + message.format(value=v, column=column))
        else:
            raise RuntimeError(f"{where}: the kind's table declares an unknown rule '{rule}' (a bug in the kind)")


def _angle_checks(obs: list, cols, machine: Machine, path: str, lines: list) -> None:
    """Rotary columns of an axes object other than ``axes`` (a step's
    reference cut) that look like radians warn as the axes do."""
    for c in cols:
        if not c.key.endswith("_axes") or not machine.is_rotary(c.part):
            continue
        values = [o[c.key][c.part] for o in obs if c.part in (o.get(c.key) or {})]
        if values and looks_like_radians(values):
            _warn(radians_message(f"{path}: column '{c.header}'", values)
                  + f", name the column {c.header}_rad or give --angle-units rad", RadiansWarning)


#: A test turns a rotary axis through a turn at most (plus an approach): a
#: column declared in radians whose values pass a turn and a quarter holds
#: degrees (8 rad is 458 degrees; 8 degrees is what was meant).
_RAD_TURNS = 1.25


def _rotary_columns(obs: list, cols, machine: Machine, lines: list, angle_units: Optional[str]) -> list:
    """The rotary axis columns of a read table as (what to call it, unit,
    [(value in that unit, line)], how to say it is in degrees, how to say it
    is in radians): axis columns, a step's reference axes, and a joint
    layout's position column per rotary joint."""
    out = []
    default = (angle_units or "deg").lower()
    for c in cols:
        key, part = (c.key, c.part) if isinstance(c, _GColumn) else ("axes", c.field)
        if not (key == "axes" or key.endswith("_axes")) or part not in machine.axis_names or \
                not machine.is_rotary(part):
            continue
        values = [(o[key][part] / c.factor, n) for o, n in zip(obs, lines) if part in (o.get(key) or {})]
        out.append(_rotary_column(c.header, values, default))
    position = next((c.header for c in cols if getattr(c, "field", None) == "position"), "position")
    factor = _units.ANGLE_SUFFIXES[default]
    for a in machine.axis_names:
        values = [(o["_joint"][1] / factor, n) for o, n in zip(obs, lines) if o.get("_joint", ("",))[0] == a]
        if values and machine.is_rotary(a):
            out.append((f"column '{position}' (joint {a})", default, values,
                        f"drop --angle-units {default} (degrees are the default)", "give --angle-units rad"))
    return out


def _rotary_column(header: str, values: list, default: str) -> tuple:
    """A rotary axis column for :func:`_rotary_units`: its unit is its
    header's, else ``default`` (``--angle-units``, else deg)."""
    base, unit = _split_unit(header)
    if unit is not None:
        return (f"column '{header}'", unit.lower(), values, f"name the column {base}_deg",
                f"name the column {base}_rad")
    return (f"column '{header}'", default, values, f"drop --angle-units {default} (degrees are the default) or "
            f"name the column {base}_deg", f"name the column {base}_rad or give --angle-units rad")


def _rotary_units(columns: list, path: str) -> None:
    """Refuse a rotary column whose values are plainly in another unit than
    the one declared (its header, else --angle-units, else degrees), naming
    the column, the line and the fix."""
    for what, unit, values, to_deg, to_rad in columns:
        if not values:
            continue
        factor = _units.ANGLE_SUFFIXES[unit]
        if factor != 1.0:
            bound = _RAD_TURNS * 360.0 / factor
            big = next(((v, n) for v, n in values if abs(v) > bound), None)
            if big:
                v, n = big
                raise ValueError(f"{path}:{n}: {what}: {v:.6g} {unit} is {v * factor:.6g} degrees, more than a "
                                 f"turn and a quarter ({bound:.4g} {unit}); the values look like degrees: {to_deg}")
            nonzero = [(v, n) for v, n in values if v != 0.0]
            if unit == "rad" and len({v for v, _ in nonzero}) >= 2 and all(v == round(v) for v, _ in nonzero):
                # radians are written in decimals (0.7854, 1.5708); whole numbers are degrees
                v, n = nonzero[0]
                shown = ", ".join(f"{x:g}" for x in sorted({x for x, _ in nonzero})[:4])
                raise ValueError(f"{path}:{n}: {what}: {v:g} rad, and every value of the column is a whole "
                                 f"number ({shown}, ...), as degrees are written; the values look like degrees: "
                                 f"{to_deg}")
        elif _units.written_as_radians([v for v, _ in values]):
            v, n = next((v, n) for v, n in values if v != 0.0)
            k = round(v / (math.pi / 12))
            raise ValueError(f"{path}:{n}: {what}: {v:g} degrees, and every value of the column is a multiple of "
                             f"π/12 written in decimals ({v:g} = {k}π/12), as radians are written; the values "
                             f"look like radians: {to_rad}")


def write_table(dataset, path: Union[str, os.PathLike], *, delimiter: str = ",") -> dict:
    """Write ``dataset``'s observations as a ``fivecal`` table (one row per
    observation, the columns of every key they use; see docs/formats.md) that
    ``fivecal import fivecal`` reads back to the same observations; returns
    the sidecar (probe, artefact) that goes with it. Numbers are written to
    round trip exactly."""
    doc = dataset.to_dict() if hasattr(dataset, "to_dict") else dict(dataset)
    registry = _registered()
    machine = Machine.from_dict(doc["machine"])
    order = [a for a in machine.axis_names]
    columns, cells = [], []

    def add(col):
        if col not in columns:
            columns.append(col)

    def flatten(key, value, where) -> list:
        if key == "axes":
            return [(a, value[a]) for a in order if a in value]
        if key == "direction":
            return [(f"dir_{a}", value[a]) for a in order if a in value]
        if isinstance(value, Mapping):
            if not key.endswith("_axes"):
                raise ValueError(f"{where}.{key}: an object other than an axes object has no table columns")
            return [(f"{key[:-5]}_{a}", value[a]) for a in order if a in value]
        if isinstance(value, (list, tuple)):
            names = [f"{key}_{_XYZ[i]}" for i in range(3)] if key not in numbered else \
                [f"{key}_{i + 1}" for i in range(len(value))]
            return list(zip(names, value))
        return [(key, value)]

    # a key that is a list of other than three numbers in any row is numbered in every row
    numbered = {k for o in doc["observations"] for k, v in o.items()
                if isinstance(v, (list, tuple)) and len(v) != 3}

    for i, o in enumerate(doc["observations"]):
        typ = o["type"]
        if typ not in registry:
            raise ValueError(f"observations[{i}].type: '{typ}' is not a registered observation type")
        row = {"type": typ}
        for key in ["id", "axes", "direction"] + [k for k in registry[typ]["json_keys"]
                                                   if k not in ("type", "id", "axes", "direction")]:
            if key in o:
                row.update(flatten(key, o[key], f"observations[{i}]"))
        unknown = set(o) - set(registry[typ]["json_keys"])
        if unknown:
            raise ValueError(f"observations[{i}]: {', '.join(sorted(unknown))}: not a key of a {typ} observation")
        for col in row:
            add(col)
        cells.append(row)
    front = ["type", "id"] + [a for a in order] + [f"dir_{a}" for a in order]
    columns = [c for c in front if c in columns] + [c for c in columns if c not in front]

    def fmt(v):
        if isinstance(v, bool):
            raise ValueError(f"a table cell cannot hold {v!r}")
        if isinstance(v, int):
            return str(v)
        if isinstance(v, float):
            return repr(v)
        return str(v)

    buf = io.StringIO()
    w = csv.writer(buf, delimiter=delimiter, lineterminator="\n")
    w.writerow(columns)
    for row in cells:
        w.writerow([fmt(row[c]) if c in row else "" for c in columns])
    files.write_text(path, buf.getvalue())
    return {k: doc[k] for k in ("probe", "artefact") if doc.get(k)}


_OBS = re.compile(r"observations\[(\d+)\]")


def import_dataset(path: Union[str, os.PathLike], kind: str, machine, **options):
    """:func:`read_table`, then validation as a :class:`fivecal.Dataset`; an
    error the dataset checks find in an observation names its file and line.
    ``dataset.import_note`` says how a point import set the instrument's
    nominal pose (empty for other kinds)."""
    _known_options(options, "import_dataset")
    d, lines = _read(path, kind, machine, **options)
    path = os.fspath(path)
    sidecar = options.get("sidecar")
    sidecar = os.fspath(sidecar) if isinstance(sidecar, (str, os.PathLike)) else "sidecar"

    def located(message: str) -> str:
        """The dataset checks' message with the file (and line) the value came from."""
        m = re.match(r"^dataset(?:\.|: )(.*)$", message, re.S)
        if not m:
            return message
        rest = m.group(1)
        if rest.startswith(("artefact", "probe")):
            return f"{sidecar}: {rest}"
        at = lambda k: (f"{path}:{lines[int(k.group(1))]} ({k.group(0)})"
                        if int(k.group(1)) < len(lines) else k.group(0))
        if _OBS.match(rest):
            return _OBS.sub(at, rest, count=1)
        return f"{path}: " + _OBS.sub(at, rest)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            ds = Dataset.from_dict(d)
        except ValueError as e:
            raise ValueError(located(str(e))) from None
    for w in caught:
        text = located(str(w.message))
        m = re.search(r"observations\[\*\]\.axes\.(\w+)", text)
        if issubclass(w.category, RadiansWarning) and m:
            text = (text.replace(m.group(0), f"axis column {m.group(1)}")
                    + f", name the column {m.group(1)}_rad or give --angle-units rad")
        _warn(text, w.category)
    # how a point import placed the instrument: the user must be able to see it
    ds.import_note = d.get("_comment", "")
    return ds


def _known_options(options: Mapping, what: str) -> None:
    """Refuse an unknown keyword naming it and the accepted ones (a raw
    TypeError from deep inside names a private function); a sidecar key
    given as a keyword is told where it belongs."""
    accepted = [p for p in inspect.signature(read_table).parameters if p not in ("path", "kind", "machine")]
    for key in sorted(set(options) - set(accepted)):
        side_keys = sorted(set(_schema_keys()) - set(accepted))
        if key in side_keys:
            raise ValueError(f"{what}: '{key}' is a sidecar key, not a keyword: pass sidecar={{'{key}': ...}} "
                             f"(or a sidecar JSON file; `fivecal docs import`)")
        close = difflib.get_close_matches(key, accepted, n=1)
        raise ValueError(f"{what}: unknown keyword '{key}'" + (f" (did you mean '{close[0]}'?)" if close else "")
                         + f"; accepted: {', '.join(accepted)}")


def _schema_keys() -> list:
    """The keys an import sidecar may hold (import.schema.json)."""
    return [k for k in schema.load_schema("import").get("properties", {}) if not k.startswith(("$", "_"))]


def _warn(message: str, category) -> None:
    """Warn at the first caller outside the fivecal package (the user's line)."""
    pkg = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    level, f = 2, sys._getframe(1)
    while f is not None and os.path.abspath(f.f_code.co_filename).startswith(pkg + os.sep):
        f, level = f.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)


def write_dataset(path: Union[str, os.PathLike], out: Union[str, os.PathLike], kind: str, machine, **options):
    """Import ``path`` and write the dataset JSON ``out`` (atomically); returns the Dataset."""
    ds = import_dataset(path, kind, machine, **options)
    doc = ds.to_dict()
    if ds.import_note:
        doc = {"_comment": ds.import_note, **doc}
    files.write_json(out, doc)
    return ds


def parse_columns(items: Iterable[str]) -> dict:
    """``--column reading=dL_um`` options to {field: header}."""
    out = {}
    for item in items or ():
        if "=" not in item:
            raise ValueError(f"--column '{item}': expected FIELD=HEADER, like reading=dL_um")
        k, v = item.split("=", 1)
        if not k.strip() or not v.strip():
            raise ValueError(f"--column '{item}': expected FIELD=HEADER, like reading=dL_um")
        out[k.strip()] = v.strip()
    return out

