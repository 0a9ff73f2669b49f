"""``fivecal demo``: the bundled HU40T TANGO example, simulated, identified and reported."""
from __future__ import annotations

import argparse

from ..demo import run_demo
from .common import SEED


def _demo(args) -> int:
    run_demo(args.out, seed=args.seed)
    return 0


def register(sub) -> None:
    pd = sub.add_parser("demo", help="simulate, identify and validate the bundled HU40T TANGO example",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="example:\n  fivecal demo --out fivecal_demo")
    pd.add_argument("--out", default="fivecal_demo", help="report folder (default: fivecal_demo)")
    pd.add_argument("--seed", type=SEED, default=1, help="random seed of the simulated noise and of the "
                    "held-out indexations (default: 1)")
    pd.set_defaults(func=_demo)
