"""Where runs execute: on local worker processes or on a Dask cluster (or, for library
callers, in this process) — one interface, results handed back as they finish.

`Runner.results(tasks)` takes `writing.StoreTask` s and yields ``(key, Stored)`` as each
run completes: the worker that ran it has stored its file (`validation.batch.store.writing`)
and sends back only its index row, which the caller commits.  Before it waits for the
next result, a runner calls the caller's ``idle()``, which may commit what has arrived
and says how long the runner may wait before asking again.  Nothing a run does can take
the command down: every run of a local runner executes in a worker process (one for
``--workers 1``).  A run whose worker exits, is killed or crashes (a law calling
``os._exit``, a segfault) is handed back as a "failed" result saying what happened and
how long after the run started, and the worker is replaced; a run past its time limit
(`limits.default_run_timeout`, or ``run_timeout``) is killed and handed back as failed
("no result after N s"); a worker runs under a memory limit (`limits`) and dies with
this process.  On SIGINT/SIGTERM the runner stops submitting, hands back what has
already finished, kills its workers (none is left behind) and raises `Interrupted`; a
second signal exits at once.

The local pool: `validation.batch.local_pool`; the cluster: `validation.batch.cluster`.
Every process that runs or stores runs keeps its freed memory for the next run
(`keep_freed_memory`).
"""
from __future__ import annotations

import os
from typing import TextIO

from ..run.config import ConfigError, check
from .cluster import DaskRunner
from .limits import MIN_MEMORY_MIB
from .local_pool import LocalPoolRunner
from .runner import Runner, SerialRunner, available_cores
from .worker import keep_freed_memory

__all__ = ["Runner", "SerialRunner", "LocalPoolRunner", "DaskRunner", "make_runner",
           "check_runner", "available_cores"]


def check_runner(kind: str = "local", workers: int | None = None,
                 scheduler: str | None = None, *, force: bool = False,
                 run_timeout: float | None = None, memory_limit: int | None = None):
    """The options of `make_runner`, checked (a `ConfigError` naming the first bad one)
    before anything is compiled, started or written; returns the number of local workers
    (default: the cores), or the Dask scheduler's address."""
    check(run_timeout is None or run_timeout > 0, "--run-timeout",
          f"must be > 0 s, got {run_timeout!r}")
    if kind == "local":
        check(memory_limit is None or memory_limit >= MIN_MEMORY_MIB, "--memory-limit",
              f"must be >= {MIN_MEMORY_MIB} MiB (an idle worker takes ~650 MiB of address "
              f"space), got {memory_limit}")
        check(scheduler is None, "--scheduler", "only for --executor dask")
        cores = available_cores()
        workers = workers or cores
        check(workers >= 1, "--workers", f"must be >= 1, got {workers}")
        check(workers <= cores or force, "--workers", f"{workers} workers on {cores} cores "
              "only share the cores (each costs ~300 MB); pass --force-workers to insist")
        return workers
    if kind == "dask":
        address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS")
        check(bool(address), "--scheduler", "the dask executor needs --scheduler "
                                            "tcp://HOST:PORT or DASK_SCHEDULER_ADDRESS")
        check(workers is None, "--workers", "the Dask cluster decides its workers")
        check(memory_limit is None, "--memory-limit", "the Dask workers have their own "
                                                      "(dask worker --memory-limit)")
        return address
    raise ConfigError("--executor", f"must be 'local' or 'dask', got {kind!r}")


def make_runner(kind: str = "local", workers: int | None = None, scheduler: str | None = None,
                *, force: bool = False, run_timeout: float | None = None,
                memory_limit: int | None = None, scenarios=None,
                progress: TextIO | None = None) -> Runner:
    """A runner: local worker processes or a Dask cluster, for `run_campaign`, `calibrate`
    and the verdicts; as a context manager, leaving it ends its workers.  Every option is
    checked first (`check_runner`).

    Parameters
    ----------
    kind : {"local", "dask"}
        Local worker processes, or a Dask cluster.
    workers : int, optional
        Local worker processes (default: the cores; 1 is one worker process).
    scheduler : str, optional
        The Dask scheduler's address (default $DASK_SCHEDULER_ADDRESS).
    force : bool
        Allow more local workers than cores (they only share the cores).
    run_timeout : float, optional
        Every run's wall-time limit [s] (default `limits.default_run_timeout`, per run).
    memory_limit : int, optional
        Each local worker's memory limit [MiB] (default `limits.default_memory_limit`).
    scenarios : list of Scenario, optional
        The runs to come: their kernels are compiled or loaded before the workers fork
        (default: the PBC with the paper's SMO on both plants, `worker.warm_up`).
    progress : file, optional
        Where compilation progress goes (`compiling.compile_for`; default: silent).

    Returns
    -------
    Runner
        `LocalPoolRunner` or `DaskRunner`.

    Raises
    ------
    ConfigError
        A bad option, naming it; an unreachable scheduler or one without workers.
    """
    where = check_runner(kind, workers, scheduler, force=force, run_timeout=run_timeout,
                         memory_limit=memory_limit)
    keep_freed_memory()  # this process stores the runs (and forks the local workers)
    if kind == "local":
        return LocalPoolRunner(where, run_timeout=run_timeout, memory_limit=memory_limit,
                               scenarios=scenarios, progress=progress)
    return DaskRunner(where, run_timeout=run_timeout)
