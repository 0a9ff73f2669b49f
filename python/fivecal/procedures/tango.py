"""Builders for the TANGO experiments of Rahman's thesis (``shared/seeds/002_*``).

Chapter 4: TANGO ("Touch ANd GO") on a Mitsui Seiki HU40T (``wCBXfZYSt``): 26
facets of the octagonal machine table (an uncalibrated "indigenous" artefact)
probed at the 28 (S, B, C) indexation triplets of Table 4-2, plus the two balls
of a 304.6686 mm scale bar.  Chapter 5: a Huron KX8-five (``wCAYbXZSt``, A axis
tilted 45 deg) whose phi 500 mm cylindrical table is probed at 23 A/C
indexations, estimating the ten parameters of Table 5-1.

Everything here is plain data (dicts and lists in the formats of docs/formats.md) so
tests, the demo and the benchmarks build the same experiments::

    m = tango.hu40t_machine()
    art = tango.octagonal_table()
    plan = tango.hu40t_plan(art, m)
    ds = fivecal.simulate(m, plan, errors=tango.thesis_s3_errors(), artefact=art,
                          tip_radius=3.0, sigma=0.0006, seed=1,
                          setup=tango.hu40t_setup(art))
    fivecal.identify(ds, "S3")

Units: mm, degrees for rotary commands, rad for angular errors (docs/formats.md).

What comes from the thesis and what is assumed is said at each number.  The
thesis figures (4-1, 4-2, 5-2, 5-3, 5-5) did not survive in the text, so the
facet coordinates are a plausible reconstruction, not the real tables.
"""
from __future__ import annotations

import json
import math
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ..machine import Machine
from ..simulation import simulate
# the design layer's rule (an axis an indexation does not name is at 0), re-exported
from ..design import rotary_directions

__all__ = [
    "HU40T_MACHINE", "KX8_MACHINE", "hu40t_machine", "kx8_machine",
    "TABLE_4_2", "SCALE_BAR_LENGTH", "SCALE_BAR_BALL_RADIUS", "TIP_RADIUS", "PROBE_SIGMA",
    "octagonal_table", "octagonal_table_obstacles", "hu40t_plan", "hu40t_setup",
    "thesis_s3_errors", "s4_error_motions", "thesis_s4_errors", "S3_NAMES", "LOCATION_NAMES",
    "indexation_of", "indexation_groups", "rotary_directions", "facet_accessible",
    "kx8_cylinder_table", "kx8_cylinder_obstacles", "KX8_INDEXATIONS", "kx8_plan", "kx8_errors",
    "kx8_setup", "TABLE_5_1_NAMES", "STYLUS_OFFSETS", "hu40t_dataset", "kx8_dataset",
    "KX8_TABLE_CYLINDER", "kx8_curved", "kx8_as_facets", "kx8_curved_setup", "kx8_curved_dataset",
]

# --------------------------------------------------------------------------
# Machines (same content as examples/machines/*.json; see the README there)
# --------------------------------------------------------------------------

#: HU40T-like machine (thesis ch. 4, topology wCBXfZYSt, Fig. 4-3); identical to
#: ``examples/machines/hu40t.json`` so the module works from an installed package.
HU40T_MACHINE = {
    "name": "HU40T-like",
    "topology": "wCBXfZYSt",
    "axes": {
        "X": {"type": "linear", "direction": [-1, 0, 0]},
        "B": {"type": "rotary", "direction": [0, -1, 0], "point": [0, 0, -120]},
        "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
        "Z": {"type": "linear", "direction": [0, 0, 1]},
        "Y": {"type": "linear", "direction": [0, 1, 0]},
        "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]},
    },
    "tool": {"tip": [0, 0, 100]},
}

#: KX8-like machine (thesis ch. 5, wCAYbXZ(C1)t, Fig. 5-4); identical to
#: ``examples/machines/kx8.json``.
KX8_MACHINE = {
    "name": "KX8-like",
    "topology": "wCAYbXZSt",
    "axes": {
        "C": {"type": "rotary", "direction": [0, 0, -1], "point": [0, 0, 0]},
        "A": {"type": "rotary", "direction": [-math.sqrt(0.5), 0, math.sqrt(0.5)], "point": [0, 0, 0]},
        "Y": {"type": "linear", "direction": [0, -1, 0]},
        "X": {"type": "linear", "direction": [1, 0, 0]},
        "Z": {"type": "linear", "direction": [0, 0, 1]},
        "S": {"type": "rotary", "direction": [0, 0, 1], "point": [0, 0, 0]},
    },
    "tool": {"tip": [0, 0, 250]},
}


def hu40t_machine():
    """The HU40T-like :class:`fivecal.Machine` (``HU40T_MACHINE``)."""
    return Machine.from_dict(HU40T_MACHINE)


def kx8_machine():
    """The KX8-like :class:`fivecal.Machine` (``KX8_MACHINE``)."""
    return Machine.from_dict(KX8_MACHINE)


# --------------------------------------------------------------------------
# Probe and accessibility
# --------------------------------------------------------------------------

#: Stylus ball radius (mm). The thesis gives the MP700 probe and a 100 mm stylus
#: (§4.5) but not the ball; a 6 mm ball is the usual one for that stylus.
TIP_RADIUS = 3.0
#: Probing repeatability (mm): 0.6 µm, the pooled standard deviations of §4.6
#: (0.63, 0.59, 0.63 µm along X, Y, Z; 0.64 µm 2D; Table 4-3: 0.60-0.72 µm).
PROBE_SIGMA = 0.0006
#: Stylus length (mm), §4.5 "MP700 ... with a 100 mm stylus length".
STYLUS_LENGTH = 100.0
#: Radius of the stylus shaft (mm, assumed, thinner than the ball) and of the
#: probe body (mm, MP700 is about 63 mm in diameter) and the length of body
#: checked for collisions beyond the stylus (mm, assumed).
STYLUS_SHAFT_RADIUS = 2.5
PROBE_BODY_RADIUS = 31.5
PROBE_BODY_LENGTH = 100.0


