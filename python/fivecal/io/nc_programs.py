"""ISO G-code for fivecal's sphere, mixed probing and R-test plans (docs/linuxcnc.md).

* :func:`sphere_program`: the touches of a sphere plan
  (:func:`fivecal.procedures.sphere_check.plan`,
  :func:`fivecal.procedures.sphere_test.sphere_plan`) as a ``G38.2`` cycle for
  LinuxCNC with tool-centre-point kinematics: per rotary position the table is
  indexed (from the side the plan's ``direction`` asks for, with an
  ``overshoot``), then per touch the stylus comes in along the touch
  direction, probes through the surface and backs off the same way. The
  probed positions go to a ``PROBEOPEN`` log, which
  :func:`fivecal.io.linuxcnc.read_probe_log` reads back into sphere
  observations.
* :func:`touch_program`: a plan that mixes facet and sphere touches (as
  ``fivecal design`` and the TANGO plan write them) as one such cycle, in
  the plan's order; its log reads back into facet and sphere observations.
* :func:`sphere_trigger_model` / :func:`sphere_sim_lines` /
  :func:`sphere_log` (and ``touch_*`` for mixed plans): where a touch trips
  on a machine with given errors (the exact crossing of the probe line with
  the sphere or the facet's plane), as the plane the
  simulator's probe input (:func:`fivecal.io.linuxcnc.probe_sim_hal`) needs,
  or as the log a perfect probe would write.
* :func:`rtest_program`: the path of an R-test K test
  (:func:`fivecal.procedures.rtest.plan`) with a dwell at each of the plan's
  samples, either as axis commands (joint positions from fivecal's nominal
  inverse kinematics; no tool-centre-point function needed) or, for
  LinuxCNC, as world coordinates with ``xyzac-trt-kins`` / ``xyzbc-trt-kins``
  switched on.

Units: mm, degrees, mm/min; world coordinates are LinuxCNC's (workpiece point
- tool tip at the zero pose, the pins' convention).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from .. import _core, _json
from ..machine import Machine
from . import linuxcnc as L
from . import nc_options as O


#: The registry's word on each kind (``_core.nc_kinds()``, observations/
#: nc_geometry.h): the program its plan entries run in, whether it is a probe
#: touch, the artefact list its targets are in.
NC_KINDS: Dict[str, dict] = {k["name"]: k for k in _core.nc_kinds()}
#: plan entry type -> the program it runs in
PLAN_PROGRAMS: Dict[str, str] = {n: k["program"] for n, k in NC_KINDS.items() if k["program"]}
#: the touch programs: a plan of probe touches of several kinds runs in the
#: first (the probing cycle, every probe touch in plan order), the second is
#: the sphere cycle
TOUCH_PROGRAMS = ("probing", "sphere")
#: The programs fivecal writes (``fivecal export program --kind``): the touch
#: programs, then those of the other kinds' entries in the registry's order
#: (an R-test K test, a ball bar test: fivecal.io.dbb_program)
PROGRAMS = tuple(dict.fromkeys([*TOUCH_PROGRAMS, *PLAN_PROGRAMS.values()]))


def program_kinds(program: str) -> List[str]:
    """The plan entry types a program runs (registry order): a probing
    cycle runs every probe touch, any other program its own kinds' entries."""
    if program == TOUCH_PROGRAMS[0]:
        return [n for n, k in NC_KINDS.items() if k["touch"]]
    return [n for n, p in PLAN_PROGRAMS.items() if p == program]


def _kind_words(kinds: Sequence[str], last: str = "and") -> str:
    return ", ".join(kinds[:-1]) + f" {last} " + kinds[-1] if len(kinds) > 1 else "".join(kinds)


@dataclass(frozen=True)
class Dialect:
    """How one controller writes a probing cycle (``fivecal export program
    --dialect``): its comments, modal words, tool-centre-point switch, the
    probing move and how the probed position reaches a log file. Each log
    line is 'x y z a b c u v w' as LinuxCNC's ``PROBEOPEN`` writes it (the
    rotary values are the program's own commands), so
    :func:`fivecal.io.linuxcnc.read_probe_log` reads every dialect's log.
    ``sources``: where each word's syntax comes from (public manuals)."""

    name: str
    title: str
    comment: Callable[[str], str]
    declare: Tuple[str, ...]          # lines before any statement (Siemens DEF)
    preamble: str
    tcp_on: str                       # default tool-centre-point switch ("" none)
    tcp_off: str
    open_log: Callable[[str], List[str]]
    probe: Callable[[str, float], str]
    record: Callable[[str, Sequence[float]], List[str]]
    close_log: Callable[[str], List[str]]
    dwell: Callable[[float], str]
    end: str
    notes: Tuple[str, ...] = ()
    sources: Tuple[str, ...] = ()


def _paren(text: str) -> str:
    return f"({text})"


def _semi(text: str) -> str:
    return f"; {text}"


def _rest(rot: Sequence[float]) -> str:
    return " ".join(_f(v) for v in rot) + " 0 0 0"


