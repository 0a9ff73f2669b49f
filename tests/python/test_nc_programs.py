"""NC programs for the tests themselves (fivecal.io.nc_programs,
fivecal.io.dbb_program): the sphere cycle, the R-test paths and the ball bar
programs of rotary-axis paths, read back with fivecal's G-code tokenizer and
replayed through fivecal's nominal model; the ball bar and R-test programs
also in the LinuxCNC simulator (the sphere cycle's simulator run is in
test_linuxcnc.py)."""
import math
import re

import numpy as np
import pytest

import fivecal
from fivecal import gcode
from fivecal.io import linuxcnc as L
from fivecal.io import nc_programs as N
from fivecal.io.dbb_program import bar_length, dbb_program, rotary_dbb_program
from fivecal.procedures import dbb, rtest, sphere_check

import linuxcnc_harness as harness
from test_linuxcnc import MACHINES, TRUE_LOCATION, _sphere_cycle

REASON = harness.unavailable_reason()
KINS = "xyzac-trt"


def _blocks(prog, letters="XYZABC"):
    """Per line with axis words: (1-based line, G motion, modal position
    after the line, F word, line text)."""
    pos, motion, out = {}, None, []
    for ln, line in enumerate(gcode.split_lines(prog), 1):
        words = gcode.tokenize(line.rstrip("\n"), "prog", ln)
        for g in gcode.g_codes(words):
            if g in (0.0, 1.0, 38.2):
                motion = g
        ax = {w.letter: w.value for w in words if w.letter in letters}
        f = next((w.value for w in words if w.letter == "F"), None)
        if ax and 4.0 not in gcode.g_codes(words):
            pos.update(ax)
            out.append((ln, motion, dict(pos), f, line.rstrip("\n")))
    return out


def _machine():
    return fivecal.Machine.from_dict(MACHINES[KINS])


# ---- sphere cycle -----------------------------------------------------------

def test_sphere_cycle_touches_along_the_sphere_normal():
    m = _machine()
    art, plan = _sphere_cycle(m)
    ball = art["spheres"][0]
    prog = N.sphere_program(m, KINS, plan, art, 3.0, clearance=0.5, overtravel=0.8, retract=4.0)
    assert prog.count("G38.2") == len(plan)
    assert "(PROBEOPEN probe-log.txt)" in prog and "(PROBECLOSE)" in prog and "M428" in prog
    blocks = _blocks(prog)
    origin = np.asarray(L.match(m, KINS)["origin"])
    centre = np.asarray(ball["center"]) - origin  # world coordinates
    rr = ball["radius"] + 3.0
    probes = [i for i, b in enumerate(blocks) if b[1] == 38.2]
    for k, i in enumerate(probes):
        n = np.asarray(plan[k]["normal"])
        start = np.array([blocks[i - 1][2][a] for a in "XYZ"])
        end = np.array([blocks[i][2][a] for a in "XYZ"])
        # from 0.5 mm outside to 0.8 mm inside, along the touch direction, at the plan's rotary pose
        np.testing.assert_allclose(start, centre + (rr + 0.5) * n, atol=2e-6)
        np.testing.assert_allclose(end, centre + (rr - 0.8) * n, atol=2e-6)
        assert abs(blocks[i][2]["A"] - plan[k]["axes"]["A"]) < 1e-6
        assert abs(blocks[i][2]["C"] - plan[k]["axes"]["C"]) < 1e-6
    # no rapid move comes nearer the sphere than the clearance (rotary moves
    # with TCP on: straight in world coordinates)
    prev = None
    for ln, g, pos, _, text in blocks:
        p = np.array([pos[a] for a in "XYZ"])
        if g == 0.0 and prev is not None:
            s = np.linspace(0, 1, 50)[:, None]
            d = np.linalg.norm(prev + s * (p - prev) - centre, axis=1).min()
            assert d > rr + 0.5 - 1e-6, (ln, text, d - rr)
        # after a G38.2 the stylus stands at the contact, not at the word's end
        # point; the move back out along the normal starts there
        prev = None if g == 38.2 else p


def _sphere_cycle_bc(m):
    from fivecal.procedures import sphere_test
    ball = {"id": "S1", "center": [50.0, -20.0, 30.0], "radius": 12.5}
    visits = []
    for a, vals in (("B", [-60.0, -15.0, 30.0]), ("C", [-120.0, 0.0, 120.0])):
        visits += [{a: v} for v in vals] + [{a: v} for v in vals[::-1]]
    plan = sphere_test.sphere_plan(m, ball, visits, tip_radius=3.0, rings=[(0.0, 4), (45.0, 4), (90.0, 1)])
    return {"spheres": [ball]}, plan


@pytest.mark.parametrize("kins", ["xyzac-trt", "xyzbc-trt"])
def test_sphere_cycle_reaches_each_position_from_the_planned_side(kins):
    m = fivecal.Machine.from_dict(MACHINES[kins])
    art, plan = (_sphere_cycle if kins == KINS else _sphere_cycle_bc)(m)
    tilt = L.TILT[kins]
    sign = L.match(m, kins)["sign"]  # xyzbc-trt machine: ISO table C, LinuxCNC's C is -C
    prog = N.sphere_program(m, kins, plan, art, 3.0, overshoot=2.0)
    blocks = _blocks(prog)
    probes = [b for b in blocks if b[1] == 38.2]
    rot = [(b[2][tilt] * sign[3], b[2]["C"] * sign[4]) for b in blocks]  # back to fivecal commands
    checked = 0
    for k, b in enumerate(probes):
        d = plan[k].get("direction", {})
        i = blocks.index(b)
        # the last rotary move before this touch
        j = max(j for j in range(i) if rot[j] != rot[i]) if any(r != rot[i] for r in rot[:i]) else None
        for axis, col in ((tilt, 0), ("C", 1)):
            if d.get(axis) and j is not None:
                assert abs(rot[i][col] - plan[k]["axes"][axis]) < 1e-6
                # the last move of the axis into the position went the planned way
                # (an axis that did not move came there the planned way before)
                assert (rot[i][col] - rot[j][col]) * d[axis] > 0 or rot[i][col] == rot[j][col], (k, axis)
                checked += 1
    assert checked > 50
    # with overshoot 0 the turning points of the up-down sequence are not re-approached
    assert "(overshoot)" in prog and "(overshoot)" not in N.sphere_program(m, kins, plan, art, 3.0, overshoot=0)


