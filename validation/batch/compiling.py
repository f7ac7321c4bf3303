"""Compile the simulation kernels group by group and say how far it got.

numba compiles a kernel on its first call and caches the machine code in the
``__pycache__`` folders next to the sources, that is, in this checkout: a fresh clone (or
a changed kernel source) compiles again, once.  A cold compile takes minutes on a small
machine, so `compile_groups` runs the groups a command needs — (label, callable that
compiles or loads the group) pairs, as `validation.batch.worker.kernel_groups` lists them
— and reports each group that had to compile as it finishes, with an estimate of the
time left: the remaining groups' compile times measured on a reference machine
(`REFERENCE_SECONDS`), scaled by how fast this machine has been so far.  Groups that only
load from the cache are silent.

This module is not on a run's import path: editing it leaves stored runs valid
(`validation.batch.fingerprint`).
"""
from __future__ import annotations

import sys
import time
from typing import Callable, TextIO

__all__ = ["compile_groups", "compile_for", "REFERENCE_SECONDS", "COMPILE_NOTE"]

#: What the first progress line says about where the compiled code is kept.
COMPILE_NOTE = "once per checkout: numba keeps the machine code in its __pycache__ folders"

#: Cold compile time [s] of each group, by the label `kernel_groups` gives it, measured
#: on the reference machine (2 quiet cores, 2026-12-05, every group of
#: tests/warm_kernels.py in that order in one process: 90 s for all 17); laws that share
#: a compiled kernel with one compiled before them load in well under a second.  A group
#: not listed counts as the mean of those that are.  bench/bench_compile.py checks the
#: estimate against cold runs of each entry point.
REFERENCE_SECONDS = {
    "reduced plant (the paper's kinematics)": 6.0,
    "controller pbc": 4.5, "controller pbc-idealised": 0.5, "controller pd": 2.3,
    "controller ct": 1.0, "controller lqr": 2.6,
    "observer smo-paper": 3.0, "observer smo-bl": 0.5, "observer smo-pos": 0.5,
    "observer ekf": 4.3, "observer ekf-pos": 0.5,
    "closed loop on the exudyn plant": 9.6, "closed loop on the reduced plant": 2.0,
    "reduced plant (the paper's kinematics, joints)": 12.3,
    "reduced plant (exact kinematics)": 15.0, "controller pbc (exact kinematics)": 18.2,
    "observer smo-paper (exact kinematics)": 4.4,
}


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min"


def compile_groups(groups: list[tuple[str, Callable[[], object]]], *,
                   stream: TextIO | None = sys.stderr, quiet_below: float = 0.5,
                   reference: dict[str, float] | None = None,
                   clock: Callable[[], float] = time.perf_counter) -> dict[str, float]:
    """Compile (or load) each group in order; return {label: seconds}.

    A group that takes more than ``quiet_below`` seconds compiled: the first such group
    is preceded by a line saying what is happening, and each is followed by a line with
    its time, how many groups are ready (those loaded from the cache since the last line
    counted and said), and the estimated time left: the ``reference`` times (default
    `REFERENCE_SECONDS`) of the groups still to come scaled by (time taken by the
    compiled groups) / (their reference time); an estimate is not repeated.
    ``stream=None`` compiles silently.
    """
    reference = REFERENCE_SECONDS if reference is None else reference
    mean = sum(reference.values()) / len(reference) if reference else 1.0
    expected = [reference.get(label, mean) for label, _ in groups]
    taken, spent, spent_reference, announced = {}, 0.0, 0.0, False
    cached, last_tail = 0, ""
    for i, (label, build) in enumerate(groups):
        start = clock()
        build()
        taken[label] = clock() - start
        if taken[label] <= quiet_below or stream is None:
            cached += 1
            continue
        if not announced:
            print(f"compiling the simulation kernels ({COMPILE_NOTE}): {len(groups)} groups, "
                  f"about {_duration(sum(expected[i:]))} on a quiet 2-core machine", file=stream,
                  flush=True)
            announced = True
        spent += taken[label]
        spent_reference += expected[i]
        ready = f"{i + 1} of {len(groups)} groups ready" + (
            f" ({cached} loaded from the cache)" if cached else "")
        cached = 0
        tail = ""
        if i + 1 < len(groups):
            tail = f", about {_duration(sum(expected[i + 1:]) * spent / spent_reference)} left"
            tail, last_tail = ("" if tail == last_tail else tail), tail
        print(f"  {label}: {_duration(taken[label])} — {ready}{tail}", file=stream, flush=True)
    return taken


def compile_for(scenarios, *, stream: TextIO | None = sys.stderr) -> dict[str, float]:
    """Compile or load here, with progress on ``stream``, the kernels the runs of
    ``scenarios`` use (`validation.batch.worker.kernel_groups`: plug-in laws left out),
    before a local runner forks its workers: they inherit them, and compiling is not
    counted in the runs' time limits."""
    from .worker import kernel_groups
    return compile_groups(kernel_groups(scenarios), stream=stream)
