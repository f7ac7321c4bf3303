"""Progress of a long job, said the way its reader sees it: a bar redrawn in place on a
terminal, a few plain lines in a log.

A bar (tqdm) redraws itself with carriage returns several times a second: on a terminal
that is one line; in a file (``make demo > log``, CI) every redraw stays, ~1,200 of them
for the paper reproduction.  Where the stream is not a terminal, `progress` writes a
line when the job starts, when it crosses each tenth of its total (at most one line per
`LINE_INTERVAL` seconds) and when it ends: about a dozen lines, whatever the job.
"""
from __future__ import annotations

import sys
import time
from typing import Callable, TextIO

__all__ = ["progress", "LineProgress", "is_terminal", "LINE_INTERVAL"]

#: The shortest time between two progress lines in a log [s] (the last line is always
#: written).
LINE_INTERVAL = 30.0


def is_terminal(stream) -> bool:
    """Whether ``stream`` is an interactive terminal (a file, a pipe or a closed stream
    is not)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def progress(total: int, label: str, *, unit: str = "run", enabled: bool = True,
             stream: TextIO | None = None):
    """A progress counter of ``total`` steps named ``label``: ``update(n)``,
    ``set_postfix(**counts)``, ``close()``.  A tqdm bar if ``stream`` (default: stderr)
    is a terminal, else a `LineProgress`; silent if not ``enabled``."""
    stream = sys.stderr if stream is None else stream
    if enabled and is_terminal(stream):
        from tqdm import tqdm
        tqdm.monitor_interval = 0  # no monitor thread: worker processes may still fork
        return tqdm(total=total, desc=label, unit=unit, file=stream, dynamic_ncols=True)
    return LineProgress(total, label, unit=unit, stream=stream if enabled else None)


def _duration(seconds: float) -> str:
    seconds = round(seconds)
    return f"{seconds} s" if seconds < 90 else f"{seconds // 60} min {seconds % 60:02d} s"


class LineProgress:
    """Progress as sparse lines (module docstring); ``stream=None`` says nothing.

    Parameters
    ----------
    total : int
        Steps the job has.
    label : str
        What the lines start with (a campaign's name).
    unit : str
        What a step is ("run", "fig"); an "s" is added for more than one.
    stream : file-like or None
        Where the lines go.
    interval : float
        The shortest time between two lines [s] (not the last).
    clock : callable
        Seconds, monotone (a test's own clock).
    """

    def __init__(self, total: int, label: str, *, unit: str = "run",
                 stream: TextIO | None = None, interval: float = LINE_INTERVAL,
                 clock: Callable[[], float] = time.monotonic):
        self.total, self.label, self.unit, self.stream = total, label, unit, stream
        self.interval, self.clock = interval, clock
        self.n, self.postfix, self.closed = 0, "", False
        self.start = self.last_line = clock()
        self.tenths = 0
        self._say(f"{label}: {total} {self._units(total)} to do")

    def _units(self, n: int) -> str:
        return self.unit if n == 1 else self.unit + "s"

    def _say(self, text: str) -> None:
        if self.stream is not None:
            print(text, file=self.stream, flush=True)

    def _line(self, last: bool) -> str:
        elapsed = self.clock() - self.start
        text = f"{self.label}: {self.n}/{self.total} {self._units(self.total)}"
        if self.total:
            text += f" ({100 * self.n // self.total} %)"
        text += f", {_duration(elapsed)}"
        if not last and 0 < self.n < self.total:
            text += f", about {_duration(elapsed * (self.total - self.n) / self.n)} left"
        return text + (f"; {self.postfix}" if self.postfix else "")

    def update(self, n: int = 1) -> None:
        """``n`` more steps done: a line if that crosses a tenth of the total and the last
        line is `interval` old."""
        self.n += n
        tenths = 10 * self.n // self.total if self.total else 10
        if tenths > self.tenths and self.n < self.total \
                and self.clock() - self.last_line >= self.interval:
            self.tenths = tenths
            self.last_line = self.clock()
            self._say(self._line(last=False))

    def set_postfix(self, **counts) -> None:
        """What the next line ends with, e.g. ``ok=3, failed=1`` → "ok 3, failed 1"."""
        self.postfix = ", ".join(f"{k} {v}" for k, v in counts.items())

    def close(self) -> None:
        """The last line (once): how far the job got, and in how long."""
        if not self.closed:
            self.closed = True
            self._say(self._line(last=True))
