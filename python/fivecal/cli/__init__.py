"""Command line: fivecal identify | simulate | compensate | design | sphere | demo | import.

Errors are one clear line on stderr, never a traceback (set FIVECAL_DEBUG=1
to see one). Exit status: 0 success, 1 the fit failed / did not converge / is
not usable, 2 bad input or a refused request, 3 internal error (a bug). Long runs draw a progress bar on stderr
when it is a terminal (FIVECAL_PROGRESS=1 forces it, =0 silences it).

One module per command (or group of sub-commands), each with a ``register(sub)``
that adds its parser; :mod:`.common` holds what they share. This package is
the top layer: nothing else in fivecal imports it.
"""
from __future__ import annotations

import sys

from .._version import __version__
from . import (compensate, convert, dbb, demo, design, docs, export, history, identify, import_, plan, rtest, simulate,
               sphere, sphere_check, uncertainty)
from .common import _Parser, _PipeSafeStdout, execute

__all__ = ["main"]


def main(argv=None) -> int:
    """Entry point of the ``fivecal`` command; returns the exit status: 0 ok,
    1 the fit failed, did not converge or is not usable, 2 bad input or a
    refused request (one line), 3 an unexpected failure (a bug)."""
    p = _Parser(prog="fivecal", description="Geometric error identification for "
                                "five-axis machine tools (units: mm, degrees for rotary commands, rad "
                                "for angular errors).")
    p.add_argument("--version", action="version", version=f"fivecal {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    # the order of `fivecal --help`
    for command in (identify, convert, simulate, demo, docs, dbb, plan, export, history, import_, compensate, uncertainty,
                    design, sphere, sphere_check, rtest):
        command.register(sub)

    old_stdout = sys.stdout
    sys.stdout = _PipeSafeStdout(old_stdout)  # --help | head too
    try:
        args = p.parse_args(argv)
    except SystemExit:
        sys.stdout.flush()
        raise
    finally:
        sys.stdout = old_stdout
    return execute(args)
