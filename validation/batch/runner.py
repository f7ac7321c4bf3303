"""What a runner is: it executes runs and hands their results back as they finish
(`Runner`; where: `validation.batch.executor`), the serial runner of library callers,
and the time limit of one run."""
from __future__ import annotations

import os

from .interrupts import signals_interrupt
from .limits import RUN_TIMEOUT_BASE, default_run_timeout
from .store.writing import run_and_store

__all__ = ["Runner", "SerialRunner", "available_cores", "run_time_limit"]


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


class Runner:
    """Executes tasks ``(key, StoreTask)`` (`writing.run_and_store`); subclasses say
    where.  ``results(tasks, idle)`` is a generator of ``(key, Stored)`` as runs finish;
    closed early (a Ctrl-C between two results: `queue.run_jobs`), it ends the runs still
    in flight where it can.  ``idle()`` (optional) is called before each wait for a result
    and returns the longest wait [s] before it wants to be called again (None: no
    limit)."""

    workers = 1

    def results(self, tasks, idle=None):
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SerialRunner(Runner):
    """In this process, one run after another: for library callers and tests (a run that
    exits the process or crashes takes this process with it; the command line never
    uses it)."""

    def results(self, tasks, idle=None):
        with signals_interrupt():
            for key, task in tasks:
                if idle is not None:
                    idle()
                yield key, run_and_store(task)


def run_time_limit(task, run_timeout: float | None) -> float:
    """The wall-time limit of the run of ``task`` (its scenario: a `Scenario` or its
    mapping)."""
    if run_timeout is not None:
        return run_timeout
    from ..run.scenario import Scenario, scenario_from_mapping
    data = task.scenario
    try:
        scenario = data if isinstance(data, Scenario) else scenario_from_mapping(data)
    except ValueError:  # a mapping that is no scenario: its worker says so at once
        return RUN_TIMEOUT_BASE
    return default_run_timeout(scenario)
