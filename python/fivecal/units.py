"""Display units for parameters: files and APIs keep mm and rad, reports show
µm, µrad and µm/m (docs/formats.md, "Units and conventions")."""
from __future__ import annotations

import re

_MOTION = re.compile(r"^E([XYZABC])([XYZABCS])([123])$")
_LOCATION = re.compile(r"^E([XYZABC])0([XYZABCS])$")
_BACKLASH = re.compile(r"^E([XYZABC])([XYZABCS])b$")


def display_scale(name: str) -> tuple[float, str]:
    """Factor and unit label that turn a parameter value (mm / rad based) into
    its report unit."""
    m = _MOTION.match(name)
    if m:
        comp, axis, d = m.group(1), m.group(2), int(m.group(3))
        num, nlabel = (1e6, "µrad") if comp in "ABC" else (1e3, "µm")
        if axis in "ABCS":
            return num, f"{nlabel}/rad" + ("" if d == 1 else f"^{d}")
        return num * 1e3 ** d, f"{nlabel}/m" + ("" if d == 1 else f"^{d}")
    m = _LOCATION.match(name)
    if m:
        return (1e6, "µrad") if m.group(1) in "ABC" else (1e3, "µm")
    m = _BACKLASH.match(name)
    if m:
        return (1e6, "µrad") if m.group(2) in "ABC" else (1e3, "µm")
    return 1e3, "µm"  # tip, facet, sphere, dbb, ball3d setup parameters


def format_value(name: str, value: float) -> str:
    """A parameter value (mm / rad based) as report text, e.g. ``'-108.060 µm'``."""
    f, unit = display_scale(name)
    return f"{value * f:.3f} {unit}"