#: the dialects of :func:`sphere_program` / :func:`touch_program`, by name
DIALECTS: Dict[str, Dialect] = {d.name: d for d in (
    Dialect("linuxcnc", "LinuxCNC 2.9", _paren, (), "G21 G90 G94 G17 G40 G49 G54 G61", "M428", "",
            lambda log: [f"(PROBEOPEN {log})"], lambda xyz, feed: f"G38.2 {xyz} F{feed:g}", lambda log, rot: [],
            lambda log: ["(PROBECLOSE)"], lambda t: f"G4 P{t:g}", "M2",
            sources=("LinuxCNC G-code reference: G38.2, PROBEOPEN / PROBECLOSE, G4 P seconds",)),
    Dialect("siemens", "Siemens SINUMERIK 840D sl / ONE", _semi, ("DEF INT FCERR",), "G71 G90 G94 G17 G40",
            "TRAORI", "TRAFOOF", lambda log: [],
            lambda xyz, feed: f"MEAS=1 G01 {xyz} F{feed:g}",
            lambda log, rot: [f'WRITE(FCERR, "{log}", $AA_MW[X] << " " << $AA_MW[Y] << " " << $AA_MW[Z] << '
                              f'" {_rest(rot)}")'],
            lambda log: [], lambda t: f"G4 F{t:g}", "M30",
            notes=("MEAS=1: measuring with deletion of distance-to-go, probe 1, rising edge; $AA_MW[axis]: the "
                   "measured position in workpiece coordinates of the axes programmed in the MEAS block; WRITE "
                   "appends one line to the file",),
            sources=("SINUMERIK 840D sl programming manual job planning 03/2006 (6FC5398-2BP10-1BA0) section 5.7 "
                     "Measurements with touch trigger probe (MEAS, MEAW), p. 5-24 (via easymanua.ls)",
                     "SINUMERIK ONE programming manual job planning, WRITE(<error>, <file name>, <block/data>), "
                     "p. 566 (via easymanua.ls)")),
    Dialect("fanuc", "Fanuc Series 30i / 31i", _paren, (), "G21 G90 G94 G17 G40 G49 G54", "G43.4 H1", "G49",
            lambda log: ["POPEN"], lambda xyz, feed: f"G31 {xyz} F{feed:g}",
            lambda log, rot: [f"#1={_f(rot[0])}", f"#2={_f(rot[1])}", f"#3={_f(rot[2])}",
                              "DPRNT[#5061[44]*#5062[44]*#5063[44]*#1[44]*#2[44]*#3[44]*0*0*0]"],
            lambda log: ["PCLOS"], lambda t: f"G04 X{t:g}", "M30",
            notes=("G31: skip function, the move ends at the probe's signal; #5061-#5063: the skip position of "
                   "axes 1-3 (workpiece coordinates); DPRNT prints them to the device POPEN opened ('*' a "
                   "space, [44] four digits before and after the point); G43.4: tool centre point control "
                   "type 1 with tool offset H1 (give --tcp-on for another)",),
            sources=("Fanuc Series 15i/150i-MA programming manual, skip function G31 and #5061-#5080, p. 564 "
                     "(via cncmanuals.com)",
                     "Fanuc Series 30i/300i/300is-Model A descriptions B-63942EN/02, appendix B, G43.4 "
                     "p. 411 (via cncmanuals.com)",
                     "custom macro B: DPRNT / POPEN / PCLOS (cncci.com; NCT 2000M manual p. 193)")),
    Dialect("heidenhain", "Heidenhain TNC (no public probing move found: ISO G-code)", _paren, (),
            "G21 G90 G94 G17 G40 G49 G54 G61", "", "",
            lambda log: [f"(PROBEOPEN {log})"], lambda xyz, feed: f"G38.2 {xyz} F{feed:g}", lambda log, rot: [],
            lambda log: ["(PROBECLOSE)"], lambda t: f"G4 P{t:g}", "M2",
            notes=("Heidenhain TNC: no public source found here gives the syntax of a touch probe move in an "
                   "arbitrary 3-D direction with its touch point written to a file; this program is ISO "
                   "G-code with G38.2 probing moves: replace each G38.2 with your TNC's touch probe cycle "
                   "(the TNC keeps the touch point, stylus not compensated, in Q115-Q117) and switch on "
                   "tool centre point (TCPM) as your machine does",),
            sources=("TNC 640 user's manual DIN/ISO programming 34059x-05 (1/2015) section 9.11 Preassigned Q "
                     "parameters, coordinates after probing Q115-Q119, p. 341 (via manualsdir.com)",)),
    Dialect("beckhoff", "Beckhoff TwinCAT 3 CNC (ISG kernel)", _semi, (), "G90 G17 G40", "#TRAFO ON", "#TRAFO OFF",
            lambda log: [f'#FILE NAME [MSG="{log}"]', "#MEAS [TYPE=1]"],
            lambda xyz, feed: f"G100 {xyz} F{feed:g}",
            lambda log, rot: [f'#MSG SAVE ["%f %f %f {_rest(rot)}", V.A.MEAS.PCS.VALUE.X, '
                              "V.A.MEAS.PCS.VALUE.Y, V.A.MEAS.PCS.VALUE.Z]"],
            lambda log: [], lambda t: f"#TIME {t:g}", "M30",
            notes=("G100: measuring run (type 1: any axes, feed by F), V.A.MEAS.PCS.VALUE.<axis>: the measured "
                   "position in program coordinates; #MSG SAVE appends it to the file #FILE NAME [MSG=...] "
                   "names; the axes must be measuring axes (P-AXIS-00118)",),
            sources=("Beckhoff TF5200 programming manual: measuring functions and #MEAS [TYPE=..] "
                     "(infosys.beckhoff.com tf5200_programming_manual 206164491, 207092107), G100 "
                     "(tccncprogramming 15556655755)",
                     "TF5200 measurement: V.A.MEAS.PCS.VALUE (tf5200_measurement 342045451); #FILE NAME / "
                     "#MSG SAVE (tf5225_tc3_cnc_cycles_measurement 312235147); #TRAFO ON (tf5200_programming_manual "
                     "208436363); #TIME (206132747)")),
)}


