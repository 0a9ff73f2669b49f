"""G-code input: what the reader refuses, units, and property-based round trips
(issue 12, G-code item).

Must show: every refusal names the line; exponent notation, bare letters and
over-long words are refused instead of misread; G70/G71 are inch/mm; a unit
switch never reinterprets a held position; with zero errors any program of
G0/G1 moves comes back byte for byte.
"""
import os
import re
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fivecal
from fivecal.compensation import compensate_gcode
from fivecal import gcode

ROOT = os.path.join(os.path.dirname(__file__), "..", "..")
MACHINES = os.path.join(ROOT, "examples", "machines")
HEAD = "G21 G90 G0 X0 Y0 Z0 B0 C0\n"


@pytest.fixture(scope="module")
def hu40t():
    return fivecal.Machine.load(os.path.join(MACHINES, "hu40t.json"))


def refusal(program, m, line, *fragments):
    with pytest.raises(ValueError) as ei:
        compensate_gcode(program, m, {"EX0C": 0.01})
    msg = str(ei.value)
    assert f"program:{line}:" in msg and f"line {line}" in msg, msg
    for f in fragments:
        assert f in msg, msg
    return msg


def test_exponent_notation_is_refused(hu40t):
    # before: read as X1 and a word E2, the move went to X1
    refusal(HEAD + "G1 X1e2 Y0\n", hu40t, 2, "X1e2", "exponent")
    refusal(HEAD + "G1 X-1.5E+2\n", hu40t, 2, "X-1.5E+2", "exponent")
    # a separate E word is still a word
    res = compensate_gcode(HEAD + "G1 X1 E2\n", hu40t, {})
    assert res.moves == 2


def test_bare_letter_is_refused(hu40t):
    # before: 'X' was skipped and a second X word read from 'X 10'? no: the bare
    # X vanished and the line moved as if it were not there
    refusal(HEAD + "G1 X Y5\n", hu40t, 2, "'X'", "without a number")
    refusal(HEAD + "G1 Y5 X\n", hu40t, 2, "'X'")


def test_number_without_letter_and_foreign_characters_are_refused(hu40t):
    refusal(HEAD + "G1 X10 20\n", hu40t, 2, "'20' without a letter")
    refusal(HEAD + "G1 X10 *52\n", hu40t, 2, "'*'")
    refusal(HEAD + "#100=5\n", hu40t, 2, "variables")
    refusal(HEAD + "G1 X10 (unclosed\n", hu40t, 2, "not closed")


def test_400_digit_word_names_the_line_and_word(hu40t):
    # before: 'pose 1: X value is not finite', no line
    msg = refusal(HEAD + "N20 G1 X" + "9" * 400 + "\n", hu40t, 2, "X999", "400 digits")
    assert len(msg) < 400


@pytest.mark.parametrize("code,fragment", [
    ("G51.1 X0", "mirror"), ("G16", "polar"), ("G10 L2 P1 X10", "G10"), ("M98 P1000", "M98"),
    ("G65 P9010", "G65"), ("G7.1 C50", "cylindrical"), ("G71 P10 Q20 U0.5 W0.1", "turning cycle"),
])
def test_what_cannot_be_compensated_is_refused(hu40t, code, fragment):
    refusal(HEAD + code + "\nG1 X5\n", hu40t, 2, fragment)


@pytest.mark.parametrize("inch,mm", [("G70", "G71"), ("G20", "G21"), ("G700", "G710")])
def test_g70_g71_are_inch_and_mm(hu40t, inch, mm):
    # before: G70 was ignored and X1 read as 1 mm
    res = compensate_gcode(f"{inch} G90 G0 X1 Y0 Z0 B0 C0\nG1 Y2\n{mm}\nG1 Z3\n", hu40t, {})
    p = res.poses.nominal
    assert np.allclose(p["X"], [25.4, 25.4, 25.4])
    assert np.allclose(p["Y"], [0.0, 50.8, 50.8])
    assert np.allclose(p["Z"], [0.0, 0.0, 3.0])


def test_unit_switch_keeps_held_positions(hu40t):
    # before: after G20 the held X25.4 (mm) was read as 25.4 inch = 645 mm
    text = "G21 G90 G0 X25.4 Y10 Z0 B0 C0\nG20\nG1 Y1\nG21\nG1 Z5\n"
    res = compensate_gcode(text, hu40t, {})
    p = res.poses.nominal
    assert np.allclose(p["X"], 25.4) and np.allclose(p["Y"], [10, 25.4, 25.4])
    assert np.allclose(p["Z"], [0, 0, 5])
    assert res.text == text


