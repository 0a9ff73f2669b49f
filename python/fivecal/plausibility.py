"""Magnitude checks at the boundary: inputs whose size fits the wrong unit.

A dataset in µm, ball bar readings in µm, a sphere radius given as its
diameter or rotary readings in radians all load and fit without complaint,
and give a confident wrong answer. These checks run where data comes in
(:func:`fivecal.load_dataset`, :meth:`fivecal.Dataset.from_dict`, the plan of
:func:`fivecal.simulate`, CSV traces) and decide per case:

* **refuse** (ValueError naming the field) when the evidence does not depend
  on the nominal model: a ball bar reading beyond ±2 mm (a QC20 ballbar
  measures about ±1 mm), an R-test displacement beyond 5 mm, a position or
  length beyond 100 m, a sphere (or cylinder) whose touches at the nominal
  machine lie consistently at R/2 + r from its centre (axis): the radius is
  the diameter;
* **warn** (:class:`fivecal.UnitsWarning`) when a rough nominal model could
  explain it: positions or lengths beyond 10 m, sphere touches far from
  R + r, cylinder touches far from R ± r of its axis, facet touches more
  than 5 mm from their facet;
* **warn** (:class:`fivecal.RadiansWarning`) once per rotary axis whose
  values look like radians (:func:`fivecal.units.looks_like_radians`).
"""
from __future__ import annotations

import functools
import json
import math
import numbers
import os
import sys
import warnings
from typing import Mapping, Optional, Sequence

import numpy as np

from . import _core
from .machine import Machine, RadiansWarning
from .units import UnitsWarning, looks_like_radians, radians_message

#: mm. Beyond WARN_POSITION a value is more likely µm than a machine of that size;
#: beyond REFUSE_POSITION no machine tool explains it.
WARN_POSITION = 1e4
REFUSE_POSITION = 1e5
#: mm: a ball bar reading is the bar length minus its nominal length; a QC20
#: ballbar's range is about ±1 mm.
DBB_RANGE = 2.0
#: mm: R-test / 3D ball sensors measure displacements of at most a few mm.
BALL3D_RANGE = 5.0
#: mm: facet touches farther than this from their facet at the nominal machine.
FACET_DISTANCE = 5.0
#: mm: sizes of the set-up an import reads (sidecar, options, columns) beyond
#: which a value is µm typed as mm: a ball bar's nominal length (a QC20-W with
#: every extension is 600 mm), a probe tip radius, a reference sphere's or
#: cylinder's radius, and how far a ball, a target or a tracer's dead length
#: reaches from its frame's origin (positions in F use REFUSE_POSITION).
BAR_LENGTH = 2000.0
TIP_RADIUS = 50.0
ARTEFACT_RADIUS = 1000.0
LOCAL_POSITION = 1e4


def _warn(message: str, category) -> None:
    """Warn at the first caller outside the fivecal package (the user's line)."""
    pkg = os.path.dirname(os.path.abspath(__file__))
    level, f = 2, sys._getframe(1)
    while f is not None and os.path.dirname(os.path.abspath(f.f_code.co_filename)) == pkg:
        f, level = f.f_back, level + 1
    warnings.warn(message, category, stacklevel=level)


def _num(v) -> float:
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        return math.nan
    return float(v)


def _vec(v, n=3) -> np.ndarray:
    if isinstance(v, (list, tuple, np.ndarray)) and len(v) == n:
        return np.array([_num(x) for x in v])
    return np.full(n, math.nan)


def _check_size(values: np.ndarray, fields: Sequence[str], where: str, what: str) -> None:
    """Refuse / warn on the largest |value| of a set of positions or lengths (mm)."""
    if not len(values):
        return
    a = np.abs(np.where(np.isfinite(values), values, 0.0))
    i = int(np.argmax(a))
    if a[i] > REFUSE_POSITION:
        raise ValueError(f"{where}: {fields[i]} = {values[i]:.6g} mm is beyond any machine tool "
                         f"({REFUSE_POSITION / 1e3:g} m); {what} look like µm: divide by 1000 "
                         "(fivecal expects mm)")
    if a[i] > WARN_POSITION:
        _warn(f"{where}: {fields[i]} = {values[i]:.6g} mm is beyond {WARN_POSITION / 1e3:g} m; "
              f"if {what} are in µm, divide by 1000 (fivecal expects mm)", UnitsWarning)


