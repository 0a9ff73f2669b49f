"""ISO G-code that runs a fivecal planar ball bar plan (docs/dbb.md).

:func:`dbb_program` turns the entries of
:func:`fivecal.procedures.dbb.planar_plan` (one circle per setup, rotary axes
at 0) into the moves of a ball bar test, per setup:

1. rapid to the approach point, ``feed_in`` mm inside the circle on the
   radius through the first planned point (the bar is fitted there);
2. feed-in: ``G1`` radially out onto the circle;
3. the arc: ``G2``/``G3`` full circles (``turns``) starting and ending at the
   first planned point, centre given incrementally (I J K) in the plane;
4. feed-out: ``G1`` radially back to the approach point.

Words are the machine's axis commands (what fivecal's G-code reader and
compensation read): the circle's centre and points go through the nominal
inverse kinematics at the plan's rotary pose, so a reversed or table-side
linear axis mirrors the circle and flips G2/G3 as the machine needs.
"""
from __future__ import annotations

import math
from typing import Dict, List, Mapping, Sequence

import numpy as np

from ..machine import Machine

_PLANES = {"XY": ("G17", "X", "Y", "IJ"), "ZX": ("G18", "Z", "X", "KI"), "YZ": ("G19", "Y", "Z", "JK")}


def _setups(plan: Sequence[Mapping]) -> Dict[str, List[Mapping]]:
    out: Dict[str, List[Mapping]] = {}
    for i, p in enumerate(plan):
        if p.get("type") != "dbb":
            raise ValueError(f"plan[{i}]: type '{p.get('type')}': a ball bar program needs dbb entries")
        out.setdefault(str(p.get("setup", "")), []).append(p)
    if not out:
        raise ValueError("plan: no dbb entries")
    return out


def circle_of(machine: Machine, entries: Sequence[Mapping]) -> dict:
    """The commanded circle of one setup: plane (G17/G18/G19 and its two
    command axes), centre and first point (axis commands), radius (mm),
    ``ccw`` (seen from the plane's positive normal, in command space)."""
    q = {a: np.array([float(e["axes"].get(a, 0.0)) for e in entries]) for a in machine.axis_names}
    rot = [a for a in machine.axis_names if machine.is_rotary(a) and a != "S"]
    for a in rot:
        if np.ptp(q[a]) > 1e-9:
            raise ValueError(f"setup {entries[0].get('setup')}: rotary axis {a} moves; only planar "
                             "circles (rotary axes fixed) become arcs")
    lin = [a for a in "XYZ" if a in machine.axis_names]
    spread = {a: np.ptp(q[a]) for a in lin}
    moving = sorted(a for a in lin if spread[a] > 1e-6)
    plane = next((k for k, v in _PLANES.items() if sorted(v[1:3]) == moving), None)
    if plane is None:
        raise ValueError(f"setup {entries[0].get('setup')}: the circle moves axes {moving}; "
                         "expected two of X Y Z")
    g, a1, a2, _ = _PLANES[plane]
    e0 = entries[0]
    tb = np.asarray(e0["tool_ball"], float)
    centre_w = np.asarray(e0["table_ball"], float)
    start = {a: float(q[a][0]) for a in machine.axis_names}
    cq = machine.inverse((centre_w + (machine.tip - tb))[None, :], start=start)
    centre = {a: float(cq[a][0]) for a in machine.axis_names}
    for a in rot:
        centre[a] = start[a]
    u = np.array([start[a1] - centre[a1], start[a2] - centre[a2]])
    r = float(np.linalg.norm(u))
    if abs(r - float(e0["length"])) > 1e-6 * max(1.0, r):
        raise ValueError(f"setup {e0.get('setup')}: the planned points are {r:.6f} mm from the centre in "
                         f"command space, the bar is {float(e0['length']):g} mm (the linear axes are "
                         "not orthonormal in this plane)")
    # orientation of the planned sequence in the command plane
    w = [np.array([q[a1][i] - centre[a1], q[a2][i] - centre[a2]]) for i in range(min(len(entries), 3))]
    cross = float(w[0][0] * w[1][1] - w[0][1] * w[1][0]) if len(w) > 1 else 1.0
    return {"plane": plane, "g": g, "axes": (a1, a2), "centre": centre, "start": start, "radius": r,
            "ccw": cross > 0, "setup": e0.get("setup")}


def dbb_program(machine: Machine, plan: Sequence[Mapping], feed: float = 1000.0,
                feed_in: float = 1.5, turns: int = 1) -> str:
    """ISO G-code for the planar ball bar setups of ``plan`` (module text);
    ``feed`` mm/min for feed-in, arc and feed-out."""
    if not (feed > 0 and math.isfinite(feed)):
        raise ValueError(f"feed: expected a positive number of mm/min, got {feed}")
    if not (0 < feed_in and math.isfinite(feed_in)):
        raise ValueError(f"feed_in: expected a positive distance in mm, got {feed_in}")
    if int(turns) != turns or turns < 1:
        raise ValueError(f"turns: expected a whole number >= 1, got {turns}")
    f = lambda v: f"{v:.6f}"  # noqa: E731
    out = [f"(fivecal ball bar program, machine {machine.name}: feed-in, arc, feed-out per setup)",
           "G21 G90 G94 G40 G49 G54"]
    for setup, entries in _setups(plan).items():
        c = circle_of(machine, entries)
        if feed_in >= c["radius"]:
            raise ValueError(f"feed_in: {feed_in} mm is not less than the radius {c['radius']:g} mm")
        a1, a2 = c["axes"]
        cen, st = c["centre"], c["start"]
        u = np.array([st[a1] - cen[a1], st[a2] - cen[a2]]) / c["radius"]
        approach = {**st, a1: cen[a1] + (c["radius"] - feed_in) * u[0],
                    a2: cen[a2] + (c["radius"] - feed_in) * u[1]}
        words = lambda p: " ".join(f"{a}{f(p[a])}" for a in machine.axis_names if a != "S")  # noqa: E731
        ij = _PLANES[c["plane"]][3]
        off = {a1: cen[a1] - st[a1], a2: cen[a2] - st[a2]}
        arc = "G3" if c["ccw"] else "G2"
        out += [f"(setup {setup}: radius {c['radius']:g} mm, plane {c['plane']}, "
                f"{'counter-clockwise' if c['ccw'] else 'clockwise'} in axis commands, {turns} turn{'s' if turns > 1 else ''})",
                c["g"], f"G0 {words(approach)}",
                f"G1 {a1}{f(st[a1])} {a2}{f(st[a2])} F{feed:g} (feed-in)"]
        for _ in range(int(turns)):
            out.append(f"{arc} {a1}{f(st[a1])} {a2}{f(st[a2])} {ij[0]}{f(off[a1])} {ij[1]}{f(off[a2])}")
        out.append(f"G1 {a1}{f(approach[a1])} {a2}{f(approach[a2])} (feed-out)")
    out.append("M2")
    return "\n".join(out) + "\n"