def _inside(p: np.ndarray, rad: float, solid: Sequence[tuple]) -> bool:
    """True if a ball of radius ``rad`` at ``p`` overlaps the convex ``solid``
    (conservatively: every constraint expanded by ``rad``).  A constraint is
    ``("plane", n, d)`` meaning n.p <= d or ``("cyl", R)`` meaning
    x^2 + y^2 <= R^2 (a cylinder about the workpiece Z axis)."""
    for c in solid:
        if c[0] == "plane":
            if float(np.dot(c[1], p)) - c[2] >= rad:
                return False
        else:
            if math.hypot(p[0], p[1]) - c[1] >= rad:
                return False
    return True


def facet_accessible(point, normal, tool_axis, obstacles: Sequence[Sequence[tuple]] = (),
                     tip_radius: float = TIP_RADIUS, min_dot: float = -0.02) -> bool:
    """Can the probe touch the surface at ``point`` (normal ``normal``) with the
    tool axis ``tool_axis`` (unit, workpiece frame, pointing from the stylus
    ball towards the spindle, as :meth:`fivecal.Machine.tool_pose` returns)?

    Two conditions:

    * the normal must not face away from the spindle: ``normal . tool_axis >=
      min_dot``.  Lateral touches (normal perpendicular to the tool axis) are
      allowed: Table 4-2 lists all 26 facets, the side faces of the table
      included, as accessible at B = 0, where the side-face normals are
      perpendicular to the spindle; the 100 mm stylus reaches down beside the
      table.
    * the stylus (a shaft of ``STYLUS_SHAFT_RADIUS`` over ``STYLUS_LENGTH``) and
      the probe body (``PROBE_BODY_RADIUS`` over ``PROBE_BODY_LENGTH``) along the
      tool axis from the ball centre must clear every convex solid of
      ``obstacles`` (the table, its support).
    """
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    a = np.asarray(tool_axis, float)
    a = a / np.linalg.norm(a)
    if float(n @ a) < min_dot:
        return False
    centre = np.asarray(point, float) + tip_radius * n
    step = 2.0
    t = tip_radius + 1.0
    end = STYLUS_LENGTH + PROBE_BODY_LENGTH
    while t <= end:
        p = centre + t * a
        rad = STYLUS_SHAFT_RADIUS if t < STYLUS_LENGTH else PROBE_BODY_RADIUS
        for solid in obstacles:
            if _inside(p, rad, solid):
                return False
        t += step
    return True


def _tool_axes(machine, axes_list: Sequence[Mapping[str, float]]) -> np.ndarray:
    """Nominal tool axis (workpiece frame) at each rotary indexation."""
    names = machine.axis_names
    cols = {a: np.array([float(ax.get(a, 0.0)) for ax in axes_list]) for a in names}
    _, axis = machine.tool_pose(cols)
    return np.asarray(axis)


def _facet_basis(normal) -> Tuple[np.ndarray, np.ndarray]:
    """Two unit in-plane directions of a facet: for a horizontal normal, the
    horizontal tangent and Z; for an upward normal, X and Y."""
    n = np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    ref = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(ref, n)
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    return u, v


# Touch-point pattern inside a facet (multiples of the spread): successive
# visits of a facet land on different points of the small probed area.
_SPREAD_PATTERN = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0),
                   (0.7, 0.7), (-0.7, -0.7), (0.7, -0.7), (-0.7, 0.7)]


# --------------------------------------------------------------------------
# Chapter 4: HU40T, octagonal table
# --------------------------------------------------------------------------

#: Scale bar length (mm), §4.7: "a fixed length double ball bar 304.6686 mm long".
SCALE_BAR_LENGTH = 304.6686
#: Scale bar ball radius (mm): 1 inch balls (assumed; not given in the thesis).
SCALE_BAR_BALL_RADIUS = 12.7

#: Table half-width (mm): "The table has overall dimensions of 400x400 mm" (§4.5).
TABLE_HALF_WIDTH = 200.0
#: Corner chamfer leg (mm), assumed: the table is "an octagonal prism with nine
#: nominally flat surfaces" (§4.3), i.e. the top face and eight side faces.
TABLE_CHAMFER = 60.0
#: Height of the side faces (mm), assumed.
TABLE_THICKNESS = 50.0

# Table 4-2 verbatim: (S, B, C, accessible facet ids); ids 1 and 2 are the
# scale-bar balls, probed once (row 17).  The first column of the thesis,
# "A(C1)", is the spindle indexation.
TABLE_4_2: List[Tuple[float, float, float, Tuple[int, ...]]] = [
    (0, 30, -90, (3, 5, 8, 9, 10, 11, 14, 16, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28)),
    (0, 60, -180, tuple(range(10, 24))),
    (0, 90, -270, (5, 6, 7, 8, 10, 12, 13, 14, 15)),
    (0, 75, -225, (10, 12, 13, 14, 15, 16, 17, 18, 21)),
    (0, 45, -135, (10, 11, 13, 14, 15, 16, 17, 18, 21, 22, 23)),
    (0, 15, -45, (3, 5, 8, 9, 10, 11, 14, 16, 19, 20, 21, 22, 23, 24, 25, 26, 27, 28)),
    (0, 0, 0, (3,) + tuple(range(5, 29))),
    (0, -15, 45, (3, 8, 9, 10, 11) + tuple(range(14, 29))),
    (0, -45, 135, (3, 5, 6, 8, 9, 10) + tuple(range(21, 29))),
    (0, -60, 180, (3, 5, 6, 7, 8, 9, 10) + tuple(range(23, 29))),
    (0, -90, 270, (5, 6, 7, 8, 10, 12, 13, 14, 15)),
    (0, -75, 225, (3, 5, 6, 7, 8, 26, 27, 28)),
    (0, -30, 90, (3, 9, 11) + tuple(range(15, 29))),
    (0, 0, 270, tuple(range(3, 29))),
    (0, 0, 180, tuple(range(3, 29))),
    (0, 0, 90, tuple(range(3, 29))),
    (0, 0, 0, (1, 2) + tuple(range(3, 29))),
    (0, 0, -90, tuple(range(3, 29))),
    (0, 0, -180, tuple(range(3, 29))),
    (0, 0, -270, tuple(range(3, 29))),
    (0, 0, 0, (5, 7)),
    (90, 0, 0, (5, 7)),
    (180, 0, 0, (5, 7)),
    (270, 0, 0, (5, 7)),
    (0, 0, 0, (12, 15)),
    (90, 0, 0, (12, 15)),
    (180, 0, 0, (12, 15)),
    (270, 0, 0, (12, 15)),
]