def check_rotary(machine: Machine, columns: Mapping[str, np.ndarray], where: str) -> None:
    """One RadiansWarning per rotary axis whose values look like radians."""
    for a, v in columns.items():
        letter = "S" if a == "C1" else a
        if letter in machine.axis_names and machine.is_rotary(letter) and looks_like_radians(v):
            _warn(radians_message(f"{where}.{a}", v), RadiansWarning)


def _column(values: list) -> np.ndarray:
    """Floats of a list (NaN where a value is not a number)."""
    try:
        a = np.array(values, dtype=float)
        if a.ndim == 1:
            return a
    except (TypeError, ValueError):
        pass
    return np.array([_num(v) for v in values], dtype=float)


def _rows(values: list, n: int = 3) -> np.ndarray:
    """(N, n) floats of a list of n-vectors (NaN rows where one is not)."""
    try:
        a = np.array(values, dtype=float)
        if a.ndim == 2 and a.shape[1] == n:
            return a
    except (TypeError, ValueError):
        pass
    return np.array([_vec(v, n) for v in values], dtype=float).reshape(-1, n)


def _axis_columns(machine: Machine, entries: Sequence[Mapping]):
    axes = [e.get("axes") if isinstance(e, dict) else None for e in entries]
    axes = [x if isinstance(x, dict) else {} for x in axes]
    return {a: _column([x.get(a, 0.0 if a == "S" else math.nan) for x in axes])
            for a in machine.axis_names}


#: Keys of observations and plan entries that hold a position (3-vector, mm) or
#: a length (mm), besides the ball bar / 3D ball fields ``Dataset.columns``
#: gives (``length``, ``tool_ball``, ``table_ball``): checked for µm wherever a
#: registered kind has them (``_core.observation_kinds()``).
POSITION_KEYS = ("target_point", "instrument_origin", "station_position", "point", "reference_point")
LENGTH_KEYS = ("dead_length",)
#: The other keys of the registered kinds: no position or length in mm (ids,
#: axes (checked apart), directions, angles in rad, readings checked against
#: their instrument's range, a point or pose's reading in the instrument frame).
#: A kind that brings a key in neither list fails the test that holds this
#: module to the registry.
OTHER_KEYS = ("type", "target", "setup", "instrument", "station", "part", "feature", "id", "sigma", "axes",
              "direction", "reference_axes", "reading", "measured", "measured_rotation", "target_rotation",
              "instrument_angles", "normal", "reference_normal", "length", "tool_ball", "table_ball")


@functools.lru_cache(maxsize=None)
def _kinds() -> dict:
    """name -> (type code, the keys of its observations and plan entries), from the registry."""
    return {k["name"]: (int(k["code"]), set(k["json_keys"]) | set(k["plan_keys"]))
            for k in _core.observation_kinds()}


def _code(name: str) -> int:
    """The core's type code of a kind (``Dataset.columns``)."""
    return _kinds()[name][0]


def _reports() -> dict:
    """type code -> the kind's registry entry (name, report pieces, ...)."""
    return {int(k["code"]): k for k in _core.observation_kinds()}


def _codes_where(test) -> list:
    """Type codes of the kinds whose registry entry passes ``test``."""
    return [c for c, k in _reports().items() if test(k)]


def _target_lists() -> dict:
    """type code -> the artefact list its touches name (``facets``, ...)."""
    return {c: k["report"]["target_list"] for c, k in _reports().items() if k["report"]["target_list"]}


def _codes_with(keys) -> list:
    """Type codes of the kinds that have any of ``keys``."""
    return [c for c, k in _kinds().values() if k & set(keys)]