def test_unit_switch_writes_inserted_words_in_the_line_units(hu40t):
    errors = {"EX0C": 0.05, "EY0C": -0.03, "EXZ1": 1e-3}
    mixed = "G21 G90 G0 X25.4 Y12.7 Z0 B0 C0\nG20\nG1 Z0.5\nG1 Y1\n"
    mm = "G21 G90 G0 X25.4 Y12.7 Z0 B0 C0\nG1 Z12.7\nG1 Y25.4\n"
    a = compensate_gcode(mixed, hu40t, errors, min_decimals=6)
    b = compensate_gcode(mm, hu40t, errors, min_decimals=6)
    for k in "XYZBC":
        assert np.allclose(a.poses.axes[k], b.poses.axes[k], atol=1e-9)
    assert a.max_written_error() < 2e-5 and b.max_written_error() < 2e-6
    x_inch = float(re.search(r"X(-?[\d.]+)", a.text.splitlines()[2]).group(1))
    assert abs(x_inch * 25.4 - a.poses.axes["X"][1]) < 1e-4


def test_windows_1252_comment_bytes_do_not_split_lines(hu40t):
    # 0x85 is the ellipsis of Windows-1252; read as Latin-1 it is NEL, a line
    # break for str.splitlines, which cut the comment and shifted line numbers
    text = HEAD + "(roughing\x85 done)\nG1 X5\x0c\nG1 X1e2\n"
    with pytest.raises(ValueError, match=r"program:4: "):
        compensate_gcode(text, hu40t, {})
    ok = HEAD + "(roughing\x85 done)\nG1 X5\n"
    assert compensate_gcode(ok, hu40t, {}).text == ok


@pytest.mark.parametrize("word", ["X1\u00b2", "X\u0663", "X\u0663.5", "Y1.\u00b2"])
def test_non_ascii_digits_are_refused(hu40t, word):
    # before: 'X1²' escaped as a bare float() error without the line, and
    # 'X٣' (an Arabic-Indic three) was read as X3
    refusal(HEAD + "G1 " + word + "\n", hu40t, 2)


def test_additional_work_offsets_are_told_apart(hu40t):
    refusal("G54.1 P1 G0 X0 Y0 Z0 B0 C0\nG54.1 P2 G0 X1\n", hu40t, 2, "G54.1 P2 after G54.1 P1")


def test_probe_moves_end_where_the_program_does_not_say(hu40t):
    text = HEAD + "G31 X50 F100\nG1 Y5\nG1 X10\n"
    res = compensate_gcode(text, hu40t, {"EX0C": 0.01})
    assert res.skipped == [(3, "position of X not known yet")] and res.lines == [1, 4]


def test_refusal_messages_are_short_and_quote_the_line(hu40t):
    msg = refusal(HEAD + "G1 X1e2" + " Y0" * 100 + "\n", hu40t, 2)
    assert "..." in msg and len(msg) < 300


# ---------------------------------------------------------------- properties
AXES = "XYZBC"


@st.composite
def number(draw, lo=-500.0, hi=500.0):
    v = draw(st.floats(lo, hi, allow_nan=False))
    dec = draw(st.integers(0, 6))
    s = f"{v:.{dec}f}"
    if dec == 0 and draw(st.booleans()):
        s += "."
    if not s.startswith("-") and draw(st.booleans()):
        s = "+" + s
    return s


@st.composite
def move_line(draw, n):
    sp = draw(st.sampled_from(["", " ", "\t", "  "]))
    parts = []
    if draw(st.booleans()):
        parts.append(f"N{n * 10}")
    if draw(st.booleans()):
        parts.append(draw(st.sampled_from(["G0", "G1", "G00", "G01", "g1"])))
    letters = draw(st.lists(st.sampled_from(AXES), min_size=1, max_size=5, unique=True))
    for a in letters:
        lo, hi = (-90.0, 90.0) if a in "BC" else (-400.0, 400.0)
        a = a.lower() if draw(st.booleans()) else a
        parts.append(a + draw(number(lo, hi)))
    if draw(st.booleans()):
        parts.append("F" + draw(number(1.0, 5000.0)))
    line = sp.join(parts) if sp else "".join(parts)
    if draw(st.booleans()):
        line += draw(st.sampled_from([" (cut X1 Y2)", " ; note", "(a)", " ;"]))
    return line