def test_sphere_cycle_log_round_trip_on_xyzbc_trt():
    """The same model round trip on the B-C table with an ISO C (LinuxCNC's C
    joint is fivecal's -C): the C reversal error comes back with its sign."""
    kins = "xyzbc-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    art, plan = _sphere_cycle_bc(m)
    pins = L.nominal_pins(m, kins)
    errors = {"EX0C": -0.0226, "EY0C": 0.0174, "EX0B": 0.0291, "EZ0B": -0.0138, "ECCb": -4e-5}
    obs = L.read_probe_log(N.sphere_log(m, kins, plan, art, 3.0, pins, errors=errors), m, kins, plan, pins)
    ds = fivecal.Dataset.from_dict({"machine": m.to_dict(), "probe": {"tip_radius": 3.0},
                                    "artefact": art, "observations": obs})
    got = sphere_check.evaluate(ds).values()
    # reported under the names every command uses (EX0C on A/C is EX0S, ...; equal to first order)
    for name, truth in sphere_check.spindle_names(m, errors).items():
        assert abs(got[name] - truth) < (1e-8 if name[1] in "ABC" else 1e-6), (name, got[name], truth)


def test_sphere_cycle_log_reads_back_into_a_check_that_fits():
    """fivecal's own model of the trigger positions (no controller): the
    log of the program on a machine with pivot errors and a C reversal error
    reads back into sphere touches whose check recovers them."""
    m = _machine()
    art, plan = _sphere_cycle(m)
    pins = L.nominal_pins(m, KINS)
    errors = dict(TRUE_LOCATION, ECCb=3e-5)
    log = N.sphere_log(m, KINS, plan, art, 3.0, pins, errors=errors)
    obs = L.read_probe_log(log, m, KINS, plan, pins)
    assert {o["type"] for o in obs} == {"sphere"}
    assert all(o["direction"] == p["direction"] for o, p in zip(obs, plan) if p.get("direction"))
    ds = fivecal.Dataset.from_dict({"machine": m.to_dict(), "probe": {"tip_radius": 3.0},
                                    "artefact": art, "observations": obs})
    got = sphere_check.evaluate(ds).values()
    # reported under the names every command uses (EX0C on A/C is EX0S, ...; equal to first order)
    for name, truth in sphere_check.spindle_names(m, errors).items():
        # the log's 6 decimals; plus the nanometre by which the spindle's name
        # (EX0S for EX0C) differs at second order (axis tilt x offset)
        tol = 1e-8 if name[1] in "ABC" else 3e-6
        assert abs(got[name] - truth) < tol, (name, got[name], truth)
    # on the nominal machine every logged point is a sphere contact of the plan
    nominal = L.read_probe_log(N.sphere_log(m, KINS, plan, art, 3.0, pins), m, KINS, plan, pins)
    for o, p in zip(nominal, plan):
        q = {a: np.array([o["axes"][a]]) for a in m.axis_names}
        tp = m.tool_point(q)[0]
        np.testing.assert_allclose(tp, np.asarray(art["spheres"][0]["center"]) + 15.5 * np.asarray(p["normal"]),
                                   atol=2e-6)


def test_sphere_cycle_refusals():
    m = _machine()
    art, plan = _sphere_cycle(m)
    with pytest.raises(ValueError, match="sphere touches"):
        N.sphere_program(m, KINS, [{"type": "facet", "target": "S1", "axes": {}}], art, 3.0)
    with pytest.raises(ValueError, match="not a sphere of the artefact"):
        N.sphere_program(m, KINS, [dict(plan[0], target="S9")], art, 3.0)
    with pytest.raises(ValueError, match="no spheres"):
        N.sphere_program(m, KINS, plan, {"facets": []}, 3.0)
    with pytest.raises(ValueError, match="retract"):
        N.sphere_program(m, KINS, plan, art, 3.0, clearance=2.0, retract=1.0)
    with pytest.raises(ValueError, match=r"plan\[0\].normal"):
        N.sphere_program(m, KINS, [dict(plan[0], normal=[0, 0, 0])], art, 3.0)
    # a probe move too short for the machine's errors is named, not mis-logged
    with pytest.raises(ValueError, match="touch 1: the stylus is already"):
        N.sphere_trigger_model(m, KINS, plan[:1], art, 3.0, L.nominal_pins(m, KINS),
                               errors={"EX0C": 0.2, "EY0A": 0.2}, clearance=0.01)


# ---- mixed facet and sphere plans (TANGO) ---------------------------------------

TANGO_KINS = "xyzbc-trt"
# location errors of B and C and C's reversal error on the HU40T-like machine
TANGO_ERRORS = {"EX0C": 0.0312, "EY0C": -0.0187, "EA0C": 2.1e-5, "EB0C": -1.6e-5,
                "EX0B": 0.0241, "EZ0B": -0.0153, "EA0B": 1.2e-5, "EC0B": -2.4e-5, "ECCb": 3e-5}


def _tango():
    from fivecal.procedures import tango
    m, art = tango.hu40t_machine(), tango.octagonal_table()
    return m, art, tango.hu40t_plan(art, m)