def _key_positions(entries, rows, codes) -> dict:
    """key -> (rows, values) of POSITION_KEYS / LENGTH_KEYS over ``entries``
    (the observations or plan entries at ``rows``, of type codes ``codes``):
    only the entries whose kind has the key."""
    out = {}
    kinds = _kinds()
    has = {c: k for c, k in kinds.values()}
    for key in POSITION_KEYS + LENGTH_KEYS:
        sel = [i for i, c in enumerate(codes) if key in has.get(int(c), ())]
        if not sel:
            continue
        sub = [entries[i] for i in sel]
        vals = _optional_rows(sub, key) if key in POSITION_KEYS else _optional_column(sub, key)
        out[key] = (np.asarray([rows[i] for i in sel], dtype=int), vals)
    return out


def _optional_column(entries, key: str) -> np.ndarray:
    """``entry[key]`` of every entry as floats, NaN where absent or not a number."""
    return _column([e.get(key, math.nan) if isinstance(e, dict) else math.nan for e in entries])


def _optional_rows(entries, key: str) -> np.ndarray:
    return _rows([e.get(key, [math.nan] * 3) if isinstance(e, dict) else [math.nan] * 3
                  for e in entries])


def _dict_columns(machine: Machine, entries: Sequence, artefact) -> dict:
    """What ``Dataset.columns`` gives for a dataset, from a list of
    observation (or plan) dicts: axes, type code and target index of every
    entry; the ball fields (reading, length, measured, tool_ball, table_ball)
    of the rows listed in ``ball``, here every entry (NaN where a field is
    absent or not of that entry's type)."""
    kinds = _kinds()
    # A malformed entry (a type that is not a string: a list, a dict) is left
    # to the core, which names it; here it only has no kind.
    types = np.array([kinds[e["type"]][0] if isinstance(e, dict) and isinstance(e.get("type"), str)
                      and e["type"] in kinds else -1 for e in entries], dtype=int)
    lists = _target_lists()
    ids = {}
    if isinstance(artefact, Mapping):
        for code, key in lists.items():
            for k, x in enumerate(artefact.get(key) or []):
                if isinstance(x, Mapping):
                    ids.setdefault((code, str(x.get("id"))), k)
    target = np.array([ids.get((int(t), str(e.get("target"))), -1) if t in lists else -1
                       for t, e in zip(types, entries)], dtype=int)
    # a ball-mount kind's own value: a reading with a bar length, or a measured displacement
    ranged = {f: _codes_where(lambda k, f=f: k["ball_mount"] and k["report"]["range_field"] == f)
              for f in ("reading", "measured")}
    measured = _optional_rows(entries, "measured")
    measured[~np.isin(types, ranged["measured"])] = math.nan
    return {"axes": _axis_columns(machine, entries), "type": types, "target": target,
            "ball": np.arange(len(entries)),
            "reading": np.where(np.isin(types, ranged["reading"]), _optional_column(entries, "reading"), math.nan),
            "length": _optional_column(entries, "length"), "measured": measured,
            "tool_ball": _optional_rows(entries, "tool_ball"), "table_ball": _optional_rows(entries, "table_ball"),
            "positions": _key_positions(entries, range(len(entries)), types)}


def _largest(values: np.ndarray, fields, out_vals: list, out_fields: list) -> None:
    if values.size:
        a = np.abs(np.nan_to_num(values, nan=0.0, posinf=np.inf, neginf=np.inf)).reshape(values.shape[0], -1)
        i = int(np.argmax(a.max(axis=1)))
        j = int(np.argmax(a[i]))
        out_vals.append(float(values.reshape(values.shape[0], -1)[i, j]))
        out_fields.append(fields(i, j))


