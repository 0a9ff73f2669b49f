"""Readings of a planned test back into a dataset, lined up with the plan
(``fivecal import rtest READINGS --plan PLAN``, ``fivecal import probe-log
LOG --plan PLAN --kins K``; docs/linuxcnc.md).

* :func:`rtest_readings`: the R-test nest's readings of a program
  :func:`fivecal.io.nc_programs.rtest_program` wrote, one per ``G4`` dwell.
  A table with ``dx dy dz`` (units from the header, ``dx_um``, or ``units``)
  and either an ``id`` column naming the plan sample (the id in the dwell's
  comment, e.g. ``K1-3``; a test read must have every sample, a test left
  out is fine) or no id, the rows then in program order (one per dwell).
  Axis columns, when the logger writes them, are checked against the
  plan's commands. The axes, direction, balls and mounting of each
  observation come from the plan.
* :func:`probe_log_dataset`: LinuxCNC's ``PROBEOPEN`` log of a program
  ``fivecal export program`` wrote for a plan of probe touches, through
  :func:`fivecal.io.linuxcnc.read_probe_log`: every line must be its touch
  of the plan (the rotary positions the plan commands, a position on that
  touch's probe line), so a log in another order, with lines missing, or of
  another plan is refused naming the line.
"""
from __future__ import annotations

import os
from typing import Dict, List, Mapping, Optional, Tuple

from .. import files, plausibility
from .. import units as _units
from ..dataset import Dataset
from ..machine import Machine
from ..schema import read_checked as _read_json
from . import linuxcnc as L
from . import nc_programs as N
from . import tables as T

#: the imports that line readings up with a plan (``fivecal import KIND
#: --plan``): an R-test's nest readings, LinuxCNC's probe log
PLANNED = ("rtest", "ball3d", "probe-log")
#: how far an axis column of a readings file may be from the plan's command
#: (mm or degrees): a logger's rounding, not another pose
AXIS_TOLERANCE = 1e-3


def read_plan(path: str):
    """(machine, plan, artefact, stylus radius) of a plan / simulation spec file."""
    return _read_spec(os.fspath(path))


def _program_order(plan) -> List[Tuple[int, dict]]:
    """The entries an R-test program runs (their kind's program, the
    registry's), as rtest_program runs them: grouped by mounting in the order
    the mountings first appear."""
    groups: Dict[str, list] = {}
    for i, e in enumerate(plan):
        if N.PLAN_PROGRAMS.get(e.get("type")) == "rtest":
            groups.setdefault(str(e.get("setup", "")), []).append((i, e))
    return [x for g in groups.values() for x in g]