def dialect(name: str) -> Dialect:
    """The dialect ``name`` (ValueError naming the ones there are)."""
    if name not in DIALECTS:
        raise ValueError(f"dialect: '{name}' (expected one of {', '.join(DIALECTS)})")
    return DIALECTS[name]


def touches_a_sphere(plan: Sequence[Mapping]) -> bool:
    """Whether a plan touches a target of the sphere cycle's kinds (its
    probing cycle keeps out of those solids)."""
    return any(PLAN_PROGRAMS.get(e.get("type")) == TOUCH_PROGRAMS[1] for e in plan)


def _f(v: float) -> str:
    s = f"{v:.6f}"
    return "0.000000" if float(s) == 0.0 else s


def touch_cycle(plan: Sequence[Mapping], artefact: Mapping) -> bool:
    """Whether a probing plan runs as :func:`touch_program` (any probe
    touch; the moves keep out of the artefact's balls) rather than as
    :func:`fivecal.io.linuxcnc.probing_program` (touches of facets, no solid
    modelled): it touches anything but facets, or the artefact has balls
    (a scale bar beside the facets, as in TANGO)."""
    plane = L._plane_touch()
    balls = any((artefact or {}).get(NC_KINDS[k]["target_list"]) for k in program_kinds(TOUCH_PROGRAMS[1]))
    return balls or any(e.get("type") != plane for e in plan)


def _setup(machine: Machine, artefact: Mapping, tip_radius: float):
    """The core's dataset of a plan's machine, artefact and stylus (no
    observations): what the kinds answer the writers' questions from."""
    # the targets' geometry only: a scale bar's length moves no stylus (and may name balls left out)
    art = {k: v for k, v in (artefact or {}).items() if k != "scale_bars"}
    d = {"machine": machine.to_dict(), "probe": {"tip_radius": float(tip_radius)}, "artefact": art,
         "observations": []}
    return _core.Dataset.from_json(_json.dumps(d, "dataset"), False)


@dataclass(frozen=True)
class Touch:
    """A planned touch as the program runs it (its kind's contact geometry,
    ``_core.planned_touch_contacts``): the nominal contact point on the
    surface and the outward normal there (workpiece frame), and the radius
    of the ball around its target the moves keep out of (0: none)."""

    point: np.ndarray
    normal: np.ndarray
    clearance: float


def _touches(machine: Machine, plan: Sequence[Mapping], artefact: Mapping, tip_radius: float, cycle: str,
             setup=None) -> List[Touch]:
    """The touches of ``plan`` for the ``cycle`` program (``sphere`` or
    ``probing``), each entry's kind answering for its target; ValueError
    naming the entry of another type or with a target the artefact lacks."""
    runs = program_kinds(cycle)
    for i, t in enumerate(plan):
        kind = t.get("type")
        if kind not in runs:
            raise ValueError(f"plan[{i}]: type '{kind}': a {cycle} cycle runs {_kind_words(runs)} touches")
        where = NC_KINDS[kind]["target_list"]
        targets = {x.get("id") for x in (artefact or {}).get(where) or []}
        if not targets:
            raise ValueError(f"artefact: no {where} (a {kind} touch needs its target's geometry)")
        if t.get("target") not in targets:
            raise ValueError(f"plan[{i}]: target '{t.get('target')}' is not a {kind} of the artefact")
    setup = setup if setup is not None else _setup(machine, artefact, tip_radius)
    return [Touch(np.asarray(c[0], float), np.asarray(c[1], float), float(c[2]))
            for c in _core.planned_touch_contacts(setup, _json.dumps([dict(t) for t in plan], "plan"))]


def _geometry(machine, kins, plan, artefact, tip_radius, workpiece_shift=(0.0, 0.0, 0.0), cycle="probing",
              touches=None):
    """Per touch (joint tilt, joint C, stylus-centre world point, normal,
    tool axis): each touch as one of the plane tangent to its target at the
    contact point, the plane probing geometry of fivecal.io.linuxcnc."""
    if touches is None:
        touches = _touches(machine, plan, artefact, tip_radius, cycle)
    plane = L._plane_touch()
    fplan = [{"type": plane, "target": f"#{i + 1}", "axes": t.get("axes", {})} for i, t in enumerate(plan)]
    planes = [{"id": f"#{i + 1}", "point": c.point.tolist(), "normal": c.normal.tolist()}
              for i, c in enumerate(touches)]
    return L._touch_geometry(machine, kins, fplan, {"facets": planes}, tip_radius, workpiece_shift)


def _joint_directions(machine: Machine, kins: str, plan: Sequence[Mapping]):
    """Per touch, the planned approach direction (+1/-1/0) of the tilt and C
    joints: fivecal's ``direction`` times the joint's sign."""
    k = L._kins(kins)
    mp = L.match(machine, k)
    tilt = L.TILT[k]
    out = []
    for t in plan:
        d = t.get("direction", {}) or {}
        out.append((int(np.sign(d.get(tilt, 0))) * int(mp["sign"][3]),
                    int(np.sign(d.get("C", 0))) * int(mp["sign"][4])))
    return out


def _lift(touch: Touch, tip_radius: float, retract: float, safe: float) -> float:
    """How far along the tool axis the move to or from this touch's retract
    point is lifted between two touches of one rotary position: over a ball
    target by its stylus-centre radius, else to the safe height."""
    if touch.clearance > 0:
        return touch.clearance + tip_radius + retract
    return safe