def check_touch_program(m, kins, plan, art, prog, tip, clearance, overtravel):
    """Every G38.2 of ``prog`` runs from ``clearance`` outside to
    ``overtravel`` inside the contact point of its plan entry (a facet touch:
    its point plus the stylus radius along the facet normal; a sphere touch:
    the centre plus radius plus stylus radius along its normal), at the
    entry's rotary pose, in plan order; no other straight move comes nearer
    any sphere of the artefact than the clearance. Returns the number of
    facet and sphere touches."""
    tilt = L.TILT[kins]
    mp = L.match(m, kins)
    origin = np.asarray(mp["origin"])
    facets = {f["id"]: f for f in art["facets"]}
    spheres = {s["id"]: s for s in art["spheres"]}
    blocks = _blocks(prog)
    probes = [i for i, b in enumerate(blocks) if b[1] == 38.2]
    assert len(probes) == len(plan)
    kinds = {"facet": 0, "sphere": 0}
    for k, i in enumerate(probes):
        e = plan[k]
        if e["type"] == "facet":
            n = np.asarray(facets[e["target"]]["normal"], float)
            contact = np.asarray(e["point"], float) + tip * n
        else:
            n = np.asarray(e["normal"], float)
            n = n / np.linalg.norm(n)
            s = spheres[e["target"]]
            contact = np.asarray(s["center"]) + (s["radius"] + tip) * n
        kinds[e["type"]] += 1
        start = np.array([blocks[i - 1][2][a] for a in "XYZ"])
        end = np.array([blocks[i][2][a] for a in "XYZ"])
        np.testing.assert_allclose(start, contact - origin + clearance * n, atol=2e-6, err_msg=f"touch {k + 1}")
        np.testing.assert_allclose(end, contact - origin - overtravel * n, atol=2e-6, err_msg=f"touch {k + 1}")
        assert abs(blocks[i][2][tilt] - mp["sign"][3] * e["axes"][tilt]) < 1e-6
        assert abs(blocks[i][2]["C"] - mp["sign"][4] * e["axes"]["C"]) < 1e-6
    # the touch comments name the plan's targets in the plan's order
    assert re.findall(r"\(touch \d+: ([^\s)]+)", prog) == [e["target"] for e in plan]
    balls = [(np.asarray(s["center"]) - origin, s["radius"] + tip) for s in art["spheres"]]
    prev, near = None, np.inf
    for ln, g, pos, _, text in blocks:
        p = np.array([pos[a] for a in "XYZ"])
        if g == 0.0 and prev is not None:
            t = np.linspace(0, 1, 400)[:, None]
            for c, rr in balls:
                d = np.linalg.norm(prev + t * (p - prev) - c, axis=1).min() - rr
                assert d > clearance - 1e-6, (ln, text, d)
                near = min(near, d)
        prev = None if g == 38.2 else p
    return kinds


def test_mixed_tango_plan_is_one_program_touching_each_target_kind():
    """The TANGO plan (facets of the octagonal table and the scale bar's
    balls, as fivecal design's pool) becomes one G38.2 program: each touch
    ends at the contact of its own kind of target, no move cuts through a
    ball (facet touches lifted only by --safe passed 2-5 mm through them)."""
    m, art, plan = _tango()
    assert {e["type"] for e in plan} == {"facet", "sphere"}
    prog = N.touch_program(m, TANGO_KINS, plan, art, 3.0, clearance=0.5, overtravel=0.8, retract=4.0)
    assert prog.count("G38.2") == len(plan) and "(PROBEOPEN probe-log.txt)" in prog
    assert check_touch_program(m, TANGO_KINS, plan, art, prog, 3.0, 0.5, 0.8) == {"facet": 378, "sphere": 10}
    # facets and spheres interleaved at one position (B = C = 0: five touches
    # of each ball, then the facets): a facet touch between two of S1's and
    # between S1's last and S2's first
    mixed = [dict(e) for e in plan]
    k = next(i for i, e in enumerate(mixed) if e["type"] == "sphere")
    mixed.insert(k + 2, mixed.pop(k + 10))
    mixed.insert(k + 6, mixed.pop(k + 11))
    assert [e["target"] for e in mixed[k:k + 8]] == ["S1", "S1", "F3", "S1", "S1", "S1", "F4", "S2"]
    prog = N.touch_program(m, TANGO_KINS, mixed, art, 3.0, clearance=0.5, overtravel=0.8, retract=4.0)
    check_touch_program(m, TANGO_KINS, mixed, art, prog, 3.0, 0.5, 0.8)


def test_mixed_tango_log_reads_back_into_facet_and_sphere_touches_that_fit():
    """The log a probe writes running that program on a machine with errors
    (fivecal's trigger model plus 0.6 um noise) reads back with the plan into
    facet and sphere observations of the plan's targets; identify recovers
    the errors within 3 sigma."""
    m, art, plan = _tango()
    pins = L.nominal_pins(m, TANGO_KINS)
    log = N.touch_log(m, TANGO_KINS, plan, art, 3.0, pins, errors=TANGO_ERRORS)
    rng = np.random.default_rng(5)
    rows = [[float(v) for v in ln.split()] for ln in log.splitlines()]
    for r in rows:
        r[:3] = list(np.asarray(r[:3]) + rng.normal(0, 0.0006, 3))
    log = "".join(" ".join(f"{v:.6f}" for v in r) + "\n" for r in rows)
    obs = L.read_probe_log(log, m, TANGO_KINS, plan, pins)
    assert [(o["type"], o["target"]) for o in obs] == [(e["type"], e["target"]) for e in plan]
    # each touch came back where its plan entry commanded the rotary axes
    assert all(abs(o["axes"][a] - e["axes"][a]) < 1e-6 for o, e in zip(obs, plan) for a in "BC")
    for o in obs:
        o["sigma"] = 0.0006
    ds = fivecal.Dataset.from_dict({"machine": m.to_dict(), "probe": {"tip_radius": 3.0}, "artefact": art,
                                    "observations": obs})
    r = fivecal.identify(ds, estimate=list(TANGO_ERRORS), fix=["tip.x", "tip.y", "tip.z"])
    assert r.converged
    for name, truth in TANGO_ERRORS.items():
        assert abs(r.values[name] - truth) < 3 * r.std[name], (name, r.values[name], truth, r.std[name])


def _cylinder_plan():
    """Touches of a boss and a bore on the table (cylinder sections, a kind
    the program writers never name) at three C and two A positions, each
    point given in the workpiece frame around the section."""
    art = {"cylinders": [{"id": "Z1", "point": [55.0, 25.0, 0.0], "axis": [0, 0, 1], "radius": 20.0},
                         {"id": "H1", "point": [-40.0, -20.0, 0.0], "axis": [0, 0, 1], "radius": 15.0,
                          "inside": True}]}
    plan = []
    for a in (0.0, -20.0):
        for c in (-90.0, 0.0, 120.0):
            for cyl in art["cylinders"]:
                for t in (0.3, 2.4, 4.4):
                    # the side of the section facing the probe after C turned it
                    phi = t - math.radians(c)
                    x, y, _ = cyl["point"]
                    r = cyl["radius"]
                    plan.append({"type": "cylinder", "target": cyl["id"], "axes": {"A": a, "C": c},
                                 "point": [x + r * math.cos(phi), y + r * math.sin(phi), 12.0],
                                 "direction": {"A": 1, "C": 1}})
    return art, plan


