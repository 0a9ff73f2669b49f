"""Command line: fivecal identify | simulate | demo.

Errors are one clear line on stderr (exit status 2), never a traceback.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

from . import __version__


def _identify(args) -> int:
    from .dataset import load_dataset
    from .identification import identify

    ds = load_dataset(args.dataset)
    result = identify(ds, estimate=args.estimate, fix=args.fix, robust=args.robust,
                      allow_unidentifiable=args.allow_unidentifiable)
    print(result.report())
    if args.out:
        result.save(args.out)
        print(f"\nresult written to {args.out}")
    return 0


def _simulate(args) -> int:
    from .dataset import save_dataset
    from .machine import Machine
    from .simulation import simulate

    with open(args.spec) as f:
        spec = json.load(f)
    machine = spec.get("machine")
    if isinstance(machine, str):  # a path relative to the spec file
        machine = Machine.load(os.path.join(os.path.dirname(os.path.abspath(args.spec)), machine))
    if machine is None:
        raise ValueError(f"{args.spec}: 'machine' missing (a machine object or a path)")
    ds = simulate(machine, spec.get("plan", []), errors=spec.get("errors"), artefact=spec.get("artefact"),
                  tip_radius=spec.get("probe", {}).get("tip_radius", 0.0),
                  sigma=args.sigma if args.sigma is not None else spec.get("sigma", 0.0),
                  seed=args.seed if args.seed is not None else spec.get("seed", 0), setup=spec.get("setup"))
    save_dataset(ds, args.out)
    print(f"simulated {len(ds)} observations on {ds.machine.name}; dataset written to {args.out}")
    return 0


def _demo(args) -> int:
    from .demo import run_demo

    run_demo(args.out, seed=args.seed)
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="fivecal", description="Geometric error identification for "
                                "five-axis machine tools (units: mm, degrees for rotary commands, rad "
                                "for angular errors).")
    p.add_argument("--version", action="version", version=f"fivecal {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    pi = sub.add_parser("identify", help="fit machine errors to a dataset",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Estimate the listed parameters plus the default setup set "
                        "(tip, touched facets, sphere centres, DBB lengths) and print a report.",
                        epilog="example:\n  fivecal identify tango.json --estimate S3 --out result.json\n"
                        "  fivecal identify tango.json --estimate location,EXX1 --fix EXXb")
    pi.add_argument("dataset", help="dataset JSON (DESIGN.md format)")
    pi.add_argument("--estimate", default="location",
                    help="parameter names and/or presets S1 S2 S3 S4 location auto, comma separated "
                    "(default: location)")
    pi.add_argument("--fix", default=None, help="names to keep fixed, comma separated")
    pi.add_argument("--robust", choices=["huber", "cauchy"], default=None,
                    help="robust loss that down-weights and flags outlier touches")
    pi.add_argument("--allow-unidentifiable", action="store_true",
                    help="fit even when parameters are confounded (they are named in the report)")
    pi.add_argument("--out", help="write the result JSON here")
    pi.set_defaults(func=_identify)

    ps = sub.add_parser("simulate", help="simulate a measurement on a machine with known errors",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Read a simulation spec (machine or machine path, errors, setup, "
                        "probe, artefact, plan, sigma, seed; see cpp/include/fivecal/simulate.h) and "
                        "write the dataset a real machine would record.",
                        epilog="example:\n  fivecal simulate spec.json --out dataset.json --sigma 0.0006")
    ps.add_argument("spec", help="simulation spec JSON")
    ps.add_argument("--out", required=True, help="dataset JSON to write")
    ps.add_argument("--sigma", type=float, default=None, help="noise (mm), overrides the spec")
    ps.add_argument("--seed", type=int, default=None, help="random seed, overrides the spec")
    ps.set_defaults(func=_simulate)

    pd = sub.add_parser("demo", help="simulate, identify and validate the bundled HU40T TANGO example",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        epilog="example:\n  fivecal demo --out fivecal_demo")
    pd.add_argument("--out", default="fivecal_demo", help="report folder (default: fivecal_demo)")
    pd.add_argument("--seed", type=int, default=1)
    pd.set_defaults(func=_demo)

    args = p.parse_args(argv)
    try:
        return args.func(args)
    except (ValueError, OSError) as e:
        print(f"fivecal {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fivecal: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
