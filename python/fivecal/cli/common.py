"""What every command shares: the option types (a bad value is refused
naming the option), reading the JSON files a command is given, the exit
status of a command that fits, and running a command: its outputs in a
files.transaction, any error as one line with its exit status (README "Exit
codes")."""
from __future__ import annotations

import argparse
import io
import math
import os
import re
import signal
import sys
import warnings

from .. import files, guards
from ..guards import FitWarning
from ..machine import Machine
from ..schema import read_checked as _read_json


def _fit_warning():
    return FitWarning


def _values_verdict(values, std=None, converged: bool = True, iterations=None):
    """The :class:`fivecal.guards.Assessment` of a fit that gives plain
    values (and standard uncertainties) rather than a Result: judged on
    convergence and finiteness like ``identify``'s."""
    params = {n: {"value": v, **({"std": std[n]} if std and n in std else {})} for n, v in values.items()}
    return guards.assess({"parameters": params, "converged": bool(converged), "iterations": iterations})


def fit_status(command: str, verdicts, force: bool = False, written=()) -> int:
    """The exit status of a command that fits, judged as ``fivecal identify``
    judges its fit: 0 when every verdict is usable; otherwise one line on
    stderr saying why and 1 (the outputs are still written, to inspect) or,
    with ``--force``, the same line as a warning and 0. ``verdicts``: pairs
    (what, Assessment)."""
    why = [f"{what}: {a.reason}" if what else a.reason for what, a in verdicts if not a.usable]
    if not why:
        return EXIT_OK
    written = [x for x in written if x]
    if force:
        print(f"fivecal {command}: warning: not usable: {'; '.join(why)} (used anyway: --force)", file=sys.stderr)
        return EXIT_OK
    print(f"fivecal {command}: not usable: {'; '.join(why)}"
          + (f" ({' and '.join(written)} written, to inspect)" if written else "")
          + "; --force accepts it", file=sys.stderr)
    return EXIT_FIT


def _axis_values(text: str, option: str) -> dict:
    out = {}
    for item in [t for t in text.replace(";", ",").split(",") if t.strip()]:
        if "=" not in item:
            raise ValueError(f"{option}: expected AXIS=VALUE pairs like X=0,Z=100, got '{item.strip()}'")
        k, v = item.split("=", 1)
        k = k.strip().upper()
        if len(k) != 1 or not k.isalpha():
            raise ValueError(f"{option}: '{k}' is not an axis letter (AXIS=VALUE pairs like X=0,Z=100)")
        if k in out:
            raise ValueError(f"{option}: axis {k} given twice")
        try:
            x = float(v)
        except ValueError:
            raise ValueError(f"{option}: {k}: '{v.strip()}' is not a number") from None
        if not math.isfinite(x):
            raise ValueError(f"{option}: {k}: '{v.strip()}' is not a finite number")
        out[k] = x
    return out


# ---- option types: a bad value is refused by argparse naming the option -----
def _integer_type(low: int, high=None, what: str = "an integer"):
    def parse(text: str) -> int:
        t = text.strip()
        try:
            v = int(t, 10)
        except ValueError:
            try:
                f = float(t)
            except ValueError:
                f = float("nan")
            if not (math.isfinite(f) and f == math.floor(f)):
                raise argparse.ArgumentTypeError(f"expected {what}, got '{text}'") from None
            v = int(f)
        if v < low or (high is not None and v >= high):
            bound = f">= {low}" if high is None else f"in {low} .. {high - 1}"
            raise argparse.ArgumentTypeError(f"expected {what} {bound}, got '{text}'")
        return v

    return parse


def _float_type(low=None, high=None, low_open: bool = False, what: str = "a number"):
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got '{text}'") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"expected a finite number, got '{text}'")
        if low is not None and (v < low or (low_open and v == low)):
            raise argparse.ArgumentTypeError(f"must be {'>' if low_open else '>='} {low:g}, got '{text}'")
        if high is not None and v >= high:
            raise argparse.ArgumentTypeError(f"must be < {high:g}, got '{text}'")
        return v

    return parse


