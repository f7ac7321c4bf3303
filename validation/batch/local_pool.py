"""Runs on local worker processes, started once and reused for every run, forked from a
process that has already loaded the simulation code and its compiled kernels, each limited
to one BLAS thread (two workers on two cores would otherwise busy-wait on each other's
cores); a replacement is forked the same way.  Each worker has its own pipe, so this
process always knows which run a worker holds.  (`concurrent.futures.ProcessPoolExecutor`
cannot say that: one dead worker breaks the whole pool and every run in flight with it,
and a run that hangs cannot be stopped alone.)"""
from __future__ import annotations

import multiprocessing
import os
import time
from contextlib import contextmanager
from multiprocessing import connection
from typing import TextIO

from ..run.processes import describe_exit, kill_group, signals_held
from ..run.threads import ONE_THREAD
from .fingerprint import code_fingerprint
from .interrupts import Interrupted, signals_interrupt
from .limits import default_memory_limit
from .runner import Runner, run_time_limit
from .store.writing import serve, store_failure

__all__ = ["LocalPoolRunner"]


class _Worker:
    """One worker process (`worker.serve`), the parent's end of its pipe, and the run it
    holds: ``task`` (key, scenario), when it started and its deadline."""

    def __init__(self, ctx, memory_mib: int | None, warm: bool) -> None:
        parent_end, child_end = ctx.Pipe()
        self.process = ctx.Process(target=serve, name="flexarm-worker", daemon=True,
                                   args=(child_end, os.getpid(), memory_mib, warm))
        self.process.start()
        child_end.close()  # the worker's death is then end-of-file here
        self.conn = parent_end
        self.task: tuple | None = None
        self.started = self.deadline = 0.0
        self.timeout = 0.0

    def give(self, task, timeout: float) -> bool:
        """Send ``task`` to the worker; False if it has died."""
        try:
            self.conn.send(task[1])
        except OSError:
            return False
        self.task, self.timeout = task, timeout
        self.started = time.monotonic()
        self.deadline = self.started + timeout
        return True

    def kill(self) -> None:
        kill_group(self.process)  # and whatever a plug-in started in it
        self.conn.close()

    def stop(self) -> None:
        """End an idle worker: ask it to leave, kill it if it does not."""
        try:
            self.conn.send(None)
        except OSError:
            pass
        self.process.join(timeout=5)
        self.kill()


