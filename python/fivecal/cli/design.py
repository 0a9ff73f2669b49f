"""``fivecal design``: choose the rotary indexations of a probing test."""
from __future__ import annotations

import argparse
import os

from .. import design
from .._json import plain
from ..files import write_json
from ..machine import Machine
from .common import COUNT, POSITIVE, _read_json, check_size


def _design_spec(path: str) -> dict:
    spec = _read_json(path, "design spec")
    if not isinstance(spec, dict):
        raise ValueError(f"{path}: expected a JSON object (a simulation spec with a candidate plan)")
    machine = spec.get("machine")
    if isinstance(machine, str):  # a path relative to the spec file
        machine = Machine.load(os.path.join(os.path.dirname(os.path.abspath(path)), machine))
    if machine is None:
        raise ValueError(f"{path}: 'machine' missing (a machine object or a path)")
    spec["machine"] = Machine.from_dict(machine).to_dict()
    return spec


def _design(args) -> int:
    spec = _design_spec(args.spec)
    machine, artefact = spec["machine"], spec.get("artefact") or {}
    probe = spec.get("probe") or {}
    if not isinstance(probe, dict) or not isinstance(artefact, dict):
        raise ValueError(f"{args.spec}: {'probe' if not isinstance(probe, dict) else 'artefact'}: expected an object")
    try:
        tip_radius = float(probe.get("tip_radius", 0.0))
    except (TypeError, ValueError):
        raise ValueError(f"{args.spec}: probe.tip_radius: expected a number") from None
    groups = None
    if spec.get("candidates"):
        c = spec["candidates"]
        if not isinstance(c, dict):
            raise ValueError(f"{args.spec}: candidates: expected an object with 'indexations' (and 'limits', "
                             "'min_dot', ...)")
        plan, groups = design.candidate_plan(machine, artefact, c.get("indexations", []), tip_radius=tip_radius,
                                             limits=c.get("limits"), min_dot=c.get("min_dot", -0.02),
                                             targets=c.get("targets"), sphere_normals=c.get("sphere_normals"))
        if not plan:
            raise ValueError(f"{args.spec}: no accessible candidate touch at the given indexations")
    else:
        plan = spec.get("plan")
        if not plan:
            raise ValueError(f"{args.spec}: give the candidate touches as 'plan' or 'candidates'")
    try:
        ks = [int(x) for x in str(args.k).split(",") if x.strip()]
    except ValueError:
        ks = []
    if not ks or min(ks) < 1:
        raise ValueError(f"-k: expected a number of indexations (>= 1) or a comma-separated list, got '{args.k}'")
    check_size("-k", max(ks), "indexations")
    try:
        required = [int(x) for x in args.require.split(",") if x.strip()] if args.require else None
    except ValueError:
        raise ValueError(f"--require: expected comma-separated visit numbers, got '{args.require}'") from None
    if required:
        check_size("--require", max(abs(r) for r in required), "(a visit number)")
    pool = design._as_dataset(plan, machine, artefact, tip_radius, None)
    rows = None
    for i, k in enumerate(ks):
        d = design.design_plan(pool, k, args.estimate, groups=groups, fix=args.fix, required=required,
                               criterion=args.criterion, method=args.method, max_touches=args.max_touches,
                               sigma=args.sigma, progress=False if args.no_progress else "auto")
        d.plan = [plan[j] for j in d.observations]
        if len(ks) == 1:
            print(d.report())
        else:
            if rows is None:
                print(f"fivecal design ({args.criterion}, estimate {args.estimate}): candidate pool "
                      f"{len(set(d.pool_groups))} indexations, {d.reference.n_observations} touches")
                rows = [{"plan": "complete", "indexations": len(set(d.pool_groups)),
                         "touches": d.reference.n_observations, "condition_number": d.reference.condition_number,
                         "d_criterion": d.reference.d_criterion, "d_std": d.reference.d_std}]
            rows.append({"plan": f"designed k={k}", "indexations": len(d.groups), "touches": d.quality.n_observations,
                         "condition_number": d.quality.condition_number, "d_criterion": d.quality.d_criterion,
                         "d_std": d.quality.d_std})
        if args.out:
            out = args.out.replace("{k}", str(k)) if "{k}" in args.out or len(ks) == 1 else \
                f"{os.path.splitext(args.out)[0]}_k{k}{os.path.splitext(args.out)[1] or '.json'}"
            result = dict(spec)
            result.pop("candidates", None)
            result["plan"] = d.plan
            finite = lambda x: x if x == x and abs(x) != float("inf") else None  # noqa: E731
            result["design"] = {"criterion": args.criterion, "estimate": args.estimate, "k": k,
                                "condition_number": finite(d.quality.condition_number),
                                "candidate_condition_number": finite(d.reference.condition_number),
                                "groups": d.groups}

            write_json(out, plain(result, "design"))
            print(f"designed plan (a simulation spec) written to {out}")
    if rows is not None:
        print(design.format_comparison(rows))
    return 0


def register(sub) -> None:
    pg = sub.add_parser("design", help="choose K rotary indexations that minimise the condition number",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Read a simulation spec whose 'plan' is the pool of candidate touches "
                        "(visits: consecutive touches at one rotary pose), or whose 'candidates' lists "
                        "indexations ({'indexations': [{'B': 30, 'C': -90}, ...], 'limits': {'X': [-300, 300]}, "
                        "'min_dot': -0.02}: every facet or sphere touch facing the probe within the axis "
                        "limits), pick K indexations (greedy, then exchange) and write the chosen plan as "
                        "a simulation spec. Compares the condition number, a D-optimality figure and the "
                        "predicted uncertainties of the candidates and of the design (thesis Table 8-4).",
                        epilog="examples:\n"
                        "  fivecal design examples/design/hu40t_table_4_2.json -k 14 --estimate S3 "
                        "--out plan14.json\n"
                        "  fivecal simulate plan14.json --out plan14_data.json\n"
                        "  fivecal design examples/design/hu40t_table_4_2.json -k 21,22,23,24,25 "
                        "   (Table 8-4: several subsets)")
    pg.add_argument("spec", help="simulation spec JSON with the candidate plan")
    pg.add_argument("-k", required=True, help="indexations to pick (or a comma-separated list)")
    pg.add_argument("--estimate", default="S3", help="parameter names and/or presets (default: S3)")
    pg.add_argument("--fix", default=None, help="names to keep fixed, comma separated")
    pg.add_argument("--criterion", choices=["condition", "d"], default="condition",
                    help="minimise the condition number (default) or maximise the D-optimality")
    pg.add_argument("--method", choices=["exchange", "greedy"], default="exchange",
                    help="forward greedy selection, then exchange swaps while they improve (default), "
                    "or greedy only")
    pg.add_argument("--require", default=None, help="candidate visit numbers always kept, comma separated")
    pg.add_argument("--max-touches", type=COUNT, default=0, help="then drop single touches down to this many")
    pg.add_argument("--sigma", type=POSITIVE, default=0.0006, help="probing noise (mm) for the predicted "
                    "uncertainties (default 0.0006)")
    pg.add_argument("--no-progress", action="store_true", help="no progress bar")
    pg.add_argument("--out", help="write the designed plan (a simulation spec) here; '{k}' is replaced by K")
    pg.set_defaults(func=_design)
