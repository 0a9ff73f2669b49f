"""The virtual machine: datasets a real machine with known errors would record."""
from __future__ import annotations

from typing import Mapping, Optional, Sequence, Union

from . import _core, schema
from .dataset import Dataset
from .machine import Machine


def simulate(machine: Union[Machine, Mapping], plan: Sequence[Mapping], errors: Optional[Mapping] = None,
             artefact: Optional[Mapping] = None, tip_radius: float = 0.0,
             sigma: Union[float, Mapping] = 0.0, seed: int = 0,
             setup: Optional[Mapping[str, float]] = None) -> Dataset:
    """Simulate a measurement on a machine with known errors.

    ``plan`` lists the touches and samples (see ``cpp/include/fivecal/simulate.h``):
    ``{"type": "facet", "target": "F3", "axes": {"B": 30, "C": -90, "S": 0}}``,
    ``{"type": "sphere", "target": "S1", "axes": {...}, "normal": [0, 0, 1]}``,
    ``{"type": "dbb", "axes": {...all axes...}, "length": 100, "tool_ball": [...],
    "table_ball": [...], "setup": "A1"}``, ``{"type": "ball3d", ...}``.
    ``errors``: true machine errors (mm, rad); ``setup``: true setup parameters
    (``facet.F3``, ``sphere.S1.x``, ``dbb.length`` ...); ``sigma`` (mm): probing
    repeatability along the approach, or a dict with ``probe``, ``dbb``, ``ball3d``.
    """
    machine = Machine.from_dict(machine)
    spec = {"machine": machine.to_dict(), "errors": dict(errors or {}), "setup": dict(setup or {}),
            "probe": {"tip_radius": float(tip_radius)}, "artefact": dict(artefact or {}),
            "plan": list(plan), "sigma": sigma, "seed": int(seed)}
    return Dataset(_core.simulate(schema.checked_dumps(spec, "spec")))