def _positions(machine: Machine, cols: dict, where_list: str, ix=lambda i: i):
    """The largest position or length of each kind and the field naming it:
    vectorised over every row; only the winners get a name."""
    vals, fields = [], []
    for a in machine.axis_names:
        if not machine.is_rotary(a):
            _largest(cols["axes"][a], lambda i, j, a=a: f"{where_list}[{ix(i)}].axes.{a}", vals, fields)
    ball = cols["ball"]
    _largest(cols["length"], lambda i, j: f"{where_list}[{ix(ball[i])}].length", vals, fields)
    for key in ("tool_ball", "table_ball"):
        _largest(cols[key], lambda i, j, key=key: f"{where_list}[{ix(ball[i])}].{key}[{j}]", vals, fields)
    for key, (rows, v) in cols.get("positions", {}).items():
        _largest(v, (lambda i, j, key=key, rows=rows: f"{where_list}[{ix(rows[i])}].{key}"
                     + (f"[{j}]" if v.ndim == 2 else "")), vals, fields)
    return vals, fields


def check_plan(machine: Machine, plan: Sequence[Mapping], where: str = "plan") -> None:
    """Rotary plan values in radians (warn), positions and lengths in µm."""
    if not isinstance(plan, (list, tuple)) or not plan:
        return
    cols = _dict_columns(machine, plan, None)
    check_rotary(machine, cols["axes"], f"{where}[*].axes")
    vals, fields = _positions(machine, cols, where)
    _check_size(np.array(vals, dtype=float), fields, where, "the plan's positions")


def check_loaded(ds, where: str = "dataset") -> None:
    """All magnitude checks of a validated :class:`fivecal.Dataset`, on every
    observation: the core hands the observations over as arrays (10^6 in a
    fraction of a second) and a message names the first offending row."""
    check_loaded_pieces(ds, [loaded_columns(ds)], where)


def loaded_columns(ds, offset: int = 0) -> dict:
    """What :func:`check_loaded` reads of the observations of ``ds``, their
    rows counted from ``offset`` (a piece of a dataset read piece by piece)."""
    # Long traces held as column blocks are checked on views of their
    # columns (no per-row arrays of 10^7 samples); the other rows as arrays.
    blocks = ds._core.block_columns() if ds._core.num_block_rows else []
    cols = ds._core.columns(include_blocks=not blocks)
    m = ds.machine
    cols["axes"] = {a: cols["axes"][:, k] for k, a in enumerate(m.axis_names)}
    if offset:
        cols["ball"] = cols["ball"] + offset
        blocks = [dict(b, first=b["first"] + offset) for b in blocks]
    # The kinds' other positions (a tracker's pose, a station, a target point) are
    # not among the columns: the few observations that have them go through JSON.
    balls = _codes_where(lambda k: k["ball_mount"])
    extra = [c for c in _codes_with(POSITION_KEYS + LENGTH_KEYS) if c not in balls]
    rows = np.flatnonzero(np.isin(cols["type"], extra))
    if rows.size:
        obs = json.loads(ds._core.subset(rows.tolist()).to_json())["observations"]
        cols["positions"] = _key_positions(obs, rows + offset, cols["type"][rows])
    cols["blocks"] = blocks
    return cols


def check_loaded_pieces(head, parts, where: str = "dataset") -> None:
    """:func:`check_loaded` of a dataset read piece by piece: ``head`` one of
    its pieces (machine, probe, artefact), ``parts`` the
    :func:`loaded_columns` of every piece in order, as if of the whole."""
    if not parts:
        return
    if len(parts) == 1:
        cols = parts[0]
    else:
        cols = {}
        for key in parts[0]:
            if key == "axes":
                cols[key] = {a: np.concatenate([p[key][a] for p in parts]) for a in parts[0][key]}
            elif key not in ("positions", "blocks"):
                cols[key] = np.concatenate([p[key] for p in parts])
        positions = {}
        for p in parts:
            for key, (r, v) in p.get("positions", {}).items():
                positions.setdefault(key, []).append((r, v))
        cols["blocks"] = [b for p in parts for b in p.get("blocks", ())]
        if positions:
            cols["positions"] = {key: (np.concatenate([r for r, _ in x]), np.concatenate([v for _, v in x]))
                                 for key, x in positions.items()}
    d = json.loads(head._core.subset([]).to_json())  # machine, probe, artefact: no observations
    _check_columns(head.machine, d, cols, where, blocks=cols.get("blocks", ()))