def test_a_cylinder_touch_plan_gets_a_probing_program_for_free():
    """A probe-touch kind the writers do not name runs through them as its
    kind answers (issue 29): a cylinder plan becomes one G38.2 cycle, aimed
    along each touch's surface normal at the simulator's own contact point;
    the trip log the module's trigger model writes for a machine with
    location errors reads back into the observations fivecal.simulate
    records for that plan on that machine (to the log's 6 decimals)."""
    m = _machine()
    art, plan = _cylinder_plan()
    pins = L.nominal_pins(m, KINS)
    prog = N.touch_program(m, KINS, plan, art, 3.0, clearance=0.5, overtravel=0.8, retract=4.0)
    assert prog.count("G38.2") == len(plan) and "(PROBEOPEN probe-log.txt)" in prog
    assert N.PLAN_PROGRAMS["cylinder"] == N.TOUCH_PROGRAMS[0] and not N.touches_a_sphere(plan)
    # every probe move runs along its touch's normal through the contact (the nominal tool point)
    probes = [b for b in _blocks(prog) if b[1] == 38.2]
    geo = N._geometry(m, KINS, plan, art, 3.0)
    assert len(probes) == len(geo)
    for (_, _, pos, _, _), (_, _, w, n, _) in zip(probes, geo):
        np.testing.assert_allclose([pos[a] for a in "XYZ"], w - 0.8 * n, atol=1e-6)
    errors = dict(TRUE_LOCATION)
    log = N.touch_log(m, KINS, plan, art, 3.0, pins, errors=errors)
    sim = N.touch_sim_lines(m, KINS, plan, art, 3.0, pins, errors=errors)
    assert len(sim) == len(plan) and all(len(lines) == 4 for lines in sim)
    obs = L.read_probe_log(log, m, KINS, plan, pins)
    truth = fivecal.simulate(m, plan, errors=errors, artefact=art, tip_radius=3.0, sigma=0.0, seed=1)
    want = truth.to_dict()["observations"]
    assert [(o["type"], o["target"]) for o in obs] == [(o["type"], o["target"]) for o in want]
    for o, w in zip(obs, want):
        for a in m.axis_names:
            assert abs(o["axes"].get(a, 0.0) - w["axes"].get(a, 0.0)) < 3e-6, (a, o, w)
    # the errors show: on the nominal machine the same touches read back elsewhere
    nominal = L.read_probe_log(N.touch_log(m, KINS, plan, art, 3.0, pins), m, KINS, plan, pins)
    assert max(abs(o["axes"][a] - w["axes"][a]) for o, w in zip(nominal, want) for a in "XYZ") > 0.01


def test_a_cylinder_plan_through_the_command_line(tmp_path, capsys):
    """`fivecal export program` picks the probing cycle for a cylinder plan
    (the registry's program of its kind) and `fivecal import probe-log
    --plan` reads its log back, each log line checked against its touch's
    probe line."""
    from fivecal.cli import main
    from fivecal.io import plan_readings
    m = _machine()
    art, plan = _cylinder_plan()
    spec = _spec(tmp_path, "cyl.json", m.to_dict(), plan, artefact=art, probe={"tip_radius": 3.0})
    out = str(tmp_path / "cyl.ngc")
    assert main(["export", "program", spec, "--kins", KINS, "--out", out]) == 0
    assert open(out).read() == N.touch_program(m, KINS, plan, art, 3.0)
    assert main(["export", "program", spec, "--kins", KINS, "--dialect", "siemens"]) == 0
    assert capsys.readouterr().out.count("MEAS=1 G01") == len(plan)
    pins = L.nominal_pins(m, KINS)
    log = tmp_path / "probe-log.txt"
    log.write_text(N.touch_log(m, KINS, plan, art, 3.0, pins, errors=TRUE_LOCATION))
    d = plan_readings.probe_log_dataset(str(log), spec, KINS)
    assert d["observations"] == L.read_probe_log(str(log), m, KINS, plan, pins)
    # a log of another plan (the touches in another order) is refused naming the line
    rows = log.read_text().splitlines()
    log.write_text("\n".join([rows[1], rows[0], *rows[2:]]) + "\n")
    with pytest.raises(ValueError, match=r"probe-log.txt:1"):
        plan_readings.probe_log_dataset(str(log), spec, KINS)


def test_a_cylinder_touch_that_starts_inside_or_misses_is_refused():
    m = _machine()
    art, plan = _cylinder_plan()
    pins = L.nominal_pins(m, KINS)
    # A 0, C 0 (the workpiece frame is the machine's): the C line moved 2 mm
    # along the touch's normal one way or the other puts the boss into the
    # stylus' start or out of its reach
    touch = plan[6]
    assert touch["axes"] == {"A": 0.0, "C": 0.0} and touch["target"] == "Z1"
    said = []
    for sign in (1.0, -1.0):
        shift = {"EX0C": sign * 2.0 * math.cos(0.3), "EY0C": sign * 2.0 * math.sin(0.3)}
        with pytest.raises(ValueError) as e:
            N.touch_log(m, KINS, [touch], art, 3.0, pins, errors=shift, clearance=0.1, overtravel=0.1)
        said.append(str(e.value))
    assert sorted(x.split(" (")[0] for x in said) == [
        "touch 1: the probe move misses cylinder Z1 on this machine",
        "touch 1: the stylus is already on or in cylinder Z1 at the start of the probe move"]
    with pytest.raises(ValueError, match=r"plan\[0\]: target 'Z9' is not a cylinder of the artefact"):
        N.touch_program(m, KINS, [dict(plan[0], target="Z9")], art, 3.0)
    with pytest.raises(ValueError, match=r"plan\[0\]: type 'cylinder': a sphere cycle runs sphere touches"):
        N.sphere_program(m, KINS, plan, art, 3.0)


def test_mixed_program_refusals():
    m, art, plan = _tango()
    with pytest.raises(ValueError, match=r"plan\[1\]: type 'ball3d'"):
        N.touch_program(m, TANGO_KINS, [plan[0], {"type": "ball3d", "axes": {"B": 0, "C": 0}}], art, 3.0)
    with pytest.raises(ValueError, match="not a facet of the artefact"):
        N.touch_program(m, TANGO_KINS, [dict(plan[0], target="S1")], art, 3.0)
    # a sphere standing over a facet touch: the stylus cannot come down to it
    over = dict(art, spheres=[{"id": "S9", "center": [0.0, -160.0, 40.0], "radius": 10.0}])
    f22 = [e for e in plan if e["target"] == "F22" and e["axes"]["B"] == 0][:1]
    assert f22 and np.allclose(f22[0]["point"][:2], [0.0, -160.0], atol=6)
    with pytest.raises(ValueError, match="touch 1: the tool-axis move .* sphere S9"):
        N.touch_program(m, TANGO_KINS, [dict(f22[0], point=[0.0, -160.0, 0.0])], over, 3.0)


