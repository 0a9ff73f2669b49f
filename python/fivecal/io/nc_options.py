"""The numeric options of fivecal's NC program writers, one rule each
(docs/linuxcnc.md, "Program options").

Every writer (:mod:`fivecal.io.nc_programs`, :func:`fivecal.io.linuxcnc.probing_program`,
:mod:`fivecal.io.dbb_program`) checks its options with :func:`check`, and
``fivecal export program`` checks its command line with :func:`check_cli`
against the same :data:`RULES`, so a value is refused the same way whichever
door it comes in by: a refusal names the option (``feed`` from Python,
``--feed`` from the command line), the bound and the value.

The upper bounds are there because the program is run on a machine: a
distance option puts a G0 or a G38.2 end point that far away, and a
kilometre-long probe move or a feed of 10^9 mm/min is a slip (a unit, a
missing decimal point), never a plan. Bounds that depend on the plan (the
G38.2 overtravel on a sphere, the ball bar feed-in) are checked by the
writers, which raise :class:`OptionError` for them too.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Optional

from ..plausibility import REFUSE_POSITION


@dataclass(frozen=True)
class Rule:
    unit: str
    low: float
    high: float
    low_open: bool = False       # the low end itself is refused (a feed of 0)
    integer: bool = False
    why: str = ""                # what the upper bound stands for
    cli_unit: Optional[str] = None   # the command line's unit when it differs
    cli_scale: float = 1.0           # option value * cli_scale = value in ``unit``
    cli_flag: Optional[str] = None   # the command line's name when it is not the writer's


#: name -> rule; the values are the writers' (mm, mm/min, s, degrees)
RULES = {
    "feed": Rule("mm/min", 0.0, 1e5, low_open=True,
                 why="100 m/min, beyond any probing, R-test or ball bar feed"),
    "dwell": Rule("s", 0.0, 3600.0, why="an hour"),
    "clearance": Rule("mm", 0.0, 50.0, low_open=True,
                      why="the G38.2 move starts this far off the surface at the probing feed"),
    "overtravel": Rule("mm", 0.0, 10.0, low_open=True,
                       why="a touch probe's stylus gives way a few mm before it breaks"),
    "retract": Rule("mm", 0.0, 500.0),
    "safe": Rule("mm", 0.0, 2000.0, why="a lift along the tool axis beyond a large machine's travel"),
    "overshoot": Rule("degrees", 0.0, 45.0),
    "subdivide": Rule("points", 0.0, 1000.0, integer=True),
    "feed_in": Rule("mm", 0.0, 50.0, low_open=True),
    "turns": Rule("turns", 1.0, 100.0, integer=True),
    # --path-tolerance: read with its unit by fivecal.tolerances.path_tolerance, then checked here in mm
    "tolerance": Rule("mm", 0.0, 1.0, low_open=True, cli_flag="--path-tolerance",
                      why="the bar length between two blocks of a ball bar path"),
    "tip_radius": Rule("mm", 0.0, 50.0, low_open=True),
}


def flag(name: str) -> str:
    """The command-line spelling of an option (``feed_in`` -> ``--feed-in``,
    ``tolerance`` -> ``--path-tolerance``)."""
    rule = RULES.get(name)
    if rule is not None and rule.cli_flag:
        return rule.cli_flag
    return "--" + name.replace("_", "-")


class OptionError(ValueError):
    """A refused option value; ``option`` is its name, ``text`` the reason
    (the message is ``option: text``)."""

    def __init__(self, option: str, text: str):
        self.option, self.text = option, text
        super().__init__(f"{option}: {text}")

    def for_cli(self) -> ValueError:
        """The same refusal naming the command-line option."""
        return ValueError(f"{flag(self.option)}: {self.text}")


def _requirement(rule: Rule, cli: bool) -> str:
    scale = rule.cli_scale if cli else 1.0
    unit = (rule.cli_unit or rule.unit) if cli else rule.unit
    lo, hi = rule.low / scale, rule.high / scale
    kind = "a whole number" if rule.integer else "a number"
    low = f"> {lo:g}" if rule.low_open else f">= {lo:g}"
    why = f" ({rule.why})" if rule.why else ""
    return f"expected {kind} {low} and <= {hi:g} {unit}{why}"


def _problem(rule: Rule, value, cli: bool) -> Optional[str]:
    """Why ``value`` (in the rule's unit, or the command line's with ``cli``)
    breaks ``rule``; None when it does not."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return f"{_requirement(rule, cli)}, got {value!r}"
    if isinstance(value, bool):
        return f"{_requirement(rule, cli)}, got {value!r}"
    scaled = v * (rule.cli_scale if cli else 1.0)
    ok = (math.isfinite(v) and (scaled > rule.low if rule.low_open else scaled >= rule.low)
          and scaled <= rule.high and (not rule.integer or v == math.floor(v)))
    return None if ok else f"{_requirement(rule, cli)}, got {value!r}"