@st.composite
def program(draw):
    n = draw(st.integers(1, 12))
    lines = [draw(move_line(i)) for i in range(n)]
    if draw(st.booleans()):
        lines.insert(0, "(header) " + draw(st.sampled_from(["%", "O1000", "G21 G90", ""])))
    ending = draw(st.sampled_from(["\n", "\r\n"]))
    text = ending.join(lines)
    if draw(st.booleans()):
        text += ending
    return text


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(program())
def test_property_zero_errors_round_trip(text):
    m = _machine()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # small rotary values may look like radians
        res = compensate_gcode(text, m, {}, start={a: 0.0 for a in AXES})
    assert res.text == text
    assert res.changed_lines == 0


_M = {}


def _machine():
    if "m" not in _M:
        _M["m"] = fivecal.Machine.load(os.path.join(MACHINES, "hu40t.json"))
    return _M["m"]


GARBAGE = st.text(alphabet=st.sampled_from(list("GXYZBCAMNFST0123456789.+-eE ;()#[]=%/\t\n\r:*xyz"
                                                "\x85\x0c\xe9\u00b2\u0663")),
                  max_size=120)


@settings(max_examples=300, deadline=None)
@given(st.one_of(GARBAGE, st.text(max_size=80)))
def test_property_garbage_raises_only_named_value_errors(text):
    m = _machine()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            compensate_gcode(HEAD + text, m, {"EX0C": 0.01})
        except ValueError as e:
            msg = str(e)
            mt = re.match(r"program:(\d+): .*\(line (\d+): ", msg, re.S)
            assert mt and mt.group(1) == mt.group(2), msg
            assert 1 <= int(mt.group(1)) <= len(gcode.split_lines(HEAD + text))


@st.composite
def unit_program(draw):
    """Pairs of programs: one switching between G20/G21 (or G70/G71), and the
    same moves written in mm only."""
    n = draw(st.integers(1, 8))
    mixed, mm = [HEAD.strip()], [HEAD.strip()]
    for _ in range(n):
        inch = draw(st.booleans())
        code = draw(st.sampled_from(["G20", "G70"])) if inch else draw(st.sampled_from(["G21", "G71"]))
        letters = draw(st.lists(st.sampled_from(AXES), min_size=1, max_size=5, unique=True))
        wm, wi = [], []
        for a in letters:
            if a in "BC":
                v = draw(st.integers(-90, 90))
                wm.append(f"{a}{v}")
                wi.append(f"{a}{v}")
            else:
                k = draw(st.integers(-4000, 4000))  # 0.1 inch steps: exact in both units
                wi.append(f"{a}{k / 10:.1f}" if inch else f"{a}{k * 2.54:.2f}")
                wm.append(f"{a}{k * 2.54:.2f}")
        mixed.append(code + " G1 " + " ".join(wi))
        mm.append("G1 " + " ".join(wm))
    return "\n".join(mixed) + "\n", "\n".join(mm) + "\n"


@settings(max_examples=60, deadline=None)
@given(unit_program())
def test_property_unit_switch_equals_mm_program(pair):
    mixed, mm = pair
    m = _machine()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = compensate_gcode(mixed, m, {})
        b = compensate_gcode(mm, m, {})
    for k in AXES:
        assert np.allclose(a.poses.nominal[k], b.poses.nominal[k], atol=1e-9)


def test_tokenizer_spans_and_decimals():
    w = gcode.tokenize("N5 G1X-.5 y+2. (X9) Z 3.25 ; X7")
    assert [(x.letter, x.value, x.decimals, x.plus) for x in w] == [
        ("N", 5.0, 0, False), ("G", 1.0, 0, False), ("X", -0.5, 1, False), ("Y", 2.0, 0, True),
        ("Z", 3.25, 2, False)]
    text = "N5 G1X-.5 y+2. (X9) Z 3.25 ; X7"
    assert text[w[4].start:w[4].end] == "3.25"


# ------------------------------------------- cutter radius / tool length compensation
@pytest.mark.parametrize("program,line,fragments", [
    # set on the line of the move
    (HEAD + "G43 H1 Z100.\n", 2, ["G43 (tool length compensation)", "on this line", "G49"]),
    (HEAD + "G1 G41 D1 X10. F500\n", 2, ["G41 (cutter radius compensation, left)", "G40"]),
    # set before, the move refused names both lines
    (HEAD + "G42 D3\nG1 Y5.\n", 3, ["G42 (cutter radius compensation, right)", "since line 2"]),
    (HEAD + "T1 M6\nG44 H2\n(approach)\nG0 X10. Y10.\n", 5, ["G44", "since line 3"]),
    (HEAD + "G43.1 Z50.\n", 2, ["G43.1 (dynamic tool length compensation)"]),
    # a rotary move is a move too
    (HEAD + "G43 H1\nG0 B30.\n", 3, ["G43", "since line 2"]),
    # cancelling one of the two leaves the other active
    (HEAD + "G41 D1 G43 H1\nG40\nG1 X5.\n", 4, ["G43", "since line 2"]),
    # a G41 after the cancel (the last word of the line wins)
    (HEAD + "G40 G41 D1\nG1 X5.\n", 3, ["G41", "since line 2"]),
])
def test_radius_and_length_compensation_at_a_move_are_refused(hu40t, program, line, fragments):
    refusal(program, hu40t, line, "move with", *fragments)