def _segment_gap(a: np.ndarray, b: np.ndarray, centre: np.ndarray) -> float:
    """Distance of ``centre`` from the segment a-b."""
    d = b - a
    dd = float(d @ d)
    s = 0.0 if dd == 0 else min(1.0, max(0.0, float((centre - a) @ d) / dd))
    return float(np.linalg.norm(a + s * d - centre))


def _clear_lift(a, va, b, vb, lift, balls, touch: int, step: float = 5.0, extra: float = 500.0) -> float:
    """The smallest lift >= ``lift`` (in ``step`` mm) for which the moves
    a -> a + lift va -> b + lift vb -> b (up from one retract point along its
    tool axis, across, down to the next; ``a`` or ``b`` None: that end only)
    keep out of every ball (world centre, stylus-centre radius plus clearance).
    A lift along the tool axis cannot go round a sphere: a sphere in its way
    is refused, naming the touch."""
    ends = [(p, v) for p, v in ((a, va), (b, vb)) if p is not None]
    k = 0
    while k * step <= extra:
        h = lift + k * step
        for name, c, r in balls:
            if any(_segment_gap(p, p + h * v, c) <= r for p, v in ends):
                raise ValueError(f"touch {touch}: the tool-axis move to or from its retract point passes "
                                 f"through sphere {name} (lifted {h:g} mm); the cycle cannot reach this touch "
                                 "from above (change the plan, --safe or the artefact's sphere)")
        if len(ends) < 2 or all(_segment_gap(a + h * va, b + h * vb, c) > r for _, c, r in balls):
            return h
        k += 1
    raise ValueError(f"touch {touch}: no lift up to {lift + extra:g} mm along the tool axis clears the spheres "
                     "between this touch and the one before (raise --safe or change the plan)")


def sphere_program(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                   tip_radius: float, clearance: float = 1.0, overtravel: float = 1.0,
                   feed: float = 60.0, retract: float = 5.0, safe: float = 100.0,
                   overshoot: float = 1.0, dwell: float = 0.0, arm: str = "", disarm: str = "",
                   sync: str = "", log: str = "probe-log.txt", tcp_on: Optional[str] = None,
                   workpiece_shift=(0.0, 0.0, 0.0),
                   before_probe: Optional[Sequence[Sequence[str]]] = None, dialect: str = "linuxcnc") -> str:
    """An ISO G-code program for LinuxCNC running the sphere touches of
    ``plan`` (``{"type": "sphere", "target": id, "axes": {tilt, C},
    "normal": [...], "direction": {...}}``) on ``artefact["spheres"]``.

    Per rotary position: up to ``safe`` mm along the tool axis above the
    first touch's retract point, index the rotary axes there. When the plan
    asks for a position to be reached from one side (``direction``, for the
    reversal error) and the previous position does not already lie on that
    side, the axis first goes ``overshoot`` degrees beyond it (``overshoot
    0``: no pre-positioning). ``dwell`` s (G4) after each indexing.
    Per touch: G0 to ``retract`` mm and then ``clearance`` mm off the contact
    point along the touch direction (the sphere's normal there), ``G38.2``
    to ``overtravel`` mm inside at ``feed`` mm/min, back to the start and
    retract points. Between touches of one position the stylus goes from one
    retract point to the next lifted along the tool axis by the sphere's
    radius plus the stylus radius plus ``retract``, so the straight move does
    not cut across the sphere (for touches at or above its equator as seen
    from the spindle; any lift is raised until its moves keep ``clearance``
    off every sphere of the artefact, as in :func:`touch_program`; check the
    moves against your fixtures). ``sync``, ``arm``,
    ``disarm``, ``before_probe``, ``log`` and ``tcp_on`` as in
    :func:`fivecal.io.linuxcnc.probing_program`. ``dialect`` (:data:`DIALECTS`):
    the same cycle in another controller's words (its probing move, log
    and tool-centre-point switch; ``tcp_on`` None: the dialect's); the
    coordinates stay those of ``kins`` (workpiece point − tool tip at the
    zero pose: set the work offset so)."""
    return _touch_program(machine, kins, plan, artefact, tip_radius, TOUCH_PROGRAMS[1], clearance, overtravel,
                          feed, retract, safe, overshoot, dwell, arm, disarm, sync, log, tcp_on,
                          workpiece_shift, before_probe, dialect)


