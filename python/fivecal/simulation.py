"""The virtual machine: datasets a real machine with known errors would record."""
from __future__ import annotations

import math
import numbers
from typing import Mapping, Optional, Sequence, Union

from . import _core, plausibility, schema
from .dataset import Dataset
from .machine import Machine

SEED_LIMIT = 2 ** 64


def integer(value, name: str, low: int, high: Optional[int] = None) -> int:
    """``value`` as an int in ``[low, high)``: Python and numpy integers, and
    floats with an integral value (a JSON ``3.0``); anything else, a bool, a
    fraction (2.9 is not silently 2), NaN or a value out of range is a
    ValueError naming ``name``."""
    rng = f"an integer >= {low}" if high is None else f"an integer {low} <= {name} < {_power(high)}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name}: must be {rng}, got {value!r}")
    if isinstance(value, numbers.Integral):
        v = int(value)
    else:
        f = float(value)
        if not math.isfinite(f) or f != math.floor(f):
            raise ValueError(f"{name}: must be {rng}, got {value!r}")
        v = int(f)
    if v < low or (high is not None and v >= high):
        raise ValueError(f"{name}: must be {rng}, got {value!r}")
    return v


def _power(n: int) -> str:
    if n > 1 and n & (n - 1) == 0:
        return f"2^{n.bit_length() - 1}"
    return str(n)


def seed_value(seed, name: str = "seed") -> int:
    """A random seed: an integer 0 <= seed < 2^64 (see :func:`integer`)."""
    return integer(seed, name, 0, SEED_LIMIT)


def _mapping(value, name: str, what: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ValueError(f"{name}: expected an object {what}, got {type(value).__name__}")
    return dict(value)


def _number(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    return float(value)


def simulate(machine: Union[Machine, Mapping], plan: Sequence[Mapping], errors: Optional[Mapping] = None,
             artefact: Optional[Mapping] = None, tip_radius: float = 0.0,
             sigma: Union[float, Mapping] = 0.0, seed: int = 0,
             setup: Optional[Mapping[str, float]] = None) -> Dataset:
    """Simulate a measurement on a machine with known errors.

    ``plan`` lists the touches and samples (see ``docs/formats.md, "Simulation spec"``):
    ``{"type": "facet", "target": "F3", "axes": {"B": 30, "C": -90, "S": 0}}``,
    ``{"type": "sphere", "target": "S1", "axes": {...}, "normal": [0, 0, 1]}``,
    ``{"type": "dbb", "axes": {...all axes...}, "length": 100, "tool_ball": [...],
    "table_ball": [...], "setup": "A1"}``, ``{"type": "ball3d", ...}``.
    ``errors``: true machine errors (mm, rad); ``setup``: true setup parameters
    (``facet.F3``, ``sphere.S1.x``, ``dbb.length`` ...); ``sigma`` (mm): probing
    repeatability along the approach, or a dict with ``probe``, ``dbb``, ``ball3d``,
    ``point``, ``pose`` (mm), ``pose_angle`` (rad) and ``distance``.
    ``seed``: an integer 0 <= seed < 2^64 (integral floats such as 3.0 too).
    """
    machine = Machine.from_dict(machine)
    if isinstance(plan, (str, bytes, Mapping)) or not isinstance(plan, Sequence):
        raise ValueError(f"plan: expected a list of planned observations, got {type(plan).__name__}")
    plausibility.check_plan(machine, plan)
    spec = {"machine": machine.to_dict(), "errors": _mapping(errors, "errors", "name -> value (mm, rad)"),
            "setup": _mapping(setup, "setup", "name -> value"),
            "probe": {"tip_radius": _number(tip_radius, "probe.tip_radius")},
            "artefact": _mapping(artefact, "artefact", "with facets, spheres, scale bars"),
            "plan": list(plan), "sigma": sigma, "seed": seed_value(seed)}
    return Dataset(_core.simulate(schema.checked_dumps(spec, "spec")))