# Facet geometry, workpiece frame (origin on the C axis at the table face,
# Z along the table normal; see examples/machines/README.md).  Reconstructed:
# Figure 4-2 is not in the text.  Ten facets on the top face, three on each
# long side face (at 15 and 30 mm below the top) and one on each corner
# chamfer.  The thesis numbers 3..28 were assigned to these 26 places by a
# linear assignment that maximises agreement with Table 4-2 under the
# accessibility test of :func:`facet_accessible`: 180 of the 185 (facet,
# indexation) pairs the table lists for its first 13 rows (B tilted, and the
# first B = C = 0) are geometrically accessible here (at B = 0 all 26 are),
# and the spindle-indexed facets 5, 7, 12 and 15
# come out on side faces (normals +X, +Y, +Y, -X), as they must to separate the
# stylus offsets from the spindle offsets (§4.5).
# id: (point, normal)
_S2 = math.sqrt(0.5)
_CH = (2 * TABLE_HALF_WIDTH - TABLE_CHAMFER) * _S2  # distance of a chamfer plane from the axis
_OCTAGON_FACETS = {
    3: ((160.0, 20.0, 0.0), (0, 0, 1)),
    4: ((0.0, 200.0, -30.0), (0, 1, 0)),
    5: ((200.0, 100.0, -15.0), (1, 0, 0)),
    6: ((_CH * _S2, _CH * _S2, -20.0), (_S2, _S2, 0)),
    7: ((100.0, 200.0, -15.0), (0, 1, 0)),
    8: ((150.0, 150.0, 0.0), (0, 0, 1)),
    9: ((150.0, -150.0, 0.0), (0, 0, 1)),
    10: ((-150.0, 150.0, 0.0), (0, 0, 1)),
    11: ((-50.0, 60.0, 0.0), (0, 0, 1)),
    12: ((-100.0, 200.0, -15.0), (0, 1, 0)),
    13: ((-_CH * _S2, _CH * _S2, -20.0), (-_S2, _S2, 0)),
    14: ((0.0, 160.0, 0.0), (0, 0, 1)),
    15: ((-200.0, 100.0, -15.0), (-1, 0, 0)),
    16: ((-150.0, -150.0, 0.0), (0, 0, 1)),
    17: ((-200.0, -100.0, -15.0), (-1, 0, 0)),
    18: ((-200.0, 0.0, -30.0), (-1, 0, 0)),
    19: ((0.0, -200.0, -30.0), (0, -1, 0)),
    20: ((-100.0, -200.0, -15.0), (0, -1, 0)),
    21: ((-_CH * _S2, -_CH * _S2, -20.0), (-_S2, -_S2, 0)),
    22: ((0.0, -160.0, 0.0), (0, 0, 1)),
    23: ((-160.0, 20.0, 0.0), (0, 0, 1)),
    24: ((100.0, -200.0, -15.0), (0, -1, 0)),
    25: ((50.0, 60.0, 0.0), (0, 0, 1)),
    26: ((200.0, -100.0, -15.0), (1, 0, 0)),
    27: ((200.0, 0.0, -30.0), (1, 0, 0)),
    28: ((_CH * _S2, -_CH * _S2, -20.0), (_S2, -_S2, 0)),
}


def octagonal_table() -> dict:
    """The HU40T indigenous artefact (thesis §4.3, Figs. 4-1, 4-2).

    Facets ``"F3"`` .. ``"F28"`` (the thesis numbers 3..28) on the 400 x 400 mm
    octagonal table (§4.5): ten on the top face (normal +Z), three on each of
    the four long side faces and one on each of the four 60 mm corner chamfers
    (assumed), side facets 15 or 30 mm below the top.  Plus the scale bar
    (§4.5, §4.7): balls ``"S1"`` and ``"S2"`` (the thesis' 1 and 2), radius
    12.7 mm, 304.6686 mm apart along X (the bar "was measured when aligned
    with the X-axis"), standing 50 mm above the table at y = -80 mm
    (assumed).  ``simulate`` replaces the bar length by the true distance.
    """
    facets = []
    for fid in sorted(_OCTAGON_FACETS):
        p, n = _OCTAGON_FACETS[fid]
        n = np.asarray(n, float)
        n = n / np.linalg.norm(n)
        facets.append({"id": f"F{fid}", "point": [float(v) for v in p],
                       "normal": [float(v) for v in n]})
    half = SCALE_BAR_LENGTH / 2.0
    spheres = [{"id": "S1", "center": [-half, -80.0, 50.0], "radius": SCALE_BAR_BALL_RADIUS},
               {"id": "S2", "center": [half, -80.0, 50.0], "radius": SCALE_BAR_BALL_RADIUS}]
    return {"facets": facets, "spheres": spheres,
            "scale_bars": [{"spheres": ["S1", "S2"], "length": SCALE_BAR_LENGTH}]}


