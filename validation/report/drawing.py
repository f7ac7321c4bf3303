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
    """The result of every task, in order.  ``stores``: results folders whose
    connections to close before forking (they reopen on their next use)."""
    global _TASKS
    from tqdm import tqdm

    from ..batch.executor import available_cores
    from ..run.processes import die_with_parent
    workers = min(available_cores(), len(tasks))
    if workers < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return [make() for make in tqdm(tasks, desc=label, unit="fig", disable=not progress)]
    for store in stores:
        store.close()
    tqdm.monitor_interval = 0  # no monitor thread across the fork
    _TASKS = tasks
    try:
        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"),
                                 initializer=die_with_parent,
                                 initargs=(os.getpid(),)) as pool:  # a killed report ends them
            pool.submit(int).result()  # every worker forked now, before any thread starts
            futures = {pool.submit(_draw, i): i for i in range(len(tasks))}
            results = [None] * len(tasks)
            for future in tqdm(as_completed(futures), total=len(futures), desc=label,
                               unit="fig", disable=not progress):
                results[futures[future]] = future.result()
        return results
    finally:
        _TASKS = []
