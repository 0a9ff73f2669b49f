"""``fivecal identify``: fit machine errors to a dataset and report them."""
from __future__ import annotations

import argparse
import os
import sys

from ..dataset import load_dataset
from ..identification import identify
from ..procedures.classify import procedure_of, procedure_values
from ..progress import busy
from ..report.document import write_report
from .common import EXIT_FIT, EXIT_OK, _fit_warning
from .history import (add_identify_options, alarms_identify, check_identify_history, grade_identify, identify_history,
                      record_identify)


def _identify(args) -> int:
    import warnings

    hist = identify_history(args)
    ds = load_dataset(args.dataset)
    check_identify_history(args, hist, ds)
    with busy(f"fitting {len(ds)} observations"), warnings.catch_warnings():
        warnings.simplefilter("ignore", category=_fit_warning())  # said once below, in one line
        result = identify(ds, estimate=args.estimate, fix=args.fix, robust=args.robust,
                          allow_unidentifiable=args.allow_unidentifiable,
                          variance_components=args.variance_components)
    print(result.report())
    procedure = procedure_of(ds)
    values = procedure_values(result, procedure)
    # An unusable fit is still written (marked so in the report and refused by
    # `fivecal compensate`): it is what one inspects to find out why.
    if args.out:
        result.save(args.out, procedure, values)
        print(f"\nresult written to {args.out}")
    if args.report:
        path = write_report(result, args.report, title=f"fivecal identification — {os.path.basename(args.dataset)}",
                            summary=f"dataset {args.dataset}, estimate {args.estimate}"
                                    + (f", fixed {args.fix}" if args.fix else ""),
                            history=hist, procedure=procedure, procedure_values=values)
        print(f"\nreport: {os.path.abspath(path)} (with result.json and the plots as PNG)")
    if hist is not None and args.record:
        record_identify(args, result, hist)
    a = result.assessment()
    if not a.usable:
        written = [x for x in (args.out, args.report) if x]
        print(f"fivecal identify: not usable: {a.reason}"
              + (f" ({' and '.join(written)} written, marked not usable)" if written else ""),
              file=sys.stderr)
        return EXIT_FIT
    if hist is not None and (hist.tolerances or hist.volumetric_tolerance is not None):
        # a machine out of tolerance must stop a script as `history compare` does,
        # not only turn a box red in the report
        if grade_identify(result, hist) == "fail":
            print("fivecal identify: FAIL against the tolerances (see the grade above)", file=sys.stderr)
            return EXIT_FIT
    alarmed = alarms_identify(result, hist) if hist is not None else []
    if alarmed:  # an alarm stops a script as a FAIL does (`history trend` too)
        print(f"fivecal identify: CUSUM ALARM on this result: {', '.join(alarmed)} changed (the report's trend)",
              file=sys.stderr)
        return EXIT_FIT
    return EXIT_OK


def register(sub) -> None:
    pi = sub.add_parser("identify", help="fit machine errors to a dataset",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Estimate the listed parameters plus the default setup set the data "
                        "imply (the probe tip, touched facets, sphere centres, ball-bar lengths, R-test "
                        "nests, each fixed instrument's pose instrument.<id>.x|y|z|a|b|c with its target's offsets "
                        "and, for a 6D pose, the target's orientation, each distance station's place and dead "
                        "length), minus --fix, and print a report. Presets (location ...) say which of their "
                        "parameters they left out and why; which sizes count as plausible follows the machine "
                        "file's kind (machining_centre, positioner, robot, cmm: `fivecal docs formats`).",
                        epilog="example:\n  fivecal identify tango.json --estimate S3 --out result.json\n"
                        "  fivecal identify fivecal_demo/dataset.json --estimate S3 --robust huber\n"
                        "  fivecal identify camera.json --estimate location --variance-components")
    pi.add_argument("dataset", help="dataset, JSON or Parquet (format: `fivecal docs formats`)")
    pi.add_argument("--estimate", default="auto",
                    help="parameter names and/or presets S1 S2 S3 S4 location auto, comma separated "
                    "(default: auto, as in Python: every error under its prior, the undetermined "
                    "ones listed)")
    pi.add_argument("--fix", default=None, help="names to keep fixed, comma separated")
    pi.add_argument("--robust", choices=["huber", "cauchy"], default=None,
                    help="robust loss that down-weights and flags outlier touches")
    pi.add_argument("--allow-unidentifiable", action="store_true",
                    help="fit even when parameters are confounded (they are named in the report)")
    pi.add_argument("--variance-components", action="store_true",
                    help="estimate the noise of each instrument group (probe, dbb, ball3d, point, pose, "
                    "pose_rad, distance) from the residuals instead of trusting the declared sigmas "
                    "(`fivecal docs identification`)")
    pi.add_argument("--out", help="write the result document here (its procedure: machining for machined "
                    "features only, tango for facet or cylinder touches, else identify; `fivecal docs formats`)")
    pi.add_argument("--report", metavar="DIR", help="also write an HTML report (report.html, result.json, "
                    "plots as PNG) into this folder")
    add_identify_options(pi)
    pi.set_defaults(func=_identify)
