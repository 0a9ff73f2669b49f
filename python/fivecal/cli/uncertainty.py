"""``fivecal uncertainty``: Monte Carlo (JCGM 101) or pooled-cycles GUM uncertainty."""
from __future__ import annotations

import argparse
import os

from .. import schema, uncertainty
from ..files import read_json
from ..identification import identify
from ..machine import Machine
from .common import (MAX_WORKERS, POSITIVE, PROBABILITY, SEED, SIGMA, TRIALS, _FORCE_HELP, _fit_warning, _integer_type,
                     _values_verdict, count_type, fit_status)


def _uncertainty(args) -> int:
    def load(path):
        d = read_json(path, "spec or dataset")
        d = schema.validate(d, "dataset" if isinstance(d, dict) and "observations" in d else "spec", path)
        if isinstance(d, dict) and isinstance(d.get("machine"), str):  # a path relative to the file
            d["machine"] = Machine.load(os.path.join(os.path.dirname(os.path.abspath(path)),
                                                     d["machine"])).to_dict()
        return d

    import warnings

    inputs = [load(p) for p in args.inputs]
    if len(inputs) == 1:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", category=_fit_warning())  # judged below, in one line
            mc = uncertainty.monte_carlo(inputs[0], args.estimate, trials=args.trials, threads=args.threads,
                                         seed=args.seed, progress=not args.no_progress,
                                         probability=args.probability, significant_digits=args.digits,
                                         fix=args.fix, sigma=args.sigma)
        print(mc.report())
        if args.plot:
            mc.plot(args.plot)
            print(f"\nhistograms written to {args.plot}")
        if args.out:
            mc.save(args.out, include_samples=args.samples)
            print(f"result written to {args.out}")
        verdicts = []
        if mc.fit is not None:  # a dataset: the noise is drawn around its fit
            verdicts.append(("the fit of the dataset", mc.fit.assessment()))
        verdicts.append(("Monte Carlo", _values_verdict(mc.mean, mc.std, converged=mc.used > 0)))
        if mc.used == 0:
            verdicts[-1][1].reason = f"none of the {mc.trials} trials converged"
        return fit_status("uncertainty", verdicts, args.force, (args.out, args.plot))
    try:
        days = [int(x) for x in args.days.split(",")] if args.days else None
    except ValueError:
        raise ValueError(f"--days: expected one integer day label per INPUT, comma separated (e.g. 1,1,2,2), "
                         f"got '{args.days}'") from None
    if days is not None and len(days) != len(inputs):
        raise ValueError(f"--days: {len(days)} labels for {len(inputs)} cycles")
    u = uncertainty.gum_input_covariance(inputs, args.estimate, day=days, pooling=args.pool,
                                         probability=args.probability, k=args.k, fix=args.fix)
    print(u.report())
    if args.out:
        u.save(args.out)
        print(f"\nresult written to {args.out}")
    # The sensitivities come from the fit of the first cycle: judged as
    # `fivecal identify` would judge it.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=_fit_warning())  # said once, in one line
        reference = identify(inputs[0], args.estimate, fix=args.fix)
    return fit_status("uncertainty", [(f"the fit of {args.inputs[0]}", reference.assessment()),
                                      ("GUM", _values_verdict(u.values, u.std))], args.force, (args.out,))


def register(sub) -> None:
    pu = sub.add_parser("uncertainty", help="Monte Carlo (JCGM 101) or pooled-cycles GUM uncertainty "
                        "of the identified parameters",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="One INPUT (a simulation spec or a dataset): Monte Carlo -- re-draw the "
                        "measurement noise TRIALS times, re-fit on all cores, report the mean, standard "
                        "uncertainty and shortest coverage interval of every parameter and compare them "
                        "with the GUM (linearised) uncertainty as JCGM 101 section 8 validates it. Several "
                        "INPUTs (datasets of repeated cycles of one plan): GUM U_y = C U_x C^T with U_x "
                        "pooled by cycles or by days (thesis ch. 5), coverage factor stated.",
                        epilog="examples:\n"
                        "  fivecal uncertainty tango_spec.json --estimate S3 --trials 10000 "
                        "--out mc.json --plot mc.png\n"
                        "  fivecal uncertainty measured.json --estimate S3 --trials 2000 --threads 4\n"
                        "  fivecal uncertainty d1c1.json d1c2.json d2c1.json d2c2.json --days 1,1,2,2 "
                        "--pool days --estimate S3")
    pu.add_argument("inputs", nargs="+", metavar="INPUT",
                    help="simulation spec JSON (truth = its errors) or dataset JSON (noise around its "
                    "readings); several datasets = repeated cycles")
    pu.add_argument("--estimate", default="location",
                    help="parameter names and/or presets, comma separated (default: location)")
    pu.add_argument("--fix", default=None, help="names to keep fixed, comma separated")
    pu.add_argument("--trials", type=TRIALS, default=10000,
                    help="Monte Carlo trials M (default 10000)")
    pu.add_argument("--threads", type=count_type(0, MAX_WORKERS, "a number of threads"), default=0,
                    help="worker threads (default 0: all cores; the result does not depend on it)")
    pu.add_argument("--seed", type=SEED, default=1, help="master seed, 0 <= seed < 2^64 (default 1)")
    pu.add_argument("--sigma", type=SIGMA, default=None, help="noise (mm): overrides the spec's, or the "
                    "fit's residual sigma for a dataset")
    pu.add_argument("--probability", type=PROBABILITY, default=0.95, help="coverage probability (default 0.95)")
    pu.add_argument("--digits", type=_integer_type(1, 16), default=2, help="significant digits of u for the JCGM 101 "
                    "numerical tolerance (default 2)")
    pu.add_argument("--no-progress", action="store_true", help="no progress bar")
    pu.add_argument("--plot", help="write histograms (PNG) here")
    pu.add_argument("--samples", action="store_true", help="include the trial values in --out")
    pu.add_argument("--days", help="cycles: day label of each INPUT, comma separated (default: one day)")
    pu.add_argument("--pool", choices=["cycles", "days", "none"], default="cycles",
                    help="cycles: pool the input covariance by cycles (default) or by days")
    pu.add_argument("--k", type=POSITIVE, default=None, help="cycles: coverage factor (default: Student t "
                    "with the pooled degrees of freedom)")
    pu.add_argument("--out", help="write the result JSON here")
    pu.add_argument("--force", action="store_true", help=_FORCE_HELP)
    pu.set_defaults(func=_uncertainty)