def rtest_readings(path, plan_path, *, units: Optional[str] = None, delimiter: Optional[str] = None,
                   decimal: Optional[str] = None, header=None, sigma: Optional[float] = None,
                   ignore=(), angle_units: Optional[str] = None) -> dict:
    """A ball3d dataset dict from the nest readings at the dwells of an
    R-test program, lined up with the plan of ``plan_path`` by id or by
    program order (module docstring). ValueError names the file, line and
    column of a bad cell, an unknown or repeated id, a row count that does
    not match the dwells, or an axis cell that is not the plan's command."""
    path = os.fspath(path)
    machine, plan, _, _ = read_plan(plan_path)
    order = _program_order(plan)
    if not order:
        raise ValueError(f"--plan {plan_path}: no ball3d (R-test) entries in the plan")
    if units is not None and units.lower() not in _units.LENGTH_SUFFIXES:
        raise ValueError(f"--units '{units}': expected um or mm (length units: {_units.unit_list('length')})")
    if angle_units is not None and angle_units.lower() not in _units.ANGLE_SUFFIXES:
        raise ValueError(f"--angle-units '{angle_units}': expected deg or rad (angle units: "
                         f"{_units.unit_list('angle')})")
    if sigma is not None and not sigma > 0:
        raise ValueError(f"--sigma: {sigma:g} mm must be > 0")
    if decimal not in (None, "comma", "point"):
        raise ValueError(f"--decimal '{decimal}': expected comma or point")
    lines = list(T._lines(files.read_text(path, "R-test readings")))
    if not lines:
        raise ValueError(f"{path}: empty; expected a header naming dx dy dz [id] and one row per dwell")
    if header is not None:
        names = T._header_names(header, "--header")
        delim = T._delimiter(lines[0][1], delimiter)
        hwhere = "--header"
    else:
        hline, first = lines[0]
        delim = T._delimiter(first, delimiter)
        names = T._split(first, delim, f"{path}:{hline}")
        lines = lines[1:]
        hwhere = f"{path}:{hline}"
        if all(T._is_number(h) for h in names):
            raise ValueError(f"{hwhere}: no header row (this line holds numbers); name the columns "
                             "dx dy dz [id] (e.g. dx_um dy_um dz_um) or give --header")
    decimal_comma = decimal == "comma" or (decimal is None and delim != ",")
    ignored = {i.strip().lower() for i in ignore or ()}
    T._once(names, hwhere, ignored)
    axes = {a.lower(): a for a in machine.axis_names}
    cols = {}
    for i, h in enumerate(names):
        if h.strip().lower() in ignored:
            continue
        name, unit = T._split_unit(h)
        key = name.strip().lower()
        field = axes.get(key, key)
        if field not in ("id", "dx", "dy", "dz", "sigma") and field not in machine.axis_names:
            raise ValueError(f"{hwhere}: column '{h.strip()}': not a column of R-test readings (dx dy dz, "
                             f"optionally id, sigma and the axes {' '.join(machine.axis_names)}); --ignore skips it")
        if field in cols:
            raise ValueError(f"{hwhere}: column '{h.strip()}': {field} given twice")
        if field == "id":
            factor = None
        elif field in machine.axis_names:
            if unit:
                factor = _units.column_unit(h, "angle" if machine.is_rotary(field) else "length", hwhere)[0]
            else:
                factor = _units.ANGLE_SUFFIXES[(angle_units or "deg").lower()] if machine.is_rotary(field) else 1.0
        else:
            factor = (_units.column_unit(h, "length", hwhere)[0] if unit
                      else _units.LENGTH_SUFFIXES[(units or "mm").lower()])
        cols[field] = (i, h.strip(), factor)
    missing = [k for k in ("dx", "dy", "dz") if k not in cols]
    if missing:
        raise ValueError(f"{hwhere}: no '{missing[0]}' column; R-test readings need dx dy dz (e.g. dx_um "
                         "dy_um dz_um) and optionally the plan id of each reading")
    # a rotary column in another unit than declared, said before a mismatch with the plan hides why
    rotary = []
    for field, (ci, h, factor) in cols.items():
        if field in machine.axis_names and machine.is_rotary(field):
            values = []
            for lineno, line in lines:
                try:
                    values.append((T._number(T._split(line, delim, path)[ci], decimal_comma, path), lineno))
                except (ValueError, IndexError):
                    pass  # the reading loop below names the bad cell
            rotary.append(T._rotary_column(h, values, (angle_units or "deg").lower()))
    T._rotary_units(rotary, path)
    by_id = {str(e.get("id")): (i, e) for i, e in order if e.get("id") is not None}
    obs, used = [], {}
    for n, (lineno, line) in enumerate(lines):
        where = f"{path}:{lineno}"
        cells = T._split(line, delim, where)
        if len(cells) != len(names):
            raise ValueError(f"{where}: {len(cells)} cells, the header has {len(names)} columns ({', '.join(names)})")
        if "id" in cols:
            rid = cells[cols["id"][0]].strip()
            if rid not in by_id:
                raise ValueError(f"{where}: column '{cols['id'][1]}': '{rid}' is not a sample id of the plan "
                                 f"{plan_path} (ids like {next(iter(by_id), '?')})")
            if rid in used:
                raise ValueError(f"{where}: id '{rid}' already read on line {used[rid]}")
            used[rid] = lineno
            _, e = by_id[rid]
        else:
            if n >= len(order):
                raise ValueError(f"{where}: more readings than the {len(order)} dwells of the plan {plan_path} "
                                 "(rows in program order need one reading per dwell; an id column lines "
                                 "them up by plan id)")
            _, e = order[n]
        vals = {}
        for field, (ci, h, factor) in cols.items():
            if field == "id":
                continue
            vals[field] = T._number(cells[ci], decimal_comma, f"{where}: column '{h}'") * factor
        for a in machine.axis_names:
            if a in vals:
                want = float(e["axes"].get(a, 0.0))
                if abs(vals[a] - want) > AXIS_TOLERANCE:
                    raise ValueError(f"{where}: column '{cols[a][1]}': {vals[a]:.6g} is not the plan's command "
                                     f"{want:.6g} for sample {e.get('id') or n + 1} (the rows and the plan do "
                                     "not line up)")
        m = []
        for k in ("dx", "dy", "dz"):
            if abs(vals[k]) > plausibility.BALL3D_RANGE:
                raise ValueError(f"{where}: column '{cols[k][1]}': {vals[k]:.6g} mm is beyond an R-test sensor's "
                                 f"range (refused beyond {plausibility.BALL3D_RANGE:g} mm); readings look like "
                                 f"µm: name the column {k}_um or give --units um")
            m.append(vals[k])
        o = {key: e[key] for key in ("type", "setup", "axes", "direction", "tool_ball", "table_ball", "id")
             if key in e}
        o["measured"] = m
        if "sigma" in vals:
            if not vals["sigma"] > 0:
                raise ValueError(f"{where}: column '{cols['sigma'][1]}': sigma must be > 0")
            o["sigma"] = vals["sigma"]
        elif sigma is not None:
            o["sigma"] = float(sigma)
        obs.append(o)
    if not obs:
        raise ValueError(f"{path}: a header but no readings")
    last = lines[-1][0]
    if "id" not in cols and len(obs) != len(order):
        raise ValueError(f"{path}:{last}: the readings end here: {len(obs)} readings for the {len(order)} dwells "
                         f"of the plan {plan_path} (rows in program order need one reading per dwell; an id "
                         "column lines them up by plan id)")
    if "id" in cols:
        # a whole test may be left out (read another day); a test read with
        # samples missing has a range and a fit over part of its path
        read = {str(e.get("setup", "")) for i, e in order if str(e.get("id")) in used}
        missing = [e for i, e in order if str(e.get("setup", "")) in read and str(e.get("id")) not in used]
        if missing:
            ids = ", ".join(str(e.get("id")) for e in missing[:5]) + (" ..." if len(missing) > 5 else "")
            raise ValueError(f"{path}:{last}: the readings end here without sample {ids} of the plan {plan_path} "
                             f"({len(missing)} missing of test {missing[0].get('setup', '?')}, whose other "
                             "samples were read): every sample of a test read, or none")
    return {"machine": machine.to_dict(), "observations": obs}