def octagonal_table_obstacles() -> List[List[tuple]]:
    """Convex solids the probe must clear on the HU40T: the octagonal table
    (top face z = 0, TABLE_THICKNESS deep) and, under it, the rotary table
    housing (300 x 300 mm, assumed) down to the B axis and beyond."""
    table = [("plane", np.array([0.0, 0.0, 1.0]), 0.0),
             ("plane", np.array([0.0, 0.0, -1.0]), TABLE_THICKNESS)]
    for k in range(8):
        ang = math.radians(45 * k)
        n = np.array([math.cos(ang), math.sin(ang), 0.0])
        table.append(("plane", n, TABLE_HALF_WIDTH if k % 2 == 0 else _CH))
    housing = [("plane", np.array([0.0, 0.0, 1.0]), -TABLE_THICKNESS)]
    for n in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]):
        housing.append(("plane", np.array(n, float), 150.0))
    return [table, housing]


def _facet_map(artefact: Mapping) -> Dict[str, dict]:
    return {str(f["id"]): f for f in artefact.get("facets", [])}


def hu40t_plan(artefact: Optional[Mapping] = None, machine=None, points_per_visit: int = 1,
               spread: float = 5.0, min_dot: float = -0.02,
               obstacles: Optional[Sequence[Sequence[tuple]]] = None,
               sphere_normals: Optional[Sequence[Sequence[float]]] = None,
               rows: Optional[Iterable[int]] = None) -> List[dict]:
    """The TANGO probing plan of Table 4-2 (thesis §4.5).

    The 28 (S, B, C) triplets in the order of the table, each with its listed
    facets (ids ``"F<n>"``), minus those :func:`facet_accessible` finds not
    approachable with this geometry (5 of the 383 listed facet probings with
    :func:`octagonal_table`: F19 at B=60, F16 at B=75, F26 and F27 at B=-15,
    F3 at B=-75).  Each visit of a facet touches ``points_per_visit``
    points; successive touches of a facet walk over a small pattern of
    ``spread`` mm around its nominal point (the thesis probes a "small surface
    area" and never exactly the same spot).  The scale-bar balls are probed
    once, in row 17 (B = C = S = 0), with the five touches ``sphere_normals``
    (top and four at 45 deg) so that their centres are determined.  Rotary
    last-move directions follow the order of the table, starting from
    B = C = 0 reached by positive moves: B moves positively up to +90, then
    negatively down to -90, ...; C alternates too (§4.5: "Positive and negative
    axis motions are used for the B- and C-axis in order to observe any
    backlash").  388 touches: 378 facet probings (the thesis: 383) and 10 on the bar.

    ``rows`` (indices into :data:`TABLE_4_2`) restricts the plan to some rows
    (directions still follow the full sequence).
    """
    if artefact is None:
        artefact = octagonal_table()
    if machine is None:
        machine = hu40t_machine()
    if obstacles is None:
        obstacles = octagonal_table_obstacles()
    if sphere_normals is None:
        sphere_normals = [(0, 0, 1), (_S2, 0, _S2), (-_S2, 0, _S2), (0, _S2, _S2), (0, -_S2, _S2)]
    facets = _facet_map(artefact)
    spheres = {str(s["id"]) for s in artefact.get("spheres", [])}
    indexations = [{"S": float(s), "B": float(b), "C": float(c)} for s, b, c, _ in TABLE_4_2]
    dirs = rotary_directions(indexations, ("B", "C"))
    tool_axes = _tool_axes(machine, indexations)
    keep = set(range(len(TABLE_4_2))) if rows is None else {int(r) for r in rows}
    visits: Dict[str, int] = {}
    plan: List[dict] = []
    for i, (s, b, c, ids) in enumerate(TABLE_4_2):
        if i not in keep:
            continue
        axes = dict(indexations[i])
        for k in ids:
            if k in (1, 2):
                sid = f"S{k}"
                if sid not in spheres:
                    continue
                for v in sphere_normals:
                    plan.append({"type": "sphere", "target": sid, "axes": dict(axes),
                                 "normal": [float(x) for x in v], "direction": dict(dirs[i])})
                continue
            fid = f"F{k}"
            f = facets.get(fid)
            if f is None:
                continue
            n = np.asarray(f["normal"], float)
            n = n / np.linalg.norm(n)
            u, w = _facet_basis(n)
            p0 = np.asarray(f["point"], float)
            for _ in range(points_per_visit):
                j = visits.get(fid, 0)
                visits[fid] = j + 1
                du, dw = _SPREAD_PATTERN[j % len(_SPREAD_PATTERN)]
                p = p0 + spread * (du * u + dw * w)
                if not facet_accessible(p, n, tool_axes[i], obstacles, min_dot=min_dot):
                    p = p0
                    if not facet_accessible(p, n, tool_axes[i], obstacles, min_dot=min_dot):
                        continue
                plan.append({"type": "facet", "target": fid, "axes": dict(axes),
                             "point": [float(x) for x in p], "direction": dict(dirs[i])})
    return plan


def hu40t_setup(artefact: Optional[Mapping] = None, seed: int = 2016) -> Dict[str, float]:
    """True setup of the simulated HU40T experiment (mm).

    * ``facet.<id>``: how far each facet really is off its nominal plane.  The
      thesis found the table "dimension differences from nominal ... in a range
      of 197.25 µm" (§4.8): uniform in [-0.1, +0.1] mm.
    * ``sphere.S1|S2.x|y|z``: the bar sits up to 0.2 mm off its nominal place
      (assumed).
    Deterministic for a given ``seed``.  The stylus offsets are machine
    parameters (``tip.x|y|z``), see :data:`STYLUS_OFFSETS`.
    """
    if artefact is None:
        artefact = octagonal_table()
    rng = np.random.default_rng(seed)
    setup = {}
    for f in artefact.get("facets", []):
        setup[f"facet.{f['id']}"] = float(rng.uniform(-0.1, 0.1))
    for s in artefact.get("spheres", []):
        for c in "xyz":
            setup[f"sphere.{s['id']}.{c}"] = float(rng.uniform(-0.2, 0.2))
    return setup


