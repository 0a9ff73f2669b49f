"""Compensation: poses, G-code, error tables (issue 6, item 4).

Must show: compensation leaves under 1e-6 mm of tool-point error on the
simulated erroneous machine, and G-code round-trips byte for byte when the
errors are zero.
"""
import csv
import io
import json
import os
import re

import numpy as np
import pytest

import fivecal
from fivecal.procedures import tango
from fivecal.compensation import (SIGN_CONVENTION, compensate_gcode, compensate_gcode_file,
                                  compensate_poses, error_table, load_errors, write_error_table)

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
MACHINES = os.path.join(ROOT, "examples", "machines")
PROGRAM = os.path.join(ROOT, "examples", "gcode", "hu40t_5axis.nc")


def machine(name):
    return fivecal.Machine.load(os.path.join(MACHINES, f"{name}.json"))


def random_poses(m, n, seed=0, rotary_range=(-80, 80)):
    rng = np.random.default_rng(seed)
    axes = {}
    for a in m.axis_names:
        if a == "S":
            continue
        axes[a] = rng.uniform(*rotary_range, n) if a in "ABC" else rng.uniform(-200, 200, n)
    return axes


def big_errors(m, seed=1):
    """Location errors, error motions and backlash of realistic size on any machine."""
    rng = np.random.default_rng(seed)
    e = {}
    for name in m.parameter_names():
        kind = m.parameter_kind(name)
        if kind == "tip":
            continue
        ang = m.parameter_is_angular(name)
        if kind == "location":
            e[name] = rng.normal(0, 30e-6 if ang else 0.05)
        elif kind == "backlash":
            e[name] = rng.normal(0, 10e-6 if ang else 0.005)
        elif name.endswith("1"):
            comp_angular = name[1] in "ABC"
            axis_rotary = name[2] in "ABCS"
            # mm/mm and rad/rad ~ 20e-6; rad/mm ~ 1e-7 (40 µrad over 400 mm); mm/rad ~ 5 µm/rad
            scale = {(False, False): 20e-6, (True, True): 20e-6, (True, False): 1e-7,
                     (False, True): 5e-3}[(comp_angular, axis_rotary)]
            e[name] = rng.normal(0, scale)
    return e


# ---------------------------------------------------------------- poses
@pytest.mark.parametrize("name", ["hu40t", "c600u", "kx8", "vmc0656"])
def test_compensated_poses_leave_under_1nm(name):
    m = machine(name)
    errors = big_errors(m)
    axes = random_poses(m, 300, seed=3)
    comp = compensate_poses(m, errors, axes)
    assert comp.max_before() > 0.02            # the errors matter (tens of µm)
    assert comp.max_remaining() < 1e-6         # and are compensated
    # independent check through the public forward kinematics
    real = m.tool_point(comp.axes, errors=errors)
    nominal = m.tool_point(axes)
    assert np.abs(real - nominal).max() < 1e-6
    # where the tool axis was compensated too, it is back on its nominal direction
    assert comp.orientation.mean() > 0.9
    assert comp.axis_error_remaining[comp.orientation].max() < 1e-9
    assert comp.axis_error_before.max() > 1e-5
    # the compensated commands stay next to the nominal ones (same solution branch)
    for a in axes:
        assert np.abs(comp.axes[a] - np.asarray(axes[a])).max() < (0.2 if a in "ABC" else 1.0)


def test_compensation_with_backlash_uses_directions():
    m = machine("hu40t")
    errors = {"EXXb": 0.008, "EYYb": -0.004, "ECCb": 40e-6, "EX0C": -0.1}
    axes = random_poses(m, 50, seed=5)
    dirs = {a: np.where(np.arange(50) % 2 == 0, 1.0, -1.0) for a in "XYC"}
    comp = compensate_poses(m, errors, axes, directions=dirs)
    real = m.tool_point(comp.axes, errors=errors, directions=dirs)
    assert np.abs(real - m.tool_point(axes)).max() < 1e-6
    # ignoring the directions would leave the backlash in
    wrong = compensate_poses(m, errors, axes)
    real_wrong = m.tool_point(wrong.axes, errors=errors, directions=dirs)
    assert np.abs(real_wrong - m.tool_point(axes)).max() > 1e-3


