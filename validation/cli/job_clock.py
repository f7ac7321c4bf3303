"""One estimate of the time a command of several phases has left: a bar per phase says
nothing of how long the whole will take.

A command names its phases with their wall times on the reference machine (`PAPER`,
`LAB`, measured by ``bench/bench_paper.py``); `JobClock` says the total when the command
starts and, after each phase, the time it took and about how long is left: the reference
times of the phases to come, scaled by how fast this machine has been on the phases so
far — but a phase over in under a tenth of its reference time, which read runs stored
before rather than ran them, says nothing of the machine.  The same scaling as the
compile's estimate (`validation.batch.compiling`).
"""
from __future__ import annotations

import sys
import time
from typing import Callable, TextIO

__all__ = ["JobClock", "PAPER", "LAB", "PAPER_COLD_START", "PAPER_DISK_MB", "RESUMED"]

#: A phase over in less than this share of its reference time read stored runs.
RESUMED = 0.1

#: ``flexarm reproduce-paper``'s phases and their wall times [s] on the reference machine
#: (2 cores, quiet, two workers; this tree alone through bench/bench_paper.py's
#: ``reproduce``, 2026-12-05: 177 s in all from an empty numba cache), kernels compiled
#: already (the compile says its own estimate).
PAPER = (("the paper's runs", 44.0), ("the stability map", 58.0), ("the mesh checks", 26.0),
         ("the claims", 2.0), ("the report", 9.0))

#: ``flexarm reproduce-paper --lab``'s phases, the same but for its runs (8, on the lab
#: arm): the mean of two runs on a quiet 2-core machine, kernels compiled
#: (bench/bench_paper.py --lab of 2026-12-05 and one more that day).
LAB = (("the lab arm's runs", 12.0), ("the stability map", 14.0), ("the mesh checks", 59.0),
       ("the claims", 1.0), ("the report", 4.0))

#: The paper's job's start-up and first compile of the kernels [s] (a fresh checkout), and
#: the disk its results folder took [MB]: what the README states.
PAPER_COLD_START = 38.0
PAPER_DISK_MB = 77.0


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.0f} min"


class JobClock:
    """The phases of one command (label, reference seconds) and what they took; says its
    lines on ``stream`` (None: silent)."""

    def __init__(self, name: str, phases, *, stream: TextIO | None = sys.stderr,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        self.name, self.phases, self.stream, self.clock = name, dict(phases), stream, clock
        self.started = self.last = clock()
        self.ran = self.ran_reference = 0.0
        self.left = list(self.phases)

    def _say(self, text: str) -> None:
        if self.stream is not None:
            print(text, file=self.stream, flush=True)

    def begin(self, skipped=()) -> None:
        """Say the phases and the total (``skipped``: phases this run leaves out)."""
        self.left = [p for p in self.left if p not in skipped]
        total = sum(self.phases[p] for p in self.left)
        self._say(f"{self.name}: {len(self.left)} phases ({', '.join(self.left)}), about "
                  f"{_duration(total)} on a quiet 2-core machine (less for runs already "
                  "stored)")

    def done(self, phase: str) -> None:
        """``phase`` is over: say how long it took and about how long is left."""
        now = self.clock()
        taken, self.last = now - self.last, now
        if taken >= RESUMED * self.phases[phase]:
            self.ran += taken
            self.ran_reference += self.phases[phase]
        self.left.remove(phase)
        if not self.left:
            return
        pace = self.ran / self.ran_reference if self.ran_reference else 1.0
        left = sum(self.phases[p] for p in self.left) * pace
        self._say(f"{self.name}: {phase} took {_duration(taken)}; about {_duration(left)} "
                  f"left ({', '.join(self.left)})")
