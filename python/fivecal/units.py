"""Display units for parameters: files and APIs keep mm and rad, reports show
µm, µrad and µm/m (docs/formats.md, "Units and conventions")."""
from __future__ import annotations

import re
from functools import lru_cache

from . import _core

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
    if _setup_unit(name) == "rad":  # an instrument's or a part's angle
        return 1e6, "µrad"
    return 1e3, "µm"  # tip, facet, sphere, dbb, ball3d setup parameters


@lru_cache(maxsize=None)
def _setup_unit(name: str) -> str:
    # The unit the setup parameter's kind declares (its prior class).
    return _core.setup_parameter_unit(name)


def format_value(name: str, value: float) -> str:
    """A parameter value (mm / rad based) as report text, e.g. ``'-108.060 µm'``."""
    f, unit = display_scale(name)
    return f"{value * f:.3f} {unit}"


# ---------------------------------------------------------------------------
# units at the boundary: radians where degrees are expected, units in CSV headers
# ---------------------------------------------------------------------------
class UnitsWarning(UserWarning):
    """Input magnitudes look like the wrong unit (µm for mm, a diameter for a
    radius) but a rough nominal model could also explain them."""


def looks_like_radians(values) -> bool:
    """True when rotary values (meant in degrees) are clearly radians.

    Evidence required, all of it: every |value| <= 2*pi; the values span more
    than 1 (rad, 57 degrees of motion); and at least one value is not round
    in degrees (more than 3 decimals, e.g. 0.785398 = pi/4). Or: every
    non-zero value is a multiple of pi/12 written to 4 or more decimals
    (``1.5708``, even alone). So a dense sweep ``linspace(0, 2*pi, n)`` or
    indexations ``[0, pi/2, pi]`` warn, while ``[0, 0.5, 1]`` (ambiguous),
    ``[0, 0.001, 0.002]`` (tiny motions) or a single round value do not.
    Non-finite values are ignored.
    """
    import numpy as np

    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0 or np.abs(v).max() > 2 * np.pi + 1e-6:
        return False
    if _pi_over_12(v):
        return True
    if v.size < 2 or v.max() - v.min() <= 1.0:
        return False
    return bool(np.any(_non_round(v)))


def _non_round(v):
    """Values with more than 3 decimals."""
    import numpy as np

    milli = v * 1000.0
    return np.abs(milli - np.round(milli)) > 1e-6 * np.maximum(1.0, np.abs(milli))


def _pi_over_12(v) -> bool:
    """Radian indexations written out (1.5708 = 90 degrees): every non-zero
    value a multiple of pi/12 to 4 decimals, none round in degrees."""
    import numpy as np

    nz = v[v != 0.0]
    if not nz.size or not np.all(_non_round(nz)) or np.abs(nz).max() > 2 * np.pi + 1e-6:
        return False
    k = nz / (np.pi / 12)
    return bool(np.all(np.abs(k - np.round(k)) < 5e-4) and np.all(np.round(k) != 0))


def written_as_radians(values) -> bool:
    """True when rotary values meant in degrees are radian indexations beyond
    doubt: every non-zero value a multiple of pi/12 written to 4 or more
    decimals (``0.7854``, ``1.5708``) and at least two different ones.
    Degrees never fall on that pattern by chance, so an importer may refuse
    them, where :func:`looks_like_radians` (ambiguous cases too) only warns."""
    import numpy as np

    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    return _pi_over_12(v) and np.unique(v[v != 0.0]).size >= 2


def radians_message(where: str, values) -> str:
    import numpy as np

    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v)]
    return (f"{where}: rotary values look like radians ({v.size} values within ±2π spanning "
            f"{v.max() - v.min():.4g}, max |value| {np.abs(v).max():.4g}); fivecal expects degrees "
            "(multiply by 180/π)")


#: Unit suffixes of CSV column names (``reading_um``, ``angle_rad``) and the
#: factor to fivecal's unit of that quantity (mm, degrees). The micro sign is
#: accepted as U+00B5 (what keyboards type) and U+03BC (Greek mu).
LENGTH_SUFFIXES = {"mm": 1.0, "um": 1e-3, "µm": 1e-3, "μm": 1e-3, "m": 1e3, "in": 25.4, "inch": 25.4}
ANGLE_SUFFIXES = {"deg": 1.0, "°": 1.0, "degree": 1.0, "degrees": 1.0, "rad": 180.0 / 3.141592653589793,
                  "mrad": 0.18 / 3.141592653589793, "urad": 1.8e-4 / 3.141592653589793,
                  "µrad": 1.8e-4 / 3.141592653589793, "μrad": 1.8e-4 / 3.141592653589793}


def unit_list(kind: str) -> str:
    """The units of a quantity (``length`` or ``angle``) as message text."""
    return ", ".join(LENGTH_SUFFIXES if kind == "length" else ANGLE_SUFFIXES)


def split_unit(header: str):
    """(name, unit text or None) of a column header: the unit in brackets
    (``dx [um]``, ``A (°)``), a trailing degree sign (``A°``) or the suffix
    after the last ``_`` (``reading_um``), this last only when it is a known
    unit (``table_ball_x`` is a name)."""
    h = header.strip().strip('"').strip("'")
    m = re.match(r"^(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*$", h)
    if m:
        return m.group(1).strip(), m.group(2).strip()
    if h.endswith("°") and len(h) > 1:
        return h[:-1].rstrip().rstrip("_").rstrip(), "°"
    if "_" in h:
        base, suffix = h.rsplit("_", 1)
        if base and (suffix.lower() in LENGTH_SUFFIXES or suffix.lower() in ANGLE_SUFFIXES):
            return base, suffix
    return h, None


def column_unit(column: str, kind: str, where: str = "CSV"):
    """(factor to mm or degrees, unit text or None) of a CSV column named with
    a unit suffix after the last ``_`` (``reading_um``) or in brackets
    (``reading [um]``, ``reading (um)``); ``kind`` is ``length`` or
    ``angle``. No suffix: (1.0, None). An unknown suffix, or the unit of the
    other kind (``reading_deg``), is a ValueError naming the column."""
    name = column.strip().strip('"').strip("'")
    m = re.match(r"^(.*?)\s*[\[(]\s*([^\])]*)\s*[\])]\s*$", name)
    if m:
        suffix = m.group(2).strip()
    elif name.endswith("°") and len(name) > 1:
        suffix = "°"
    elif "_" in name:
        suffix = name.rsplit("_", 1)[1]
    else:
        return 1.0, None
    table = LENGTH_SUFFIXES if kind == "length" else ANGLE_SUFFIXES
    key = suffix.lower()
    if key in table:
        return table[key], key
    raise ValueError(f"{where}: column '{column.strip()}': unknown unit '{suffix}' for "
                     f"{'a length' if kind == 'length' else 'an angle'} (units: {unit_list(kind)})")
