"""``fivecal simulate``: the dataset a simulation spec describes."""
from __future__ import annotations

import argparse
import os

from ..dataset import save_dataset
from ..machine import Machine
from ..simulation import simulate
from .common import SEED, SIGMA, _read_json


def _simulate(args) -> int:
    spec = _read_json(args.spec, "the simulation spec")
    if not isinstance(spec, dict):
        raise ValueError(f"{args.spec}: expected a JSON object with machine, plan, errors, ...")
    machine = spec.get("machine")
    if isinstance(machine, str):  # a path relative to the spec file
        machine = Machine.load(os.path.join(os.path.dirname(os.path.abspath(args.spec)), machine))
    if machine is None:
        raise ValueError(f"{args.spec}: 'machine' missing (a machine object or a path)")
    probe = spec.get("probe") or {}
    if not isinstance(probe, dict):
        raise ValueError(f"{args.spec}: probe: expected an object like {{\"tip_radius\": 3.0}}")
    try:
        ds = simulate(machine, spec.get("plan", []), errors=spec.get("errors"), artefact=spec.get("artefact"),
                      tip_radius=probe.get("tip_radius", 0.0),
                      sigma=args.sigma if args.sigma is not None else spec.get("sigma", 0.0),
                      seed=args.seed if args.seed is not None else spec.get("seed", 0), setup=spec.get("setup"))
    except ValueError as e:
        raise ValueError(f"{args.spec}: {e}") from None
    save_dataset(ds, args.out)
    print(f"simulated {len(ds)} observations on {ds.machine.name}; dataset written to {args.out}")
    return 0


def register(sub) -> None:
    ps = sub.add_parser("simulate", help="simulate a measurement on a machine with known errors",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Read a simulation spec (machine or machine path, errors, setup, "
                        "probe, artefact, plan, sigma, seed; see `fivecal docs formats`) and "
                        "write the dataset a real machine would record.",
                        epilog="example:\n  fivecal simulate spec.json --out dataset.json --sigma 0.0006")
    ps.add_argument("spec", help="simulation spec JSON")
    ps.add_argument("--out", required=True, help="dataset JSON to write")
    ps.add_argument("--sigma", type=SIGMA, default=None, help="noise (mm), overrides the spec")
    ps.add_argument("--seed", type=SEED, default=None, help="random seed (an integer 0 <= seed < 2^64), "
                    "overrides the spec")
    ps.set_defaults(func=_simulate)