#: True stylus ball offsets (mm) used in the simulations, assumed: 12, -8, 35 µm.
#: They are machine parameters in fivecal (pass them with the errors).
STYLUS_OFFSETS = {"tip.x": 0.012, "tip.y": -0.008, "tip.z": 0.035}

#: The thesis' subset S3 on wCBXfZYSt (§4.7, Table 4-5), fivecal names.
S3_NAMES = ["EA0B", "EC0B", "EX0C", "EA0C", "EB0C", "EB0Z", "EA0Y", "EC0Y", "EX0S", "EY0S",
            "EXX1", "EYY1", "EZZ1", "EXXb", "EYYb", "EBBb", "ECCb"]
#: The eight inter-axis errors and two spindle offsets of §4.4 / §4.7.
LOCATION_NAMES = ["EA0B", "EC0B", "EX0C", "EA0C", "EB0C", "EB0Z", "EA0Y", "EC0Y", "EX0S", "EY0S"]

_UM = 1e-3    # µm -> mm
_URAD = 1e-6  # µrad -> rad (and µm/m -> mm/mm)


def thesis_s3_errors() -> Dict[str, float]:
    """True errors of the size the thesis estimated for the HU40T, Table 4-5,
    "Scale enriched TANGO" column, in fivecal names, mm and rad.

    The thesis' parameter equivalences are used as printed: its E_AX0
    [E_A0B] -> ``EA0B``, E_CX0 [E_C0B] -> ``EC0B``, E_XB0 [E_X0C] -> ``EX0C``,
    E_AB0 [E_A0C] -> ``EA0C``, E_BB0 [E_B0C] -> ``EB0C``, E_XZ1 [E_B0Z] ->
    ``EB0Z``, E_AZ0 [E_A0Y] -> ``EA0Y``, the second E_CX0 [E_C0Y] (a typo for
    E_CZ0, §4.4) -> ``EC0Y``, E_XY0 [E_X0S] -> ``EX0S``, E_YY0 [E_Y0S] ->
    ``EY0S``; scale gains E_XX1, E_YY1, E_ZZ1 (µm/m) and the backlashes.
    Signs follow the thesis numbers; fivecal's own sign conventions (axis
    directions of examples/machines/hu40t.json) make them a realistic but not a
    literal replica of the HU40T.
    """
    return {
        "EA0B": -9.31 * _URAD,
        "EC0B": -10.92 * _URAD,
        "EX0C": -108.06 * _UM,
        "EA0C": -7.83 * _URAD,
        "EB0C": 21.00 * _URAD,
        "EB0Z": 73.60 * _URAD,
        "EA0Y": -4.34 * _URAD,
        "EC0Y": 16.03 * _URAD,
        "EX0S": -134.24 * _UM,
        "EY0S": 28.60 * _UM,
        "EXX1": -8.64 * _URAD,
        "EYY1": -17.88 * _URAD,
        "EZZ1": -25.79 * _URAD,
        "EXXb": 6.95 * _UM,
        "EYYb": -0.93 * _UM,
        "EBBb": 5.88 * _URAD,
        "ECCb": -47.27 * _URAD,
    }


def s4_error_motions(scale: float = 1.0) -> Dict[str, float]:
    """Small, realistic error motions (terms of the thesis' subset S4, Table 4-1).

    Not the thesis' Table 4-4 S4 values: those are strongly correlated fits
    (e.g. E_XB1 = -94 µm/rad), not physical error motions.  Instead each term
    is sized so that it moves the tool point by a few µm over the travel used
    (linear commands within about ±250 mm, B within ±pi/2, C within ±2 pi
    rad): positioning non-linearity 2-4 µm, straightness 2-3 µm, angular error
    motions 5-15 µrad, rotary axis radial/axial motions 2-5 µm, rotary
    positioning 10-20 µrad.  Polynomial variable: mm (linear axes), rad (rotary).
    ``scale`` multiplies all of them.
    """
    L2, L3 = 200.0 ** 2, 200.0 ** 3           # linear axes, ±200 mm
    B1, B2, B3 = 1.5, 1.5 ** 2, 1.5 ** 3       # B, ±90 deg
    C1, C2, C3 = 3.0, 3.0 ** 2, 3.0 ** 3       # C, a half turn and more
    m = {
        # linear positioning non-linearity (µm over the travel)
        "EXX2": 3.0 * _UM / L2, "EXX3": -2.0 * _UM / L3,
        "EYY2": -2.5 * _UM / L2, "EYY3": 1.5 * _UM / L3,
        "EZZ2": 2.0 * _UM / L2, "EZZ3": 1.0 * _UM / L3,
        # straightness
        "EYX2": 2.0 * _UM / L2, "EZX2": -2.5 * _UM / L2, "EZX3": 1.5 * _UM / L3,
        "EXZ2": -2.0 * _UM / L2, "EYZ2": 2.5 * _UM / L2,
        "EXY2": 2.0 * _UM / L2, "EZY2": -1.5 * _UM / L2,
        # angular error motions of linear axes (µrad over the travel)
        "EAX1": 8.0 * _URAD / 200.0, "EBX1": -6.0 * _URAD / 200.0, "ECX2": 5.0 * _URAD / L2,
        "EAZ1": -7.0 * _URAD / 200.0, "ECZ2": 6.0 * _URAD / L2,
        # rotary axes: radial/axial error motions (µm per rad^k) and tilts
        "EXB1": 3.0 * _UM / B1, "EZB2": -2.5 * _UM / B2, "EYB1": 2.0 * _UM / B1,
        "EAB1": 10.0 * _URAD / B1, "ECB2": -8.0 * _URAD / B2,
        "EBB1": 12.0 * _URAD / B1, "EBB3": -6.0 * _URAD / B3,
        "EXC1": 3.0 * _UM / C1, "EYC2": -2.0 * _UM / C2, "EZC1": 2.5 * _UM / C1,
        "EAC1": 8.0 * _URAD / C1, "EBC2": -6.0 * _URAD / C2,
        "ECC1": 15.0 * _URAD / C1, "ECC2": -8.0 * _URAD / C2, "ECC3": 5.0 * _URAD / C3,
    }
    return {k: v * scale for k, v in m.items()}


