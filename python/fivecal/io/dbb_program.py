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

:func:`rotary_dbb_program` writes the setups in which a rotary axis moves
(:func:`fivecal.procedures.dbb.four_step_plan`, :func:`~fivecal.procedures.dbb.wang_plan`):

1. rapid to the approach point: the first planned pose with the linear axes
   moved so that the bar is ``feed_in`` mm short (the bar is fitted there);
2. feed-in: ``G1`` along the bar onto the first planned pose;
3. the path: ``G1`` blocks through the planned poses, in inverse time
   (``G93``, so ``feed`` is the speed of one ball relative to the other
   whichever axes move). Where the straight line in axis commands between two
   poses would change the bar length by more than ``tolerance``, poses are
   added in between, each with the linear axes moved along the bar so that its
   nominal length is exact (synchronous linear-axis moves);
4. feed-out: ``G1`` along the bar ``feed_in`` mm short again.

With ``kins`` (``xyzac-trt`` / ``xyzbc-trt``) the words are LinuxCNC's joint
values, for its identity kinematics (``M429`` in fivecal's sample configs).
:func:`bar_length` replays axis commands through the nominal model.
"""
from __future__ import annotations

import warnings
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np

from .. import _core
from ..machine import Machine, RadiansWarning
from . import linuxcnc as L
from . import nc_options as O

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
                feed_in: float = 1.5, turns: int = 1, tolerance: float = 2e-5) -> str:
    """ISO G-code for the ball bar setups of ``plan`` (module text):
    planar circles as arcs, setups in which a rotary axis moves as in
    :func:`rotary_dbb_program` (with ``tolerance``, exact stop); ``feed``
    mm/min for feed-in, path and feed-out."""
    O.check(feed=feed, feed_in=feed_in, turns=turns, tolerance=tolerance)
    f = lambda v: f"{v:.6f}"  # noqa: E731
    out = [f"(fivecal ball bar program, machine {O.comment_text(machine.name)}: feed-in, arc, feed-out per "
           "setup)",
           "G21 G90 G94 G40 G49 G54"]
    for setup, entries in _setups(plan).items():
        if _rotary_moves(machine, entries):
            out += _rotary_setup(machine, setup, entries, feed, feed_in, None, tolerance, "G61")
            continue
        c = circle_of(machine, entries)
        if feed_in >= c["radius"]:
            raise O.OptionError("feed_in", f"{feed_in} mm is not less than the radius {c['radius']:g} mm")
        a1, a2 = c["axes"]
        cen, st = c["centre"], c["start"]
        u = np.array([st[a1] - cen[a1], st[a2] - cen[a2]]) / c["radius"]
        approach = {**st, a1: cen[a1] + (c["radius"] - feed_in) * u[0],
                    a2: cen[a2] + (c["radius"] - feed_in) * u[1]}
        words = lambda p: " ".join(f"{a}{f(p[a])}" for a in machine.axis_names if a != "S")  # noqa: E731
        ij = _PLANES[c["plane"]][3]
        off = {a1: cen[a1] - st[a1], a2: cen[a2] - st[a2]}
        arc = "G3" if c["ccw"] else "G2"
        out += [f"(setup {O.comment_text(setup)}: radius {c['radius']:g} mm, plane {c['plane']}, "
                f"{'counter-clockwise' if c['ccw'] else 'clockwise'} in axis commands, {turns} turn{'s' if turns > 1 else ''})",
                c["g"], f"G0 {words(approach)}",
                f"G1 {a1}{f(st[a1])} {a2}{f(st[a2])} F{feed:g} (feed-in)"]
        for _ in range(int(turns)):
            out.append(f"{arc} {a1}{f(st[a1])} {a2}{f(st[a2])} {ij[0]}{f(off[a1])} {ij[1]}{f(off[a2])}")
        out.append(f"G1 {a1}{f(approach[a1])} {a2}{f(approach[a2])} (feed-out)")
    out.append("M2")
    return O.check_positions("\n".join(out) + "\n", "ball bar program")


# ---- setups in which a rotary axis moves ------------------------------------

def _rotary(machine: Machine) -> List[str]:
    return [a for a in machine.axis_names if machine.is_rotary(a) and a != "S"]


def _rotary_moves(machine: Machine, entries: Sequence[Mapping]) -> bool:
    return any(np.ptp([float(e["axes"].get(a, 0.0)) for e in entries]) > 1e-9 for a in _rotary(machine))


def _rows(machine: Machine, qs: Sequence[Mapping[str, float]]) -> Dict[str, np.ndarray]:
    return {a: np.array([float(q.get(a, 0.0)) for q in qs]) for a in machine.axis_names}


def bar_length(machine: Machine, axes: Sequence[Mapping[str, float]], tool_ball, table_ball,
               errors=None) -> np.ndarray:
    """(N,) mm: the distance between the tool ball (machine frame at the zero
    pose) and the table ball (workpiece frame) at each of the axis commands
    ``axes`` (a list of dicts), on the nominal machine or with ``errors``."""
    p = machine.tool_point(_rows(machine, axes), errors=errors, tip=np.asarray(tool_ball, float))
    return np.linalg.norm(p - np.asarray(table_ball, float), axis=1)


class _Bar:
    """The nominal bar of one setup: ball positions and the linear-axis moves
    that change them (exact: at fixed rotary axes the tool ball is affine in
    the linear commands)."""

    def __init__(self, machine: Machine, entry: Mapping):
        self.m = machine
        self.tool = np.asarray(entry["tool_ball"], float)
        self.table = np.asarray(entry["table_ball"], float)
        self.length = float(entry["length"])

    def ball(self, Q: Dict[str, np.ndarray]) -> np.ndarray:
        with warnings.catch_warnings():
            # a few small rotary commands of a path look like radians to the
            # heuristic; they are the plan's degrees
            warnings.simplefilter("ignore", RadiansWarning)
            return self.m.tool_point(Q, errors=None, tip=self.tool)

    def deviation(self, Q: Dict[str, np.ndarray]) -> np.ndarray:
        return np.linalg.norm(self.ball(Q) - self.table, axis=1) - self.length

    def restore(self, Q: Dict[str, np.ndarray], short: float = 0.0) -> Dict[str, np.ndarray]:
        """Q (axis -> array) with the linear axes moved along the bar so that
        it is ``short`` mm shorter than nominal at every pose (C++
        ``BarLengthCommands``)."""
        names = self.m.axis_names
        n = len(next(iter(Q.values())))
        q = np.column_stack([np.broadcast_to(np.asarray(Q.get(a, 0.0), float), (n,)) for a in names])
        out = _core.bar_length_commands(self.m._core, self.tool, self.table, self.length - short, q)
        return {a: np.array(out[:, names.index(a)]) for a in Q}


def _interp(Q: Dict[str, np.ndarray], i: np.ndarray, t: np.ndarray) -> Dict[str, np.ndarray]:
    return {a: v[i] + t * (v[i + 1] - v[i]) for a, v in Q.items()}


def _path(bar: _Bar, Q: Dict[str, np.ndarray], tolerance: float) -> Dict[str, np.ndarray]:
    """The planned poses, with poses added where the straight line in axis
    commands between two would leave the nominal bar length by more than
    ``tolerance`` (checked at 7 points of each step). The added poses are
    spread evenly in the step (the deviation of a chord falls with the square
    of its length), each with its linear axes restored to the nominal bar."""
    check = np.linspace(0.0, 1.0, 9)[1:-1]
    for _ in range(6):
        n = len(next(iter(Q.values())))
        if n < 2:
            return Q
        i = np.repeat(np.arange(n - 1), len(check))
        t = np.tile(check, n - 1)
        dev = np.abs(bar.deviation(_interp(Q, i, t))).reshape(n - 1, len(check)).max(axis=1)
        if dev.max() <= tolerance:
            return Q
        parts = np.where(dev > tolerance, np.ceil(np.sqrt(dev / tolerance) * 1.1), 1).astype(int)
        idx, tt = [], []
        for k, m in enumerate(parts):
            idx += [k] * m
            tt += list(np.arange(m) / m)
        idx.append(n - 2)
        tt.append(1.0)
        new = _interp(Q, np.array(idx), np.array(tt))
        keep = np.isclose(np.array(tt), 0.0) | (np.arange(len(tt)) == len(tt) - 1)
        added = bar.restore({a: v[~keep] for a, v in new.items()})
        for a in new:
            new[a][~keep] = added[a]
        Q = new
    raise ValueError(f"the path cannot be split finely enough to keep the bar length within {tolerance} mm")


def _rotary_setup(machine: Machine, setup: str, entries: Sequence[Mapping], feed: float, feed_in: float,
                  kins: Optional[str], tolerance: float, path_mode: str) -> List[str]:
    letters = [a for a in machine.axis_names if a != "S"]
    bar = _Bar(machine, entries[0])
    if feed_in >= bar.length:
        raise O.OptionError("feed_in", f"{feed_in} mm is not less than the bar length {bar.length:g} mm")
    for i, e in enumerate(entries):
        if (np.abs(np.asarray(e["tool_ball"], float) - bar.tool).max() > 1e-12
                or np.abs(np.asarray(e["table_ball"], float) - bar.table).max() > 1e-12
                or float(e["length"]) != bar.length):
            raise ValueError(f"setup {setup}: entry {i} has other balls or another bar length than the "
                             "first; one setup is one mounting of the bar")
    Q = {a: np.array([float(e["axes"].get(a, 0.0)) for e in entries]) for a in machine.axis_names}
    dev = bar.deviation(Q)
    k = int(np.argmax(np.abs(dev)))
    if abs(dev[k]) > 1e-6:
        raise ValueError(f"setup {setup}: at planned pose {k + 1} the nominal balls are "
                         f"{bar.length + dev[k]:.6f} mm apart, the bar is {bar.length:g} mm (not a "
                         "constant-length path)")
    P = _path(bar, Q, tolerance)
    npts = len(P[letters[0]])
    if kins:
        kk = L._kins(kins)
        names = ["X", "Y", "Z", L.TILT[kk], "C"]

        def rows(R):
            return [" ".join(f"{a}{v:.6f}" for a, v in zip(names, j)) for j in L.joints(machine, kk, R)]
    else:
        def rows(R):
            n = len(R[letters[0]])
            return [" ".join(f"{a}{float(R[a][i]):.6f}" for a in letters) for i in range(n)]
    first = {a: v[:1] for a, v in P.items()}
    last = {a: v[-1:] for a, v in P.items()}
    approach = bar.restore(first, feed_in)
    leave = bar.restore(last, feed_in)
    moving = [a for a in _rotary(machine) if np.ptp(Q[a]) > 1e-9]
    path = rows(P)
    out = [f"(setup {O.comment_text(setup)}: bar {bar.length:g} mm, {', '.join(moving)} moving, {len(entries)} planned "
           f"poses, {npts} path points, bar length within {tolerance * 1e3:g} um between them)",
           path_mode, "G94", f"G0 {rows(approach)[0]}", f"G1 {path[0]} F{feed:g} (feed-in)", "G93"]
    # A block's travel: the largest of the balls' motion relative to each
    # other, the linear axes' travel, and the rotary turn as an arc of the bar's
    # length. In a four-step setup the balls turn together about one on the
    # axis (no relative motion, no linear move): timing those blocks by the
    # relative motion alone gave F1e9, blocks the controller runs flat out.
    rel = np.linalg.norm(np.diff(bar.ball(P), axis=0), axis=1)
    linear = [a for a in letters if not machine.is_rotary(a)]
    lin = np.linalg.norm(np.diff(np.column_stack([P[a] for a in linear]), axis=0), axis=1)
    turn = np.abs(np.diff(np.column_stack([P[a] for a in _rotary(machine)]), axis=0)).max(axis=1)
    travel = np.maximum.reduce([rel, lin, np.radians(turn) * bar.length])
    for i in range(1, npts):
        # inverse time: 1 / minutes for the block at ``feed`` mm/min
        out.append(f"G1 {path[i]} F{feed / max(travel[i - 1], 1e-6):.6f}")
    out += ["G94", f"G1 {rows(leave)[0]} F{feed:g} (feed-out)"]
    return out


def rotary_dbb_program(machine: Machine, plan: Sequence[Mapping], feed: float = 1000.0,
                       feed_in: float = 1.5, kins: Optional[str] = None, tolerance: float = 2e-5,
                       path_mode: str = "G61", tcp_off: str = "M429") -> str:
    """ISO G-code for the ball bar setups of ``plan`` in which a rotary axis
    moves (module text). ``feed``: mm/min on the path (inverse time: of the
    largest of the balls' relative motion, the linear axes' travel and the
    rotary turn as an arc of the bar's length, which times a four-step setup
    whose balls turn together) and of the feed-in and feed-out; ``tolerance`` (mm):
    largest change of the nominal bar length along the straight blocks;
    ``path_mode``: ``G61`` (exact stop: the controller runs the blocks as
    written) or e.g. ``G64 P0.0001`` (blending within 0.1 µm, continuous);
    ``kins``: write LinuxCNC joint values (``tcp_off`` switches its identity
    kinematics on first)."""
    O.check(feed=feed, feed_in=feed_in, tolerance=tolerance)
    O.check_line("tcp_off", tcp_off)
    O.check_line("path_mode", path_mode)
    setups = _setups(plan)
    fixed = [s for s, e in setups.items() if not _rotary_moves(machine, e)]
    if fixed:
        raise ValueError(f"setup {fixed[0]}: no rotary axis moves (a planar circle: dbb_program)")
    out = [f"(fivecal ball bar program, machine {O.comment_text(machine.name)}: rotary-axis paths, feed-in, path, "
           "feed-out per setup)",
           f"(words: {'LinuxCNC ' + kins + ' joint values' if kins else 'axis commands'}; path feed in "
           "inverse time for the balls' relative speed " + f"{feed:g} mm/min)",
           "G21 G90 G94 G40 G49 G54"]
    if kins and tcp_off:
        out.append(f"{tcp_off} (identity kinematics: words are joint values)")
    for setup, entries in setups.items():
        out += _rotary_setup(machine, setup, entries, feed, feed_in, kins, tolerance, path_mode)
    out.append("M2")
    return O.check_positions("\n".join(out) + "\n", "ball bar program")