def touch_program(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                  tip_radius: float, clearance: float = 1.0, overtravel: float = 1.0,
                  feed: float = 60.0, retract: float = 5.0, safe: float = 100.0,
                  overshoot: float = 1.0, dwell: float = 0.0, arm: str = "", disarm: str = "",
                  sync: str = "", log: str = "probe-log.txt", tcp_on: Optional[str] = None,
                  workpiece_shift=(0.0, 0.0, 0.0),
                  before_probe: Optional[Sequence[Sequence[str]]] = None, dialect: str = "linuxcnc") -> str:
    """One ``G38.2`` program for a plan that mixes facet touches
    (``{"type": "facet", "target": id, "axes": {...}, "point": [...]}``) and
    sphere touches (as in :func:`sphere_program`), in the plan's order, as
    ``fivecal design`` and :func:`fivecal.procedures.tango.hu40t_plan` write
    them. Indexing, ``overshoot``, ``dwell`` and each touch run as in
    :func:`sphere_program`; a facet touch approaches along the facet normal
    to its contact point (its ``point`` plus the stylus radius along the
    normal). Between two touches of one rotary position the stylus moves from
    one retract point to the next lifted along the tool axis: by ``safe`` mm
    when either touch is on a facet (as :func:`fivecal.io.linuxcnc.probing_program`
    does), otherwise by the sphere's radius plus the stylus radius plus
    ``retract`` (over the sphere); any lift, and the lift out of a position
    before indexing, is raised in 5 mm steps until the straight moves keep
    ``clearance`` off every sphere of the artefact, touched or not (a sphere
    over a retract point is refused, naming the touch). Other solids are not
    modelled: check the moves against your fixtures. The log reads back
    with :func:`fivecal.io.linuxcnc.read_probe_log` into facet and sphere
    observations in plan order."""
    return _touch_program(machine, kins, plan, artefact, tip_radius, TOUCH_PROGRAMS[0], clearance,
                          overtravel, feed, retract, safe, overshoot, dwell, arm, disarm, sync, log, tcp_on,
                          workpiece_shift, before_probe, dialect)


def _touch_program(machine, kins, plan, artefact, tip_radius, cycle, clearance, overtravel, feed, retract,
                   safe, overshoot, dwell, arm, disarm, sync, log, tcp_on, workpiece_shift, before_probe,
                   dialect_name="linuxcnc"):
    d = dialect(dialect_name)
    tcp_on = d.tcp_on if tcp_on is None else tcp_on
    if d.name in ("siemens", "beckhoff") and '"' in str(log):
        raise O.OptionError("log", f"{log!r}: the file name is written inside a quoted string")
    k = L._kins(kins)
    tilt = L.TILT[k]
    setup = _setup(machine, artefact, tip_radius)
    touches = _touches(machine, plan, artefact, tip_radius, cycle, setup)
    geo = _geometry(machine, k, plan, artefact, tip_radius, workpiece_shift, cycle, touches)
    if before_probe is not None and len(before_probe) != len(geo):
        raise ValueError(f"before_probe: {len(before_probe)} entries for {len(geo)} touches")
    O.check(tip_radius=tip_radius, clearance=clearance, overtravel=overtravel, feed=feed, retract=retract,
            safe=safe, overshoot=overshoot, dwell=dwell)
    O.check_probe_lines(log, arm, disarm, sync, tcp_on, before_probe)
    if retract < clearance:
        raise O.OptionError("retract", f"{retract} mm is less than the clearance {clearance} mm")
    touched = sorted((c.clearance, str(t["target"]), str(t["type"])) for t, c in zip(plan, touches) if c.clearance > 0)
    if touched:
        # past the radius the G38.2 of a probe that does not trip ends beyond the ball's centre
        O.at_most("overtravel", overtravel, touched[0][0], f"the radius of {touched[0][2]} {touched[0][1]}")
    dirs = _joint_directions(machine, k, plan)
    origin = np.asarray(L.match(machine, k)["origin"], float) + np.asarray(workpiece_shift, float)
    # every ball of the artefact stands in the way, touched in this plan or not
    balls = [(name, np.asarray(c, float) - origin, float(r) + tip_radius + clearance)
             for name, c, r in _core.clearance_balls(setup)]
    xyz = lambda p: f"X{_f(p[0])} Y{_f(p[1])} Z{_f(p[2])}"  # noqa: E731
    targets = sorted({str(t.get("target")) for t in plan})
    what = f"{cycle} cycle"
    c = d.comment
    out = [c(f"fivecal {what}: {len(geo)} touches on {O.comment_text(', '.join(targets))}, machine "
             f"{O.comment_text(machine.name)}, {k}-kins"),
           c("units mm and degrees; world coordinates = workpiece point - tool tip at the zero pose"),
           c(f"stylus ball radius {tip_radius:g} mm; touches approach and retract along the "
             f"{'sphere' if cycle == TOUCH_PROGRAMS[1] else 'surface'} normal")]
    if d.name != "linuxcnc":
        out += [c(f"dialect {d.name}: {O.comment_text(d.title)}"),
                *[c(O.comment_text(n)) for n in d.notes],
                *[c("source: " + O.comment_text(src)) for src in d.sources],
                c("log lines: x y z a b c u v w as LinuxCNC's PROBEOPEN writes them; "
                  "fivecal.io.linuxcnc.read_probe_log reads them")]
    out += list(d.declare)
    out.append(d.preamble)
    if tcp_on:
        out.append(f"{tcp_on} {c('tool centre point kinematics on')}")
    out += d.open_log(log)
    last_rot = None   # (tilt, C) joint values the table stands at
    last_dir = None
    hold = v_prev = None  # the retract point and tool axis of the previous touch
    for i, (t, cc, w, n, v) in enumerate(geo):
        start, end = w + clearance * n, w - overtravel * n
        off = w + retract * n
        rot = (t, cc)
        out.append(c(f"touch {i + 1}: {O.comment_text(plan[i]['target'])} direction {' '.join(_f(x) for x in n)}"))
        if rot != last_rot or dirs[i] != last_dir:
            lift = _clear_lift(hold, v_prev, off, v, safe, balls, i + 1)
            up = off + lift * v
            if hold is not None:
                out.append(f"G0 {xyz(hold + lift * v_prev)}")
            side = ["+-"[d < 0] if d else "." for d in dirs[i]]
            out.append(c(f"position {tilt} {_f(t)} C {_f(cc)}, approached {side[0]}{tilt} {side[1]}C"))
            if overshoot > 0 and any(dirs[i]):
                pre = []
                for val, dd, prev in ((t, dirs[i][0], None if last_rot is None else last_rot[0]),
                                      (cc, dirs[i][1], None if last_rot is None else last_rot[1])):
                    # the move into the position already comes from the planned side
                    ok = dd == 0 or (prev is not None and (val - prev) * dd > 1e-9)
                    pre.append(val if ok else val - dd * overshoot)
                if tuple(pre) != rot:
                    out.append(f"G0 {xyz(up)} {tilt}{_f(pre[0])} C{_f(pre[1])} {c('overshoot')}")
            out.append(f"G0 {xyz(up)} {tilt}{_f(t)} C{_f(cc)}")
            if dwell > 0:
                out.append(d.dwell(dwell))
            last_rot, last_dir = rot, dirs[i]
            out.append(f"G0 {xyz(off)}")
        else:
            # to the next touch of this position: both retract points lifted
            # along the tool axis, over a sphere by its stylus-centre radius
            # (the straight move between them stays outside it), to the safe
            # height when a facet is involved (its solid can be anywhere below)
            lift = max(_lift(touches[i - 1], tip_radius, retract, safe), _lift(touches[i], tip_radius, retract, safe))
            lift = _clear_lift(hold, v, off, v, lift, balls, i + 1)
            out += [f"G0 {xyz(hold + lift * v)}", f"G0 {xyz(off + lift * v)}", f"G0 {xyz(off)}"]
        out.append(f"G0 {xyz(start)}")
        out += [sync] if sync else []
        out += list(before_probe[i]) if before_probe is not None else []
        out += [arm] if arm else []
        out.append(d.probe(xyz(end), feed))
        out += d.record(log, (t, 0.0, cc) if tilt == "A" else (0.0, t, cc))
        out += [disarm] if disarm else []
        out += [f"G0 {xyz(start)}", f"G0 {xyz(off)}"]
        hold, v_prev = off, v
    if hold is not None:
        out.append(f"G0 {xyz(hold + _clear_lift(hold, v_prev, None, None, safe, balls, len(geo)) * v_prev)}")
    out += d.close_log(log)
    out += [d.tcp_off] if tcp_on and d.tcp_off else []
    out.append(d.end)
    return O.check_positions("\n".join(out) + "\n", what)


