"""``fivecal sphere-check``: the quick sphere check of the rotary axes."""
from __future__ import annotations

import argparse

from ..dataset import load_dataset
from ..files import write_text
from ..procedures import sphere_check
from .common import fit_status


def _sphere_check(args) -> int:
    ds = load_dataset(args.dataset)
    check = sphere_check.evaluate(ds, previous=args.previous, calibrated_stylus=not args.free_stylus,
                                  backlash=False if args.no_backlash else None, sphere=args.sphere)
    print(check.report())
    if args.out:
        write_text(args.out, sphere_check.to_json(check) + "\n")
        print(f"\ncheck written to {args.out} (give it as --previous to the next check)")
    return fit_status("sphere-check", [("the pivot fit", check.result.assessment())], args.force,
                      written=[args.out])


def register(sub) -> None:
    pp = sub.add_parser("sphere-check", help="quick sphere check: rotary pivots, reversal, dispersion",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Evaluate a quick sphere check (a calibrated stylus, one sphere, a few "
                        "positions per rotary axis, approached from both sides), as controller cycles do: "
                        "the pivot of each rotary axis (position across the axis and tilt) and its reversal "
                        "error with their uncertainty, the change since the previous check, the dispersion of "
                        "the sphere positions before and after, and how well the positions determine them. "
                        "Plans: fivecal.procedures.sphere_check.plan (`fivecal docs design`).",
                        epilog="example:\n  fivecal sphere-check touches.json --previous last.json --out check.json")
    pp.add_argument("dataset", help="dataset JSON with the sphere touches")
    pp.add_argument("--previous", help="the previous check (--out of an earlier run, or a result JSON)")
    pp.add_argument("--out", help="write the check (parameters with value and std) as JSON")
    pp.add_argument("--sphere", default=None, help="sphere id (default: the first sphere touched)")
    pp.add_argument("--no-backlash", action="store_true", help="do not estimate the rotary reversal errors")
    pp.add_argument("--free-stylus", action="store_true",
                    help="estimate the stylus offsets too (default: the stylus is calibrated, tip.* fixed)")
    pp.add_argument("--force", action="store_true", help="exit 0 even when the fit is not usable")
    pp.set_defaults(func=_sphere_check)
