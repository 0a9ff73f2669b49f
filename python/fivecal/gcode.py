"""ISO (RS-274) G-code reading and writing for compensation.

The reader turns a program into the sequence of G0/G1 moves as machine axis
commands (mm, degrees) and refuses, naming the line, everything it cannot
read unambiguously or that cannot be compensated; the writer puts compensated
numbers back into the original text, touching nothing else.

Reading rules:

* A word is a letter followed by a decimal number (``X-12.5``, ``x.5``,
  ``Z+3.``); spaces or tabs may separate them. Exponent notation (``X1e2``)
  is not G-code and is refused, as are a letter without a number (``X``), a
  number without a letter, more than 15 digits in one number (no controller
  holds that many; a 400-digit word is a corrupted file), an unclosed ``(``
  comment and characters that are no part of ISO words (``#``, ``[``, ``=``,
  ``*``, ...: variables, expressions, checksums).
* Units: G20 (inch) / G21 (mm); G70 / G71 (and G700 / G710) are read as
  G20 / G21 too, as Siemens and several other milling controllers define
  them. On a Fanuc lathe G70 / G71 are the finishing and roughing cycles:
  a G70 / G71 line carrying P, Q, U, W or R words is refused as a cycle.
* Every axis word is converted to machine units (mm) with the unit mode in
  force on its own line, and the modal positions are kept in machine units,
  so a G21 -> G20 switch never reinterprets a position already held. A
  compensated linear word on an inch line is written with one decimal more
  than on a millimetre line (0.00001 in beside 0.0001 mm).
* Cutter radius compensation (G41, G42) and tool length compensation (G43,
  G44) shift the path by the tool's radius or length in the controller's
  offset table: a move while one is active is refused, naming the move and
  the line that set it; a program that cancels them (G40, G49) before its
  moves is read. Tool centre point control (G43.4, G43.5) is refused outright.
* Every refusal is a ``ValueError`` of the form ``name:N: message (line N:
  text)`` with the 1-based line number.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

ROTARY = "ABC"
AXIS_ORDER = "XYZABC"
INCH = 25.4  # mm
_DIGITS = "0123456789"  # str.isdigit also takes '²' and '٣', which no controller reads
MAX_DIGITS = 15  # a double holds 15-17 significant digits; controllers about 9

_MOTION_LINEAR = {0.0, 1.0}
_MOTION_ARC = {2.0, 3.0}
_CYCLES = {73.0, 74.0, 76.0, 81.0, 82.0, 83.0, 84.0, 85.0, 86.0, 87.0, 88.0, 89.0}
# Axis words that are not a G0/G1 target, or a move that ends where the program does
# not say (G31 / G38.x skip and probe moves stop at the touch).
_NONMODAL_AXIS_WORDS = {27.0, 28.0, 30.0, 31.0, 38.2, 38.3, 38.4, 38.5, 53.0}
_DWELL = 4.0  # G4 X1.5: X is a time
_INCH = {20.0, 70.0, 700.0}
_MM = {21.0, 71.0, 710.0}
_REFUSED = {92.0: "G92 (set position) changes the coordinate system",
            52.0: "G52 (local coordinate system) shifts the coordinates",
            68.0: "G68 (coordinate rotation) rotates the coordinates",
            68.2: "G68.2 (tilted working plane) transforms the coordinates",
            53.1: "G53.1 (tool axis control for a tilted plane) moves the rotary axes implicitly",
            43.4: "G43.4 (tool centre point control) means the words are tool-tip coordinates, "
                  "not axis commands",
            43.5: "G43.5 (tool centre point control) means the words are tool-tip coordinates, "
                  "not axis commands",
            51.0: "G51 (scaling) scales the coordinates",
            51.1: "G51.1 (mirror image) mirrors the coordinates",
            16.0: "G16 (polar coordinates) makes X and Y a radius and an angle",
            7.1: "G7.1 (cylindrical interpolation) makes the words cylinder coordinates",
            12.1: "G12.1 (polar interpolation) makes the words polar coordinates",
            10.0: "G10 (data setting) changes work or tool offsets",
            65.0: "G65 (macro call) moves the axes where the program does not say",
            66.0: "G66 (modal macro call) moves the axes where the program does not say"}
# Cutter radius and tool length compensation: the controller moves the axes by
# the radius or length of the tool in its offset table, which the program does
# not hold, so the words are no longer the axis commands fivecal compensates.
# Accepted while cancelled (G40, G49), as in the usual safety line of a
# program head; a move while one is active is refused.
_RADIUS_COMP = {41.0: "G41 (cutter radius compensation, left)", 42.0: "G42 (cutter radius compensation, right)",
                41.1: "G41.1 (dynamic cutter radius compensation, left)",
                42.1: "G42.1 (dynamic cutter radius compensation, right)"}
_LENGTH_COMP = {43.0: "G43 (tool length compensation)", 44.0: "G44 (tool length compensation, negative)",
                43.1: "G43.1 (dynamic tool length compensation)",
                43.2: "G43.2 (additional tool length compensation)"}
_REFUSED_M = {98.0: "M98 (subprogram call) moves the axes where the program does not say",
              99.0: "M99 (return / jump) changes the order of the blocks",
              198.0: "M198 (subprogram call) moves the axes where the program does not say"}


_LINE = re.compile(r"[^\r\n]*(?:\r\n|\r|\n)|[^\r\n]+\Z")


def split_lines(text: str) -> List[str]:
    """Lines with their endings, split at CR LF, LF or CR only: str.splitlines
    also splits at form feed, NEL (byte 0x85, the ellipsis of Windows-1252 read
    as Latin-1) and others, which would cut a comment and shift line numbers."""
    return _LINE.findall(text)


def _refuse(name: str, ln: int, text: str, msg: str) -> ValueError:
    shown = text.strip()
    if len(shown) > 60:
        shown = shown[:57] + "..."
    return ValueError(f"{name}:{ln}: {msg} (line {ln}: {shown})")


@dataclass
class Word:
    letter: str        # upper case
    raw_letter: str
    value: float       # as written, in program units
    start: int         # span of the number text in the line
    end: int
    decimals: int
    plus: bool


def code_spans(text: str, name: str = "program", ln: int = 0) -> List[Tuple[int, int]]:
    """(start, end) of the parts of a line outside ( ) and ; comments."""
    spans = []
    i, start, n = 0, 0, len(text)
    while i < n:
        ch = text[i]
        if ch == "(":
            spans.append((start, i))
            j = text.find(")", i + 1)
            if j < 0:
                raise _refuse(name, ln, text, "comment '(' is not closed with ')'")
            i = j + 1
            start = i
            continue
        if ch == ";":
            spans.append((start, i))
            start = i = n
            break
        i += 1
    spans.append((start, n))
    return [(a, b) for a, b in spans if b > a]


def _number_end(s: str, i: int) -> int:
    """End of the decimal number starting at s[i] (sign allowed), or i if none."""
    n = len(s)
    j = i
    if j < n and s[j] in "+-":
        j += 1
    k = j
    while k < n and s[k] in _DIGITS:
        k += 1
    digits = k - j
    if k < n and s[k] == ".":
        k += 1
        m = k
        while k < n and s[k] in _DIGITS:
            k += 1
        digits += k - m
    return k if digits else i


def tokenize(text: str, name: str = "program", ln: int = 0) -> List[Word]:
    """The words of one line (without its line ending), strictly: see the
    module docstring. ValueError names the line and the offending text."""
    words: List[Word] = []
    for a, b in code_spans(text, name, ln):
        s = text[a:b]
        i, n = 0, len(s)
        while i < n:
            ch = s[i]
            if ch in " \t\f\v":
                i += 1
                continue
            if ch == "%" or (ch == "/" and not words and not s[:i].strip()):
                # program start/end marker; block delete at the start of a line
                i += 1
                while ch == "/" and i < n and s[i] in _DIGITS:
                    i += 1
                continue
            if ch == ":" and not words and not s[:i].strip():
                i += 1  # ':1234' program number (ISO), like O1234
                continue
            if ch.isascii() and ch.isalpha():
                j = i + 1
                while j < n and s[j] in " \t":
                    j += 1
                k = _number_end(s, j)
                if k == j:
                    bad = s[i:j + 1].strip() if j < n else ch
                    if j < n and s[j] in "#[=":
                        kind = "axis word" if ch.upper() in AXIS_ORDER else "word"
                        raise _refuse(name, ln, text, f"{kind} '{s[i:j + 1].strip()}…' uses a variable or "
                                      "expression; only literal numbers can be compensated")
                    raise _refuse(name, ln, text, f"letter '{ch}' without a number ('{bad}'); every "
                                  "G-code word is a letter and a number")
                num = s[j:k]
                if k < n and s[k] in "eE" and _number_end(s, k + 1 if k + 1 < n and s[k + 1] in "+-"
                                                          else k + 1) > k + 1:
                    e_end = _number_end(s, k + 1)
                    raise _refuse(name, ln, text, f"word '{ch}{num}{s[k:e_end]}' uses exponent notation, "
                                  f"which G-code does not have; write the number in full, or separate an "
                                  f"'{s[k]}' word with a space")
                if k < n and s[k] in "#[=":
                    kind = "axis word" if ch.upper() in AXIS_ORDER else "word"
                    raise _refuse(name, ln, text, f"{kind} '{ch}{num}{s[k]}…' uses a variable or "
                                  "expression; only literal numbers can be compensated")
                ndig = sum(c in _DIGITS for c in num)
                if ndig > MAX_DIGITS:
                    shown = num if len(num) <= 24 else num[:20] + "…"
                    raise _refuse(name, ln, text, f"word '{ch}{shown}' has {ndig} digits; a controller "
                                  f"takes about 9 (at most {MAX_DIGITS} here)")
                dec = len(num.split(".", 1)[1]) if "." in num else 0
                words.append(Word(ch.upper(), ch, float(num), a + j, a + k, dec, num.startswith("+")))
                i = k
                continue
            if ch in _DIGITS or ch in "+-.":
                k = _number_end(s, i)
                raise _refuse(name, ln, text, f"number '{s[i:max(k, i + 1)]}' without a letter")
            if ch in "#[]=":
                raise _refuse(name, ln, text, "variables and expressions ('#', '[', '=') cannot be "
                              "compensated; post the program with literal numbers")
            raise _refuse(name, ln, text, f"character {ch!r} is no part of an ISO G-code word")
    return words


def g_codes(words: Sequence[Word]) -> List[float]:
    return [round(w.value, 1) for w in words if w.letter == "G"]


@dataclass
class Move:
    line: int                      # 0-based line index
    words: Dict[str, Word]         # axis words present on the line
    pose: Dict[str, float]         # machine command of every axis after the line (mm, deg)
    insert_at: int                 # where missing axis words go (end of the last axis word)
    sep: str
    lower: bool
    inch: bool


@dataclass
class LineState:
    """What the writer needs of a line with axis words that is not a compensated
    move: its axis words and the unit mode, or ``reset`` when the axes end where
    the program does not say (G28, G30, G53)."""
    words: Dict[str, Word]
    inch: bool
    reset: bool


@dataclass
class Program:
    lines: List[str]
    axis_letters: List[str]
    offset: Dict[str, float]
    start: Dict[str, Optional[float]]          # machine commands before the first line
    moves: List[Move] = field(default_factory=list)
    other: Dict[int, LineState] = field(default_factory=dict)
    skipped: List[Tuple[int, str]] = field(default_factory=list)

    def to_machine(self, a: str, v: float, inch: bool) -> float:
        if a in ROTARY:
            return v
        return (v * INCH if inch else v) + self.offset[a]

    def to_program(self, a: str, v: float, inch: bool) -> float:
        if a in ROTARY:
            return v
        v = v - self.offset[a]
        return v / INCH if inch else v


def read_program(program: str, axis_letters: Sequence[str], machine_name: str = "machine",
                 offset: Optional[Mapping[str, float]] = None,
                 start: Optional[Mapping[str, float]] = None, name: str = "program") -> Program:
    """Read the G0/G1 moves of ``program`` for a machine with the given axis
    letters (X Y Z A B C, no S). ``offset``: linear work offset (mm) added to
    every word; ``start``: axis positions before the first line, in program
    coordinates in mm (degrees for rotary axes)."""
    axis_letters = [a for a in axis_letters if a != "S"]
    off = {a: 0.0 for a in axis_letters}
    off.update(offset or {})
    prog = Program(split_lines(program), list(axis_letters), off, {})
    modal: Dict[str, Optional[float]] = {a: None for a in axis_letters}  # machine units
    for k, v in (start or {}).items():
        try:
            fv = float(v)
        except (TypeError, ValueError):
            fv = math.nan
        if not math.isfinite(fv):
            raise ValueError(f"start: {k}: expected a finite number (mm or degrees), got {v!r}")
        modal[k] = prog.to_machine(k, fv, False)
    prog.start = dict(modal)
    motion: Optional[float] = None
    absolute = True
    g91_line = 0
    inch = False
    wcs: Optional[Tuple[str, int]] = None
    radius_comp: Optional[Tuple[float, int]] = None  # (G code, line) while active
    length_comp: Optional[Tuple[float, int]] = None

    for li, raw in enumerate(prog.lines):
        ln = li + 1
        text = raw.rstrip("\r\n")
        words = tokenize(text, name, ln)
        if not words:
            continue
        nonmodal_axis = False
        dwell = False
        letters = {w.letter for w in words}
        for w in words:
            if w.letter == "M" and round(w.value, 1) in _REFUSED_M:
                raise _refuse(name, ln, text, f"{_REFUSED_M[round(w.value, 1)]}; compensation needs "
                              "every move in the program")
        for g in g_codes(words):
            if g in _REFUSED:
                raise _refuse(name, ln, text, f"{_REFUSED[g]}; compensation needs plain machine axis "
                              "commands")
            if g in (70.0, 71.0) and letters & set("PQUWR"):
                raise _refuse(name, ln, text, f"G{g:g} with {', '.join(sorted(letters & set('PQUWR')))} "
                              "words is a turning cycle (Fanuc lathe); only G70/G71 as inch/mm are read")
            if g in _MOTION_LINEAR or g in _MOTION_ARC or g in _CYCLES:
                motion = g
            elif g == 80.0:
                motion = None
            elif g == 90.0:
                absolute = True
            elif g == 91.0:
                absolute, g91_line = False, ln
            elif g in _INCH:
                inch = True
            elif g in _MM:
                inch = False
            elif g in _RADIUS_COMP:
                radius_comp = (g, ln)
            elif g == 40.0:
                radius_comp = None
            elif g in _LENGTH_COMP:
                length_comp = (g, ln)
            elif g == 49.0:
                length_comp = None
            elif g in _NONMODAL_AXIS_WORDS:
                nonmodal_axis = True
            elif g == _DWELL:
                dwell = True
            elif 54.0 <= g < 60.0:
                code = f"G{g:g}"
                if g == 54.1:  # additional work offsets: G54.1 P1 .. P300
                    code += "".join(f" P{w.value:g}" for w in words if w.letter == "P")
                if wcs is None:
                    wcs = (code, ln)
                elif wcs[0] != code:
                    raise _refuse(name, ln, text, f"work offset {code} after {wcs[0]} (line {wcs[1]}); "
                                  "compensate the parts of the program for each work offset separately")
        axis_words: Dict[str, Word] = {}
        for w in words:
            if w.letter in AXIS_ORDER:
                if w.letter not in axis_letters:
                    if w.letter in ROTARY and not (nonmodal_axis or dwell):
                        raise _refuse(name, ln, text, f"rotary word {w.raw_letter} but machine "
                                      f"{machine_name!r} has no {w.letter} axis (axes "
                                      f"{', '.join(axis_letters)})")
                    continue
                if w.letter in axis_words:
                    raise _refuse(name, ln, text, f"axis word {w.letter} appears twice")
                if not math.isfinite(w.value):
                    raise _refuse(name, ln, text, f"word {w.letter}: value is not finite")
                axis_words[w.letter] = w
        if not axis_words or dwell:
            continue
        for comp, names, cancel, what in ((radius_comp, _RADIUS_COMP, "G40", "radius"),
                                          (length_comp, _LENGTH_COMP, "G49", "length")):
            if comp is not None:
                since = "on this line" if comp[1] == ln else f"since line {comp[1]}"
                raise _refuse(name, ln, text, f"move with {names[comp[0]]} active ({since}): the controller "
                              f"shifts the path by the tool {what} from its offset table, which the "
                              "compensation of the axis commands cannot take into account; cancel it "
                              f"({cancel}) before the moves and give the cutting tool's tip instead (--tool-tip)")
        if nonmodal_axis:
            # G27/G28/G30 (via a point to home), G31/G38.x (stop at a touch), G53
            # (machine coordinates): left as written; the axes they move end where the
            # program does not say.
            for a in axis_words:
                modal[a] = None
            prog.other[li] = LineState(axis_words, inch, True)
            continue
        if motion is not None and motion in _MOTION_ARC:
            raise _refuse(name, ln, text, f"G{motion:g} arc moves are not supported; post the program "
                          "with linear moves (G1)")
        if motion is not None and motion in _CYCLES:
            raise _refuse(name, ln, text, f"canned cycle G{motion:g} is not supported; post the "
                          "program with explicit G0/G1 moves")
        if not absolute:
            raise _refuse(name, ln, text, f"incremental move (G91 set at line {g91_line}); only "
                          "absolute programs (G90) can be compensated")
        for a, w in axis_words.items():
            modal[a] = prog.to_machine(a, w.value, inch)
        unknown = [a for a in sorted(axis_letters, key=AXIS_ORDER.index) if modal[a] is None]
        if unknown:
            prog.skipped.append((ln, f"position of {', '.join(unknown)} not known yet"))
            prog.other[li] = LineState(axis_words, inch, False)
            continue
        last = max(axis_words.values(), key=lambda w: w.end)
        first = min(axis_words.values(), key=lambda w: w.start)
        codes = [text[a:b] for a, b in code_spans(text, name, ln)]
        sep = " " if any(c in " \t" for c in "".join(codes).strip()) else ""
        prog.moves.append(Move(li, axis_words, {a: float(modal[a]) for a in axis_letters}, last.end, sep,
                               first.raw_letter.islower(), inch))
    return prog


def fmt(value: float, decimals: int, plus: bool) -> str:
    s = f"{value:.{decimals}f}"
    if float(s) == 0.0:
        s = s.lstrip("-")
    if plus and not s.startswith("-"):
        s = "+" + s
    return s


def write_program(prog: Program, compensated: Mapping[str, Sequence[float]], min_decimals: int = 4
                  ) -> Tuple[str, int, Dict[str, List[float]]]:
    """The program text with the compensated machine commands of its moves
    (dict axis -> one value per move, mm / degrees) written back with at
    least ``min_decimals`` decimals (one more for a linear word on an inch
    line, G20/G70, so an inch program is written to the same resolution as a
    millimetre one); the number
    of changed lines; and per axis the machine command the controller holds at
    each move as written (after rounding), for checking what was written."""
    letters = sorted(prog.axis_letters, key=AXIS_ORDER.index)

    def least(a: str, inch: bool) -> int:
        # the same resolution in inch: 0.00001 in (0.25 um) beside 0.0001 mm
        return min_decimals + (1 if inch and a not in ROTARY else 0)

    # The values the controller holds, in machine units, as the program is rewritten.
    held: Dict[str, Optional[float]] = dict(prog.start)
    held_dec: Dict[str, int] = {a: min_decimals for a in letters}
    written: Dict[str, List[float]] = {a: [] for a in letters}
    result = list(prog.lines)
    changed = 0
    move_at = {mv.line: i for i, mv in enumerate(prog.moves)}
    for li, raw in enumerate(prog.lines):
        if li not in move_at:
            st = prog.other.get(li)
            if st is not None:
                for a, w in st.words.items():
                    if st.reset:
                        held[a] = None
                    else:
                        held[a] = prog.to_machine(a, w.value, st.inch)
                        held_dec[a] = max(w.decimals, least(a, st.inch))
            continue
        mi = move_at[li]
        mv = prog.moves[mi]
        text = raw.rstrip("\r\n")
        ending = raw[len(text):]
        edits: List[Tuple[int, int, str]] = []
        inserts: List[str] = []
        for a in letters:
            v = prog.to_program(a, float(compensated[a][mi]), mv.inch)
            if a in mv.words:
                w = mv.words[a]
                dec = max(w.decimals, least(a, mv.inch))
                held_dec[a] = dec
                if abs(v - w.value) < 0.5 * 10.0 ** (-dec):
                    held[a] = prog.to_machine(a, w.value, mv.inch)
                    continue
                s = fmt(v, dec, w.plus)
                edits.append((w.start, w.end, s))
                held[a] = prog.to_machine(a, float(s), mv.inch)
            else:
                dec = max(held_dec[a], least(a, mv.inch))
                h_machine = held[a] if held[a] is not None else mv.pose[a]
                h = prog.to_program(a, h_machine, mv.inch)
                if abs(v - h) < 0.5 * 10.0 ** (-dec):
                    held[a] = h_machine
                    continue
                s = fmt(v, dec, False)
                inserts.append(mv.sep + (a.lower() if mv.lower else a) + s)
                held[a] = prog.to_machine(a, float(s), mv.inch)
        for a in letters:
            written[a].append(float(held[a]))
        if not edits and not inserts:
            continue
        new = text
        if inserts:
            new = new[:mv.insert_at] + "".join(inserts) + new[mv.insert_at:]
        for s0, e0, s in sorted(edits, reverse=True):
            new = new[:s0] + s + new[e0:]
        result[li] = new + ending
        changed += 1
    return "".join(result), changed, written