# ---- R-test -----------------------------------------------------------------

def _rtest_plan(m):
    return (rtest.plan(m, "K1", table_ball=[60, 20, 30], tool_ball=[0, 0, 140], step=30)
            + rtest.plan(m, "K4", table_ball=[60, 20, 30], tool_ball=[0, 0, 140], step=30, tilt=-30))


def _dwell_points(prog):
    """The axis positions at each G4 dwell, with its comment."""
    pos, out = {}, []
    for ln, line in enumerate(gcode.split_lines(prog), 1):
        words = gcode.tokenize(line.rstrip("\n"), "prog", ln)
        if 4.0 in gcode.g_codes(words):
            out.append((dict(pos), line))
            continue
        pos.update({w.letter: w.value for w in words if w.letter in "XYZABC"})
    return out


def test_rtest_program_axis_commands_dwell_at_the_plan_samples():
    m = _machine()
    plan = _rtest_plan(m)
    prog = N.rtest_program(m, plan, dwell=0.5, subdivide=3)
    dw = _dwell_points(prog)
    assert len(dw) == len(plan)
    for (pos, line), e in zip(dw, plan):
        assert e["id"] in line and "G4 P0.5" in line
        for a in "XYZAC":
            assert abs(pos[a] - e["axes"][a]) < 1e-6
    # every commanded point, samples and the 3 between each, puts the tool
    # ball into the nest on the nominal machine
    blocks = _blocks(prog)
    assert len(blocks) == len(plan) + 3 * (len(plan) - 2)  # two setups
    q = {a: np.array([b[2].get(a, 0.0) for b in blocks]) for a in m.axis_names}
    np.testing.assert_allclose(m.tool_point(q, tip=np.array([0, 0, 140.0])), np.tile([60, 20, 30.0], (len(blocks), 1)),
                               atol=2e-6)


def test_rtest_program_joint_values_and_tcp_world_moves():
    m = _machine()
    plan = _rtest_plan(m)
    pins = L.nominal_pins(m, KINS)
    want = L.joints(m, KINS, {a: np.array([e["axes"].get(a, 0.0) for e in plan]) for a in m.axis_names})
    # joint values, identity kinematics
    prog = N.rtest_program(m, plan, kins=KINS)
    assert "M429" in prog and "M428" not in prog
    got = np.array([[p[a] for a in "XYZAC"] for p, _ in _dwell_points(prog)])
    np.testing.assert_allclose(got, want, atol=1e-6)
    # world coordinates with LinuxCNC's tool centre point: its own inverse
    # kinematics (transcribed) gives the same joints; the tool tip's world
    # point stays put within a setup (tool ball at the tip here)
    plan_tip = rtest.plan(m, "K4", table_ball=[60, 20, 30], step=30, tilt=-30)
    prog = N.rtest_program(m, plan_tip, mode="tcp", kins=KINS)
    assert "M428" in prog
    world = np.array([[p[a] for a in "XYZAC"] for p, _ in _dwell_points(prog)])
    want = L.joints(m, KINS, {a: np.array([e["axes"].get(a, 0.0) for e in plan_tip]) for a in m.axis_names})
    np.testing.assert_allclose(L.inverse(KINS, pins, world), want, atol=1e-5)
    assert np.ptp(world[:, :3], axis=0).max() < 2e-6
    with pytest.raises(ValueError, match="give kins"):
        N.rtest_program(m, plan, mode="tcp")
    with pytest.raises(ValueError, match="ball3d"):
        N.rtest_program(m, [{"type": "dbb"}])


# ---- ball bar programs of rotary-axis paths ---------------------------------

def _wang_machine():
    """The xyzac-trt test machine with A and C intersecting (Wang's path needs it)."""
    d = dict(MACHINES[KINS])
    d["axes"] = {**d["axes"], "C": {**d["axes"]["C"], "point": [12, 20, 0]}}
    return fivecal.Machine.from_dict(d)


def _replay(m, prog, entries, kins=None, between=25):
    """Bar length along every path block (straight in the words, as a
    controller without TCP interpolates), at ``between`` points per block;
    and the feed-in / feed-out blocks."""
    blocks = _blocks(prog)
    start = next(i for i, b in enumerate(blocks) if "(feed-in)" in b[4])
    stop = next(i for i, b in enumerate(blocks) if "(feed-out)" in b[4])
    words = np.array([[b[2][a] for a in ("XYZAC" if kins else [x for x in m.axis_names if x != "S"])]
                      for b in blocks])
    s = np.linspace(0, 1, between)
    a, b = words[start:stop - 1, None, :], words[start + 1:stop, None, :]
    seg = a + s[None, :, None] * (b - a)
    seg = seg.reshape(-1, words.shape[1])

    def axes(rows):
        if kins:
            return [{a: float(v[i]) for a, v in L.commands(m, kins, rows).items()} for i in range(len(rows))]
        names = [x for x in m.axis_names if x != "S"]
        return [dict(zip(names, r)) for r in rows]
    e = entries[0]
    lengths = bar_length(m, axes(seg), e["tool_ball"], e["table_ball"])
    ends = bar_length(m, axes(words[[start - 1, stop]]), e["tool_ball"], e["table_ball"])
    return lengths, ends, blocks[start + 1:stop], axes(words[start:stop])


