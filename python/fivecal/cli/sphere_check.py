"""``fivecal sphere-check``: the quick sphere check of the rotary axes."""
from __future__ import annotations

import argparse
import sys

from ..dataset import load_dataset
from ..identification import write_result
from ..procedures import sphere_check
from .common import EXIT_FIT, deprecated_alias, fit_status


def _sphere_check(args) -> int:
    ds = load_dataset(args.dataset)
    if args.expect and not args.previous:
        raise ValueError("--expect: needs --previous, the check before loading (the change is predicted from it)")
    check = sphere_check.evaluate(ds, previous=args.previous, calibrated_stylus=not args.free_stylus,
                                  backlash=False if args.no_backlash else None, sphere=args.sphere,
                                  expect=args.expect)
    print(check.report())
    if args.out:
        write_result(args.out, check.result, "sphere-check", check.procedure_values())
        print(f"\nresult written to {args.out} (give it as --previous to the next check)")
    status = fit_status("sphere-check", [("the pivot fit", check.result.assessment())], args.force,
                        written=[args.out])
    v = check.verification
    if v is not None and not v.took_effect:
        # --force accepts a fit, never a change that did not take effect
        print(f"fivecal sphere-check: the loaded change: {v.message}", file=sys.stderr)
        return EXIT_FIT
    return status


def register(sub) -> None:
    pp = sub.add_parser("sphere-check", help="quick sphere check: rotary pivots, reversal, dispersion",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Evaluate a quick sphere check (a calibrated stylus, one sphere, a few "
                        "positions per rotary axis, approached from both sides), as controller cycles do: "
                        "the pivot of each rotary axis (position across the axis and tilt) and its reversal "
                        "error with their uncertainty, the change since the previous check, the dispersion of "
                        "the sphere positions before and after, and how well the positions determine them. "
                        "Plans: fivecal.procedures.sphere_check.plan (`fivecal docs design`).",
                        epilog="examples:\n  fivecal sphere-check touches.json --previous last.json --out check.json\n"
                        "  fivecal sphere-check after.json --previous before.json --expect siemens_out/export.json "
                        "--out after_check.json")
    pp.add_argument("dataset", help="dataset JSON with the sphere touches")
    pp.add_argument("--previous", help="the previous check: any result document (--out of an earlier check, "
                    "of identify, rtest, ...)")
    pp.add_argument("--expect", metavar="EXPORT", help="verify after loading: the export.json (or its folder) of "
                    "the values loaded into the controller since --previous; says per parameter and overall "
                    "whether the change took effect as predicted, or names what differs (not applied, sign "
                    "reversed, applied twice, a unit, one component's sign); exit 1 unless it took effect "
                    "(`fivecal docs controllers`)")
    pp.add_argument("--out", help="write the result document (parameters with value and std, verdict, and the "
                    "check's pivots, reversal, dispersion and change as procedure sphere-check)")
    pp.add_argument("--sphere-id", dest="sphere", default=None, help="sphere id (default: the first sphere touched)")
    deprecated_alias(pp, "--sphere", "--sphere-id")   # the id's name in plan too
    pp.add_argument("--no-backlash", action="store_true", help="do not estimate the rotary reversal errors")
    pp.add_argument("--free-stylus", action="store_true",
                    help="estimate the stylus offsets too (default: the stylus is calibrated, tip.* fixed)")
    pp.add_argument("--force", action="store_true", help="exit 0 even when the fit is not usable")
    pp.set_defaults(func=_sphere_check)
