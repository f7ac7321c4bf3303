"""The signals of a stored run whose file keeps less than all of them (a campaign's
``[keep]``, `validation.batch.runfiles.Keep`): re-simulated from the run's exact
scenario, which every run file keeps.  A run is a deterministic function of its scenario
(seeded noise) and of the code, so the re-simulation gives the run's signals bit for bit
— and is checked to: its metrics must equal the stored ones exactly and the signals the
file kept must equal the re-simulated ones, else `StoreError` says so (the code changed
since: the run's fingerprint tells).

Reading a folder runs no code it names: a run of a plug-in law or plant is not
re-simulated here (`resimulable`); ``flexarm run --like RESULTS/RUN`` re-runs it on
purpose.  `StoredRun.load` is `full_result`: every reader of a run's signals (reports,
``show``, the claims, ``export --signals``, calibration) gets them all.  Re-simulating loads the simulation code (Exudyn for a truth-plant run)."""
from __future__ import annotations

import math

import numpy as np

from ..run.results import RunResult
from .fingerprint import plugin_kinds
from .index import StoreError, finite_or_none, metric_values
from .runfiles import Keep

__all__ = ["full_result", "resimulable"]


def resimulable(row) -> bool:
    """Whether ``row``'s run may be re-simulated while a folder is read: its laws and
    plant are built in (a plug-in's module is never imported by reading a folder)."""
    return not plugin_kinds(row.config)


def full_result(row) -> RunResult:
    """Every signal of stored run ``row`` at every sample: read from its file, or, where
    the file keeps less, re-simulated and checked (module docstring)."""
    result, meta = row.store.read(row.run_id)
    kept = meta.get("kept")
    if kept is None:
        return result
    if not resimulable(row):
        raise StoreError(f"run {row.run_id}: its file keeps {_what(result)} and its laws or "
                         f"plant are plug-ins, not re-simulated while reading a folder; "
                         f"'flexarm run --like {row.store.out}/{row.run_id}' reruns it")
    from .worker import execute_run
    again, metrics = execute_run(row.config)
    keep = Keep(tuple(result.names), int(kept["every"]))
    same_signals = np.array_equal(keep.apply(again).signals, result.signals)
    if not (same_signals and _equal(metric_values(finite_or_none(metrics)), row.metrics)):
        raise StoreError(f"run {row.run_id}: re-simulating its scenario did not reproduce "
                         f"its stored {'metrics' if same_signals else 'signals'} (stored by "
                         "other code? 'flexarm campaign' reruns stale runs)")
    return again


def _what(result: RunResult) -> str:
    return f"{len(result.names)} signals at {result.time.size} samples" if result.names \
        else "no signals (metrics only)"


def _equal(a: dict, b: dict) -> bool:
    """Metrics equal value for value (NaN equals NaN: a metric that does not apply)."""
    same = lambda x, y: x == y or (isinstance(x, float) and isinstance(y, float)  # noqa: E731
                                   and math.isnan(x) and math.isnan(y))
    return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