@pytest.mark.parametrize("which", ["four-step", "wang"])
def test_rotary_ball_bar_program_keeps_the_bar_length(which):
    if which == "wang":
        m = _wang_machine()
        plan = dbb.wang_plan(m, start=90, end=180, step=2.0)
    else:
        m = fivecal.Machine.load("examples/machines/c600u.json")
        plan = dbb.four_step_plan(m, step=3.0)
    prog = rotary_dbb_program(m, plan, feed=800, feed_in=1.5)
    setups = {}
    for e in plan:
        setups.setdefault(e["setup"], []).append(e)
    for name, entries in setups.items():
        lines = prog.splitlines()
        a = next(i for i, x in enumerate(lines) if x.startswith(f"(setup {name}:"))
        b = next(i for i in range(a, len(lines)) if "(feed-out)" in lines[i])
        part = "\n".join(lines[a:b + 1]) + "\n"
        lengths, ends, path, pts = _replay(m, part, entries)
        L0 = entries[0]["length"]
        assert np.abs(lengths - L0).max() < 1e-4, (name, np.abs(lengths - L0).max())
        # feed-in from and feed-out to 1.5 mm short of the bar, along it
        np.testing.assert_allclose(ends, L0 - 1.5, atol=2e-6)
        # every planned pose is a point of the path, in order
        names = [a for a in m.axis_names if a != "S"]
        P = np.array([[p[a] for a in names] for p in pts])
        k = 0
        for e in entries:
            row = np.array([e["axes"].get(a, 0.0) for a in names])
            while k < len(P) and np.abs(P[k] - row).max() > 1e-6:
                k += 1
            assert k < len(P), f"planned pose {e['axes']} is not on the path"
        # inverse time: every block has its time; none is F1e9 (before: a
        # four-step setup's balls turn together, their relative travel is 0)
        assert all(b[3] is not None for b in path)
        g93 = [b[3] for b in path]
        assert max(g93) < 800 / 1e-3, (name, max(g93))
    if which == "wang":
        assert "G93" in prog and len(_blocks(prog)) > 2 * len(plan)  # points added between the samples
    # the plain ball bar writer sends such setups here too
    assert dbb_program(m, plan, feed=800) .count("G93") == len(setups)


def test_rotary_ball_bar_program_refusals():
    m = fivecal.Machine.load("examples/machines/c600u.json")
    plan = dbb.four_step_plan(m, step=10.0)
    bad = [dict(e, axes=dict(e["axes"])) for e in plan]
    bad[3]["axes"]["X"] += 0.5
    with pytest.raises(ValueError, match=r"planned pose 4 .*\(not a constant-length path"):
        rotary_dbb_program(m, bad)
    with pytest.raises(ValueError, match="feed_in"):
        rotary_dbb_program(m, plan, feed_in=200)
    from fivecal.procedures.dbb import planar_plan
    with pytest.raises(ValueError, match="no rotary axis moves"):
        rotary_dbb_program(m, planar_plan(m, "ZX", radius=50.0, step=10.0))


@pytest.mark.skipif(REASON is not None, reason=f"needs LinuxCNC: {REASON}")
def test_rtest_and_rotary_ball_bar_programs_run_in_linuxcnc():
    """One simulator session: the R-test K4 path as world moves with the tool
    centre point on reaches the joints of fivecal's inverse kinematics at
    every sample; the Wang ball bar program (LinuxCNC joint values, identity
    kinematics, exact stop) runs without errors and the joints LinuxCNC
    commands keep the nominal bar length within 0.1 um all along the path."""
    m = _wang_machine()
    pins = L.nominal_pins(m, KINS)
    rplan = rtest.plan(m, "K4", table_ball=[60, 20, 30], step=30, tilt=-30)
    rprog = N.rtest_program(m, rplan, mode="tcp", kins=KINS)
    moves = [b[4].split("(")[0].strip() + (" F100000" if "F" not in b[4] else "") for b in _blocks(rprog)]
    wplan = dbb.wang_plan(m, start=90, end=130, step=2.0)
    wprog = rotary_dbb_program(m, wplan, feed=3000, kins=KINS)
    with harness.Sim(KINS, hal=L.hal_text(KINS, pins), files={"wang.ngc": wprog}) as sim:
        out = sim.run(moves, setup=["M428"], program="wang.ngc", program_timeout=300, trace=True)
    assert out["errors"] == []
    want = L.joints(m, KINS, {a: np.array([e["axes"].get(a, 0.0) for e in rplan]) for a in m.axis_names})
    np.testing.assert_allclose(np.array(out["joints"]), want, atol=1e-6)
    lines = wprog.splitlines()
    first = next(i for i, x in enumerate(lines) if "(feed-in)" in x) + 2  # 1-based, after the feed-in
    last = next(i for i, x in enumerate(lines) if "(feed-out)" in x) - 1
    tr = np.array([t for t in out["trace"] if first < t[0] < last])
    assert len(tr) > 20
    q = L.commands(m, KINS, tr[:, 1:6])
    axes = [{a: float(v[i]) for a, v in q.items()} for i in range(len(tr))]
    e = wplan[0]
    dev = np.abs(bar_length(m, axes, e["tool_ball"], e["table_ball"]) - e["length"])
    assert dev.max() < 1e-4, dev.max()


@pytest.mark.parametrize("test", ["K1", "K2", "K3", "K4"])
@pytest.mark.parametrize("tool_ball", [[0, 0, 140], [5, -3, 150]])
def test_rtest_plan_puts_a_tool_ball_off_the_tip_into_the_nest(test, tool_ball):
    """rtest.plan with a tool ball that is not the machine's tip: on the
    nominal machine the ball sits in the nest at every sample (before the
    fix, the tip - ball offset was added in the machine frame while the
    table had turned it: 5-10 mm off at tilted poses)."""
    m = _machine()
    p = rtest.plan(m, test, table_ball=[60, 20, 30], tool_ball=tool_ball, step=30, tilt=-30)
    q = {a: np.array([e["axes"].get(a, 0.0) for e in p]) for a in m.axis_names}
    assert np.abs(m.tool_point(q, tip=np.array(tool_ball, float)) - [60, 20, 30]).max() < 1e-9


# ---- command line -------------------------------------------------------------

def _spec(tmp_path, name, machine, plan, **extra):
    import json
    p = tmp_path / name
    p.write_text(json.dumps({"machine": machine, "plan": plan, **extra}))
    return str(p)