def thesis_s4_errors(scale: float = 1.0) -> Dict[str, float]:
    """:func:`thesis_s3_errors` plus :func:`s4_error_motions`."""
    e = thesis_s3_errors()
    e.update(s4_error_motions(scale))
    return e


def indexation_of(observation: Mapping) -> Tuple[float, float, float]:
    """(S, B, C) of a plan entry or observation (degrees, nominal indexation
    rounded to 1e-3 so that recorded readings group with their plan row)."""
    ax = observation["axes"]
    return tuple(round(float(ax.get(a, 0.0)), 3) for a in ("S", "B", "C"))


def indexation_groups(plan_or_dataset) -> Dict[Tuple[float, float, float], List[int]]:
    """Observation indices grouped by (S, B, C) indexation triplet, in order of
    first appearance (for held-out validation, Table 4-9)."""
    obs = plan_or_dataset.observations if hasattr(plan_or_dataset, "observations") else plan_or_dataset
    groups: Dict[Tuple[float, float, float], List[int]] = {}
    for i, o in enumerate(obs):
        groups.setdefault(indexation_of(o), []).append(i)
    return groups


# --------------------------------------------------------------------------
# Chapter 5: KX8, cylindrical table
# --------------------------------------------------------------------------

#: Table radius (mm): "the standard phi 500 mm cylindrical machine table" (§5.3).
KX8_TABLE_RADIUS = 250.0
#: Height of the table top above the A/C intersection (mm), assumed (not given;
#: the nominal tip of kx8.json is 250 mm above the intersection, clear of it).
KX8_TABLE_TOP = 100.0
#: Height of the cylindrical band below the top (mm), assumed: the shallow
#: cylindrical feature probed 10 and 30 mm below the top (§5.3).
KX8_TABLE_BAND = 40.0
#: Slot (mm), assumed: a radial slot along X through the centre, 18 mm wide and
#: 20 mm deep; facet 10 of Strategy S1 is on its side wall (§5.3).
KX8_SLOT_HALF_WIDTH = 9.0
KX8_SLOT_DEPTH = 20.0

#: The ten parameters of Table 5-1: eight inter-axis errors and the two
#: relative scale gains E_YY - E_XX and E_ZZ - E_XX, which fivecal estimates as
#: EYY1 and EZZ1 with EXX1 fixed at zero.
TABLE_5_1_NAMES = ["EY0C", "EA0C", "EB0C", "EB0A", "EC0A", "EC0X", "EA0Z", "EB0Z", "EYY1", "EZZ1"]


def kx8_cylinder_table() -> dict:
    """The KX8 indigenous artefact (thesis §5.3, Figs. 5-1 to 5-3).

    Strategy S1 facets ``"S1_1"`` .. ``"S1_10"``: 1-6 on the cylinder 10 mm below
    the top every 60 deg, 7-9 on the top surface (radius 150 mm at 30, 150 and
    270 deg), 10 on a side wall of the slot.  Strategy S2 facets ``"S2_1"`` ..
    ``"S2_8"``: every 45 deg on the cylinder, odd ones 30 mm below the top, even
    ones 10 mm below.  Angular positions and the slot are assumed (Figs. 5-2,
    5-3 are not in the text).  Workpiece frame: origin at the A/C intersection
    (§5.4), Z along the C axis; the top is ``KX8_TABLE_TOP`` above it.
    """
    R, T = KX8_TABLE_RADIUS, KX8_TABLE_TOP
    facets = []

    def cyl(fid, ang_deg, depth):
        a = math.radians(ang_deg)
        n = [math.cos(a), math.sin(a), 0.0]
        facets.append({"id": fid, "point": [R * n[0], R * n[1], T - depth], "normal": n})

    for k in range(6):
        cyl(f"S1_{k + 1}", 60.0 * k + 15.0, 10.0)
    for k, ang in enumerate((30.0, 150.0, 270.0)):
        a = math.radians(ang)
        facets.append({"id": f"S1_{k + 7}", "point": [150.0 * math.cos(a), 150.0 * math.sin(a), T],
                       "normal": [0.0, 0.0, 1.0]})
    facets.append({"id": "S1_10", "point": [120.0, KX8_SLOT_HALF_WIDTH, T - 10.0],
                   "normal": [0.0, -1.0, 0.0]})
    for k in range(8):
        cyl(f"S2_{k + 1}", 45.0 * k, 30.0 if k % 2 == 0 else 10.0)
    return {"facets": facets, "spheres": [], "scale_bars": []}


def kx8_cylinder_obstacles() -> List[List[tuple]]:
    """Convex pieces of the KX8 table for the collision check: the cylinder on
    each side of the slot, the cylinder under the slot, and the A/C housing
    below the table (radius 250 mm, assumed)."""
    R, T = KX8_TABLE_RADIUS, KX8_TABLE_TOP
    top = ("plane", np.array([0.0, 0.0, 1.0]), T)
    bottom = ("plane", np.array([0.0, 0.0, -1.0]), -(T - KX8_TABLE_BAND))
    cylr = ("cyl", R)
    w = KX8_SLOT_HALF_WIDTH
    side_pos = [cylr, top, bottom, ("plane", np.array([0.0, -1.0, 0.0]), -w)]
    side_neg = [cylr, top, bottom, ("plane", np.array([0.0, 1.0, 0.0]), -w)]
    under = [cylr, bottom, ("plane", np.array([0.0, 0.0, 1.0]), T - KX8_SLOT_DEPTH)]
    # the slot runs along +X from the centre only; the -X half is solid
    solid_negx = [cylr, top, bottom, ("plane", np.array([1.0, 0.0, 0.0]), 0.0)]
    housing = [("cyl", R - 10.0), ("plane", np.array([0.0, 0.0, 1.0]), T - KX8_TABLE_BAND)]
    return [side_pos, side_neg, under, solid_negx, housing]


