"""What runs inside a worker: one scenario in, its result and metrics out, never an
exception (`execute_run`); and what a worker process needs before it runs anything: the
simulation code (models, plants, laws, the closed loop, metrics) loaded and its kernels
compiled — not the command line and not matplotlib.  `warm_up` runs two tiny scenarios
in the parent before the workers are forked, so numba compiles (first use on a machine)
or loads (from its cache) each kernel once, not once per worker."""
from __future__ import annotations

import ctypes
import functools
import signal
import sys
from pathlib import Path

import numpy as np

from ..run import loop, metrics, requirements  # noqa: F401 - loaded once, before the fork
from ..run.results import RunResult

__all__ = ["execute_run", "failed_result", "keep_freed_memory", "worker_init", "warm_up",
           "kernels_cached"]


@functools.cache
def keep_freed_memory() -> None:
    """Have the C allocator keep freed blocks of up to 32 MiB for reuse (glibc; elsewhere
    nothing changes).  A run allocates its recording and copies of it (2.5 MB each for a
    5 s run); by default glibc maps such blocks fresh and unmaps them when freed, so
    every run pays its page faults again: ~3 ms of a 5 s reduced run's ~7 ms overhead
    (measured by timing `execute_run` over 48 runs).  Freed memory up to 128 MiB is kept
    (not trimmed): a worker's resident size stays at its largest run's."""
    if not sys.platform.startswith("linux"):
        return
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)  # the allocator of this process
    if mallopt is not None:  # glibc (musl has none)
        mallopt(-1, 128 << 20)  # M_TRIM_THRESHOLD
        mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD (glibc's largest on 64-bit)


def failed_result(scenario, exc: BaseException) -> tuple[RunResult, dict]:
    """The "failed" result of ``scenario`` (a `Scenario` or its mapping) that raised ``exc``."""
    from ..run.scenario import Scenario, scenario_to_mapping
    config = scenario_to_mapping(scenario) if isinstance(scenario, Scenario) else scenario
    text = str(exc).strip().splitlines()
    message = f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")
    return (RunResult(time=np.zeros(0), names=(), signals=np.zeros((0, 0)), status="failed",
                      message=message, config=config),
            {"status": "failed", "end_time": 0.0})


def execute_run(scenario) -> tuple[RunResult, dict]:
    """Run one scenario (in a worker; a checked `Scenario`, or a mapping to check): the
    result, with signals as float32 (what the store keeps; half the bytes to send back),
    and its metrics — with each requirement's robustness ``rho_<name>`` — computed from
    the float64 signals.  An unexpected exception becomes
    a "failed" result carrying its message, so one bad run never stops a campaign."""
    from ..run.loop import run_scenario
    from ..run.metrics import all_metrics
    from ..run.requirements import requirement_metrics
    from ..run.scenario import Scenario, scenario_from_mapping
    keep_freed_memory()
    try:
        if not isinstance(scenario, Scenario):
            scenario = scenario_from_mapping(scenario)
        result = run_scenario(scenario)
        metrics = all_metrics(result)
        metrics |= requirement_metrics(result, metrics)
    except Exception as exc:  # noqa: BLE001 - reported as the run's failure
        return failed_result(scenario, exc)
    result.signals = result.signals.astype(np.float32)
    return result, metrics


def worker_init() -> None:
    # The parent decides what a Ctrl-C means (stop, keep what finished, end the workers).
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def kernels_cached() -> bool:
    """Whether numba's cache holds the compiled sample loop (else the first run on this
    machine compiles it: a minute or two)."""
    return any((Path(__file__).parent.parent / "run" / "__pycache__").glob(
        "_sample.run_reduced-*.nbi"))


def warm_up() -> None:
    """Compile or load every kernel a run uses: the reduced loop with the built-in laws
    and an observer, and the Exudyn plant's readout."""
    from ..run.loop import run_scenario
    from ..run.scenario import scenario_from_mapping
    for plant in ("reduced", "exudyn"):
        run_scenario(scenario_from_mapping({"duration": 0.002, "transient": 0.0,
                                            "plant": {"kind": plant},
                                            "observer": {"kind": "smo-paper"}}))