def sphere_trigger_model(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                         tip_radius: float, pins: Mapping[str, float], errors=None,
                         clearance: float = 1.0, overtravel: float = 1.0,
                         workpiece_shift=(0.0, 0.0, 0.0)) -> List[dict]:
    """Per touch of :func:`sphere_program` (same ``clearance`` and
    ``overtravel``): where the probe move, run by a controller with ``pins``
    on the machine with ``errors``, first puts the stylus ball on the sphere.
    ``world``: that position in program coordinates (what a perfect probe
    logs); ``g``, ``h``: the plane tangent to the sphere there in the linear
    joints (g . joint XYZ + h < 0 inside), for the simulated probe. At fixed
    rotary joints the ball centre is affine in the linear joints and the
    G38.2 runs a straight joint line, so the crossing is exact (location
    errors)."""
    return _trigger_model(machine, kins, plan, artefact, tip_radius, pins, errors, clearance, overtravel,
                          workpiece_shift, TOUCH_PROGRAMS[1])


def touch_trigger_model(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                        tip_radius: float, pins: Mapping[str, float], errors=None,
                        clearance: float = 1.0, overtravel: float = 1.0,
                        workpiece_shift=(0.0, 0.0, 0.0)) -> List[dict]:
    """:func:`sphere_trigger_model` for the facet and sphere touches of
    :func:`touch_program`: a facet touch trips where the stylus ball reaches
    the facet's plane (``g``, ``h``: that plane in the linear joints)."""
    return _trigger_model(machine, kins, plan, artefact, tip_radius, pins, errors, clearance, overtravel,
                          workpiece_shift, TOUCH_PROGRAMS[0])


def _trigger_model(machine, kins, plan, artefact, tip_radius, pins, errors, clearance, overtravel,
                   workpiece_shift, cycle):
    k = L._kins(kins)
    O.check(tip_radius=tip_radius, clearance=clearance, overtravel=overtravel)
    setup = _setup(machine, artefact, tip_radius)
    touches = _touches(machine, plan, artefact, tip_radius, cycle, setup)
    geo = _geometry(machine, k, plan, artefact, tip_radius, workpiece_shift, cycle, touches)
    out = []
    for i, (t, c, w, n, _) in enumerate(geo):
        ws, we = w + clearance * n, w - overtravel * n
        js = L.inverse(k, pins, np.array([[*ws, t, c], [*we, t, c]]))
        jj = np.array([js[0], js[1], [0, 0, 0, t, c], [1, 0, 0, t, c], [0, 1, 0, t, c], [0, 0, 1, t, c]], float)
        # the side each rotary axis came from, for a reversal error in ``errors``
        dirs = {a: np.full(len(jj), float(v)) for a, v in (plan[i].get("direction") or {}).items()}
        p = machine.tool_point(L.commands(machine, k, jj), errors=errors, directions=dirs or None)
        ps, d = p[0], p[1] - p[0]
        # where the stylus centre first reaches the target (its kind's exact crossing)
        inside, sc, nc = _core.probe_line_crossing(setup, str(plan[i]["type"]), str(plan[i]["target"]), ps, d)
        nc = np.asarray(nc, float)
        q = ps + sc * d if np.isfinite(sc) else ps
        what = f"{plan[i]['type']} {plan[i]['target']}"
        if inside:
            raise ValueError(f"touch {i + 1}: the stylus is already on or in {what} at the "
                             f"start of the probe move (clearance {clearance} mm too small for the errors)")
        if sc > 1:
            raise ValueError(f"touch {i + 1}: the probe move misses {what} on this machine "
                             f"(overtravel {overtravel} mm too small for the errors)")
        M = (p[3:] - p[2]).T
        out.append({"world": (ws + sc * (we - ws)).tolist(), "rot": [t, c],
                    "joints": (js[0] + sc * (js[1] - js[0])).tolist(),
                    "g": (nc @ M).tolist(), "h": float(nc @ (p[2] - q))})
    return out


