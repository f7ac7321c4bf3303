"""Draw a report's figures on every core: each figure is an independent task (load the
stored runs it shows, draw, encode), so a report of many figures takes a fraction of the
time one core needs.

Tasks are callables without arguments; on Linux they run in worker processes forked
from this one (which inherit them: nothing is pickled but the PNG bytes coming back),
elsewhere or on one core, in this process.  The results folder's database connection is
closed before forking: each worker opens its own (an SQLite connection must not cross a
fork).
"""
from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed

__all__ = ["draw_all"]

_TASKS: list = []  # what the forked workers inherit


def _draw(index: int):
    return _TASKS[index]()


def draw_all(tasks: list, *, stores=(), progress: bool = True,
             label: str = "report figures") -> list:
    """The result of every task, in order, with progress on stderr
    (`validation.batch.progress`).  ``stores``: results folders whose connections to close
    before forking (they reopen on their next use)."""
    from ..batch.executor import available_cores
    workers = min(available_cores(), len(tasks))
    if workers < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return _collect(((i, make()) for i, make in enumerate(tasks)), len(tasks), label,
                        progress)
    for store in stores:
        store.close()
    return _in_workers(tasks, workers, label, progress)


def _collect(done, n: int, label: str, progress: bool) -> list:
    """The results of ``done`` ((index, result) pairs, in any order) as a list, counted
    on a progress bar."""
    from ..batch.progress import progress as progress_bar
    bar = progress_bar(n, label, unit="figure", enabled=progress)
    results = [None] * n
    try:
        for i, result in done:
            results[i] = result
            bar.update(1)
    finally:
        bar.close()
    return results


def _start_drawer(parent: int) -> None:
    """A drawing worker dies with the report's process and, once forked, receives
    signals again (`validation.run.processes.signals_held`)."""
    from ..run.processes import die_with_parent, release_signals
    die_with_parent(parent)
    release_signals()  # held while it was forked


def _in_workers(tasks: list, workers: int, label: str, progress: bool) -> list:
    global _TASKS
    from ..run.processes import signals_held
    _TASKS = tasks
    try:
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                                 initializer=_start_drawer,
                                 initargs=(os.getpid(),)) as pool:  # a killed report ends them
            with signals_held():
                started = pool.submit(int)  # every worker forked now, before any thread starts
            started.result()
            futures = {pool.submit(_draw, i): i for i in range(len(tasks))}
            return _collect(((futures[f], f.result()) for f in as_completed(futures)),
                            len(tasks), label, progress)
    finally:
        _TASKS = []