def test_cli_export_program(tmp_path, capsys):
    from fivecal.cli import main
    m = _machine()
    art, plan = _sphere_cycle(m)
    spec = _spec(tmp_path, "sphere.json", m.to_dict(), plan, artefact=art, probe={"tip_radius": 3.0})
    out = str(tmp_path / "sphere.ngc")
    assert main(["export", "program", spec, "--kins", KINS, "--out", out, "--clearance", "0.5",
                 "--overshoot", "2"]) == 0
    assert open(out).read() == N.sphere_program(m, KINS, plan, art, 3.0, clearance=0.5, overshoot=2.0,
                                                 retract=5.0, safe=100.0)
    assert "sphere program, 96 plan entries" in capsys.readouterr().out
    # R-test in TCP mode to standard output
    rplan = rtest.plan(m, "K4", table_ball=[60, 20, 30], step=30, tilt=-30)
    spec = _spec(tmp_path, "rtest.json", m.to_dict(), rplan)
    assert main(["export", "program", spec, "--mode", "tcp", "--kins", KINS]) == 0
    assert capsys.readouterr().out == N.rtest_program(m, rplan, mode="tcp", kins=KINS, dwell=1.0)
    # ball bar: a machine file path relative to the spec, four-step rotary paths
    c6 = fivecal.Machine.load("examples/machines/c600u.json")
    fplan = dbb.four_step_plan(c6, step=10.0)
    import os
    spec = _spec(tmp_path, "fs.json", os.path.abspath("examples/machines/c600u.json"), fplan)
    assert main(["export", "program", spec, "--feed", "500"]) == 0
    # the command line's path tolerance: 0.1 µm, a ball bar's resolution (fivecal docs commands)
    assert capsys.readouterr().out == dbb_program(c6, fplan, feed=500.0, tolerance=1e-4)
    # refusals: exit 2, one line naming the cause
    assert main(["export", "program", spec.replace("fs", "sphere")]) == 2
    assert "--kins" in capsys.readouterr().err
    mixed = _spec(tmp_path, "mixed.json", m.to_dict(), plan[:2] + rplan[:2], artefact=art)
    assert main(["export", "program", mixed, "--kins", KINS]) == 2
    assert "ball3d, sphere" in capsys.readouterr().err
    assert main(["export", "program", spec, "--tolerance", "0"]) == 2
    assert "--tolerance" in capsys.readouterr().err


def test_vendor_names_cite_the_public_sources():
    """The neutral table's Siemens column pairs each swivel data record vector
    with its $TC_CARR components and the TRAORI machine data; the Heidenhain
    column names the kinematics description's row kind."""
    from fivecal.io import controllers as K
    m = fivecal.Machine.load("examples/machines/c600u.json")  # swivel table, A then C
    s, h = K.vendor_names(m, "A", "direction")
    assert "V1" in s and "$TC_CARR7..9" in s and "MD24570 $MC_TRAFO5_AXIS1_1" in s
    assert "MachAxis A" in h and "AXIS A/B/C" in h
    s, h = K.vendor_names(m, "A", "point")
    assert "I2" in s and "$TC_CARR4..6" in s and "MD24550 $MC_TRAFO5_BASE_TOOL_1" in s and "KEY Trans" in h
    s, _ = K.vendor_names(m, "C", "point")
    assert "I3" in s and "$TC_CARR15..17" in s and "MD24558" in s


# ---- numeric options: one rule each, the same from Python and the command line ----

@pytest.mark.parametrize("option,value", [
    ("--feed", "0"), ("--feed", "-60"), ("--feed", "nan"), ("--feed", "inf"), ("--feed", "1e6"),
    ("--overtravel", "1e6"), ("--overtravel", "0"), ("--clearance", "0"), ("--clearance", "1e4"),
    ("--retract", "1e6"), ("--safe", "1e6"), ("--safe", "-5"), ("--overshoot", "-1"), ("--overshoot", "360"),
    ("--dwell", "-1"), ("--dwell", "nan"), ("--dwell", "1e9"),
])
def test_cli_export_program_refuses_bad_option_values(tmp_path, capsys, option, value):
    # before: --feed 0 silently became F60, --overtravel 1e6 wrote a G38.2 a
    # kilometre long, --dwell -1 was written as G4 P-1
    from fivecal.cli import main
    m = _machine()
    art, plan = _sphere_cycle(m)
    spec = _spec(tmp_path, "sphere.json", m.to_dict(), plan, artefact=art, probe={"tip_radius": 3.0})
    out = tmp_path / "s.ngc"
    assert main(["export", "program", spec, "--kins", KINS, "--out", str(out), f"{option}={value}"]) == 2
    err = capsys.readouterr().err
    assert f"{option}:" in err and "expected" in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists()


@pytest.mark.parametrize("option,value", [("--feed", "0"), ("--dwell", "-1"), ("--subdivide", "-1"),
                                          ("--subdivide", "100000"), ("--feed", "1e7")])
def test_cli_export_rtest_program_refuses_bad_option_values(tmp_path, capsys, option, value):
    from fivecal.cli import main
    m = _machine()
    spec = _spec(tmp_path, "rtest.json", m.to_dict(), rtest.plan(m, "K4", table_ball=[60, 20, 30], step=30,
                                                                  tilt=-30))
    assert main(["export", "program", spec, f"{option}={value}"]) == 2
    assert f"{option}:" in capsys.readouterr().err


def test_cli_export_program_zero_dwell_is_zero(tmp_path, capsys):
    # before: an R-test --dwell 0 became the default 1 s, as --feed 0 became F60
    from fivecal.cli import main
    m = _machine()
    rplan = rtest.plan(m, "K4", table_ball=[60, 20, 30], step=30, tilt=-30)
    spec = _spec(tmp_path, "rtest.json", m.to_dict(), rplan)
    assert main(["export", "program", spec, "--dwell", "0"]) == 0
    assert capsys.readouterr().out == N.rtest_program(m, rplan, dwell=0.0)


def test_cli_export_ball_bar_program_refuses_bad_option_values(tmp_path, capsys):
    from fivecal.cli import main
    import os
    c6 = fivecal.Machine.load("examples/machines/c600u.json")
    spec = _spec(tmp_path, "fs.json", os.path.abspath("examples/machines/c600u.json"),
                 dbb.four_step_plan(c6, step=10.0))
    for option, value in (("--feed-in", "0"), ("--feed-in", "1e6"), ("--path-tolerance", "-1"),
                          ("--path-tolerance", "1e9"), ("--feed", "0")):
        assert main(["export", "program", spec, f"{option}={value}"]) == 2
        assert f"{option}:" in capsys.readouterr().err
    # a plan-dependent bound a writer checks is named as the option too
    spec = _spec(tmp_path, "circle.json", os.path.abspath("examples/machines/c600u.json"),
                 dbb.planar_plan(c6, "ZX", radius=20.0, step=10.0))
    assert main(["export", "program", spec, "--feed-in", "30"]) == 2
    assert "--feed-in: 30.0 mm is not less than the radius 20 mm" in capsys.readouterr().err