def sphere_sim_lines(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                     tip_radius: float, pins: Mapping[str, float], errors=None, clearance: float = 1.0,
                     overtravel: float = 1.0, workpiece_shift=(0.0, 0.0, 0.0)) -> List[List[str]]:
    """Per touch, the ``M68`` lines that load the simulated probe
    (:func:`fivecal.io.linuxcnc.probe_sim_hal`) with the plane tangent to the
    sphere where that touch meets it on the machine with ``errors``
    (``sphere_program(..., before_probe=..., sync="M66 E0 L0", arm="M64 P0",
    disarm="M65 P0")``)."""
    model = sphere_trigger_model(machine, kins, plan, artefact, tip_radius, pins, errors, clearance,
                                 overtravel, workpiece_shift)
    return _sim_lines(model)


def touch_sim_lines(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping,
                    tip_radius: float, pins: Mapping[str, float], errors=None, clearance: float = 1.0,
                    overtravel: float = 1.0, workpiece_shift=(0.0, 0.0, 0.0)) -> List[List[str]]:
    """:func:`sphere_sim_lines` for :func:`touch_program` (facet and sphere
    touches)."""
    return _sim_lines(touch_trigger_model(machine, kins, plan, artefact, tip_radius, pins, errors, clearance,
                                          overtravel, workpiece_shift))


def _sim_lines(model) -> List[List[str]]:
    return [[f"M68 E{e} Q{v:.12f}" for e, v in enumerate((*m["g"], -m["h"]), 4)] for m in model]


def sphere_log(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping, tip_radius: float,
               pins: Mapping[str, float], errors=None, clearance: float = 1.0, overtravel: float = 1.0,
               workpiece_shift=(0.0, 0.0, 0.0)) -> str:
    """The probe log (LinuxCNC's ``PROBEOPEN`` format, 'x y z a b c u v w')
    a perfect probe writes running :func:`sphere_program` on the machine with
    ``errors``: fivecal's own model of the trigger positions, for checking a
    program without a controller."""
    return _log(kins, sphere_trigger_model(machine, kins, plan, artefact, tip_radius, pins, errors, clearance,
                                           overtravel, workpiece_shift))


def touch_log(machine: Machine, kins: str, plan: Sequence[Mapping], artefact: Mapping, tip_radius: float,
              pins: Mapping[str, float], errors=None, clearance: float = 1.0, overtravel: float = 1.0,
              workpiece_shift=(0.0, 0.0, 0.0)) -> str:
    """:func:`sphere_log` for :func:`touch_program` (facet and sphere touches)."""
    return _log(kins, touch_trigger_model(machine, kins, plan, artefact, tip_radius, pins, errors, clearance,
                                          overtravel, workpiece_shift))


def _log(kins: str, model) -> str:
    ti = 3 if L.TILT[L._kins(kins)] == "A" else 4
    rows = []
    for m in model:
        r = [*m["world"], 0.0, 0.0, m["rot"][1], 0.0, 0.0, 0.0]
        r[ti] = m["rot"][0]
        rows.append(" ".join(f"{x:.6f}" for x in r))
    return "\n".join(rows) + "\n"


def _rtest_setups(plan: Sequence[Mapping]) -> Dict[str, List[Mapping]]:
    out: Dict[str, List[Mapping]] = {}
    runs = _kind_words(program_kinds("rtest"), "or")
    for i, p in enumerate(plan):
        if PLAN_PROGRAMS.get(p.get("type")) != "rtest":
            raise ValueError(f"plan[{i}]: type '{p.get('type')}': an R-test program needs {runs} entries")
        out.setdefault(str(p.get("setup", "")), []).append(p)
    if not out:
        raise ValueError(f"plan: no {runs} entries")
    return out


def _full(machine: Machine, axes: Mapping) -> Dict[str, float]:
    return {a: float(axes.get(a, 0.0)) for a in machine.axis_names if a != "S"}


def rtest_points(machine: Machine, entries: Sequence[Mapping], subdivide: int = 0) -> List[dict]:
    """The commanded points of one R-test setup: the plan's samples
    (``sample``: its index) and, with ``subdivide`` = n, n points between two
    samples with the rotary commands interpolated and the linear ones from
    the nominal inverse kinematics (the ball stays in the nest there too)."""
    O.check(subdivide=subdivide)
    rot = [a for a in machine.axis_names if machine.is_rotary(a) and a != "S"]
    names = list(machine.axis_names)
    pts = []
    for i, e in enumerate(entries):
        q = _full(machine, e["axes"])
        if i and subdivide:
            q0 = pts[-1]["axes"]
            fractions = np.arange(1, subdivide + 1) / (subdivide + 1)
            steps = [{a: q0[a] + s * (q[a] - q0[a]) for a in rot} for s in fractions]
            rotary = np.array([[r.get(a, 0.0) for a in names] for r in steps])
            start = np.array([q0.get(a, 0.0) for a in names])
            # the linear axes that keep the ball in the nest there (the core's RTestPathCommands)
            lin = np.asarray(_core.rtest_path_commands(machine._core, rotary, start, np.asarray(e["table_ball"], float),
                                                       np.asarray(e["tool_ball"], float), False))
            for r, row in zip(steps, lin):
                pts.append({"axes": {**{a: float(v) for a, v in zip(names, row) if a != "S"}, **r}, "sample": None})
        pts.append({"axes": q, "sample": i, "id": e.get("id")})
    return pts


