"""Work on every core beside this process's own: independent tasks (a report's figure:
load the stored runs it shows, draw, encode; checking every stored run; a slice of an
export's table written as text) run in worker processes while this one goes on with its
own work, so that many tasks take a fraction of the time one core needs.

Tasks are callables without arguments; on Linux they run in worker processes forked
from this one (which inherit them: nothing is pickled but their results coming back),
while this one goes on (`beside`: a report's tables); elsewhere or on one core, in this
process.  The connections of the results folders named are closed before forking: each
worker opens its own (an SQLite connection must not be used across a fork); a task that
reads no folder leaves a connection, and the lock it holds, to this process.
"""
from __future__ import annotations

import contextlib
import gc
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed

__all__ = ["beside", "out_of_collection"]

_TASKS: list = []  # what the forked workers inherit


def _run_task(index: int):
    return _TASKS[index]()


@contextlib.contextmanager
def beside(tasks: list, *, stores=(), progress: bool = True, label: str = "report figures"):
    """Run ``tasks`` while the body of the ``with`` statement runs (e.g. a report's tables):
    yields a function that waits for the result of every task and returns them, in order,
    with progress on stderr (`validation.batch.progress`).  On several cores the workers
    (one per task, as many as the cores) start at once; on one, the tasks run in this
    process when it is called.  ``stores``: results folders whose connections to close
    before forking (they reopen on their next use)."""
    from .executor import available_cores
    cores = available_cores()
    if cores < 2 or not tasks or "fork" not in multiprocessing.get_all_start_methods():
        yield lambda: _collect(((i, make()) for i, make in enumerate(tasks)), len(tasks),
                               label, progress)
        return
    for store in stores:
        store.close()
    with _in_workers(tasks, min(cores, len(tasks))) as futures:
        yield lambda: _collect(((futures[f], f.result()) for f in as_completed(futures)),
                               len(tasks), label, progress)


def _collect(done, n: int, label: str, progress: bool) -> list:
    """The results of ``done`` ((index, result) pairs, in any order) as a list, counted
    on a progress bar."""
    from .progress import progress as progress_bar
    bar = progress_bar(n, label, unit="figure", enabled=progress)
    results = [None] * n
    try:
        for i, result in done:
            results[i] = result
            bar.update(1)
    finally:
        bar.close()
    return results


def _start_worker(parent: int) -> None:
    """A worker dies with the report's process and, once forked, receives
    signals again (`validation.run.processes.signals_held`)."""
    from ..run.processes import die_with_parent, release_signals
    die_with_parent(parent)
    release_signals()  # held while it was forked


@contextlib.contextmanager
def out_of_collection():
    """Inside, what this process holds now (10^5 stored runs) is out of the cyclic
    collector's reach (``gc.freeze``; the outermost of nested calls decides): its full
    passes over them cost a report of 40,000 runs ~0.35 s, and in forked workers they
    would copy every page of them (copy-on-write)."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


@contextlib.contextmanager
def _in_workers(tasks: list, workers: int):
    """Future → index of every task, submitted to ``workers`` forked processes."""
    global _TASKS
    from ..run.processes import signals_held
    _TASKS = tasks
    try:
        with out_of_collection(), ProcessPoolExecutor(
                workers, mp_context=multiprocessing.get_context("fork"),
                initializer=_start_worker, initargs=(os.getpid(),)) as pool:  # ends with us
            with signals_held():
                started = pool.submit(int)  # every worker forked now, before any thread starts
            started.result()
            try:
                yield {pool.submit(_run_task, i): i for i in range(len(tasks))}
            except BaseException:  # the tables failed or were stopped: no figure more is begun
                pool.shutdown(cancel_futures=True)
                raise
    finally:
        _TASKS = []