def check_dataset(d: Mapping, machine: Optional[Machine] = None, where: str = "dataset",
                  indices: Optional[Sequence[int]] = None) -> None:
    """All magnitude checks of a dataset dict (the JSON format). ``indices``:
    the index in the full dataset of each observation of ``d`` (a sample)."""
    if not isinstance(d, Mapping):
        return
    if machine is None:
        machine = Machine.from_dict(d["machine"])
    obs = d.get("observations") or []
    if not isinstance(obs, list):
        return
    _check_columns(machine, d, _dict_columns(machine, obs, d.get("artefact")), where,
                   (lambda i: i) if indices is None else (lambda i: int(indices[i])))


def _block_positions(machine: Machine, blocks, vals: list, fields: list) -> None:
    """:func:`_positions` of column blocks (``Dataset.block_columns``): the
    largest of each linear axis column, and the positions and lengths every
    row of a block shares."""
    for b in blocks:
        first = b["first"]
        for a, v in b["axes"].items():
            if not machine.is_rotary(a):
                _largest(v, lambda i, j, a=a, first=first: f"observations[{first + i}].axes.{a}", vals, fields)
        for key, v in b["shared"].items():
            if key in ("tool_ball", "table_ball") + POSITION_KEYS:
                for j, x in enumerate(_vec(v)):
                    vals.append(x)
                    fields.append(f"observations[{first}].{key}[{j}]")
            elif key in ("length",) + LENGTH_KEYS:
                vals.append(_num(v))
                fields.append(f"observations[{first}].{key}")


def _check_columns(machine: Machine, d: Mapping, cols: dict, where: str, ix=lambda i: i, blocks=()) -> None:
    """The checks of :func:`check_dataset` on the columns of the observations
    (``Dataset.columns`` or :func:`_dict_columns`, and the column blocks of
    ``Dataset.block_columns``); ``d`` gives the artefact and the probe."""
    axes = cols["axes"]
    if blocks:
        # The rotary columns whole (what looks like radians is a property
        # of all the values); the linear ones are checked block by block.
        axes = {a: np.concatenate([np.asarray(axes[a], float)] + [b["axes"][a] for b in blocks])
                for a in machine.axis_names if machine.is_rotary(a)}
    check_rotary(machine, axes, f"{where}: observations[*].axes")

    # Positions and lengths: a dataset in µm.
    vals, fields = _positions(machine, cols, "observations", ix)
    _block_positions(machine, blocks, vals, fields)
    art = d.get("artefact") or {}
    if isinstance(art, Mapping):
        for k, s in enumerate(art.get("spheres") or []):
            if isinstance(s, Mapping):
                for j, v in enumerate(_vec(s.get("center"))):
                    vals.append(v)
                    fields.append(f"artefact.spheres[{k}].center[{j}]")
                vals.append(_num(s.get("radius")))
                fields.append(f"artefact.spheres[{k}].radius")
        for k, f in enumerate(art.get("facets") or []):
            if isinstance(f, Mapping):
                for j, v in enumerate(_vec(f.get("point"))):
                    vals.append(v)
                    fields.append(f"artefact.facets[{k}].point[{j}]")
        for k, b in enumerate(art.get("scale_bars") or []):
            if isinstance(b, Mapping):
                vals.append(_num(b.get("length")))
                fields.append(f"artefact.scale_bars[{k}].length")
        for k, c in enumerate(art.get("cylinders") or []):
            if isinstance(c, Mapping):
                for j, v in enumerate(_vec(c.get("point"))):
                    vals.append(v)
                    fields.append(f"artefact.cylinders[{k}].point[{j}]")
                vals.append(_num(c.get("radius")))
                fields.append(f"artefact.cylinders[{k}].radius")
    _check_size(np.array(vals, dtype=float), fields, where, "the dataset's positions")

    # Instrument ranges (rows of the ball fields: cols["ball"]).
    ball_types = cols["type"][cols["ball"]]
    for code, k in _reports().items():
        rep = k["report"]
        if not (k["ball_mount"] and rep["range_field"] in ("reading", "measured")):
            continue
        field, limit = rep["range_field"], rep["range"]
        # Per source (the object rows, each block): the largest |value| of a
        # row, its row and value, and how many rows are beyond the range.
        worst, big, total = None, 0, 0
        sel = np.flatnonzero(ball_types == code)
        if sel.size:
            v = cols[field][sel]
            a = np.abs(np.nan_to_num(v)).reshape(v.shape[0], -1).max(axis=1)
            j = int(np.argmax(a))
            worst = (a[j], ix(cols["ball"][sel[j]]), f"{v[j]:.6g}" if v.ndim == 1 else f"{v[j].tolist()}")
            big, total = int((a > limit).sum()), a.size
        for b in blocks:
            if b["type"] != k["name"] or not b["rows"]:
                continue
            named = [c for c in b["values"] if c == field or c.startswith(field + "_")]
            a = None
            for c in named:
                x = np.abs(np.nan_to_num(b["values"][c]))
                a = x if a is None else np.maximum(a, x)
            if a is None:
                continue
            j = int(np.argmax(a))
            row = [float(b["values"][c][j]) for c in named]
            if worst is None or a[j] > worst[0]:
                worst = (a[j], b["first"] + j, f"{row[0]:.6g}" if len(row) == 1 else f"{row}")
            big, total = big + int((a > limit).sum()), total + a.size
        if worst is not None and worst[0] > limit:
            raise ValueError(f"{where}: observations[{worst[1]}].{field} = {worst[2]} mm ({big} of the {total} "
                             f"{k['label']} values checked are beyond ±{limit:g} mm; {rep['range_note']}): "
                             f"{rep['range_what']} look like µm: divide by 1000")
    _check_touches(machine, d, cols, where)