def test_singular_pose_falls_back_to_tool_point_only():
    m = machine("hu40t")
    errors = tango.thesis_s3_errors()
    axes = {"X": [10.0, 10.0], "Y": [20.0, 20.0], "Z": [-10.0, -10.0], "B": [0.0, 30.0], "C": [0.0, 0.0]}
    comp = compensate_poses(m, errors, axes)
    assert comp.max_remaining() < 1e-6
    assert list(comp.orientation) == [False, True]  # B = 0: tool axis along the C axis
    assert comp.axes["B"][0] == 0.0 and comp.axes["C"][0] == 0.0
    only = compensate_poses(m, errors, axes, orientation=False)
    assert not only.orientation.any() and only.max_remaining() < 1e-6


def test_probe_tip_and_setup_parameters_are_not_applied():
    m = machine("hu40t")
    res = {"parameters": {"EX0C": {"value": 0.01, "std": 1e-4}, "tip.x": {"value": 0.5, "std": 1e-3},
                          "facet.F3": {"value": 0.2, "std": 1e-3}}}
    assert load_errors(res, m) == {"EX0C": 0.01}
    with pytest.raises(ValueError, match="EQ0C"):
        load_errors({"EQ0C": 1.0}, m)


# ---------------------------------------------------------------- G-code
TRICKY = (
    "%\r\n"
    "O0042 (tricky: CRLF, lower case, comments with X1 Y2 words)\r\n"
    "n10 g21 g90 g54\r\n"
    "N20 G0 X0 Y0 Z100. B0 C0 (start)\r\n"
    "N30 G1X10.5Y-3Z50.25F500 ; glued words, X9 in a comment\r\n"
    "N40\tx+20.000\ty.5\tz40 b15. c-30.5\r\n"
    "N50 Y12.345678 M8   \r\n"
    "/N60 G0 Z120. (block delete) \r\n"
    "N70 G4 X1.5 (dwell, not a move)\r\n"
    "N80 G0 B30 C45\r\n"
    "N90 M30\r\n"
    "(caf\xe9 latin-1 comment)\r\n"
    "%")  # no final newline


def test_gcode_zero_errors_is_byte_for_byte_identical(tmp_path):
    m = machine("hu40t")
    for text in (open(PROGRAM, encoding="latin-1").read(), TRICKY):
        res = compensate_gcode(text, m, {})
        assert res.text == text
        assert res.moves >= 4 and res.changed_lines == 0
        # a result file whose values are all zero, through the file API
        src = tmp_path / "in.nc"
        src.write_bytes(text.encode("latin-1"))
        zero = {"parameters": {"EX0C": {"value": 0.0, "std": 1e-4}, "EB0C": {"value": 0.0, "std": 1e-6}}}
        compensate_gcode_file(src, tmp_path / "out.nc", m, zero, start={"X": 0, "Y": 0, "Z": 0})
        assert (tmp_path / "out.nc").read_bytes() == src.read_bytes()


AXIS = re.compile(r"([XYZABCxyzabc])\s*([+-]?(?:\d+\.?\d*|\.\d+))")


def replay(text, letters="XYZBC", start=None):
    """An independent reader of the test programs: modal axis values after each
    line that has axis words outside comments (G4 lines excepted)."""
    modal = dict(start or {})
    poses = []
    for i, line in enumerate(text.splitlines()):
        code = re.sub(r"\([^)]*\)", "", line).split(";")[0]
        if re.search(r"[Gg]0*4(?!\d)", code):
            continue
        words = AXIS.findall(code)
        if not words:
            continue
        for k, v in words:
            modal[k.upper()] = float(v)
        if all(a in modal for a in letters):
            poses.append((i + 1, {a: modal[a] for a in letters}))
    return poses


def strip_axis_words(line):
    code_parts = re.split(r"(\([^)]*\)|;.*$)", line)
    out = []
    for part in code_parts:
        if part.startswith("(") or part.startswith(";"):
            out.append(part)
        else:
            out.append(re.sub(r"\s*[XYZABCxyzabc]\s*[+-]?(?:\d+\.?\d*|\.\d+)", "", part))
    return "".join(out)