def rtest_program(machine: Machine, plan: Sequence[Mapping], mode: str = "axes", kins: Optional[str] = None,
                  pins: Optional[Mapping[str, float]] = None, feed: float = 500.0, dwell: float = 1.0,
                  subdivide: int = 0, tcp_on: str = "M428", tcp_off: str = "M429") -> str:
    """ISO G-code of the R-test setups of ``plan``
    (:func:`fivecal.procedures.rtest.plan`): per setup, ``G0`` to the first
    sample, then ``G1`` from sample to sample at ``feed`` with a ``G4 P<dwell>``
    at each (the nest is read during the dwell; the samples are numbered in
    the comments as the plan's ids, so a reading per dwell lines up with the
    plan's entries). ``subdivide``: intermediate points per step
    (:func:`rtest_points`).

    ``mode="axes"``: the words are axis commands from fivecal's nominal
    inverse kinematics (the plan's own axes), as fivecal's machine file names
    the axes; with ``kins`` (``xyzac-trt`` / ``xyzbc-trt``) they are
    LinuxCNC's joint values (signs and origin of that kinematics), to run with
    its identity kinematics (``tcp_off``, ``M429`` in the sample configs).
    ``mode="tcp"`` (needs ``kins``): world coordinates of the tool tip for
    LinuxCNC's tool-centre-point kinematics (``tcp_on``) with ``pins``
    (default the machine's nominal pins); the controller keeps the tool point
    still between the samples itself. In this mode the rotary moves are
    straight lines in the rotary joints and the tool tip's world point, so
    ``subdivide`` is not needed; ``feed`` is then the speed of the (nearly
    still) tool point and LinuxCNC limits the rotary axes by their own
    maximum speeds: use ``G93`` or a lower rotary speed on a real machine.

    There is no workpiece shift here: the path is fixed by the plan's joint
    values, and a work offset does not move the balls relative to the axes."""
    if mode not in ("axes", "tcp"):
        raise ValueError(f"mode: expected 'axes' or 'tcp', got {mode!r}")
    if mode == "tcp" and not kins:
        raise ValueError("mode 'tcp': give kins (xyzac-trt or xyzbc-trt), the kinematics whose "
                         "tool-centre-point function runs the path")
    O.check(feed=feed, dwell=dwell, subdivide=subdivide)
    O.check_line("tcp_on", tcp_on)
    O.check_line("tcp_off", tcp_off)
    k = L._kins(kins) if kins else None
    if k and pins is None:
        pins = L.nominal_pins(machine, k)
    letters = [a for a in machine.axis_names if a != "S"]
    head = (f"(fivecal R-test program, machine {O.comment_text(machine.name)}: "
            + ("axis commands from the nominal inverse kinematics" if mode == "axes" and not k else
               f"LinuxCNC {k}-kins joint values, identity kinematics" if mode == "axes" else
               f"world coordinates, {k}-kins tool centre point on") + ")")
    out = [head, "(a G4 dwell at each planned sample: read the nest there, one reading per sample)",
           "G21 G90 G94 G17 G40 G49 G54 G61"]
    if k and mode == "tcp" and tcp_on:
        out.append(f"{tcp_on} (tool centre point kinematics on)")
    if k and mode == "axes" and tcp_off:
        out.append(f"{tcp_off} (identity kinematics: words are joint values)")
    if k:
        tilt = L.TILT[k]
        names = ["X", "Y", "Z", tilt, "C"]

    def words(q: Mapping[str, float]) -> str:
        if not k:
            return " ".join(f"{a}{_f(q[a])}" for a in letters)
        j = L.joints(machine, k, {a: np.array([q.get(a, 0.0)]) for a in machine.axis_names})[0]
        if mode == "axes":
            return " ".join(f"{a}{_f(v)}" for a, v in zip(names, j))
        wxyz = L.forward(k, pins, j[None, :])[0]
        return " ".join(f"{a}{_f(v)}" for a, v in zip(names, [*wxyz, j[3], j[4]]))

    for setup, entries in _rtest_setups(plan).items():
        pts = rtest_points(machine, entries, 0 if mode == "tcp" else subdivide)
        out.append(f"(setup {O.comment_text(setup)}: {len(entries)} samples, table ball "
                   f"{' '.join(_f(x) for x in entries[0]['table_ball'])}, tool ball "
                   f"{' '.join(_f(x) for x in entries[0]['tool_ball'])})")
        for n, p in enumerate(pts):
            g = "G0" if n == 0 else "G1"
            fw = f" F{feed:g}" if n == 1 else ""
            out.append(f"{g} {words(p['axes'])}{fw}")
            if p["sample"] is not None:
                out.append(f"G4 P{dwell:g} (sample {p['sample'] + 1}: {O.comment_text(p.get('id') or '')})")
    out.append("M2")
    return O.check_positions("\n".join(out) + "\n", "R-test program")