#: The 23 A/C indexations (degrees) of §5.5 (Fig. 5-5 is not in the text):
#: assumed, A in 0..180 deg (A = 180 turns the table vertical), C over a full
#: turn, in a scrambled order so that A and C are not linearly related
#: ("Linear relationship between A and C is avoided as recommended in [11]").
KX8_INDEXATIONS: List[Tuple[float, float]] = [
    (0, 0), (0, 120), (0, 240), (30, 45), (30, 200), (30, 300), (60, 90), (60, 150),
    (60, 330), (90, 10), (90, 135), (90, 250), (120, 60), (120, 180), (120, 285),
    (150, 100), (150, 220), (150, 340), (180, 30), (180, 160), (180, 270), (45, 15), (135, 195),
]


def kx8_plan(artefact: Optional[Mapping] = None, machine=None, strategy: str = "S1",
             top: bool = True, min_dot: float = -0.02, points_per_visit: int = 1,
             spread: float = 3.0) -> List[dict]:
    """A/C indexation plan on the KX8 cylindrical table (thesis §5.5).

    ``strategy``: ``"S1"`` (10 facets: six on the cylinder, three on the top,
    one on the slot wall), ``"S2"`` (8 cylinder facets at two heights) or
    ``"S1+S2"`` (both, as in Table 5-2).  ``top=False`` drops the top-surface
    facets 7-9 of S1 (Table 5-2, "(S1 - Pts on table) + S2").  At each of the
    23 indexations of :data:`KX8_INDEXATIONS` every accessible facet
    (:func:`facet_accessible`) is touched; the spindle stays at 0.  With
    Strategy S1 that gives 121 touches (the thesis: 156), S2 100 (thesis: 118).
    """
    if artefact is None:
        artefact = kx8_cylinder_table()
    if machine is None:
        machine = kx8_machine()
    parts = [s.strip() for s in strategy.split("+")]
    for s in parts:
        if s not in ("S1", "S2"):
            raise ValueError(f"kx8_plan: unknown strategy {s!r} (S1, S2 or S1+S2)")
    obstacles = kx8_cylinder_obstacles()
    chosen = []
    for f in artefact.get("facets", []):
        fid = str(f["id"])
        pre = fid.split("_")[0]
        if pre not in parts:
            continue
        if not top and abs(f["normal"][2]) > 0.9:
            continue
        chosen.append(f)
    indexations = [{"A": float(a), "C": float(c), "S": 0.0} for a, c in KX8_INDEXATIONS]
    dirs = rotary_directions(indexations, ("A", "C"))
    tool_axes = _tool_axes(machine, indexations)
    visits: Dict[str, int] = {}
    plan = []
    for i, axes in enumerate(indexations):
        for f in chosen:
            n = np.asarray(f["normal"], float)
            u, w = _facet_basis(n)
            p0 = np.asarray(f["point"], float)
            for _ in range(points_per_visit):
                j = visits.get(f["id"], 0)
                visits[f["id"]] = j + 1
                du, dw = _SPREAD_PATTERN[j % len(_SPREAD_PATTERN)]
                p = p0 + spread * (du * u + dw * w)
                if not facet_accessible(p, n, tool_axes[i], obstacles, min_dot=min_dot):
                    continue
                plan.append({"type": "facet", "target": f["id"], "axes": dict(axes),
                             "point": [float(x) for x in p], "direction": dict(dirs[i])})
    return plan


def kx8_errors() -> Dict[str, float]:
    """True errors for the KX8 simulation: Table 5-2, row "S1+S2" mean (µm, µrad,
    µm/m), in mm and rad.  Only relative scale gains are observable without a
    scale bar (§5.2), so the truth has EXX1 = 0 and EYY1, EZZ1 equal to the
    thesis' E_YY - E_XX and E_ZZ - E_XX."""
    return {
        "EY0C": 2.0 * _UM,
        "EA0C": 16.3 * _URAD,
        "EB0C": -19.3 * _URAD,
        "EB0A": 34.9 * _URAD,
        "EC0A": 28.9 * _URAD,
        "EC0X": 7.2 * _URAD,
        "EA0Z": -3.6 * _URAD,
        "EB0Z": -49.4 * _URAD,
        "EYY1": 33.1 * _URAD,
        "EZZ1": -16.4 * _URAD,
    }


def kx8_setup(artefact: Optional[Mapping] = None, seed: int = 2015) -> Dict[str, float]:
    """True setup of the KX8 simulation: facet offsets uniform in ±50 µm (the
    table is uncalibrated; assumed)."""
    if artefact is None:
        artefact = kx8_cylinder_table()
    rng = np.random.default_rng(seed)
    setup = {}
    for f in artefact.get("facets", []):
        setup[f"facet.{f['id']}"] = float(rng.uniform(-0.05, 0.05))
    return setup


#: Id of the table periphery as a cylinder target (:func:`kx8_curved`).
KX8_TABLE_CYLINDER = "K1"


def _on_periphery(f) -> bool:
    """A facet of :func:`kx8_cylinder_table` on the cylindrical periphery (not
    the top, not the slot wall)."""
    p = np.asarray(f["point"], float)
    return abs(f["normal"][2]) < 1e-9 and abs(math.hypot(p[0], p[1]) - KX8_TABLE_RADIUS) < 1e-6