SEED = _integer_type(0, 2 ** 64, "an integer seed")
COUNT = _integer_type(0)

# ---- sizes: how much a count or a step makes a command allocate --------------
#: The most samples, plan entries, program points or Monte Carlo trials one
#: option may ask for. A real test records a few thousand; a typo (-n 1000000000,
#: --step 1e-6) is refused naming its option (exit 2), never a MemoryError.
MAX_SAMPLES = 1_000_000      # samples of one simulated trace (the core's bound as well)
MAX_PLAN_ENTRIES = 100_000   # entries of a written plan (each a JSON object) or program points
MAX_TRIALS = 1_000_000       # JCGM 101 asks for about 10^6 trials for a 95 % interval
MAX_WORKERS = 1024           # threads or worker processes on one machine (the core's thread bound)


def check_size(option: str, count: float, what: str = "plan entries", limit: int = MAX_PLAN_ENTRIES) -> int:
    """``count`` (what ``option`` asks for) as an int; refused naming ``option`` above ``limit``."""
    if not count <= limit:
        raise ValueError(f"{option}: asks for {count:.4g} {what}; at most {limit}")
    return int(count)


def check_step(option: str, step: float, span: float, unit: str = "deg", what: str = "plan entries",
               per: int = 1, limit: int = MAX_PLAN_ENTRIES) -> int:
    """The number of samples ``step`` apart over ``span`` (times ``per``, e.g.
    one set per test); refused naming ``option`` above ``limit``."""
    if not (step > 0 and math.isfinite(step)):
        raise ValueError(f"{option}: expected a step > 0 {unit}, got {step}")
    count = (math.floor(abs(span) / step + 1e-9) + 1) * per
    if not count <= limit:
        raise ValueError(f"{option}: {step:g} {unit} gives {count:.4g} {what} over {abs(span):g} {unit}"
                         f"{f' ({per} times)' if per > 1 else ''}; at most {limit} (use a larger step)")
    return int(count)


def count_type(low: int = 0, limit: int = MAX_PLAN_ENTRIES, what: str = "an integer"):
    """An argparse type: an integer from ``low`` to ``limit`` (both included)."""
    return _integer_type(low, limit + 1, what)


TRIALS = count_type(2, MAX_TRIALS, "a number of trials")
SIGMA = _float_type(0.0, what="a noise level in mm")
POSITIVE = _float_type(0.0, low_open=True)
PROBABILITY = _float_type(0.0, 1.0, low_open=True, what="a probability")


def _read_machine(path):
    """The machine of a machine file, or of a dataset file (its "machine")."""
    doc = _read_json(path, "the machine")
    if isinstance(doc, dict) and "observations" in doc and isinstance(doc.get("machine"), dict):
        doc = doc["machine"]  # a dataset file: use its machine
    try:
        return Machine.from_dict(doc)
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


class _Terminated(BaseException):
    """SIGTERM, raised in the main thread so that outputs are rolled back."""


def _on_sigterm(signum, frame):
    raise _Terminated()


class _PipeSafeStdout(io.TextIOBase):
    """stdout that goes quiet when the reader closes the pipe (``fivecal ... |
    head``): the command carries on (its files are still written) and exits
    with its own status, without a "Broken pipe" message."""

    def __init__(self, stream):
        self._stream = stream
        self._closed_pipe = False

    def _silence(self) -> None:
        self._closed_pipe = True
        # The Python docs recipe: point the descriptor at devnull so the
        # interpreter's final flush does not fail again.
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self._stream.fileno())
            finally:
                os.close(devnull)
        except (OSError, ValueError, io.UnsupportedOperation):
            pass

    def write(self, text):
        if not self._closed_pipe:
            try:
                return self._stream.write(text)
            except BrokenPipeError:
                self._silence()
        return len(text)

    def flush(self):
        if not self._closed_pipe:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._silence()

    def writable(self):
        return True

    def isatty(self):
        return self._stream.isatty()

    def fileno(self):
        return self._stream.fileno()

    @property
    def encoding(self):
        return getattr(self._stream, "encoding", "utf-8")


