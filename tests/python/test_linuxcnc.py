"""fivecal against a real LinuxCNC (Debian's linuxcnc-uspace, headless
simulator started by linuxcnc_harness.py): the pins fivecal exports make
LinuxCNC's tool-centre-point kinematics command exactly the joints of
fivecal's inverse kinematics of the same model, and a compensation file
fivecal writes makes it command the expected motor positions.

The simulator tests are skipped only when LinuxCNC is not installed; CI
installs it (scripts/install.sh). One simulator session per kinematics."""
import numpy as np
import pytest

import fivecal
from fivecal.io import linuxcnc as L

import linuxcnc_harness as harness

REASON = harness.unavailable_reason()
needs_linuxcnc = pytest.mark.skipif(REASON is not None, reason=f"needs LinuxCNC: {REASON}")

MACHINES = {
    # LinuxCNC's own rotary directions (+x, +z), pivots off the table centre
    "xyzac-trt": {"name": "trt-ac", "topology": "wCAfXYZSt", "axes": {
        "C": {"type": "rotary", "direction": [0, 0, 1], "point": [12, -7, 0]},
        "A": {"type": "rotary", "direction": [1, 0, 0], "point": [0, 20, -45]},
        "X": {"type": "linear", "direction": [1, 0, 0]},
        "Y": {"type": "linear", "direction": [0, 1, 0]},
        "Z": {"type": "linear", "direction": [0, 0, 1]},
        "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [0, 0, 150]}},
    # ISO table C (about -z): LinuxCNC's C joint is fivecal's -C
    "xyzbc-trt": {"name": "trt-bc", "topology": "wCBfXYZSt", "axes": {
        "C": {"type": "rotary", "direction": [0, 0, -1], "point": [4, 9, 0]},
        "B": {"type": "rotary", "direction": [0, 1, 0], "point": [-30, 0, -60]},
        "X": {"type": "linear", "direction": [1, 0, 0]},
        "Y": {"type": "linear", "direction": [0, 1, 0]},
        "Z": {"type": "linear", "direction": [0, 0, 1]},
        "S": {"type": "rotary", "direction": [0, 0, 1]}}, "tool": {"tip": [1, 2, 100]}},
}
# Thesis-sized location errors of the rotary axes' positions (tens of um).
ERRORS = {
    "xyzac-trt": {"EX0C": 0.0312, "EY0C": -0.0187, "EY0A": 0.0241, "EZ0A": -0.0153},
    "xyzbc-trt": {"EX0C": -0.0226, "EY0C": 0.0174, "EX0B": 0.0291, "EZ0B": -0.0138},
}


def _poses(kins, n=60, seed=11):
    """World targets (LinuxCNC X Y Z) and joint angles across the rotary ranges."""
    rng = np.random.default_rng(seed)
    w = rng.uniform(-60, 60, (n, 3))
    tilt = rng.uniform(-90, 90, n)
    c = rng.uniform(-180, 180, n)
    # not tilt 0 exactly: there the tool axis lies along C, C is free and an
    # inverse may return any C (fivecal's does, by a few millidegrees)
    tilt[:4] = [-90, 90, 20, 45]
    c[:4] = [-180, 180, 0, -90]
    return w, tilt, c


def _mdi(kins, w, t, c):
    r = L.TILT[kins]
    return [f"G1 X{x!r} Y{y!r} Z{z!r} {r}{a!r} C{cc!r} F100000"
            for (x, y, z), a, cc in zip(w.tolist(), t.tolist(), c.tolist())]


def _fivecal_joints(m, kins, errors, ab, w, tilt, c):
    """fivecal's inverse kinematics of the erroneous machine for the same
    targets, as LinuxCNC joints."""
    mp = L.match(m, kins)
    s_t, s_c = mp["sign"][3], mp["sign"][4]
    r = L.TILT[kins]
    names = m.axis_names
    out = []
    for i in range(len(w)):
        rot = {r: tilt[i] / s_t, "C": c[i] / s_c}
        start = {a: 0.0 for a in names if a != "S"}
        start.update(rot)
        # the tool axis the erroneous machine has at these angles
        _, axis = m.tool_pose(start, errors=errors)
        target = w[i] + np.asarray(mp["origin"]) + ab.workpiece_shift
        q = m.inverse(target[None, :], tool_axes=axis, start=start, errors=errors)
        out.append(L.joints(m, kins, q)[0])
    return np.array(out)


@needs_linuxcnc
@pytest.mark.parametrize("kins", ["xyzac-trt", "xyzbc-trt"])
def test_round_trip_in_linuxcnc(kins):
    m = fivecal.Machine.from_dict(MACHINES[kins])
    errors = ERRORS[kins]
    ab = L.absorb(m, kins, errors)
    assert ab.max < 1e-9, "these location errors are exactly representable by the pins"
    assert ab.max_old > 0.01
    w, tilt, c = _poses(kins)
    pins = [f"{kins}-kins.{n}" for n in L.pin_names(kins)]
    with harness.Sim(kins, hal=L.hal_text(kins, ab.pins, ab.old_pins)) as sim:
        out = sim.run(_mdi(kins, w, tilt, c), setup=["M428"], hal_pins=pins)
    assert out["errors"] == []
    # fivecal's pins are what LinuxCNC runs with
    np.testing.assert_allclose(out["hal_start"], [ab.pins[n] for n in L.pin_names(kins)],
                               rtol=0, atol=1e-12)
    got = np.array(out["joints"])
    assert got.shape == (60, 5)
    want = _fivecal_joints(m, kins, errors, ab, w, tilt, c)
    dlin = np.abs(got[:, :3] - want[:, :3]).max()
    drot = np.abs(got[:, 3:] - want[:, 3:]).max()
    assert dlin < 1e-6, f"linear joints differ by {dlin} mm"
    assert drot < 1e-6, f"rotary joints differ by {drot} deg"
    # and LinuxCNC's formulas as fivecal transcribes them
    world = np.column_stack([w, tilt, c])
    np.testing.assert_allclose(got, L.inverse(kins, ab.pins, world), rtol=0, atol=1e-9)
    # TCP really was on: identity kinematics would command the world values
    assert np.abs(got[:, :3] - w).max() > 10


@needs_linuxcnc
def test_compensation_file_loaded_by_linuxcnc():
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    errors = {"EXX1": 2e-4, "EXX2": -1e-6, "EXXb": 0.004}
    rows = L.comp_rows(m, kins, errors, "X", -100, 100, 10)
    text = L.comp_text(rows)
    # Approached upward at -50, 0 and 70, then downward at 30. LinuxCNC
    # freezes the correction at the last servo cycle that still moved, so the
    # last 10 um go at 1 mm/min: that cycle is then within 2e-5 mm of the point.
    points = [(-50, 1), (0, 1), (70, 1), (30, -1)]
    moves = ["G1 X-80 F100000"]
    for x, d in points:
        moves += [f"G1 X{x - 0.01 * d} F100000", f"G1 X{x} F1"]
    with harness.Sim(kins, joint_ini={0: ["COMP_FILE = comp-X.txt", "COMP_FILE_TYPE = 0"]},
                     files={"comp-X.txt": text}) as sim:
        out = sim.run(moves, setup=[], hal_pins=["joint.0.motor-pos-cmd", "joint.0.pos-cmd"],
                      settle=0.2)
    hal = np.array(out["hal"])[2::2]
    motor, joint = hal[:, 0], hal[:, 1]
    np.testing.assert_allclose(joint, [x for x, _ in points], rtol=0, atol=1e-9)

    def actual(x, direction):
        # X on the tool side along +x: joint = command, error along itself
        e = 2e-4 * x - 1e-6 * x ** 2
        return x + e + direction * 0.004

    # LinuxCNC commands the motor to nominal + (nominal - actual)
    for i, (x, d) in enumerate(points):
        expect = 2 * x - actual(x, d)
        assert abs(motor[i] - expect) < 1e-6, (x, d, motor[i], expect)
    assert abs(motor[2] - 70) > 0.01  # the file really was applied


def test_hal_and_ini_lines_read_back():
    kins = "xyzbc-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    ab = L.absorb(m, kins, ERRORS[kins])
    text = L.hal_text(kins, ab.pins, ab.old_pins)
    assert "setp xyzbc-trt-kins.x-offset" in text and "old" in text
    assert "y-offset" not in text  # not a pin of xyzbc-trt-kins
    import tempfile, os
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "k.hal")
        with open(p, "w") as f:
            f.write(text)
        back = L.read_hal_pins(p, kins)
    assert back == {n: v for n, v in ab.pins.items() if n not in L.HELD}  # exact decimal text
    assert "z-offset = 0.000000 is held" in text
    ini, hal = L.ini_text(kins, ab.pins)
    assert "X_ROT_POINT = " in ini and "setp xyzbc-trt-kins.x-rot-point [FIVECAL_KINS]X_ROT_POINT" in hal


def test_tilts_are_not_absorbed_and_residual_reported():
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    ab = L.absorb(m, kins, dict(ERRORS[kins], EB0C=5e-5, EA0A=-4e-5))
    assert 1e-4 < ab.max < ab.max_old
    assert ab.rms < ab.rms_old
    regions = ab.by_region("A", bins=3)
    assert len(regions) == 3 and all(r[3] <= ab.max + 1e-15 for r in regions)


def test_plausibility_limit_refuses_large_change():
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    ab = L.absorb(m, kins, {"EX0C": 0.8})
    with pytest.raises(fivecal.guards.CorrectionLimitError, match="x-rot-point"):
        L.check_change(ab.old_pins, ab.pins, 0.5)
    L.check_change(ab.old_pins, ab.pins, 0.5, force=True)
    L.check_change(ab.old_pins, ab.pins, 1.0)


def test_machine_that_does_not_fit_is_refused():
    with pytest.raises(ValueError, match="xyzac-trt"):
        L.match(fivecal.Machine.load("examples/machines/hu40t.json"), "xyzac-trt")
    with pytest.raises(ValueError, match="kins"):
        L.match(fivecal.Machine.from_dict(MACHINES["xyzac-trt"]), "5axiskins")


def _write_inputs(tmp_path, errors, result_extra=None):
    import json

    mp = tmp_path / "machine.json"
    mp.write_text(json.dumps(MACHINES["xyzac-trt"]))
    res = {"parameters": {k: {"value": v, "std": 1e-4} for k, v in errors.items()},
           "converged": True, "residual_rms": 0.0005, "n_observations": 200,
           "n_parameters": len(errors), "rank": len(errors), "condition_number": 10.0,
           "unidentifiable": [], "iterations": 5}
    res.update(result_extra or {})
    rp = tmp_path / "result.json"
    rp.write_text(json.dumps(res))
    return str(mp), str(rp)


def test_cli_export_linuxcnc(tmp_path):
    from fivecal.cli import main

    mp, rp = _write_inputs(tmp_path, dict(ERRORS["xyzac-trt"], EXX1=2e-5, EXXb=0.003, EB0C=3e-5))
    out = tmp_path / "lcnc"
    assert main(["export", "linuxcnc", rp, "--machine", mp, "--kins", "xyzac-trt",
                 "--out", str(out), "--comp-step", "10"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["comp-X.txt", "fivecal-kins-ini.hal", "fivecal-kins.hal", "fivecal-kins.ini",
                     "linuxcnc-report.txt"]
    pins = L.read_hal_pins(str(out / "fivecal-kins.hal"), "xyzac-trt")
    m = fivecal.Machine.from_dict(MACHINES["xyzac-trt"])
    nominal = L.nominal_pins(m, "xyzac-trt")
    assert abs(pins["x-rot-point"] - nominal["x-rot-point"] - 0.0312) < 2e-3
    rows = np.loadtxt(out / "comp-X.txt")
    assert rows.shape == (21, 3) and rows[0, 0] == -100 and rows[-1, 0] == 100
    report = (out / "linuxcnc-report.txt").read_text()
    assert "EB0C" in report and "COMP_FILE = comp-X.txt" in report
    # what fivecal's G-code compensation removes on top of the pins: all of it
    line = next(x for x in report.splitlines() if "G-code compensation on top" in x)
    left = float(line.split("max ")[1].split()[0])
    assert left < 0.01, line
    pins_max = float(next(x for x in report.splitlines() if "new pins rms" in x).split("max ")[-1].split()[0])
    assert pins_max > 1.0  # um: the tilt EB0C is left by the pins
    # the old pins from a file: unchanged pins give a zero change
    assert main(["export", "linuxcnc", rp, "--machine", mp, "--kins", "xyzac-trt", "--out",
                 str(tmp_path / "again"), "--old", str(out / "fivecal-kins.hal")]) == 0
    again = L.read_hal_pins(str(tmp_path / "again" / "fivecal-kins.hal"), "xyzac-trt")
    assert max(abs(again[k] - pins[k]) for k in pins) < 1e-9
    assert set(pins) == {"x-rot-point", "y-rot-point", "z-rot-point", "y-offset"}


def test_cli_export_refuses(tmp_path, capsys):
    from fivecal.cli import main

    mp, rp = _write_inputs(tmp_path, ERRORS["xyzac-trt"], {"converged": False})
    args = ["export", "linuxcnc", rp, "--machine", mp, "--kins", "xyzac-trt", "--out", str(tmp_path / "o")]
    assert main(args) == 2
    assert "refusing" in capsys.readouterr().err
    assert not (tmp_path / "o" / "fivecal-kins.hal").exists()
    mp, rp = _write_inputs(tmp_path, {"EX0C": 0.8})
    args = ["export", "linuxcnc", rp, "--machine", mp, "--kins", "xyzac-trt", "--out", str(tmp_path / "o")]
    assert main(args) == 2
    assert "x-rot-point" in capsys.readouterr().err
    assert main(args + ["--max-change", "1.0"]) == 0
    assert main(["export", "linuxcnc", rp, "--machine", "examples/machines/hu40t.json", "--kins",
                 "xyzac-trt", "--out", str(tmp_path / "p")]) == 2


# Thesis-sized location errors of both rotary axes, tilts included: the pins
# absorb the positions, not the tilts.
FULL_ERRORS = {"EX0C": 0.0312, "EY0C": -0.0187, "EA0C": 2.1e-5, "EB0C": -1.6e-5,
               "EY0A": 0.0241, "EZ0A": -0.0153, "EB0A": 1.2e-5, "EC0A": -2.4e-5}


@needs_linuxcnc
def test_absorption_and_gcode_compensation_in_linuxcnc():
    """LinuxCNC with the absorbing pins leaves exactly the error map fivecal
    predicts; fivecal's compensation (inverse kinematics on the identified
    model, sent as TCP world moves) brings the tool point below 1 um."""
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    ab = L.absorb(m, kins, FULL_ERRORS)
    assert 1e-3 < ab.max < ab.max_old
    n = 50
    w, tilt, c = _poses(kins, n, seed=5)
    world = np.column_stack([w, tilt, c])
    mp = L.match(m, kins)
    target = w + np.asarray(mp["origin"]) + ab.workpiece_shift
    # compensated moves: the commands that put the erroneous machine's tool at
    # the target with the nominal tool axis, as LinuxCNC world moves
    comp = []
    for i in range(n):
        start = {"X": 0.0, "Y": 0.0, "Z": 0.0, "A": tilt[i], "C": c[i]}
        _, axis = m.tool_pose(start)
        q = m.inverse(target[i][None, :], tool_axes=axis, start=start, errors=FULL_ERRORS)
        j = L.joints(m, kins, q)
        comp.append(np.concatenate([L.forward(kins, ab.pins, j)[0], j[0, 3:]]))
    comp = np.array(comp)
    moves = _mdi(kins, w, tilt, c) + _mdi(kins, comp[:, :3], comp[:, 3], comp[:, 4])
    with harness.Sim(kins, hal=L.hal_text(kins, ab.pins)) as sim:
        out = sim.run(moves, setup=["M428"])
    got = np.array(out["joints"])
    plain, compensated = got[:n], got[n:]
    err = L.tool_point_error(m, kins, FULL_ERRORS, ab.pins, ab.workpiece_shift, plain, w)
    predicted = L.tool_point_error(m, kins, FULL_ERRORS, ab.pins, ab.workpiece_shift,
                                   L.inverse(kins, ab.pins, world), w)
    assert np.abs(err - predicted).max() < 1e-9
    size = np.linalg.norm(err, axis=1)
    assert size.max() > 1e-3  # the tilts leave micrometres
    assert size.max() <= 1.5 * ab.max  # within what the volume fit reported
    left = L.tool_point_error(m, kins, FULL_ERRORS, ab.pins, ab.workpiece_shift, compensated, w)
    assert np.linalg.norm(left, axis=1).max() < 1e-3


def _octagon():
    """A convex octagonal prism on the table: the top face and eight sides."""
    facets = [{"id": "TOP", "point": [0, 0, 60], "normal": [0, 0, 1]}]
    for k in range(8):
        a = np.radians(45 * k)
        n = [float(np.cos(a)), float(np.sin(a)), 0.0]
        facets.append({"id": f"S{k}", "point": [80 * n[0], 80 * n[1], 30.0], "normal": n})
    return {"facets": facets}


def _probe_plan(m, art):
    """Touches at 16 indexations (A -60..30, C every 90 deg) on the facets
    facing the probe."""
    out = []
    for a in (-60, -30, 0.5, 30):
        for c in (0, 90, 180, 270):
            axes = {"A": a, "C": c, "X": 0, "Y": 0, "Z": 0}
            _, v = m.tool_pose(axes)
            for f in art["facets"]:
                n = np.array(f["normal"])
                if n @ v[0] < -0.05:
                    continue
                pts = [f["point"]]
                if f["id"] == "TOP":
                    pts = [[40, 0, 60.0], [0, 40, 60.0], [-40, -20, 60.0]]
                out += [{"type": "facet", "target": f["id"], "axes": {"A": a, "C": c},
                         "point": list(map(float, p))} for p in pts]
    return out


TRUE_LOCATION = {"EX0C": 0.0312, "EY0C": -0.0187, "EA0C": 2.1e-5, "EB0C": -1.6e-5,
                 "EY0A": 0.0241, "EZ0A": -0.0153, "EB0A": 1.2e-5, "EC0A": -2.4e-5}


def test_probing_program_and_log_reader_offline():
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    art = _octagon()
    plan = _probe_plan(m, art)
    pins = L.nominal_pins(m, kins)
    # a sphere beside the facets: this cycle's lifts would not avoid it, so it refuses
    with pytest.raises(ValueError, match=r"1 sphere\(s\).*touch_program"):
        L.probing_program(m, kins, plan, {**art, "spheres": [{"id": "S1", "centre": [0, 0, 50], "radius": 10}]},
                          3.0)
    prog = L.probing_program(m, kins, plan, art, 3.0)
    assert prog.count("G38.2") == len(plan) and "(PROBEOPEN probe-log.txt)" in prog
    # a log of the nominal contact points reads back as the planned indexations
    geo = L._touch_geometry(m, kins, plan, art, 3.0)
    log = "".join(f"{w[0]:f} {w[1]:f} {w[2]:f} {t:f} 0 {c:f} 0 0 0\n" for t, c, w, _, _ in geo)
    obs = L.read_probe_log(log, m, kins, plan, pins)
    assert len(obs) == len(plan)
    assert all(abs(o["axes"]["A"] - p["axes"]["A"]) < 1e-6 for o, p in zip(obs, plan))
    with pytest.raises(ValueError, match="planned touches"):
        L.read_probe_log(log.split("\n", 1)[1], m, kins, plan, pins)
    with pytest.raises(ValueError, match=":2: expected 9"):
        L.read_probe_log(log.replace("\n", "\n1 2\n", 1), m, kins, plan, pins)
    # the depth check finds a touch that tripped late (0.1 mm into the facet)
    d = L.probe_depths(m, kins, plan, art, 3.0, log, pins)
    assert np.abs(d).max() < 1e-5
    t, c, w, n, _ = geo[5]
    late = log.splitlines()
    late[5] = " ".join(f"{v:f}" for v in (*(w - 0.1 * n), t, 0, c, 0, 0, 0))
    d = L.probe_depths(m, kins, plan, art, 3.0, "\n".join(late) + "\n", pins)
    assert abs(d[5] + 0.1) < 1e-5 and np.abs(np.delete(d, 5)).max() < 1e-5
    # the simulator's probe planes go in at the start point: after the sync
    # line that stops the read-ahead there, before the arming line
    planes = L.probe_sim_lines(m, kins, plan, art, 3.0)
    prog = L.probing_program(m, kins, plan, art, 3.0, sync="M66 E0 L0", arm="M64 P0",
                             before_probe=planes)
    lines = prog.splitlines()
    arms = [i for i, x in enumerate(lines) if x == "M64 P0"]
    assert len(arms) == len(plan)
    assert all(lines[i - 5] == "M66 E0 L0" and lines[i - 4].startswith("M68 E4 Q")
               and lines[i - 1].startswith("M68 E7 Q") and lines[i + 1].startswith("G38.2")
               and lines[i - 6].startswith("G0 ") for i in arms)
    with pytest.raises(ValueError, match="before_probe"):
        L.probing_program(m, kins, plan, art, 3.0, before_probe=planes[1:])


@needs_linuxcnc
def test_probing_program_runs_in_linuxcnc_and_identifies():
    """A generated G38.2 program runs in the simulator with a simulated probe
    input that trips at the erroneous machine's artefact surface; LinuxCNC's
    probe log goes back through fivecal's reader into an identification that
    recovers the injected location errors."""
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    art = _octagon()
    plan = _probe_plan(m, art)
    pins = L.nominal_pins(m, kins)  # the controller does not know the errors
    # the simulated probe trips in the first 1 ms servo cycle inside the
    # touched facet's plane (loaded by M68 and armed by M64 while the machine
    # stands at the start point; the trigger itself runs in the servo thread)
    planes = L.probe_sim_lines(m, kins, plan, art, 3.0, errors=TRUE_LOCATION)
    # 10 mm/min: 0.17 um per 1 ms servo cycle. The trip depth's quantisation
    # depends on where the surface falls in the cycle grid, i.e. on the
    # errors themselves: at 30 mm/min (0.5 um) that biased EB0C by 3 urad
    prog = L.probing_program(m, kins, plan, art, 3.0, clearance=0.05, overtravel=0.3, feed=10,
                             sync="M66 E0 L0", arm="M64 P0", disarm="M65 P0", before_probe=planes)
    hal = L.hal_text(kins, pins) + L.probe_sim_hal()
    with harness.Sim(kins, hal=hal, files={"probe.ngc": prog}) as sim:
        out = sim.run([], setup=[], program="probe.ngc", program_timeout=400)
        log = sim.read("probe-log.txt")
    assert out["errors"] == []
    # each trip against the simulated surface: 1 to 2 servo cycles of feed
    # deep (the chain's output reaches motion one cycle later); a late arm
    # (before the fix: M62 synchronised with the G38.2 came on while the
    # probe move already ran, up to 0.5 s late on a busy machine) shows here
    depth = L.probe_depths(m, kins, plan, art, 3.0, log, pins, errors=TRUE_LOCATION)
    late = [(i + 1, plan[i]["target"], round(1000 * d, 2)) for i, d in enumerate(depth)
            if not -0.4e-3 <= d <= 1e-6]
    assert not late, f"touches (number, facet, depth um) not tripped at the surface: {late}"
    obs = L.read_probe_log(log, m, kins, plan, pins)
    for o in obs:
        o["sigma"] = 0.001
    ds = fivecal.Dataset.from_dict({"machine": m.to_dict(), "probe": {"tip_radius": 3.0},
                                    "artefact": art, "observations": obs})
    # the stylus is calibrated separately: its offsets are not in this plan's reach
    r = fivecal.identify(ds, estimate=list(TRUE_LOCATION), fix=["tip.x", "tip.y", "tip.z"])
    assert r.converged and r.rms < 0.002
    # the trip point is quantised by the 1 ms servo cycle (0.17 um at 10 mm/min),
    # a deterministic error the fit's sigma does not describe: compare with
    # absolute bounds far below the injected 15-31 um and 12-24 urad
    for name, truth in TRUE_LOCATION.items():
        tol = 2e-6 if name[1] in "ABC" else 1e-3  # rad / mm
        assert abs(r.values[name] - truth) < tol, (name, r.values[name], truth, r.std[name])


@pytest.mark.parametrize("topology,axis,direction", [
    ("wCAfXYZSt", "X", [-1, 0, 0]),   # tool side, reversed: joint = -command
    ("wCAYfXZSt", "Y", [0, -1, 0]),   # table side: the tool moves the other way
])
def test_comp_rows_match_the_kinematics(topology, axis, direction):
    d = {k: dict(v) for k, v in MACHINES["xyzac-trt"]["axes"].items()}
    d[axis]["direction"] = direction
    m = fivecal.Machine.from_dict({"name": "c", "topology": topology, "axes": d,
                                   "tool": {"tip": [0, 0, 150]}})
    kins = "xyzac-trt"
    errors = {f"E{axis}{axis}1": 3e-4, f"E{axis}{axis}2": 2e-6, f"E{axis}{axis}b": 0.005}
    rows = L.comp_rows(m, kins, errors, axis, -100, 100, 25)
    k = "XYZ".index(axis)
    for nominal, fwd, rev in rows:
        for col, jdir in ((fwd, 1), (rev, -1)):
            q = L.commands(m, kins, [[nominal if i == k else 0.0 for i in range(5)]])
            qdir = int(np.sign(L.match(m, kins)["sign"][k])) * jdir
            p = m.tool_point(q, errors=errors, directions={axis: [qdir]})[0]
            # the joint value at which the error-free machine puts the tool there
            j_of = lambda j: m.tool_point(L.commands(m, kins, [[j if i == k else 0.0 for i in range(5)]]))[0][k]
            slope = j_of(1.0) - j_of(0.0)
            actual = (p[k] - j_of(0.0)) / slope
            assert abs(actual - col) < 1e-9, (nominal, jdir, actual, col)


def test_bindings_refuse_bad_input():
    with pytest.raises(ValueError, match="joints"):
        L.forward("xyzac-trt", {}, np.zeros((2, 4)))
    with pytest.raises(ValueError, match="x-offset"):
        L.inverse("xyzac-trt", {"x-offset": 1.0}, np.zeros((1, 5)))
    with pytest.raises(ValueError, match="not finite|finite"):
        L.inverse("xyzac-trt", {"x-rot-point": float("nan")}, np.zeros((1, 5)))
    m = fivecal.Machine.from_dict(MACHINES["xyzac-trt"])
    q = L.pose_grid(m, "xyzac-trt", {"A": (0, 0)})
    with pytest.raises(ValueError, match="rotary angles"):
        L.absorb(m, "xyzac-trt", {}, poses=q, old_pins={})


def _sphere_cycle(m):
    """A sphere check's plan on a small point set: A and C at three
    positions each, up and down (both sides of every position)."""
    from fivecal.procedures import sphere_test
    ball = {"id": "S1", "center": [60.0, 30.0, 40.0], "radius": 12.5}
    visits = []
    for a, vals in (("A", [-60.0, -15.0, 30.0]), ("C", [-120.0, 0.0, 120.0])):
        visits += [{a: v} for v in vals] + [{a: v} for v in vals[::-1]]
    plan = sphere_test.sphere_plan(m, ball, visits, tip_radius=3.0,
                                   rings=[(0.0, 4), (45.0, 4), (90.0, 1)])
    return {"spheres": [ball]}, plan


@needs_linuxcnc
def test_sphere_cycle_runs_in_linuxcnc_and_identifies():
    """The G38.2 sphere cycle fivecal writes for a sphere check runs in the
    simulator; the simulated probe trips where each probe line meets the
    sphere on the erroneous machine (tangent plane there, reversal error of C
    included); the log, read back, gives the pivots and the reversal error."""
    from fivecal.io import nc_programs as N
    from fivecal.procedures import sphere_check
    kins = "xyzac-trt"
    m = fivecal.Machine.from_dict(MACHINES[kins])
    art, plan = _sphere_cycle(m)
    pins = L.nominal_pins(m, kins)
    errors = dict(TRUE_LOCATION, ECCb=3e-5)
    opts = dict(clearance=0.05, overtravel=0.3)
    planes = N.sphere_sim_lines(m, kins, plan, art, 3.0, pins, errors=errors, **opts)
    prog = N.sphere_program(m, kins, plan, art, 3.0, feed=10, sync="M66 E0 L0", arm="M64 P0",
                            disarm="M65 P0", before_probe=planes, **opts)
    with harness.Sim(kins, hal=L.hal_text(kins, pins) + L.probe_sim_hal(),
                     files={"sphere.ngc": prog}) as sim:
        out = sim.run([], setup=[], program="sphere.ngc", program_timeout=400)
        log = sim.read("probe-log.txt")
    assert out["errors"] == []
    # every trip 0 to 2 servo cycles (0.17 um each at 10 mm/min) past the
    # crossing fivecal's model predicts, along the probe line
    model = N.sphere_trigger_model(m, kins, plan, art, 3.0, pins, errors=errors, **opts)
    got = np.array([[float(v) for v in ln.split()[:3]] for ln in log.splitlines() if ln.strip()])
    assert got.shape == (len(plan), 3)
    lag = np.linalg.norm(got - np.array([p["world"] for p in model]), axis=1)
    assert lag.max() < 0.5e-3, f"touches off the modelled crossing: {np.flatnonzero(lag >= 0.5e-3) + 1}"
    obs = L.read_probe_log(log, m, kins, plan, pins)
    ds = fivecal.Dataset.from_dict({"machine": m.to_dict(), "probe": {"tip_radius": 3.0},
                                    "artefact": art, "observations": obs})
    chk = sphere_check.evaluate(ds)
    got = chk.values()
    for name, truth in sphere_check.spindle_names(m, errors).items():
        tol = 3e-6 if name[1] in "ABC" else 1e-3  # rad / mm; servo-cycle quantisation
        assert abs(got[name] - truth) < tol, (name, got[name], truth)


@needs_linuxcnc
def test_mixed_facet_and_sphere_program_runs_in_linuxcnc_and_identifies():
    """TANGO rows with the octagonal table's facets and the scale bar's balls
    (Table 4-2 rows 1, 7, 13, 17, 22 on the HU40T-like machine, xyzbc-trt)
    as one G38.2 program: it runs in the simulator with a probe that trips at
    each touch's own target on the machine with location errors (the facet's
    plane or the plane tangent to the ball where the probe line meets it);
    the log, read back with the plan, gives facet and sphere touches from
    which identify recovers the errors within 3 sigma."""
    from fivecal.io import nc_programs as N
    from fivecal.procedures import tango
    from test_nc_programs import TANGO_ERRORS, check_touch_program
    kins = "xyzbc-trt"
    m, art = tango.hu40t_machine(), tango.octagonal_table()
    plan = tango.hu40t_plan(art, m, rows=[0, 6, 12, 16, 21])
    assert {e["type"] for e in plan} == {"facet", "sphere"}
    errors = {k: v for k, v in TANGO_ERRORS.items() if k != "ECCb"}
    pins = L.nominal_pins(m, kins)
    # the errors move the contacts up to 0.06 mm along the probe lines here
    opts = dict(clearance=0.1, overtravel=0.2)
    planes = N.touch_sim_lines(m, kins, plan, art, 3.0, pins, errors=errors, **opts)
    prog = N.touch_program(m, kins, plan, art, 3.0, feed=10, sync="M66 E0 L0", arm="M64 P0",
                           disarm="M65 P0", before_probe=planes, **opts)
    check_touch_program(m, kins, plan, art, prog, 3.0, opts["clearance"], opts["overtravel"])
    with harness.Sim(kins, hal=L.hal_text(kins, pins) + L.probe_sim_hal(),
                     files={"mixed.ngc": prog}) as sim:
        out = sim.run([], setup=[], program="mixed.ngc", program_timeout=600)
        log = sim.read("probe-log.txt")
    assert out["errors"] == []
    # every trip 0 to 2 servo cycles (0.17 um each at 10 mm/min) past the
    # crossing fivecal's model predicts, facet and sphere touches alike
    model = N.touch_trigger_model(m, kins, plan, art, 3.0, pins, errors=errors, **opts)
    got = np.array([[float(v) for v in ln.split()[:3]] for ln in log.splitlines() if ln.strip()])
    assert got.shape == (len(plan), 3)
    lag = np.linalg.norm(got - np.array([p["world"] for p in model]), axis=1)
    assert lag.max() < 0.5e-3, f"touches off the modelled crossing: {np.flatnonzero(lag >= 0.5e-3) + 1}"
    obs = L.read_probe_log(log, m, kins, plan, pins)
    assert [(o["type"], o["target"]) for o in obs] == [(e["type"], e["target"]) for e in plan]
    for o in obs:
        o["sigma"] = tango.PROBE_SIGMA
    ds = fivecal.Dataset.from_dict({"machine": m.to_dict(), "probe": {"tip_radius": 3.0},
                                    "artefact": art, "observations": obs})
    r = fivecal.identify(ds, estimate=list(errors), fix=["tip.x", "tip.y", "tip.z"])
    assert r.converged
    for name, truth in errors.items():
        assert abs(r.values[name] - truth) < 3 * r.std[name], (name, r.values[name], truth, r.std[name])
