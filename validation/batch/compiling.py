"""Compile the simulation kernels group by group and say how far it got.

numba compiles a kernel on its first call and caches the machine code in the
``__pycache__`` folders next to the sources, that is, in this checkout: a fresh clone (or
a changed kernel source) compiles again.  Compiling every kernel takes minutes on a
small machine, so `compile_groups` compiles them in named groups — one callable per
group, which compiles (or loads from the cache) that group's kernels — and reports each
group as it finishes, with an estimate of the time left: the groups' compile times
measured on a reference machine, scaled by how fast this machine has been so far.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Callable, TextIO

__all__ = ["KernelGroup", "compile_groups", "COMPILE_NOTE"]

#: What the first progress line says about where the compiled code is kept.
COMPILE_NOTE = ("once per checkout: numba keeps the machine code in this checkout's "
                "__pycache__ folders")


@dataclass(frozen=True)
class KernelGroup:
    """Kernels compiled together.

    Parameters
    ----------
    name : str
        What the reader recognises, e.g. "the PBC (eq. 20)".
    compile : callable
        Called without arguments; compiles (or loads from the cache) the group's kernels.
    expected_s : float
        Its compile time [s] on the reference machine (2 shared cores), for the estimate
        before anything has been measured here.
    """

    name: str
    compile: Callable[[], object]
    expected_s: float


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min"


def compile_groups(groups: list[KernelGroup], *, stream: TextIO | None = sys.stderr,
                   clock: Callable[[], float] = time.perf_counter) -> dict[str, float]:
    """Run each group's ``compile`` in order and return {name: seconds}.

    With a ``stream``, print one line before starting (the groups, the expected total)
    and one per finished group: its time and the estimated time left, the reference
    times of the remaining groups scaled by (time taken so far) / (reference time of
    the groups done).  ``stream=None`` compiles silently (a cache that only loads).
    """
    def say(text: str) -> None:
        if stream is not None:
            print(text, file=stream, flush=True)

    total = sum(g.expected_s for g in groups)
    say(f"compiling the simulation kernels ({COMPILE_NOTE}): {len(groups)} groups, about "
        f"{_duration(total)} on 2 cores ...")
    taken, elapsed, reference_done = {}, 0.0, 0.0
    for i, group in enumerate(groups, start=1):
        start = clock()
        group.compile()
        taken[group.name] = clock() - start
        elapsed += taken[group.name]
        reference_done += group.expected_s
        left = total - reference_done
        pace = elapsed / reference_done if reference_done > 0 else 1.0
        tail = f"about {_duration(left * pace)} left" if i < len(groups) else \
            f"all compiled in {_duration(elapsed)}"
        say(f"  [{i}/{len(groups)}] {group.name}: {_duration(taken[group.name])}; {tail}")
    return taken
