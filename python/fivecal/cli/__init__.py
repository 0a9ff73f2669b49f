"""Command line: fivecal identify | simulate | compensate | design | sphere | demo | import.

Errors are one clear line on stderr, never a traceback (set FIVECAL_DEBUG=1
to see one). Exit status: 0 success, 1 the fit failed / did not converge / is
not usable, 2 bad input or a refused request, 3 internal error (a bug). Long runs draw a progress bar on stderr
when it is a terminal (FIVECAL_PROGRESS=1 forces it, =0 silences it).
"""


def main(argv=None) -> int:
    """Entry point of the ``fivecal`` command; returns the exit status: 0 ok,
    1 the fit failed, did not converge or is not usable, 2 bad input or a
    refused request (one line), 3 an unexpected failure (a bug)."""
    p = _Parser(prog="fivecal", description="Geometric error identification for "
                                "five-axis machine tools (units: mm, degrees for rotary commands, rad "
                                "for angular errors).")
    p.add_argument("--version", action="version", version=f"fivecal {__version__}")
    sub = p.add_subparsers(dest="command", required=True)


    from .procedures.dbb_cli import register as _register_dbb

    _register_dbb(sub)
    from .procedures.plan_cli import register as _register_plan; _register_plan(sub)  # noqa: E702
    from .io.linuxcnc_cli import register as _register_export; _register_export(sub)  # noqa: E702

    from .history.cli import register as _register_history; _register_history(sub)  # noqa: E702
    from .io.cli import register as _register_import

    _register_import(sub)


    old_stdout = sys.stdout
    sys.stdout = _PipeSafeStdout(old_stdout)  # --help | head too
    try:
        args = p.parse_args(argv)
    except SystemExit:
        sys.stdout.flush()
        raise
    finally:
        sys.stdout = old_stdout


if __name__ == "__main__":
    sys.exit(main())
