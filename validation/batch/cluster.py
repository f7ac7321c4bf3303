"""Runs on a Dask cluster (the ``cluster`` extra)."""
from __future__ import annotations

import time
from collections import deque

from ..run.config import ConfigError
from .interrupts import Interrupted, signals_interrupt
from .runner import Runner, run_time_limit
from .store.writing import Stored, run_and_store, store_failure
from .worker import describe

__all__ = ["DaskRunner"]


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
                        timeout = run_time_limit(task, self.run_timeout)
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
