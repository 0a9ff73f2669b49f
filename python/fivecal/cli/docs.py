"""``fivecal docs``: where the installed user documentation is."""
from __future__ import annotations

import argparse
import os

from .. import manual
from .common import EXIT_OK


def _docs(args) -> int:
    if args.name:
        print(manual.doc_path(args.name))
        return EXIT_OK
    names = manual.doc_names()
    if not names:
        manual.doc_path("")  # raises: says the documentation is not installed
    print(f"fivecal documentation in {manual.docs_dir()} (`fivecal docs NAME` prints a page's path):")
    for n in names:
        print(f"  {n:<28} {os.path.basename(manual.doc_path(n))}")
    return EXIT_OK


def register(sub) -> None:
    po = sub.add_parser("docs", help="where the user documentation is: list the pages or print one's path",
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                        description="The user documentation (docs/*.md and the README) is installed with "
                        "the package; messages point to it as `fivecal docs NAME`. Without NAME, list the "
                        "pages; with NAME (e.g. dbb, formats, readme), print the path of that page.",
                        epilog="examples:\n  fivecal docs\n  less \"$(fivecal docs dbb)\"")
    po.add_argument("name", nargs="?", help="a page: dbb, formats, identification, linuxcnc, readme, ...")
    po.set_defaults(func=_docs)
