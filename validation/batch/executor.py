"""Where runs execute: on local worker processes or on a Dask cluster (or, for library
callers, in this process) — one interface, results handed back as they finish.

`Runner.results(tasks)` takes `storing.StoreTask` s and yields ``(key, Stored)`` as each
run completes: the worker that ran it has stored its file (`validation.batch.storing`)
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

Local workers are started once and reused for every run, forked from a process that has
already loaded the simulation code and its compiled kernels, each limited to one BLAS
thread (two workers on two cores would otherwise busy-wait on each other's cores);
a replacement is forked the same way.  Each worker has its own pipe, so this process
always knows which run a worker holds.  (`concurrent.futures.ProcessPoolExecutor` cannot
say that: one dead worker breaks the whole pool and every run in flight with it, and a
run that hangs cannot be stopped alone.)  Every process that runs or stores runs keeps
its freed memory for the next run (`keep_freed_memory`).
"""
from __future__ import annotations

import multiprocessing
import os
import time
from collections import deque
from contextlib import contextmanager
from multiprocessing import connection
from typing import TextIO

from ..run.config import ConfigError, check
from ..run.processes import describe_exit, kill_group, signals_held
from .interrupts import Interrupted, signals_interrupt
from .limits import (MIN_MEMORY_MIB, RUN_TIMEOUT_BASE, default_memory_limit,
                     default_run_timeout)
from ..run.threads import ONE_THREAD
from .storing import Stored, run_and_store, serve, store_failure
from .worker import describe, keep_freed_memory

__all__ = ["Runner", "SerialRunner", "LocalPoolRunner", "DaskRunner", "make_runner",
           "available_cores"]


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


class Runner:
    """Executes tasks ``(key, StoreTask)`` (`storing.run_and_store`); subclasses say
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


def _run_timeout(task, run_timeout: float | None) -> float:
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
            timeout = _run_timeout(task[1], self.run_timeout)
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


class DaskRunner(Runner):
    """Runs on a Dask cluster; workers must be able to import this package (and any
    plug-in module).  Two runs per worker thread are in flight: one running, one queued
    on the scheduler, which starts it the moment a thread frees (without waiting for
    this process to hear of the finished run and submit the next: that round trip,
    once per run, made Dask 16 % slower than the local pool on 5 s reduced runs).
    Queued runs start in submission order, so a run's clock starts when it is
    submitted to an idle thread, or when a run before it ends: a run without a result
    ``run_timeout`` after its start (default `limits.default_run_timeout`) is recorded
    as failed and cancelled, and the Dask worker running it restarted (if it has a
    nanny).  The workers' memory limit is the cluster's own (``dask worker
    --memory-limit``).  Every worker loads the simulation code and its kernels when the
    runner starts."""

    def __init__(self, address: str, timeout: float = 10.0, *,
                 run_timeout: float | None = None) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ConfigError("--executor", "dask needs the cluster extra: "
                                            "pip install 'flexarm-validation[cluster]'") from None
        try:
            client = Client(address, timeout=f"{timeout}s")
        except (OSError, TimeoutError) as exc:
            raise ConfigError("--scheduler", f"cannot reach {address} within {timeout:g} s "
                                             f"({type(exc).__name__})") from None
        try:
            client.wait_for_workers(1, timeout=timeout)
        except (TimeoutError, OSError):
            client.close()
            raise ConfigError("--scheduler", f"{address} has no workers (waited {timeout:g} s); "
                                             "start some with 'dask worker " + address + "'") from None
        self.client, self.run_timeout = client, run_timeout
        self.workers = max(1, sum(w.get("nthreads", 1) for w in
                                  client.scheduler_info()["workers"].values()))
        from .worker import warm_up
        client.run(warm_up)  # load the kernels now: not within the first runs' limits

    def results(self, tasks, idle=None):
        from distributed import wait
        tasks = iter(tasks)
        in_flight: dict = {}  # future -> [key, task, timeout, deadline (None: queued)]
        queued: deque = deque()  # futures waiting for a thread, in submission order

        def started(now: float) -> None:  # a thread freed: the oldest queued run starts
            while queued:
                future = queued.popleft()
                if future in in_flight:
                    in_flight[future][3] = now + in_flight[future][2]
                    return

        with signals_interrupt():
            try:
                while True:
                    while len(in_flight) < 2 * self.workers:
                        item = next(tasks, None)
                        if item is None:
                            break
                        key, task = item
                        timeout = _run_timeout(task, self.run_timeout)
                        future = self.client.submit(run_and_store, task, pure=False)
                        running = len(in_flight) - len(queued) < self.workers
                        in_flight[future] = [key, task, timeout,
                                             time.monotonic() + timeout if running else None]
                        if not running:
                            queued.append(future)
                    if not in_flight:
                        return
                    limit = min(d for *_, d in in_flight.values() if d is not None) \
                        - time.monotonic()
                    wanted = idle() if idle is not None else None
                    try:
                        wait(list(in_flight), return_when="FIRST_COMPLETED",
                             timeout=max(0.01, limit if wanted is None else min(limit, wanted)))
                    except TimeoutError:
                        pass
                    now = time.monotonic()
                    for future in [f for f in in_flight if f.done()]:
                        item = in_flight.pop(future)
                        started(now)  # its thread is free
                        yield self._collect(future, item)
                    for future in [f for f, (*_, d) in in_flight.items()
                                   if d is not None and d <= now]:
                        key, task, timeout, _ = in_flight.pop(future)
                        self._stop(future)
                        started(now)
                        yield key, store_failure(task, f"no result after {timeout:g} s (the "
                                                       "run was stopped; --run-timeout sets "
                                                       "the limit)")
            except Interrupted:
                finished = [f for f in in_flight if f.done()]
                self.client.cancel(list(in_flight), force=True)
                for future in finished:  # keep what finished before the signal
                    yield self._collect(future, in_flight.pop(future))
                raise

    @staticmethod
    def _collect(future, item) -> tuple[str, Stored]:
        key, task, *_ = item
        try:
            return key, future.result()
        except Exception as exc:  # noqa: BLE001 - the Dask worker itself died: a failed run
            return key, store_failure(task, describe(exc))

    def _stop(self, future) -> None:
        """Cancel a run past its limit and restart the Dask worker running it (a thread
        cannot be stopped; its process can, if a nanny watches it)."""
        running = [w for w, keys in self.client.processing().items() if future.key in keys]
        self.client.cancel([future], force=True)
        if running:
            try:
                self.client.restart_workers(running, raise_for_error=False)
            except Exception:  # noqa: BLE001 - no nanny: the thread finishes on its own
                pass

    def close(self) -> None:
        self.client.close()


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
