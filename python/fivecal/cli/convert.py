"""``fivecal convert``: a dataset from JSON to Parquet or back."""
from __future__ import annotations

import argparse

from ..io.columnar import convert
from .common import EXIT_OK


def _convert(args) -> int:
    # Piece by piece between JSON and Parquet: a trace of any length in the
    # memory of one piece.
    n = convert(args.dataset, args.out)
    fmt = "Parquet" if args.out.lower().endswith((".parquet", ".pq")) else "JSON"
    print(f"{args.dataset} -> {args.out}: {n} observations ({fmt})")
    return EXIT_OK


def register(sub) -> None:
    pv = sub.add_parser("convert", help="a dataset from JSON to Parquet or back (lossless)",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="Read a dataset (JSON or Parquet, recognised by its content) and write "
                        "it as Parquet when OUT ends in .parquet or .pq (needs pyarrow: pip install "
                        "'fivecal[arrow]'), as JSON otherwise (`fivecal docs formats`).",
                        epilog="example:\n  fivecal convert trace.json trace.parquet\n"
                        "  fivecal convert trace.parquet trace.json")
    pv.add_argument("dataset", help="dataset to read (JSON or Parquet)")
    pv.add_argument("out", help="dataset to write: .parquet / .pq or .json")
    pv.set_defaults(func=_convert)
