"""``fivecal rtest``: R-test K tests."""
from __future__ import annotations

import argparse

from ..dataset import load_dataset
from ..files import write_json
from ..procedures import rtest
from ..tolerances import parse_value
from .common import EXIT_FIT, EXIT_OK, fit_status


def _rtest(args) -> int:
    # µm when bare (this command's unit since its first release), any length unit when written
    tol = None if args.tolerance is None else parse_value(args.tolerance, "--tolerance", bare_unit="um")
    out = rtest.evaluate(load_dataset(args.dataset), identify=not args.no_identify)
    print(out.report(tol))
    if args.out:
        write_json(args.out, out.to_dict(tol))
        print(f"\nresult written to {args.out}")
    verdicts = [("the location-error fit", out.result.assessment())] if out.result is not None else []
    status = fit_status("rtest", verdicts, args.force, written=[args.out])
    failed = tol is not None and not all(t.passes(tol) for t in out.tests.values())
    return EXIT_FIT if failed and status == EXIT_OK else status


def register(sub) -> None:
    pp = sub.add_parser("rtest", help="R-test K tests: deviation ranges and the rotary axes' location errors",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Evaluate R-test data (ball3d observations, one setup per test): the "
                        "range of the recorded deviation in X, Y, Z per test, pass/fail against --tolerance, "
                        "and the location errors of the rotary axes fitted to all tests. Plans: "
                        "fivecal.procedures.rtest.plan (`fivecal docs design`).",
                        epilog="example:\n  fivecal rtest rtest_data.json --tolerance 20 --out rtest_result.json")
    pp.add_argument("dataset", help="dataset JSON with the ball3d observations")
    pp.add_argument("--tolerance", default=None, metavar="UM",
                    help="largest allowed range per direction, µm, or with a unit: 0.02mm (exit 1 when a test "
                    "exceeds it)")
    pp.add_argument("--no-identify", action="store_true", help="only the ranges, no location-error fit")
    pp.add_argument("--out", help="write the result document (the location errors with value and std, verdict, "
                    "and the K tests' ranges as procedure rtest)")
    pp.add_argument("--force", action="store_true", help="exit 0 even when the fit is not usable")
    pp.set_defaults(func=_rtest)
