"""A run of a campaign, from its scenario to its stored file, where the run executes: the
worker runs it, writes its file into the results folder (under a temporary name, renamed
into ``runs/``; its checksum computed here, where the bytes are) and hands back only
its index row, already encoded — so that the coordinating process's work per run is one
row to insert, whatever the run's length.

A worker that cannot reach the results folder (a Dask worker on another machine, whose
file system does not hold it) hands back the file's bytes with the row; the coordinator
writes them (`write_bytes`).  Whether a worker sees the folder is proved, not guessed:
the coordinator leaves a token file in ``runs/`` (`Destination.reach`) and a worker
writes there only if it reads that token.

`serve` is a local worker process's life.  This module is not on a run's import path
(`validation.batch.fingerprint` hashes `validation.batch.worker`): storing changes no
result, and editing it leaves stored runs valid.
"""
from __future__ import annotations

import dataclasses
import errno
import functools
import secrets
from dataclasses import dataclass
from pathlib import Path

from .errors import StoreError
from .index import STATUS, row_values
from .runfiles import KEEP_ALL, KEEP_NONE, Keep, run_file, write_file
from ..worker import OVER_MEMORY, execute_run, failed_result, warm_up, worker_init

__all__ = ["Destination", "StoreTask", "Stored", "run_and_store", "store_failure",
           "landed", "serve", "leave_token"]


@dataclass(frozen=True)
class Destination:
    """Where a campaign's runs are stored and what is recorded with each: the results
    folder ``out`` (None: an in-memory store, `validation.batch.store.memory`, sent every
    result whole, its signals in float64), the campaign's name, the environment
    (versions) recorded with every run, what a run keeps (`Keep`), the name of the token
    file in ``out/runs`` that proves a worker sees this folder (None: workers send the
    file's bytes), and the preset dictionary rows' details are compressed with
    (`index.dictionary_for`)."""

    out: str | None
    campaign: str
    env: dict
    keep: Keep = KEEP_ALL
    reach: str | None = None
    dictionary: bytes = b""


@dataclass(frozen=True)
class StoreTask:
    """One run to execute and store: its scenario (a checked `Scenario` or its mapping),
    sweep, swept values and destination."""

    rid: str
    scenario: object
    sweep: str
    axes: dict
    destination: Destination


@dataclass(frozen=True)
class Stored:
    """What comes back for a run: its index row as `index.row_values` encodes it; the
    file's bytes if the worker could not write them (else None); or, if the file could
    not be written at all, why (``error``, with ``errno`` when the system said one).
    ``exhausted``: the run reached its worker's memory limit; what that process still
    holds (a plug-in's module-level data) is unknown, so the runner replaces it.
    ``result``: (result, metrics) for an in-memory store."""

    rid: str
    values: tuple | None
    data: bytes | None = None
    error: str = ""
    errno: int | None = None
    exhausted: bool = False
    result: tuple | None = None

    @property
    def status(self) -> str:
        return self.values[0][STATUS] if self.values else "failed"


def leave_token(out: Path) -> str:
    """Write a token file into ``out/runs`` for workers to find (`Destination.reach`);
    returns its name.  It is a hidden temporary (``.reach-*.tmp``): removed by
    `ResultStore.remove_stale_temporaries` an hour later, never taken for a run."""
    name = f".reach-{secrets.token_hex(8)}.tmp"
    (Path(out) / "runs" / name).write_text(name)
    return name


@functools.lru_cache(maxsize=64)
def _reaches(out: str, token: str) -> bool:
    """Whether this process sees the results folder ``out`` (reads its token)."""
    try:
        return (Path(out) / "runs" / token).read_text() == token
    except OSError:
        return False


def _store(task: StoreTask, result, metrics) -> Stored:
    d = task.destination
    if d.out is None:
        data, row = run_file(task.rid, result, metrics, campaign=d.campaign,
                             sweep=task.sweep, axes=task.axes, env=d.env, keep=KEEP_NONE)
        return Stored(task.rid, row_values(row, d.dictionary), result=(result, metrics))
    reaches = d.reach is not None and _reaches(d.out, d.reach)
    # A file to send is sent compressed (`validation.run.packing`: half the bytes).
    keep = d.keep if reaches else dataclasses.replace(d.keep, compress=True)
    data, row = run_file(task.rid, result, metrics, campaign=d.campaign, sweep=task.sweep,
                         axes=task.axes, env=d.env, keep=keep)
    values = row_values(row, d.dictionary)
    if data is None:  # metrics only: the row is all of it
        return Stored(task.rid, values)
    if not reaches:
        return Stored(task.rid, values, data)
    return _written(Path(d.out), task.rid, data, values)


def run_and_store(task: StoreTask) -> Stored:
    """Execute ``task``'s run (`worker.execute_run`: never raises for the run's sake) and
    store it (module docstring)."""
    result, metrics = execute_run(task.scenario,
                                  float32=task.destination.out is not None)
    stored = _store(task, result, metrics)
    if result.status == "failed" and result.message.startswith(OVER_MEMORY):
        return dataclasses.replace(stored, exhausted=True)
    return stored


def store_failure(task: StoreTask, message: str) -> Stored:
    """Store ``task``'s run as failed with ``message`` (its worker died or ran out of
    time): in the coordinating process, which alone knows it."""
    return _store(task, *failed_result(task.scenario, message))


def landed(out: Path, stored: Stored) -> Stored:
    """``stored`` with its file in the results folder ``out``: written here if its worker
    sent the bytes (it could not reach ``out``).  A full disk is raised as `OSError`
    (ENOSPC, naming ``out``: no further run can be stored); any other failure to write
    is ``stored.error`` (this run's place only: a read-only file, a folder in the way)."""
    if stored.data is not None:
        stored = _written(Path(out), stored.rid, stored.data, stored.values)
    if stored.errno == errno.ENOSPC:
        raise OSError(errno.ENOSPC, "No space left on device", str(out))
    return stored


def _written(out: Path, rid: str, data: bytes, values: tuple) -> Stored:
    """Write run ``rid``'s file ``data`` into ``out``: its `Stored` (with why not, if it
    could not be written: a full disk, a read-only folder, a place that cannot be
    cleared)."""
    try:
        write_file(out, rid, data)
    except StoreError as exc:
        return Stored(rid, None, error=str(exc))
    except OSError as exc:
        return Stored(rid, None, error=f"runs/{rid}.npz: {exc.strerror or exc}",
                      errno=exc.errno)
    return Stored(rid, values)


def serve(conn, parent: int, memory_mib: int | None, warm: bool) -> None:
    """A local worker process's life: receive a `StoreTask` on ``conn``, send back
    `run_and_store`'s `Stored`; until it receives None or the parent's end closes.
    ``warm``: the kernels are loaded already (forked from a warmed parent)."""
    worker_init(parent, memory_mib)
    if not warm:
        warm_up()
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        conn.send(run_and_store(task))