def _existing(path) -> bool:
    return isinstance(path, str) and os.path.exists(path)


def _declared_files(args):
    """(inputs, outputs) named on the command line, as (label, path) pairs."""
    inputs, outputs = [], []
    # a calibration store is read and written: an output over it loses every calibration
    for attr, label in (("dataset", "dataset"), ("spec", "spec"), ("result", "result"), ("machine", "machine"),
                        ("program", "program"), ("values", "--values"), ("store", "--store"),
                        ("history", "--store")):
        v = getattr(args, attr, None)
        if _existing(v):
            inputs.append((label, v))
    for attr, label in (("inputs", "INPUT"), ("runs", "run")):
        for v in getattr(args, attr, None) or []:
            if _existing(v):
                inputs.append((label, v))
    for attr in ("simulate", "pattern_errors"):
        v = getattr(args, attr, None)
        if _existing(v):
            inputs.append((f"--{attr.replace('_', '-')}", v))
    csv = getattr(args, "csv", None)
    if isinstance(csv, str):
        for part in csv.split(","):
            if "=" in part and _existing(part.split("=", 1)[1].strip()):
                inputs.append(("--csv", part.split("=", 1)[1].strip()))
    if args.command == "demo":
        return inputs, []
    labels = getattr(args, "file_labels", None) or {}     # a positional output is named as in --help
    for attr in ("out", "table", "plot", "patterns", "save_dataset"):
        v = getattr(args, attr, None)
        if isinstance(v, str) and not (attr == "out" and "{k}" in v):
            folder = attr == "out" and getattr(args, "out_is_folder", False)
            outputs.append((labels.get(attr, f"--{attr.replace('_', '-')}") + (" DIR" if folder else ""), v))
    report = getattr(args, "report", None)
    if isinstance(report, str):
        outputs += [("--report", os.path.join(report, "result.json")), ("--report", os.path.join(report, "report.html"))]
    return inputs, outputs


def _run(args) -> int:
    """The command inside a files.transaction: an output that is an input
    is refused before any work; if the command fails or is interrupted, the
    outputs it wrote are removed (or restored to their previous content)."""
    files.check_outputs(*_declared_files(args))
    old_stdout = sys.stdout
    sys.stdout = _PipeSafeStdout(old_stdout)
    old_term = None
    try:
        old_term = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread: leave the signal alone
        pass
    try:
        # An exception (bad input, Ctrl-C, SIGTERM) rolls the outputs back; a
        # command that ran to its end keeps them, whatever its exit status
        # (a fit that did not converge is still written, and says so).
        with files.transaction():
            rc = args.func(args)
            sys.stdout.flush()
        return rc
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        sys.stdout = old_stdout


class _Parser(argparse.ArgumentParser):
    """argparse with one-line usage errors (the subcommand parsers share it),
    and option values that start with '-' taken as values when they are
    numbers: argparse alone takes ``--height -1e-3`` or ``--tool-ball
    -5,0,100`` for an option (only plain ``-0.5`` passes), and a coordinate
    or an offset is negative as often as not. No fivecal option looks like a
    number, so nothing is lost."""

    #: a number (with exponent) or a comma separated list of them, starting with '-'
    _NEGATIVE_VALUE = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?)*$")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = self._NEGATIVE_VALUE

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _DeprecatedAlias(argparse.Action):
    """An option's old spelling, hidden from --help: it stores into the new
    option's value and says once on stderr which name to write. Only where
    scripts already used the old name (`fivecal docs commands`, "One name per
    option")."""

    def __init__(self, option_strings, dest, new_flag="", append=False, **kwargs):
        self.new_flag, self.append = new_flag, append
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"fivecal: warning: {option_string} is deprecated, write {self.new_flag}", file=sys.stderr)
        if self.nargs == 0:
            values = True
        if self.append:
            values = (getattr(namespace, self.dest, None) or []) + [values]
        setattr(namespace, self.dest, values)


