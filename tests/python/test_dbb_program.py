"""Ball bar programs (fivecal.io.dbb_program): read back with fivecal's G-code
tokenizer, the commanded arcs are the plan's circles (radius, centre, plane,
direction), with a radial feed-in and feed-out; in the LinuxCNC simulator the
commanded joints run on that circle."""
import math

import numpy as np
import pytest

import fivecal
from fivecal import gcode
from fivecal.io.dbb_program import dbb_program
from fivecal.procedures.dbb import planar_plan

import linuxcnc_harness as harness
from test_linuxcnc import MACHINES as LM

REASON = harness.unavailable_reason()


def _read(prog, letters):
    """Per arc/linear line: (G motion, plane, start, end, centre) in axis commands."""
    pos = {a: None for a in letters}
    plane, motion, out = None, None, []
    for ln, line in enumerate(gcode.split_lines(prog), 1):
        words = gcode.tokenize(line.rstrip("\n"), "prog", ln)
        for g in gcode.g_codes(words):
            if g in (17.0, 18.0, 19.0):
                plane = g
            if g in (0.0, 1.0, 2.0, 3.0):
                motion = g
        ax = {w.letter: w.value for w in words if w.letter in letters}
        off = {w.letter: w.value for w in words if w.letter in "IJK"}
        if ax:
            start = dict(pos)
            pos.update(ax)
            centre = None
            if motion in (2.0, 3.0):
                centre = dict(start)
                for L, a in zip("IJK", "XYZ"):
                    centre[a] = start[a] + off.get(L, 0.0)
            out.append((motion, plane, start, dict(pos), centre, line))
    return out


@pytest.mark.parametrize("machine,plane", [("examples/machines/hu40t.json", "XY"),
                                           ("examples/machines/c600u.json", "ZX"),
                                           ("examples/machines/vmc0656.json", "YZ")])
def test_program_arcs_are_the_plan_circles(machine, plane):
    m = fivecal.Machine.load(machine)
    centre_w = m.tip + np.array([20.0, -10.0, 5.0])
    plan = planar_plan(m, plane, radius=100.0, centre=centre_w, step=5.0)
    prog = dbb_program(m, plan, feed=800, feed_in=1.5)
    moves = _read(prog, [a for a in m.axis_names if a != "S"])
    arcs = [mv for mv in moves if mv[0] in (2.0, 3.0)]
    assert len(arcs) == 2  # P+ and P-
    assert {a[0] for a in arcs} == {2.0, 3.0}  # opposite directions
    gplane = {"XY": 17.0, "ZX": 18.0, "YZ": 19.0}[plane]
    for k, (g, pl, start, end, centre, line) in enumerate(arcs):
        setup = ["P+", "P-"][k]
        entries = [p for p in plan if p["setup"] == setup]
        assert pl == gplane
        assert all(abs(start[a] - end[a]) < 1e-9 for a in start)  # a full circle
        # the centre's and the start's tool points are the plan's (nominal machine)
        q = lambda d: {a: np.array([d.get(a, 0.0)]) for a in m.axis_names}  # noqa: E731
        assert np.abs(m.tool_point(q(centre))[0] - centre_w).max() < 1e-6
        assert np.abs(m.tool_point(q(start))[0] - m.tool_point(q(entries[0]["axes"]))[0]).max() < 1e-6
        r = math.dist([start[a] for a in "XYZ"], [centre[a] for a in "XYZ"])
        assert abs(r - 100.0) < 1e-6
        # direction: the plan's next point lies ahead along the commanded arc
        a1, a2 = {17.0: "XY", 18.0: "ZX", 19.0: "YZ"}[pl]
        v0 = np.array([start[a1] - centre[a1], start[a2] - centre[a2]])
        v1 = np.array([entries[1]["axes"][a1] - centre[a1], entries[1]["axes"][a2] - centre[a2]])
        ccw = v0[0] * v1[1] - v0[1] * v1[0] > 0
        assert (g == 3.0) == ccw
        # feed-in / feed-out: radial, 1.5 mm, G1 before and after the arc
        i = moves.index(arcs[k])
        fi, fo = moves[i - 1], moves[i + 1]
        assert fi[0] == 1.0 and "feed-in" in fi[5] and fo[0] == 1.0 and "feed-out" in fo[5]
        p_in = np.array([fi[2][a] for a in "XYZ"]) - np.array([centre[a] for a in "XYZ"])
        p_st = np.array([start[a] for a in "XYZ"]) - np.array([centre[a] for a in "XYZ"])
        assert abs(np.linalg.norm(p_in) - 98.5) < 1e-6
        assert np.linalg.norm(np.cross(p_in, p_st)) < 1e-6  # on the same radius
        assert all(abs(fo[3][a] - fi[2][a]) < 1e-9 for a in "XYZ")


def test_program_refuses_what_is_no_planar_circle():
    m = fivecal.Machine.load("examples/machines/hu40t.json")
    plan = planar_plan(m, "XY", radius=50.0, step=10.0)
    with pytest.raises(ValueError, match="feed_in"):
        dbb_program(m, plan, feed_in=60)
    plan[3]["axes"]["B"] = 5.0
    # a setup in which a rotary axis moves is a rotary-axis path, which this
    # one is not: the bar would not keep its length
    with pytest.raises(ValueError, match=r"setup P\+: at planned pose 4 .*not a constant-length path"):
        dbb_program(m, plan)
    with pytest.raises(ValueError, match="dbb entries"):
        dbb_program(m, [{"type": "facet"}])


@pytest.mark.skipif(REASON is not None, reason=f"needs LinuxCNC: {REASON}")
def test_program_runs_on_the_circle_in_linuxcnc():
    """The program runs in the simulator (identity kinematics, the sample
    config's start-up mode); the commanded joints sampled during each arc lie
    on the planned circle in its plane."""
    m = fivecal.Machine.from_dict(LM["xyzac-trt"])
    plan = planar_plan(m, "XY", radius=30.0, centre=m.tip + np.array([5.0, -4.0, -20.0]), step=10.0)
    prog = dbb_program(m, plan, feed=3000, feed_in=1.5)
    with harness.Sim("xyzac-trt", files={"dbb.ngc": prog}) as sim:
        out = sim.run([], setup=[], program="dbb.ngc", program_timeout=120, trace=True)
    assert out["errors"] == []
    moves = _read(prog, [a for a in m.axis_names if a != "S"])
    lines = prog.splitlines()
    n_on = 0
    for g, pl, start, end, centre, line in moves:
        if g not in (2.0, 3.0):
            continue
        no = lines.index(line.rstrip("\n")) + 1
        # the first sample may still be in the blend from the feed-in line
        # (LinuxCNC's default G64 path blending), the last in the one to the
        # feed-out: the circle is the arc in between
        pts = np.array([t[1:4] for t in out["trace"] if t[0] == no])[1:-1]
        c = np.array([centre[a] for a in "XYZ"])
        assert len(pts) > 10
        r = np.linalg.norm(pts[:, :2] - c[:2], axis=1)
        # (LinuxCNC's commanded arc runs 14 nm inside the radius)
        assert np.abs(r - 30.0).max() < 5e-5
        assert np.abs(pts[:, 2] - c[2]).max() < 1e-9
        n_on += len(pts)
    assert n_on > 20