@pytest.mark.parametrize("decimals,bound", [(4, 0.5e-3), (9, 1e-6)])
def test_gcode_compensated_program_puts_the_tool_on_target(decimals, bound):
    m = machine("hu40t")
    errors = {**tango.thesis_s4_errors(), "EXXb": 0.005}
    text = open(PROGRAM, encoding="latin-1").read()
    res = compensate_gcode(text, m, errors, min_decimals=decimals)
    nominal = dict(replay(text))
    written = dict(replay(res.text))
    lines = sorted(set(nominal) & set(written) & set(res.lines))
    assert len(lines) == res.moves == 19
    q_nom = {a: np.array([nominal[ln][a] for ln in lines]) for a in "XYZBC"}
    q_out = {a: np.array([written[ln][a] for ln in lines]) for a in "XYZBC"}
    # backlash directions of the nominal sequence, as the compensation assumes
    dirs = {}
    for a in "XYZBC":
        d, cur = [], 0.0
        for i, v in enumerate(q_nom[a]):
            if i and abs(v - q_nom[a][i - 1]) > 1e-9:
                cur = np.sign(v - q_nom[a][i - 1])
            d.append(cur)
        dirs[a] = np.array(d)
    target = m.tool_point(q_nom)
    real_before = m.tool_point(q_nom, errors=errors, directions=dirs)
    real_after = m.tool_point(q_out, errors=errors, directions=dirs)
    assert np.abs(real_before - target).max() > 0.02
    assert np.abs(real_after - target).max() < bound
    assert res.max_written_error() < bound
    # everything but the axis numbers is untouched: comments, N, F, S, M, G, spacing
    for a_line, b_line in zip(text.splitlines(keepends=True), res.text.splitlines(keepends=True)):
        assert strip_axis_words(a_line) == strip_axis_words(b_line)
    # decimals: at least `decimals`, more when the input word had more
    changed = [w for w in AXIS.findall(res.text) if "." in w[1]]
    assert all(len(v.split(".")[1]) >= decimals or len(v.split(".")[1]) <= 1 for _, v in changed)


def test_gcode_keeps_longer_decimals_and_case():
    m = machine("hu40t")
    res = compensate_gcode(TRICKY, m, {"EX0C": 0.01, "EY0C": 0.005, "EB0C": 20e-6},
                           start={"X": 0, "Y": 0, "Z": 0})
    out = res.text.split("\r\n")
    assert res.text.count("\r\n") == TRICKY.count("\r\n") and not res.text.endswith("\n")
    assert re.search(r"Y12\.\d{6}\b", out[6]) and "Y12.345678" not in out[6]  # 6 decimals kept
    assert out[5].startswith("N40\tx") and "\tz" in out[5]                    # tabs and case kept
    assert out[1] == TRICKY.split("\r\n")[1] and out[11] == TRICKY.split("\r\n")[11]
    assert out[8] == "N70 G4 X1.5 (dwell, not a move)"                          # dwell untouched
    assert "X9 in a comment" in out[4] and "F500" in out[4]


@pytest.mark.parametrize("program,pattern", [
    ("G90 G0 X0 Y0 Z0 B0 C0\nG91\nG1 X10\n", r"program:3: incremental move \(G91 set at line 2\)"),
    ("G90 G0 X0 Y0 Z0 B0 C0\nG2 X10 Y0 I5 J0\n", r"program:2: G2 arc"),
    ("G0 X0 Y0 Z0 B0 C0\nG81 X10 Y10 Z-5 R2\n", r"program:2: canned cycle G81"),
    ("G0 X0 Y0 Z0 B0 C0\nG1 X#100\n", r"program:2: axis word 'X#"),
    ("G0 X0 Y0 Z0 B0 C0\nG43.4 H1\n", r"program:2: G43.4"),
    ("G0 X0 Y0 Z0 B0 C0\nG92 X0\n", r"program:2: G92"),
    ("G0 X0 Y0 Z0 B0 C0\nG1 A10\n", r"program:2: rotary word A but machine 'HU40T-like' has no A axis"),
    ("G54 G0 X0 Y0 Z0 B0 C0\nG55 G0 X1\n", r"program:2: work offset G55 after G54"),
])
def test_gcode_refusals_name_the_line(program, pattern):
    with pytest.raises(ValueError, match=pattern):
        compensate_gcode(program, machine("hu40t"), {"EX0C": 0.01})


