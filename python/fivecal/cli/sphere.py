"""``fivecal sphere``: the machine as a CMM, a sphere test with the nominal and identified model."""
from __future__ import annotations

import argparse
import math

from ..dataset import load_dataset
from ..files import write_json
from ..guards import require_usable
from ..procedures.sphere_test import format_sphere_tests, sphere_test, sphere_test_document
from .common import _read_json, _values_verdict, fit_status


def _sphere(args) -> int:
    ds = load_dataset(args.dataset)
    tests = {"nominal model": sphere_test(ds, None, args.sphere)}
    res = None
    if args.values:
        res = _read_json(args.values, "result")
        # A result that did not converge, is not finite, inadequate or
        # undetermined would make the "identified model" column a confident
        # figure of nothing: refused as `fivecal compensate` refuses it.
        require_usable(res, args.force, args.values)
        params = res.get("parameters", res) if isinstance(res, dict) else None
        if not isinstance(params, dict):
            raise ValueError(f"{args.values}: expected a result JSON with 'parameters'")
        values = {}
        for k, v in params.items():
            v = v.get("value") if isinstance(v, dict) else v
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{args.values}: parameters.{k}: expected a finite number as the value")
            values[k] = v
        tests["identified model"] = sphere_test(ds, values, args.sphere)
    t0 = next(iter(tests.values()))
    print(f"fivecal sphere test: sphere {t0.sphere}, {len(t0.observations)} touches on {ds.machine.name}")
    print(format_sphere_tests(tests))
    if len(tests) == 2:
        a, b = (t.fit.out_of_sphericity for t in tests.values())
        print(f"\nout of sphericity reduced {a / b:.3g}-fold by the identified model" if b > 0 else "")
    if args.out:
        write_json(args.out, sphere_test_document(tests, res if isinstance(res, dict) and "parameters" in res
                                                  else None))
        print(f"\nresult written to {args.out}")
    return fit_status("sphere", [(f"sphere fit ({name})",
                                  _values_verdict({"center.x": t.fit.center[0], "center.y": t.fit.center[1],
                                                   "center.z": t.fit.center[2], "radius": t.fit.radius,
                                                   "out of sphericity": t.fit.out_of_sphericity},
                                                  converged=t.fit.converged, iterations=t.fit.iterations))
                                 for name, t in tests.items()], args.force, written=[args.out])


def register(sub) -> None:
    pp = sub.add_parser("sphere", help="machine as a CMM: sphere test with the nominal and identified model",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Express the touches of a precision sphere in the table frame with the "
                        "nominal model (and with an identification result), fit a sphere by Gauss-Newton "
                        "and report the out of sphericity and residual statistics (thesis Table 6-3).",
                        epilog="example:\n  fivecal sphere sphere_data.json --values result.json --out sphere_result.json")
    pp.add_argument("dataset", help="dataset JSON with sphere touches")
    pp.add_argument("--values", help="identification result JSON (the compensated model)")
    pp.add_argument("--sphere", default=None, help="sphere id (default: the only sphere touched)")
    pp.add_argument("--out", help="write the result document: the --values result's machine errors with the "
                    "sphere tests as procedure sphere-test (without --values: no machine error, not usable)")
    pp.add_argument("--force", action="store_true", help="use a --values result that is not usable and "
                    "exit 0 on a sphere fit that is not (not converged or not finite); only to inspect them")
    pp.set_defaults(func=_sphere)
