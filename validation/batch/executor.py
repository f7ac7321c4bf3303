"""Where runs execute: in this process, on a local pool of worker processes, or on a Dask
cluster — one interface, results handed back as they finish.

`Runner.results(tasks)` yields ``(key, result, metrics)`` as each run completes, so the
caller stores every finished run at once (the serial runner included).  At most
2 × workers runs are in flight, so memory stays bounded however long the campaign.  On
SIGINT/SIGTERM the runner stops submitting, hands back what has already finished,
terminates its workers (none is left behind) and raises `Interrupted`; a second signal
exits at once.

Local workers are started once and reused for every run, forked from a process that has
already loaded the simulation code and its compiled kernels, each limited to one BLAS
thread (two workers on two cores would otherwise busy-wait on each other's cores).
Every process that runs or stores runs keeps its freed memory for the next run
(`keep_freed_memory`).
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, Future, wait
from contextlib import contextmanager

from ..run._config import ConfigError, check
from .threads import ONE_THREAD
from .worker import execute_run, failed_result, keep_freed_memory, worker_init

__all__ = ["Runner", "make_runner", "Interrupted", "available_cores", "exit_status",
           "signals_interrupt"]



class Interrupted(BaseException):
    """SIGINT or SIGTERM arrived; ``signum`` says which (a BaseException, so that no
    ``except Exception`` in a run swallows it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


class Runner:
    """Executes tasks ``(key, scenario)`` (see `execute_run`); subclasses say where."""

    workers = 1

    def results(self, tasks):
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class SerialRunner(Runner):
    """In this process, one run after another (``--workers 1``)."""

    def results(self, tasks):
        with signals_interrupt():
            for key, data in tasks:
                yield (key, *execute_run(data))


class _PoolRunner(Runner):
    """A `concurrent.futures` executor with a bounded number of runs in flight."""

    def __init__(self, executor, workers: int) -> None:
        self.executor, self.workers = executor, workers

    def results(self, tasks):
        tasks = iter(tasks)
        in_flight: dict[Future, tuple] = {}
        with signals_interrupt():
            try:
                while True:
                    while len(in_flight) < 2 * self.workers:
                        task = next(tasks, None)
                        if task is None:
                            break
                        key, data = task
                        in_flight[self.executor.submit(execute_run, data)] = (key, data)
                    if not in_flight:
                        return
                    done, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                    for future in done:
                        yield self._collect(future, in_flight.pop(future))
            except Interrupted:
                finished = [f for f in in_flight if f.done() and not f.cancelled()]
                self.abort()
                for future in finished:  # keep what finished before the signal
                    yield self._collect(future, in_flight.pop(future))
                raise

    @staticmethod
    def _collect(future: Future, task) -> tuple:
        key, data = task
        try:
            return (key, *future.result())
        except Exception as exc:  # noqa: BLE001 - the worker itself died: a failed run
            return (key, *failed_result(data, exc))

    def abort(self) -> None:
        self.executor.shutdown(wait=False, cancel_futures=True)


class LocalPoolRunner(_PoolRunner):
    """``workers`` processes started once and reused for every run.  On Linux they are
    forked from this process, which has already imported and compiled everything they
    need (started at once, before any other thread exists here); elsewhere a forkserver
    that preloads the simulation code (not the CLI, not matplotlib) forks them."""

    def __init__(self, workers: int) -> None:
        from concurrent.futures import ProcessPoolExecutor
        if "fork" in multiprocessing.get_all_start_methods():
            from .worker import warm_up
            warm_up()  # compiled once here, inherited by every forked worker
            ctx = multiprocessing.get_context("fork")
        else:
            ctx = multiprocessing.get_context("forkserver")
            ctx.set_forkserver_preload(["validation.batch.worker"])  # each worker compiles or loads
        with _environment(ONE_THREAD):
            executor = ProcessPoolExecutor(max_workers=workers, mp_context=ctx,
                                           initializer=worker_init)
            # Start every worker now (with "fork" the pool forks them all on the first
            # submit, before its manager thread exists).
            executor.submit(int).result()
        super().__init__(executor, workers)

    def abort(self) -> None:
        processes = list((getattr(self.executor, "_processes", None) or {}).values())
        results_pipe = getattr(self.executor, "_result_queue", None)  # shutdown clears it
        self._aborted = True
        super().abort()
        for p in processes:  # do not wait for runs in progress: end them
            if p.is_alive():
                p.kill()
        for p in processes:
            p.join(timeout=5)
        if results_pipe is not None and not any(p.is_alive() for p in processes):
            # A worker killed while sending a result leaves half a message in the pipe;
            # the pool's manager thread would wait for the rest forever (and the exit
            # with it), since this process still holds a write end.  Closing it gives
            # that thread end-of-file.  (Private attribute, like ``_processes``.)
            results_pipe._writer.close()
        if multiprocessing.get_start_method(allow_none=True) != "fork":
            from multiprocessing import forkserver
            forkserver._forkserver._stop()  # and the server that forked them (private
            # API, the one the standard library's own tests use; nothing public stops it)

    def close(self) -> None:
        if not getattr(self, "_aborted", False):
            self.executor.shutdown(wait=True, cancel_futures=True)


class DaskRunner(_PoolRunner):
    """Runs on a Dask cluster; workers must be able to import this package (and any
    plug-in module)."""

    def __init__(self, address: str, timeout: float = 10.0) -> None:
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
        self.client = client
        workers = max(1, sum(w.get("nthreads", 1) for w in
                             client.scheduler_info()["workers"].values()))
        super().__init__(client.get_executor(pure=False), workers)

    def abort(self) -> None:
        super().abort()
        self.client.close()

    def close(self) -> None:
        try:
            self.executor.shutdown()
        finally:
            self.client.close()


def make_runner(kind: str = "local", workers: int | None = None, scheduler: str | None = None,
                *, force: bool = False) -> Runner:
    """A runner: "local" (``workers`` processes, default the cores; 1 = this process) or
    "dask" (the cluster at ``scheduler`` or $DASK_SCHEDULER_ADDRESS).  More local workers
    than cores are refused unless ``force`` (they only share the cores)."""
    keep_freed_memory()  # this process stores the runs (and forks the local workers)
    if kind == "local":
        check(scheduler is None, "--scheduler", "only for --executor dask")
        cores = available_cores()
        workers = workers or cores
        check(workers >= 1, "--workers", f"must be >= 1, got {workers}")
        check(workers <= cores or force, "--workers", f"{workers} workers on {cores} cores "
              "only share the cores (each costs ~300 MB); pass --force-workers to insist")
        return SerialRunner() if workers == 1 else LocalPoolRunner(workers)
    if kind == "dask":
        address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS")
        check(bool(address), "--scheduler", "the dask executor needs --scheduler "
                                            "tcp://HOST:PORT or DASK_SCHEDULER_ADDRESS")
        check(workers is None, "--workers", "the Dask cluster decides its workers")
        return DaskRunner(address)
    raise ConfigError("--executor", f"must be 'local' or 'dask', got {kind!r}")


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


@contextmanager
def signals_interrupt():
    """SIGINT/SIGTERM raise `Interrupted` in the main thread; a second one exits now.
    Nested uses (a search around its runner's batches) each handle their own span."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []

    def handler(signum, frame):
        if received:  # the second signal: end the workers and this process now
            for child in multiprocessing.active_children():
                child.kill()
            os._exit(exit_status(signum))
        received.append(signum)
        raise Interrupted(signum)

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def exit_status(signum: int) -> int:
    """The shell's convention: 128 + the signal number (130 for SIGINT, 143 SIGTERM)."""
    return 128 + signum

