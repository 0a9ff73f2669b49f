"""A simulated fleet of machines with nightly sphere checks (the fleet test
and bench): each machine has its own location errors, each night a sphere
check adds probing noise, and on some machines a pivot drifts from a random
night on, as a step or as a ramp.

The sphere check: one sphere (phi 19.05 mm) on the table 112 mm from the C
axis, probed at 33 ISO 230-10-like points at B in {0, 30, -30} and C in {0,
90, 180, 270} (about 260 touches, 0.6 µm probing noise), fitted with
``estimate="location"``. On the HU40T-like machine that gives σ(EX0C) ≈ 0.19 µm
per night, so a 2 µm step is some 10 σ.
"""
from __future__ import annotations

import datetime
import json
import os
from typing import List, Optional

import numpy as np

from .. import files
from ..simulation import simulate
from ..procedures import sphere_test, tango
from .. import _core

SPHERE = {"id": "P", "center": [100.0, -50.0, 60.0], "radius": 19.05 / 2}
INDEXATIONS = [{"B": float(b), "C": float(c)} for b in (0, 30, -30) for c in (0, 90, 180, 270)]
#: one-sigma of each machine's own location errors (mm, rad)
SPREAD = {"EX0C": 0.02, "EA0C": 2e-5, "EB0C": 2e-5, "EA0B": 2e-5, "EC0B": 2e-5, "EA0Y": 2e-5, "EC0Y": 2e-5,
          "EB0Z": 2e-5}
START = datetime.datetime(2026, 1, 1, 2, 0, tzinfo=datetime.timezone.utc)


def machine():

    return tango.hu40t_machine()


def sphere_check_plan(m=None) -> list:

    return sphere_test.sphere_plan(m or machine(), SPHERE, INDEXATIONS, tip_radius=tango.TIP_RADIUS)


def night_time(night: int) -> str:
    return (START + datetime.timedelta(days=night)).strftime("%Y-%m-%dT%H:%M:%SZ")


def drift_at(night: int, drift: Optional[dict]) -> float:
    """The pivot's drift (mm) on ``night`` for a drift ``{"onset", "amount", "shape"}``:
    a step jumps to ``amount`` at onset, a ramp grows by amount/5 a night from
    onset (reaching ``amount`` on the fifth night)."""
    if not drift or night < drift["onset"]:
        return 0.0
    if drift["shape"] == "step":
        return drift["amount"]
    return drift["amount"] * min(1.0, (night - drift["onset"] + 1) / 5.0)


def fleet_truth(machines: int, nights: int, drift_fraction: float = 0.05, seed: int = 0,
                parameter: str = "EX0C") -> List[dict]:
    """Per machine: id, its location errors, and its drift (None for most):
    ``round(drift_fraction * machines)`` machines (at least 1) drift by 2–10 µm
    from a night drawn in 2 .. nights-6 (at least one quiet night before, five
    after), half steps, half ramps, up or down."""
    rng = np.random.default_rng(seed)
    out = []
    drifting = set(rng.choice(machines, size=max(1 if drift_fraction > 0 else 0, round(drift_fraction * machines)), replace=False).tolist())
    for i in range(machines):
        errors = {n: float(rng.normal(0, s)) for n, s in SPREAD.items()}
        drift = None
        if i in drifting:
            drift = {"parameter": parameter, "onset": int(rng.integers(2, nights - 5)),
                     "amount": float(rng.uniform(0.002, 0.010) * rng.choice([-1, 1])),
                     "shape": "step" if rng.random() < 0.5 else "ramp"}
        out.append({"machine_id": f"M{i:04d}", "errors": errors, "drift": drift})
    return out


def write_fleet(folder: str, truth: List[dict], nights: int, seed: int = 0, sigma: Optional[float] = None,
                client=None) -> list:
    """Simulate every machine's nightly sphere checks into
    ``folder/<machine_id>/<YYYY-MM-DD>.json`` (the layout ``fivecal fleet
    identify`` reads: machine id from the folder, time from the file name);
    returns the paths. ``client``: a Dask client to simulate the machines on
    its workers (the same files as without)."""

    m = machine()
    plan = sphere_check_plan(m)
    # the first night goes through fivecal.simulate (validated); the others reuse
    # its checked spec with new errors and seed straight in the core, which
    # keeps simulating a fleet of thousands of nights affordable
    simulate(m, plan, errors=truth[0]["errors"] if truth else {}, artefact={"spheres": [SPHERE]},
             tip_radius=tango.TIP_RADIUS, sigma=tango.PROBE_SIGMA if sigma is None else sigma, seed=seed)
    spec = {"machine": m.to_dict(), "setup": {}, "probe": {"tip_radius": tango.TIP_RADIUS},
            "artefact": {"spheres": [SPHERE]}, "plan": plan,
            "sigma": tango.PROBE_SIGMA if sigma is None else sigma}
    work = list(enumerate(truth))
    if client is None:
        return _write_machines(work, folder, spec, nights, seed)
    step = max(1, -(-len(work) // (8 * max(1, sum(client.nthreads().values())))))
    spec_f = client.scatter([spec], broadcast=True)[0]
    parts = [work[i:i + step] for i in range(0, len(work), step)]
    futures = client.map(_write_machines, parts, folder=folder, spec=spec_f, nights=nights, seed=seed, pure=False)
    return [p for part in client.gather(futures) for p in part]


def _write_machines(work: list, folder: str, spec: dict, nights: int, seed: int) -> list:

    paths = []
    for k, mach in work:
        d = os.path.join(folder, mach["machine_id"])
        os.makedirs(d, exist_ok=True)
        for night in range(nights):
            errors = dict(mach["errors"])
            if mach["drift"]:
                p = mach["drift"]["parameter"]
                errors[p] = errors.get(p, 0.0) + drift_at(night, mach["drift"])
            text = json.dumps({**spec, "errors": errors, "seed": (seed * 1_000_003 + k) * 1000 + night})
            core = _core.simulate(text)
            path = os.path.join(d, night_time(night)[:10] + ".json")
            # thousands of files a simulation can make again: atomic, not fsynced
            files.write_text(path, core.to_json(), durable=False)
            paths.append(path)
    return paths