def probe_log_dataset(path, plan_path, kins: str, pins_hal: Optional[str] = None) -> dict:
    """A dataset dict of probe touches (facet, sphere, cylinder: the plan's
    kinds) from LinuxCNC's probe log of the program of ``plan_path``; ``pins_hal``: the HAL file with the kinematics pins the
    controller ran with (default the machine's nominal pins)."""
    if not kins:
        raise ValueError("--kins: the LinuxCNC kinematics the program ran with (xyzac-trt or xyzbc-trt) "
                         "turns the logged world positions into axis readings")
    machine, plan, artefact, tip = read_plan(plan_path)
    pins = L.read_hal_pins(pins_hal, kins) if pins_hal else L.nominal_pins(machine, kins)
    touch = N.program_kinds(N.TOUCH_PROGRAMS[0])
    types = {str(e.get("type")) for e in plan}
    if not types <= set(touch):
        raise ValueError(f"--plan {plan_path}: entries of type {', '.join(sorted(types))}; a probe "
                         f"log lines up with a plan of probe touches ({N._kind_words(touch, 'or')})")
    path = os.fspath(path)
    if not os.path.exists(path):
        raise ValueError(f"{path}: no such probe log")
    # each line is checked against the probe line its touch's G38.2 ran along
    geo = N._geometry(machine, kins, plan, artefact, tip, cycle=N.TOUCH_PROGRAMS[0])
    obs = L.read_probe_log(path, machine, kins, plan, pins, touches=[(w, n) for _, _, w, n, _ in geo])
    d = {"machine": machine.to_dict(), "observations": obs}
    if artefact:
        d["artefact"] = artefact
    if tip > 0:
        d["probe"] = {"tip_radius": tip}
    return d


def write(d: Mapping, out) -> "object":
    """Validate ``d`` as a Dataset and write it (atomically); returns the Dataset."""
    ds = Dataset.from_dict(d)
    files.write_json(out, ds.to_dict())
    return ds


__all__ = ["rtest_readings", "probe_log_dataset", "read_plan", "write", "AXIS_TOLERANCE"]


def _read_spec(path: str):
    """machine, plan, artefact and stylus radius of a simulation spec (or a
    dataset whose observations are the plan)."""
    spec = _read_json(path, "the plan (a simulation spec)")
    if not isinstance(spec, dict):
        raise ValueError(f"{path}: expected a JSON object with machine, plan, artefact, probe")
    machine = spec.get("machine")
    if isinstance(machine, str):  # a path relative to the spec file
        machine = Machine.load(os.path.join(os.path.dirname(os.path.abspath(path)), machine))
    elif isinstance(machine, dict):
        machine = Machine.from_dict(machine)
    else:
        raise ValueError(f"{path}: 'machine' missing (a machine object or a path)")
    plan = spec.get("plan", spec.get("observations"))
    if not isinstance(plan, list) or not plan or not all(isinstance(e, dict) for e in plan):
        raise ValueError(f"{path}: 'plan' missing or empty (a list of plan entries, `fivecal docs formats`)")
    probe = spec.get("probe") or {}
    if not isinstance(probe, dict):
        raise ValueError(f"{path}: probe: expected an object like {{\"tip_radius\": 3.0}}")
    try:
        tip = float(probe.get("tip_radius", 0.0))
    except (TypeError, ValueError):
        raise ValueError(f"{path}: probe.tip_radius: expected the stylus ball radius in mm, got "
                         f"{probe.get('tip_radius')!r}") from None
    return machine, plan, spec.get("artefact") or {}, tip