def test_gcode_work_offset_and_unknown_axes():
    m = machine("hu40t")
    text = "G90\nG0 X10 Y10\nG0 Z5 B0 C0\nG1 X20\n"
    res = compensate_gcode(text, m, {"EX0C": 0.01})
    assert res.moves == 2 and res.skipped == [(2, "position of Z, B, C not known yet")]
    assert res.text.splitlines()[1] == "G0 X10 Y10"
    # the work offset changes the machine commands; with a pure location error
    # the correction does not depend on it, but it must be applied and removed
    off = compensate_gcode(text, m, {"EX0C": 0.01, "EXX1": 1e-4}, work_offset={"X": 100.0})
    plain = compensate_gcode(text, m, {"EX0C": 0.01, "EXX1": 1e-4})
    assert off.text != plain.text
    x_off = float(re.search(r"X(-?[\d.]+)", off.text.splitlines()[3]).group(1))
    x_plain = float(re.search(r"X(-?[\d.]+)", plain.text.splitlines()[3]).group(1))
    assert abs((x_off - 20) - (x_plain - 20) - 100 * 1e-4) < 2e-4


# ---------------------------------------------------------------- error table
def test_error_table_states_the_sign_convention_and_round_trips(tmp_path):
    m = machine("hu40t")
    result = {"parameters": {"EX0C": {"value": -0.108, "std": 1.4e-4}, "EB0C": {"value": 2.1e-5, "std": 6e-7},
                             "EXX1": {"value": -8.6e-6, "std": 3e-6}, "EXXb": {"value": 0.006, "std": 2e-4},
                             "tip.x": {"value": 0.004, "std": 1e-4}, "facet.F3": {"value": 0.01, "std": 1e-3}}}
    rows = write_error_table(tmp_path / "e.csv", result, m)
    assert [r["name"] for r in rows] == ["EX0C", "EB0C"]          # location errors only by default
    text = (tmp_path / "e.csv").read_text(encoding="utf-8")
    assert "Sign convention" in text and "right-hand rule" in text and "positive EX0k" in text
    data = [line for line in text.splitlines() if not line.startswith("#")]
    table = list(csv.DictReader(io.StringIO("\n".join(data))))
    assert float(table[0]["value"]) == -0.108 and table[0]["unit"] == "mm"
    assert table[1]["unit"] == "rad" and abs(float(table[1]["display_value"]) - 21.0) < 1e-9
    assert table[1]["display_unit"] == "µrad"
    assert "relative to axis B" in table[0]["description"]
    full = write_error_table(tmp_path / "e.json", result, m, kinds=("location", "motion", "backlash"))
    doc = json.loads((tmp_path / "e.json").read_text(encoding="utf-8"))
    assert doc["convention"] == SIGN_CONVENTION and len(doc["errors"]) == len(full) == 4
    assert "shortens the travel" in next(r for r in full if r["name"] == "EXX1")["description"]


def test_sign_convention_as_stated_holds_in_the_kinematics():
    """The table says: positive EX0k displaces axis k (and what it carries) by
    +x; on the workpiece side the tool seen from the part moves -x, on the tool
    side +x; a positive EC0k rotates counter-clockwise about +z."""
    m = machine("hu40t")
    zero = {a: [0.0] for a in "XYZBC"}
    assert np.allclose(m.volumetric_error(zero, {"EX0C": 0.01}), [[-0.01, 0, 0]])
    assert np.allclose(m.volumetric_error(zero, {"EX0S": 0.01}), [[0.01, 0, 0]])
    # C table rotated by +1e-4 rad about +z: a point of the part at +x moves to +y, so the
    # (fixed) tool seen from the part sits at -y
    at_x = {"X": [100.0], "Y": [0.0], "Z": [0.0], "B": [0.0], "C": [0.0]}  # table-side X: tool at +x
    p = m.tool_point(at_x)
    assert p[0, 0] > 50
    dy = m.volumetric_error(at_x, {"EC0C": 1e-4})[0, 1]
    assert abs(dy - (-1e-4 * p[0, 0])) < 1e-9