def check(**values) -> None:
    """Refuse (:class:`OptionError`, naming the option) the first value that
    breaks its rule in :data:`RULES`; ``None`` values are skipped."""
    for name, value in values.items():
        if value is None:
            continue
        msg = _problem(RULES[name], value, False)
        if msg:
            raise OptionError(name, msg)


def check_cli(args) -> None:
    """Refuse (ValueError naming the option as typed, ``--feed-in``) the
    first option of the parsed command line ``args`` that breaks its rule;
    options the command does not have or left out (None) are skipped."""
    for name, rule in RULES.items():
        value = getattr(args, name, None)
        if value is None:
            continue
        msg = _problem(rule, value, True)
        if msg:
            raise ValueError(f"{flag(name)}: {msg}")


def at_most(name: str, value: float, bound: float, what: str) -> None:
    """A plan-dependent upper bound: :class:`OptionError` naming ``name``
    when ``value`` > ``bound`` (``what`` says what the bound is)."""
    if value > bound:
        raise OptionError(name, f"{value:g} {RULES[name].unit} is more than {what} ({bound:g} "
                                f"{RULES[name].unit})")



def check_line(name: str, value, comment: bool = False) -> None:
    """A text option written into the program as it is (``arm``, ``tcp_on``,
    or with ``comment`` the probe log's file name inside ``(PROBEOPEN ...)``):
    one line of printable text, so it cannot end its line or comment early
    and slip other blocks into the program."""
    if value is None:
        return
    if not isinstance(value, str):
        raise OptionError(name, f"expected text, got {value!r}")
    bad = next((c for c in value if not c.isprintable()), None)
    if bad is not None:
        raise OptionError(name, f"{bad!r} in {value!r}: it is written into the program as one line")
    if comment and (not value.strip() or "(" in value or ")" in value):
        raise OptionError(name, f"expected a file name without parentheses (it is written inside a G-code "
                                f"comment), got {value!r}")


_COMMENT = re.compile(r"\([^)]*\)")
_AXIS_WORD = re.compile(r"([XYZABC])([+-]?(?:\d+\.?\d*|\.\d+|nan|inf))")


def check_probe_lines(log, arm, disarm, sync, tcp_on, before_probe) -> None:
    """The text options of a probing cycle (the probe log's name and the
    lines written as they are), each by :func:`check_line`."""
    check_line("log", log, comment=True)
    for name, line in (("arm", arm), ("disarm", disarm), ("sync", sync), ("tcp_on", tcp_on)):
        check_line(name, line)
    for i, lines in enumerate(before_probe or []):
        for line in lines:
            check_line(f"before_probe[{i}]", line)


def check_positions(text: str, what: str) -> str:
    """``text`` (a program) as it is when every axis word is within
    ±plausibility.REFUSE_POSITION (mm or degrees); else ValueError naming
    the line: a position no machine tool reaches comes from an artefact, plan
    or option in the wrong unit, and must not be run."""
    for ln, line in enumerate(text.splitlines(), 1):
        for letter, number in _AXIS_WORD.findall(_COMMENT.sub("", line)):
            if not abs(float(number)) <= REFUSE_POSITION:
                raise ValueError(f"{what}: line {ln} moves {letter} to {float(number):g}, beyond any machine "
                                 f"tool (|{letter}| <= {REFUSE_POSITION:g} mm or degrees): check the plan's, the "
                                 "artefact's and the options' units")
    return text


def check_vector(name: str, value) -> None:
    """A point or shift option (``workpiece_shift``): three finite numbers
    of mm within ±plausibility.REFUSE_POSITION."""
    try:
        v = [float(x) for x in value]
    except (TypeError, ValueError):
        v = []
    if len(v) != 3 or not all(abs(x) <= REFUSE_POSITION for x in v):
        raise OptionError(name, f"expected [x, y, z] in mm, finite and within ±{REFUSE_POSITION:g}, got {value!r}")


def comment_text(value) -> str:
    """``value`` (a machine, target, setup or sample name) as text that
    stays inside the comment it is written into, a G-code ``( )`` or a HAL
    ``#``: one line, parentheses as brackets, no backslash (which would
    continue a HAL comment onto the next line). A name with ``)`` or a
    newline would otherwise end the comment and put the rest of it into the
    program as blocks."""
    s = "".join(c if c.isprintable() else " " for c in str(value))
    return s.replace("(", "[").replace(")", "]").replace("\\", "/")
