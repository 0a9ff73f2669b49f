"""A small progress bar for long runs (Monte Carlo, design search, large
fits, long G-code programs), written to stderr.

It draws only when stderr is a terminal, or when forced with
``enabled=True`` or the environment variable ``FIVECAL_PROGRESS=1``
(``FIVECAL_PROGRESS=0`` silences it everywhere). No dependency on tqdm.

    from fivecal.progress import Progress, progress

    for sample in progress(range(1000), label="Monte Carlo"):
        ...

    with Progress(total=n, label="design search") as bar:
        for ...:
            bar.update()
"""
from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from typing import Iterable, Iterator, Optional, TextIO, TypeVar

T = TypeVar("T")

__all__ = ["Progress", "progress", "progress_enabled", "busy"]


def progress_enabled(enabled: Optional[bool] = None, stream: Optional[TextIO] = None) -> bool:
    """Whether a bar should be drawn: ``enabled`` if given, else the
    ``FIVECAL_PROGRESS`` environment variable (``1``/``0``) if set, else
    whether ``stream`` (default stderr) is a terminal."""
    if enabled is not None:
        return bool(enabled)
    env = os.environ.get("FIVECAL_PROGRESS", "").strip().lower()
    if env in ("1", "true", "yes", "on"):
        return True
    if env in ("0", "false", "no", "off"):
        return False
    stream = stream if stream is not None else sys.stderr
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _fmt_time(s: float) -> str:
    if s < 60:
        return f"{s:.1f}s"
    m, s = divmod(int(round(s)), 60)
    if m < 60:
        return f"{m}m{s:02d}s"
    h, m = divmod(m, 60)
    return f"{h}h{m:02d}m"


class Progress:
    """A progress bar over ``total`` steps (``total=None``: a counter
    without percentage). Redraws at most every ``min_interval`` seconds;
    ``close()`` (or leaving the ``with`` block) ends the line."""

    def __init__(self, total: Optional[int] = None, label: str = "", enabled: Optional[bool] = None,
                 stream: Optional[TextIO] = None, width: int = 30, min_interval: float = 0.1):
        self.total = None if total is None else int(total)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = progress_enabled(enabled, self.stream)
        self.width = int(width)
        self.min_interval = float(min_interval)
        self.n = 0
        self.t0 = time.perf_counter()
        self._last_draw = -1e9
        self._closed = False
        self._drawn = False

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def update(self, n: int = 1) -> None:
        """Advance by ``n`` steps."""
        self.n += n
        now = time.perf_counter()
        if self.enabled and (now - self._last_draw >= self.min_interval
                             or (self.total is not None and self.n >= self.total)):
            self._last_draw = now
            self._draw(now)

    def line(self, now: Optional[float] = None) -> str:
        """The text of the bar as it would be drawn now."""
        now = time.perf_counter() if now is None else now
        elapsed = now - self.t0
        head = f"{self.label}: " if self.label else ""
        if self.total:
            frac = min(1.0, self.n / self.total)
            full = int(round(frac * self.width))
            bar = "#" * full + "." * (self.width - full)
            eta = ""
            if 0 < self.n < self.total:
                eta = f", eta {_fmt_time(elapsed * (self.total - self.n) / self.n)}"
            return f"{head}[{bar}] {frac * 100:3.0f}% {self.n}/{self.total} {_fmt_time(elapsed)}{eta}"
        return f"{head}{self.n} done, {_fmt_time(elapsed)}"

    def _draw(self, now: float) -> None:
        try:
            self.stream.write("\r" + self.line(now) + "\x1b[K")
            self.stream.flush()
            self._drawn = True
        except (OSError, ValueError):
            self.enabled = False

    def close(self) -> None:
        """Draw the final state and end the line (idempotent)."""
        if self._closed:
            return
        self._closed = True
        if self.enabled:
            self._draw(time.perf_counter())
            try:
                self.stream.write("\n")
                self.stream.flush()
            except (OSError, ValueError):
                pass


def progress(iterable: Iterable[T], total: Optional[int] = None, label: str = "",
             enabled: Optional[bool] = None, stream: Optional[TextIO] = None) -> Iterator[T]:
    """Iterate over ``iterable`` while drawing a bar (``total`` defaults to
    ``len(iterable)`` when it has one)."""
    if total is None:
        try:
            total = len(iterable)  # type: ignore[arg-type]
        except TypeError:
            total = None
    with Progress(total, label, enabled=enabled, stream=stream) as bar:
        for item in iterable:
            yield item
            bar.update()


@contextlib.contextmanager
def busy(label: str, enabled: Optional[bool] = None, stream: Optional[TextIO] = None,
         delay: float = 1.0, interval: float = 0.25):
    """An elapsed-time indicator for a single long call that reports no
    steps (a large fit in the C++ core, which releases the GIL): after
    ``delay`` seconds it shows ``label: 12.3s`` on stderr and clears the line
    when the block ends. Nothing is drawn for calls shorter than ``delay``."""
    stream = stream if stream is not None else sys.stderr
    if not progress_enabled(enabled, stream):
        yield
        return
    stop = threading.Event()
    t0 = time.perf_counter()
    drawn = []

    def run() -> None:
        if stop.wait(delay):
            return
        while True:
            try:
                stream.write(f"\r{label}: {_fmt_time(time.perf_counter() - t0)}\x1b[K")
                stream.flush()
                drawn.append(True)
            except (OSError, ValueError):
                return
            if stop.wait(interval):
                return

    th = threading.Thread(target=run, daemon=True)
    th.start()
    try:
        yield
    finally:
        stop.set()
        th.join()
        if drawn:
            try:
                stream.write(f"\r{label}: done in {_fmt_time(time.perf_counter() - t0)}\x1b[K\n")
                stream.flush()
            except (OSError, ValueError):
                pass