def test_overtravel_is_bounded_by_the_touched_sphere(tmp_path, capsys):
    from fivecal.cli import main
    m = _machine()
    art, plan = _sphere_cycle(m)
    small = {"spheres": [dict(art["spheres"][0], radius=4.0)]}
    with pytest.raises(ValueError, match=r"^overtravel: 6 mm is more than the radius of sphere S1"):
        N.sphere_program(m, KINS, plan, small, 3.0, overtravel=6.0)
    spec = _spec(tmp_path, "sphere.json", m.to_dict(), plan, artefact=small, probe={"tip_radius": 3.0})
    assert main(["export", "program", spec, "--kins", KINS, "--overtravel", "6"]) == 2
    assert "--overtravel: 6 mm is more than the radius of sphere S1" in capsys.readouterr().err


@pytest.mark.parametrize("name,value", [("feed", 0.0), ("feed", math.nan), ("feed", 2e5), ("dwell", -1.0),
                                        ("clearance", math.inf), ("overtravel", 1e6), ("safe", 1e6),
                                        ("retract", -1.0), ("overshoot", math.nan)])
def test_every_program_writer_checks_its_options_by_one_rule(name, value):
    m = _machine()
    art, plan = _sphere_cycle(m)
    fplan, fart = _octagon_plan(m)
    calls = [lambda kw: N.sphere_program(m, KINS, plan, art, 3.0, **kw),
             lambda kw: N.touch_program(m, KINS, plan, art, 3.0, **kw),
             lambda kw: L.probing_program(m, KINS, fplan, fart, 3.0, **{k: v for k, v in kw.items()
                                                                        if k != "overshoot"})]
    if name in ("feed", "dwell"):
        calls.append(lambda kw: N.rtest_program(m, _rtest_plan(m), **kw))
    if name == "feed":
        c6 = fivecal.Machine.load("examples/machines/c600u.json")
        calls += [lambda kw: dbb_program(c6, dbb.four_step_plan(c6, step=10.0), **kw),
                  lambda kw: rotary_dbb_program(c6, dbb.four_step_plan(c6, step=10.0), **kw)]
    for call in calls:
        if name == "overshoot" and call is calls[2]:
            continue
        with pytest.raises(ValueError, match=rf"^{name}: expected a number"):
            call({name: value})


def _octagon_plan(m):
    from test_linuxcnc import _octagon, _probe_plan
    art = _octagon()
    return _probe_plan(m, art), art


@pytest.mark.parametrize("log", ["a)\nG0 X999", "probe(1).txt", "", "log\r.txt"])
def test_probe_log_name_cannot_slip_blocks_into_the_program(tmp_path, capsys, log):
    # before: --log 'a)<newline>G0 X999' closed the PROBEOPEN comment and
    # wrote a G0 X999 block into the program
    from fivecal.cli import main
    m = _machine()
    art, plan = _sphere_cycle(m)
    with pytest.raises(ValueError, match="^log: "):
        N.sphere_program(m, KINS, plan, art, 3.0, log=log)
    with pytest.raises(ValueError, match="^arm: "):
        N.sphere_program(m, KINS, plan, art, 3.0, arm="M64 P0\nG0 Z-50")
    spec = _spec(tmp_path, "sphere.json", m.to_dict(), plan, artefact=art, probe={"tip_radius": 3.0})
    assert main(["export", "program", spec, "--kins", KINS, "--log", log]) == 2
    assert "--log: " in capsys.readouterr().err


def test_a_program_position_no_machine_reaches_is_refused(tmp_path, capsys):
    # before: a sphere 1e9 mm out (a unit slip in the artefact) gave a
    # program with X1000000000 moves; a NaN workpiece shift, 'X nan' words
    from fivecal.cli import main
    m = _machine()
    art, plan = _sphere_cycle(m)
    far = {"spheres": [dict(art["spheres"][0], center=[1e9, 0.0, 40.0])]}
    spec = _spec(tmp_path, "sphere.json", m.to_dict(), plan, artefact=far, probe={"tip_radius": 3.0})
    assert main(["export", "program", spec, "--kins", KINS]) == 2
    err = capsys.readouterr().err
    # the artefact itself is refused (its kind reads it for the contact points)
    assert "spheres[0].center[0]: 1e+09 mm is implausible" in err and "look like µm" in err, err
    # a sphere at the edge of any machine's reach: the touches beyond it are refused in the program
    edge = {"spheres": [dict(art["spheres"][0], center=[99999.0, 0.0, 40.0])]}
    spec = _spec(tmp_path, "edge.json", m.to_dict(), plan, artefact=edge, probe={"tip_radius": 3.0})
    assert main(["export", "program", spec, "--kins", KINS]) == 2
    err = capsys.readouterr().err
    assert "sphere cycle: line " in err and "beyond any machine tool" in err, err
    for shift in ([np.nan, 0, 0], [0, 0], [2e5, 0, 0]):
        with pytest.raises(ValueError, match="^workpiece_shift: expected"):
            N.sphere_program(m, KINS, plan, art, 3.0, workpiece_shift=shift)
    # an R-test path is fixed by the plan's joint values: a shift it would ignore is not taken
    with pytest.raises(TypeError, match="workpiece_shift"):
        N.rtest_program(m, _rtest_plan(m), kins=KINS, mode="tcp", workpiece_shift=[1.0, 0, 0])


def test_names_written_into_comments_stay_in_them():
    # before: a machine or target named with ')' and a newline closed the
    # comment and put the rest into the program as a block (G0 X999 here)
    m = fivecal.Machine.from_dict(dict(MACHINES_KINS(), name="trt (copy)\nG0 X999 (x"))
    art, plan = _sphere_cycle(m)
    progs = [N.sphere_program(m, KINS, plan, art, 3.0), N.rtest_program(m, [dict(e, setup="K4)\nG0 X999")
                                                                              for e in _rtest_plan(m)])]
    hal = L.hal_text(KINS, {"x-rot-point": 0.1}, header="machine a\\\nsetp xyzac-trt-kins.y-rot-point 5")
    for prog in progs:
        for ln, line in enumerate(gcode.split_lines(prog), 1):
            words = gcode.tokenize(line.rstrip("\n"), "prog", ln)
            assert not any(w.letter == "X" and w.value == 999 for w in words), line
    assert [ln for ln in hal.splitlines() if not ln.startswith("#")] == ["setp xyzac-trt-kins.x-rot-point 0.1"]


def MACHINES_KINS():
    from test_linuxcnc import MACHINES
    return MACHINES[KINS]