def kx8_curved(artefact: Optional[Mapping] = None, plan: Optional[Sequence[Mapping]] = None,
               machine=None) -> Tuple[dict, List[dict]]:
    """The KX8 table with its periphery as one cylinder target instead of
    planar facets (observation type ``"cylinder"``, docs/formats.md).

    Returns ``(artefact, plan)``: the artefact keeps the top and slot facets
    and gains the cylinder :data:`KX8_TABLE_CYLINDER` (axis along the C axis,
    radius :data:`KX8_TABLE_RADIUS`); each planned touch of a periphery facet
    becomes a cylinder touch at the same point, its ``id`` ``"<facet>#<k>"``
    keeping the facet (for :func:`kx8_as_facets`)."""
    if artefact is None:
        artefact = kx8_cylinder_table()
    if plan is None:
        plan = kx8_plan(artefact, machine)
    curved = {f["id"] for f in artefact.get("facets", []) if _on_periphery(f)}
    art = {k: [dict(x) for x in v] for k, v in artefact.items()}
    art["facets"] = [f for f in art.get("facets", []) if f["id"] not in curved]
    art["cylinders"] = [{"id": KX8_TABLE_CYLINDER, "point": [0.0, 0.0, KX8_TABLE_TOP], "axis": [0.0, 0.0, 1.0],
                         "radius": KX8_TABLE_RADIUS}]
    out = []
    for k, e in enumerate(plan):
        e = dict(e)
        if e.get("type") == "facet" and e.get("target") in curved:
            e.update(type="cylinder", target=KX8_TABLE_CYLINDER, id=f"{e['target']}#{k}")
        out.append(e)
    return art, out


def kx8_as_facets(dataset, artefact: Optional[Mapping] = None) -> dict:
    """A dataset of :func:`kx8_curved` touches with every cylinder touch
    assigned back to its thesis facet (a plane through the facet's target
    point, §5.3), as a dataset dict: what the planar-facet model of the
    thesis fits."""
    d = json.loads(json.dumps(dataset.to_dict() if hasattr(dataset, "to_dict") else dataset))
    d["artefact"] = json.loads(json.dumps(artefact if artefact is not None else kx8_cylinder_table()))
    for o in d["observations"]:
        if o["type"] == "cylinder":
            o["type"] = "facet"
            o["target"] = o["id"].split("#")[0]
    return d


def kx8_curved_setup(artefact: Optional[Mapping] = None, seed: int = 2015) -> Dict[str, float]:
    """True setup of the curved KX8 simulation: :func:`kx8_setup` for the top
    and slot facets, and a table periphery 30 µm over its nominal radius
    with its axis 15 µm / -10 µm off the C axis (assumed)."""
    if artefact is None:
        artefact = kx8_cylinder_table()
    curved = {f["id"] for f in artefact.get("facets", []) if _on_periphery(f)}
    setup = {k: v for k, v in kx8_setup(artefact, seed).items() if k.split(".", 1)[1] not in curved}
    c = KX8_TABLE_CYLINDER
    setup.update({f"cylinder.{c}.r": 30 * _UM, f"cylinder.{c}.x": 15 * _UM, f"cylinder.{c}.y": -10 * _UM})
    return setup



# --------------------------------------------------------------------------
# Ready-made simulated datasets
# --------------------------------------------------------------------------

def _with_stylus(errors: Optional[Mapping[str, float]], default: Mapping[str, float]) -> dict:
    e = dict(STYLUS_OFFSETS)
    e.update(default if errors is None else errors)
    return e


def hu40t_dataset(errors: Optional[Mapping[str, float]] = None, seed: int = 1,
                  sigma: float = PROBE_SIGMA, plan: Optional[Sequence[Mapping]] = None,
                  artefact: Optional[Mapping] = None, setup: Optional[Mapping[str, float]] = None):
    """Simulate the HU40T TANGO experiment: :func:`octagonal_table`,
    :func:`hu40t_plan`, :func:`hu40t_setup`, errors :func:`thesis_s3_errors`
    by default plus :data:`STYLUS_OFFSETS` (unless ``errors`` sets ``tip.*``),
    3 mm stylus ball, 0.6 µm probing noise."""
    machine = hu40t_machine()
    art = artefact if artefact is not None else octagonal_table()
    return simulate(machine, plan if plan is not None else hu40t_plan(art, machine),
                    errors=_with_stylus(errors, thesis_s3_errors()), artefact=art,
                    tip_radius=TIP_RADIUS, sigma=sigma, seed=seed,
                    setup=hu40t_setup(art) if setup is None else setup)


def kx8_curved_dataset(strategy: str = "S1+S2", top: bool = True,
                       errors: Optional[Mapping[str, float]] = None, seed: int = 1,
                       sigma: float = PROBE_SIGMA, setup: Optional[Mapping[str, float]] = None):
    """Simulate the KX8 experiment of chapter 5 on a table whose periphery is
    a true cylinder (:func:`kx8_curved`, :func:`kx8_curved_setup` unless
    ``setup`` is given): the thesis' touches spread over 3 mm along the
    curved surface. Fit it with the cylinder target, or with the thesis'
    planar facets through :func:`kx8_as_facets`."""
    machine = kx8_machine()
    art, plan = kx8_curved(kx8_cylinder_table(), kx8_plan(kx8_cylinder_table(), machine, strategy=strategy,
                                                         top=top), machine)
    return simulate(machine, plan, errors=_with_stylus(errors, kx8_errors()), artefact=art,
                    tip_radius=TIP_RADIUS, sigma=sigma, seed=seed,
                    setup=kx8_curved_setup() if setup is None else setup)


def kx8_dataset(strategy: str = "S1+S2", top: bool = True,
                errors: Optional[Mapping[str, float]] = None, seed: int = 1,
                sigma: float = PROBE_SIGMA):
    """Simulate the KX8 experiment of chapter 5 (:func:`kx8_plan`,
    :func:`kx8_errors`, :func:`kx8_setup`)."""
    machine = kx8_machine()
    art = kx8_cylinder_table()
    return simulate(machine, kx8_plan(art, machine, strategy=strategy, top=top),
                    errors=_with_stylus(errors, kx8_errors()), artefact=art,
                    tip_radius=TIP_RADIUS, sigma=sigma, seed=seed, setup=kx8_setup(art))