def deprecated_alias(parser, old: str, new: str) -> None:
    """Accept ``old`` (hidden from --help) as the option ``new`` already on
    ``parser`` and warn; the value lands where ``new``'s does. A required
    ``new`` must be checked by the command (argparse does not count the old
    spelling as given)."""
    target = parser._option_string_actions[new]
    parser.add_argument(old, action=_DeprecatedAlias, dest=target.dest, new_flag=new,
                        append=isinstance(target, argparse._AppendAction),
                        nargs=0 if target.nargs == 0 else None, metavar=target.metavar,
                        default=argparse.SUPPRESS, help=argparse.SUPPRESS)


def _one_line(e: BaseException) -> str:
    if isinstance(e, OSError) and e.filename is not None and e.strerror:
        text = f"{e.filename}: {e.strerror}"
    else:
        text = str(e) or type(e).__name__
    return " ".join(text.split())


#: --help of --force for the commands that judge their own fit.
_FORCE_HELP = ("exit 0 even when the fit is not usable (not converged, non-finite, inadequate or "
               "undetermined); the reason is still printed. Only to inspect the values")

#: Exit statuses of every command (README "Exit codes").
EXIT_OK = 0        # success
EXIT_FIT = 1       # the fit failed, did not converge, or is inadequate / not usable
EXIT_INPUT = 2     # bad input or a refused request (unusable result, correction limit, ...)
EXIT_INTERNAL = 3  # a bug: FIVECAL_DEBUG=1 shows the traceback


def _warning_line(command: str):
    """A ``warnings.showwarning`` that prints ``fivecal COMMAND: warning: MESSAGE``
    on one line: a user of the command line is shown neither the source line
    that warned nor a path inside the package. Python API users keep the
    standard display (it is installed only while a command runs)."""
    def show(message, category, filename, lineno, file=None, line=None):
        stream = sys.stderr if file is None else file
        try:
            stream.write(f"fivecal {command}: warning: {' '.join(str(message).split())}\n")
        except (OSError, ValueError):  # stderr closed: a warning must not end the command
            pass

    return show


def execute(args) -> int:
    """Run the parsed command (:func:`_run`) and turn what it raises into one
    line on stderr and the exit status: 2 bad input or a refused request,
    3 anything else (a bug; FIVECAL_DEBUG=1 raises it with its traceback),
    130 / 143 interrupted / terminated."""
    debug = os.environ.get("FIVECAL_DEBUG", "") not in ("", "0")
    old_showwarning = warnings.showwarning
    warnings.showwarning = _warning_line(args.command)
    try:
        return _run(args)
    except KeyboardInterrupt:
        print("fivecal: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print("fivecal: terminated", file=sys.stderr)
        return 143
    except RecursionError:
        if debug:
            raise
        print(f"fivecal {args.command}: error: input nested too deeply", file=sys.stderr)
        return 2
    except (ValueError, OSError) as e:
        # UnusableResultError and CorrectionLimitError are ValueErrors: a refused request
        if debug:
            raise
        print(f"fivecal {args.command}: error: {_one_line(e)}", file=sys.stderr)
        return EXIT_INPUT
    except Exception as e:  # an unexpected failure: still one line, with a way to see more
        if debug:
            raise
        print(f"fivecal {args.command}: internal error ({type(e).__name__}): {_one_line(e)} "
              "(set FIVECAL_DEBUG=1 for a traceback)", file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        warnings.showwarning = old_showwarning
