"""The limits every run executes under: a time limit derived from what the run simulates
and a memory limit per worker process (workers die with the process that started them:
`validation.run.processes`).

The default time limit is ``60 s + 10 × (1 ms per control sample + the plant's cost per
internal step × steps)``, the plant's cost being 0.1 ms per step for the reduced plant and
0.25 ms + 0.03 ms per finite element for the Exudyn plant.  These per-step costs are
1.6–5× what was measured on the development machine (2 cores: 20 µs per sample for a
2+2-mode reduced run with compiled laws, 100 µs with a Python plug-in law or the 4+4
EKF; Exudyn 0.31, 0.68 and 2.1 ms per step with 8, 32 and 128 ANCF elements), and the
factor 10 covers a machine that is slower or busy: no healthy run comes near its limit
(a 20 s paper run on the truth plant: 5 s measured, limit 358 s; a 0.5 s reduced run:
0.01 s measured, limit 66 s).

The default memory limit of a worker is three quarters of the machine's memory (or of
the container's, if that is smaller) shared among the workers, at least
`MIN_MEMORY_MIB`: all workers at their limits still leave the machine a quarter.  It
limits the worker's address space (``RLIMIT_AS``); an allocation beyond it fails with
`MemoryError` in the worker, which records the run as failed.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

__all__ = ["expected_work", "default_run_timeout", "default_memory_limit", "machine_memory",
           "limit_memory", "MIN_MEMORY_MIB"]

#: Wall time every run may take before its first sample (building the laws, Exudyn
#: assembling its mesh, a worker compiling a kernel on its first use in a checkout) [s].
RUN_TIMEOUT_BASE = 60.0
#: How many times the pessimistic estimate of a run's wall time its limit is.
RUN_TIMEOUT_FACTOR = 10.0
#: Pessimistic wall time per control sample: observer, controller and recording; a
#: Python plug-in law costs ~0.1 ms [s].
SAMPLE_COST = 1e-3
#: The wall time per internal step of a plant is its kind's (`PlantSpec.step_cost`).
#: The smallest memory limit a worker can run under: an idle worker's address space,
#: with the simulation code and Exudyn loaded, is ~650 MiB.
MIN_MEMORY_MIB = 1024
#: The share of the machine's memory all workers together may use by default.
MEMORY_SHARE = 0.75


def expected_work(scenario) -> float:
    """The pessimistic wall time of one run past its start [s]: control samples ×
    `SAMPLE_COST` + plant steps × the plant's cost per step (module docstring).  Also
    what orders a verdict's runs, the longest first (`validation.batch.queue.run_planned`)."""
    plant = scenario.plant
    samples = scenario.duration / scenario.Ts
    # A plug-in plant's cost is per control period (it steps as it likes).
    steps = scenario.duration / getattr(plant, "step", scenario.Ts)
    return samples * SAMPLE_COST + steps * plant.step_cost()


def default_run_timeout(scenario) -> float:
    """The default wall-time limit of one run [s], whole seconds (module docstring)."""
    return float(math.ceil(RUN_TIMEOUT_BASE + RUN_TIMEOUT_FACTOR * expected_work(scenario)))


def machine_memory() -> int:
    """Bytes of memory this process may use: the machine's, or its control group's
    limit if that is smaller (a container)."""
    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    try:  # cgroup v2: "max" or a number of bytes
        text = Path("/sys/fs/cgroup/memory.max").read_text().strip()
    except OSError:
        return total
    return min(total, int(text)) if text.isdigit() else total


def default_memory_limit(workers: int) -> int:
    """The default memory limit of each of ``workers`` worker processes [MiB]."""
    return max(MIN_MEMORY_MIB, int(MEMORY_SHARE * machine_memory() / workers) >> 20)


def limit_memory(mib: int) -> None:
    """Limit this process's address space to ``mib`` MiB (an allocation beyond it raises
    `MemoryError`)."""
    import resource
    limit = mib << 20
    hard = resource.getrlimit(resource.RLIMIT_AS)[1]
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