class LocalPoolRunner(Runner):
    """``workers`` processes started once and reused for every run (module docstring).
    On Linux (and wherever "fork" exists) they are forked from this process, which has
    already imported and compiled everything they need; elsewhere each spawned worker
    loads the simulation code and its kernels before its first run."""

    def __init__(self, workers: int, *, run_timeout: float | None = None,
                 memory_limit: int | None = None, scenarios=None,
                 progress: TextIO | None = None) -> None:
        self.workers, self.run_timeout = workers, run_timeout
        self.memory_limit = memory_limit if memory_limit is not None else \
            default_memory_limit(workers)
        self._warm = "fork" in multiprocessing.get_all_start_methods()
        if self._warm:  # loaded once here, inherited by every forked worker
            from .compiling import compile_for
            from .worker import load_run_libraries, warm_up
            if scenarios is None:
                warm_up()  # loads the run libraries too
            else:
                load_run_libraries()
                compile_for(scenarios, stream=progress)
            code_fingerprint()  # read once here (0.1-0.6 s), not again in every worker
        self._ctx = multiprocessing.get_context("fork" if self._warm else "spawn")
        self._pool: list[_Worker | None] = [None] * workers
        for i in range(workers):  # all now, before any other thread exists here
            self._worker(i)

    def _worker(self, i: int) -> _Worker:
        """Worker ``i``, started anew if it has died (or never started)."""
        w = self._pool[i]
        if w is None or (w.task is None and not w.process.is_alive()):
            if w is not None:
                w.kill()
            with _environment(ONE_THREAD), signals_held():  # a Ctrl-C: once it is in the pool
                w = self._pool[i] = _Worker(self._ctx, self.memory_limit, self._warm)
        return w

    def results(self, tasks, idle=None):
        with signals_interrupt():
            try:
                yield from self._results(iter(tasks), idle or (lambda: None))
            finally:  # left early (an error or a signal): end the runs still in flight
                self._kill_busy()

    def _results(self, tasks, idle):
        pending, unstarted = self._dispatch(tasks, True)
        yield from unstarted
        while True:
            busy = [w for w in self._pool if w is not None and w.task is not None]
            if not busy:
                return
            limit = min(w.deadline for w in busy) - time.monotonic()
            wanted = idle()
            try:
                ready = connection.wait(
                    [w.conn for w in busy] + [w.process.sentinel for w in busy],
                    timeout=max(0.0, limit if wanted is None else min(limit, wanted)))
            except Interrupted:
                yield from self._finished(busy)  # keep what finished before the signal
                raise
            outcomes = [o for o in (self._outcome(w, ready) for w in busy) if o is not None]
            # The next runs start before the caller stores these: it stores while they run.
            pending, unstarted = self._dispatch(tasks, pending)
            yield from outcomes
            yield from unstarted

    def _dispatch(self, tasks, pending: bool) -> tuple[bool, list]:
        """Give each idle worker its next task (a new worker if it died while idle):
        whether tasks remain, and the failed results of tasks no new worker would take
        (one that dies as it starts)."""
        unstarted = []
        for i in range(self.workers):
            if not pending:
                break
            if self._pool[i] is not None and self._pool[i].task is not None:
                continue
            task = next(tasks, None)
            if task is None:
                return False, unstarted
            timeout = run_time_limit(task[1], self.run_timeout)
            for _ in range(2):
                if self._worker(i).give(task, timeout):
                    break
                self._pool[i].kill()  # died while idle: a new one takes the run
                self._pool[i] = None
            else:
                unstarted.append((task[0], store_failure(
                    task[1], "no worker process could be started for the run")))
        return pending, unstarted

    def _outcome(self, w: _Worker, ready) -> tuple | None:
        """The result of ``w``'s run if it has one: what the worker sent, or a failed
        result if the worker died or ran out of time (then it is replaced)."""
        key, data = w.task
        if w.conn in ready or w.process.sentinel in ready:
            try:
                if w.conn.poll():
                    stored = w.conn.recv()
                    w.task = None
                    if stored.exhausted:  # at its memory limit: a fresh worker goes on
                        w.kill()
                        self._pool[self._pool.index(w)] = None
                    return key, stored
            except (EOFError, OSError):
                pass  # died while sending
            elapsed = time.monotonic() - w.started
            w.kill()
            message = (f"{describe_exit(w.process.exitcode, 'the run')}, {elapsed:.3g} s after "
                       "the run started")
        elif time.monotonic() >= w.deadline:
            w.kill()
            message = f"no result after {w.timeout:g} s (the run was stopped; " \
                      "--run-timeout sets the limit)"
        else:
            return None
        self._pool[self._pool.index(w)] = None  # replaced when next needed
        return key, store_failure(data, message)

    @staticmethod
    def _finished(busy: list[_Worker]):
        """The results already sent by ``busy`` workers (read without waiting for runs
        still in progress)."""
        for w in busy:
            try:
                if w.conn.poll():
                    key = w.task[0]
                    stored = w.conn.recv()
                    w.task = None
                    yield key, stored
            except (EOFError, OSError):
                pass

    def _kill_busy(self) -> None:
        for i, w in enumerate(self._pool):
            if w is not None and w.task is not None:
                w.kill()
                self._pool[i] = None

    def close(self) -> None:
        self._kill_busy()
        for w in self._pool:
            if w is not None:
                w.stop()
        self._pool = [None] * self.workers


@contextmanager
def _environment(values: dict):
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