def _check_touches(machine: Machine, d: Mapping, cols: dict, where: str) -> None:
    """Sphere, cylinder and facet touches against the artefact, at the nominal machine."""
    art = d.get("artefact") or {}
    if not isinstance(art, Mapping):
        return
    probe = d.get("probe") or {}
    r = _num(probe.get("tip_radius", 0.0)) if isinstance(probe, Mapping) else 0.0
    if not math.isfinite(r):
        return
    # the touch kinds by the artefact list they touch
    code = {key: c for c, key in _target_lists().items()}
    facet, sphere, cyl = (code.get(key, -2) for key in ("facets", "spheres", "cylinders"))
    idx = np.flatnonzero(np.isin(cols["type"], list(code.values())))
    if not idx.size:
        return
    sub = {a: c[idx] for a, c in cols["axes"].items()}
    if any(not np.isfinite(c).all() for a, c in sub.items() if a != "S"):
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RadiansWarning)  # warned once above
        try:
            P = machine.tool_point(sub)
        except ValueError:
            return  # the loader names what is wrong with the poses
    targets = cols["target"][idx]
    types = cols["type"][idx]
    for k, s in enumerate(art.get("spheres") or []):
        if not isinstance(s, Mapping):
            continue
        sel = (types == sphere) & (targets == k)
        c, R = _vec(s.get("center")), _num(s.get("radius"))
        if sel.sum() < 3 or not np.isfinite(c).all() or not (math.isfinite(R) and R > 0):
            continue
        dist = np.linalg.norm(P[sel] - c, axis=1)
        med = float(np.median(dist))
        spread = float(np.median(np.abs(dist - med)))
        expected, half = R + r, R / 2 + r
        name = f"artefact.spheres[{k}] ('{s.get('id')}')"
        if abs(med - half) < 0.05 * R and spread < 0.05 * R and abs(med - expected) > 0.25 * R:
            raise ValueError(f"{where}: {name}: its {int(sel.sum())} touches lie {med:.4g} mm from its "
                             f"centre at the nominal machine, radius + tip radius = {expected:.4g} mm "
                             f"expected: the radius looks like the diameter; give radius {R / 2:g}")
        if abs(med - expected) > 0.25 * R + 1.0:
            _warn(f"{where}: {name}: its touches lie {med:.4g} mm (median) from its centre at the "
                          f"nominal machine, radius + tip radius = {expected:.4g} mm expected; check the "
                          "radius (not the diameter), the centre, probe.tip_radius and their units", UnitsWarning)
    for k, c in enumerate(art.get("cylinders") or []):
        if not isinstance(c, Mapping):
            continue
        sel = (types == cyl) & (targets == k)
        p, a, R = _vec(c.get("point")), _vec(c.get("axis")), _num(c.get("radius"))
        if (sel.sum() < 3 or not (np.isfinite(p).all() and np.isfinite(a).all()) or np.linalg.norm(a) == 0
                or not (math.isfinite(R) and R > 0)):
            continue
        a = a / np.linalg.norm(a)
        w = P[sel] - p
        rho = np.linalg.norm(w - np.outer(w @ a, a), axis=1)
        med = float(np.median(rho))
        spread = float(np.median(np.abs(rho - med)))
        s = -1.0 if c.get("inside") is True else 1.0
        expected, half = R + s * r, R / 2 + s * r
        name = f"artefact.cylinders[{k}] ('{c.get('id')}')"
        if abs(med - half) < 0.05 * R and spread < 0.05 * R and abs(med - expected) > 0.25 * R:
            raise ValueError(f"{where}: {name}: its {int(sel.sum())} touches lie {med:.4g} mm from its "
                             f"axis at the nominal machine, {expected:.4g} mm expected (radius "
                             f"{'-' if s < 0 else '+'} tip radius): the radius looks like the diameter; "
                             f"give radius {R / 2:g}")
        if abs(med - expected) > 0.25 * R + 1.0:
            _warn(f"{where}: {name}: its touches lie {med:.4g} mm (median) from its axis at the nominal "
                  f"machine, {expected:.4g} mm expected; check the radius (not the diameter), the axis, "
                  "\"inside\", probe.tip_radius and their units", UnitsWarning)
    for k, f in enumerate(art.get("facets") or []):
        if not isinstance(f, Mapping):
            continue
        sel = (types == facet) & (targets == k)
        a, n = _vec(f.get("point")), _vec(f.get("normal"))
        if not sel.any() or not (np.isfinite(a).all() and np.isfinite(n).all()) or np.linalg.norm(n) == 0:
            continue
        dist = (P[sel] - a) @ (n / np.linalg.norm(n)) - r
        j = int(np.argmax(np.abs(dist)))
        if abs(dist[j]) > FACET_DISTANCE:
            _warn(f"{where}: artefact.facets[{k}] ('{f.get('id')}'): touches lie up to "
                          f"{dist[j]:.4g} mm from the facet at the nominal machine (more than "
                          f"{FACET_DISTANCE:g} mm); check the facet point and normal, the machine file "
                          "and their units", UnitsWarning)


def check_balls(machine: Machine, kind: str, q: np.ndarray, values: np.ndarray, where: str) -> None:
    """Checks of :func:`fivecal.ball_dataset` arrays: rotary columns of the
    (N, axes) command matrix ``q``, readings (dbb) or displacements (ball3d)."""
    check_rotary(machine, {a: q[:, i] for i, a in enumerate(machine.axis_names)}, f"{where}: axes")
    v = np.abs(np.nan_to_num(np.asarray(values, dtype=float)))
    if not v.size:
        return
    entry = next((e for e in _reports().values() if e["name"] == kind), None)
    if entry is None or not entry["report"]["range"]:
        return  # not a kind with an instrument range: the core names a wrong type
    # named as fivecal.ball_dataset's argument: readings (one row) or measured (three)
    limit, what = entry["report"]["range"], ("readings", "measured")[entry["rows"] > 1]
    k = int(np.argmax(v.max(axis=1) if v.ndim == 2 else v))
    if v.reshape(v.shape[0], -1)[k].max() > limit:
        raise ValueError(f"{where}: {what}[{k}] is {v.reshape(v.shape[0], -1)[k].max():.6g} mm, beyond the "
                         f"instrument's range ({limit:g} mm): {what} look like µm: divide by 1000")