@pytest.mark.parametrize("program", [
    "G17 G40 G49 G80\n" + HEAD + "G1 X10.\n",                 # the safety line of a program head
    HEAD + "G43 H1\nG49\nG1 X10.\n",                           # set and cancelled before any move
    HEAD + "G41 D1\nG40\nG1 X10. Y5.\n",
    HEAD + "G42 D1 G40\nG1 X10.\n",                            # cancelled on the same line
    HEAD + "G1 X10.\nG43 H1\nM30\n",                           # set after the last move
])
def test_compensation_cancelled_before_the_moves_is_read(hu40t, program):
    res = compensate_gcode(program, hu40t, {"EX0C": 0.01})
    assert res.moves >= 2


def test_example_program_cancels_compensation_in_its_head(hu40t):
    text = open(os.path.join(ROOT, "examples", "gcode", "hu40t_5axis.nc")).read()
    assert "G40 G49" in text
    assert compensate_gcode(text, hu40t, {"EX0C": 0.01}).moves > 0


INCH_ERRORS = {"EX0C": 0.05, "EY0C": -0.03, "EXZ1": 1e-3, "EA0B": 2e-5}
MM_PROGRAM = "G21 G90 G0 X25.4 Y12.7 Z0 B0 C0\nG1 Z12.7 B15\nG1 Y25.4 C30\nG1 X-50.8 Z-2.54\n"


@pytest.mark.parametrize("head", ["G70", "g70", "G70.", "G70.0", "G070", "G 70", "G700", "N10 G70",
                                  "G70\n", "(inch) G70 (ISO 6983)\n", "G20"])
def test_inch_program_compensates_as_the_mm_program_converted(hu40t, head, tmp_path):
    # before: an inch program's words were written with the mm resolution
    # (4 decimals: 0.0001 in = 2.5 um), so its output was not the mm program's
    # output converted; now inch words get one decimal more (0.25 um)
    inch = (head if head.endswith("\n") else head + " ") + \
        "G90 G0 X1 Y0.5 Z0 B0 C0\nG1 Z0.5 B15\nG1 Y1 C30\nG1 X-2 Z-0.1\n"
    a = compensate_gcode(MM_PROGRAM, hu40t, INCH_ERRORS)
    b = compensate_gcode(inch, hu40t, INCH_ERRORS)
    for k in "XYZBC":
        np.testing.assert_allclose(b.poses.axes[k], a.poses.axes[k], atol=1e-9)
    assert a.max_written_error() < 2e-4 and b.max_written_error() < 4e-4  # mm: under 0.4 um
    # the written words: the mm output's linear words / 25.4, to the last inch decimal written
    mm_lines = [ln for ln in a.text.splitlines() if ln.strip()]
    in_lines = [ln for ln in b.text.splitlines() if ln.strip()][-4:]
    word = re.compile(r"([XYZBC])(-?\d+\.?\d*)")
    for lm, li in zip(mm_lines, in_lines):
        wm, wi = dict(word.findall(lm)), dict(word.findall(li))
        assert wm.keys() == wi.keys(), (lm, li)
        for k in wm:
            if k in "XYZ" and "." in wi[k] and len(wi[k].split(".")[1]) >= 5:
                assert abs(float(wi[k]) - float(wm[k]) / 25.4) <= 0.5e-5 + 0.5e-4 / 25.4 + 1e-12, (k, lm, li)
            elif k in "BC":
                assert float(wi[k]) == float(wm[k]), (k, lm, li)
    # and the command line reads the file the same way
    from fivecal.cli import main
    (tmp_path / "in.nc").write_text(inch)
    (tmp_path / "r.json").write_text(__import__("json").dumps(INCH_ERRORS))
    assert main(["compensate", str(tmp_path / "r.json"), os.path.join(MACHINES, "hu40t.json"),
                 str(tmp_path / "in.nc"), "--out", str(tmp_path / "out.nc")]) == 0
    assert (tmp_path / "out.nc").read_text() == b.text
