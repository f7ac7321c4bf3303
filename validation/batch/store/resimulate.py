"""Every signal of a stored run, re-simulated where its file keeps less (a campaign's
``[keep]``, `validation.batch.store.runfiles.Keep`) — an explicit call, never hidden in a
read: `every_signal(store, row)`.  A run is a deterministic function of its scenario
(seeded noise) and of the code, so the re-simulation gives the run's signals bit for bit
— and is checked to: its metrics must equal the stored ones exactly and the signals the
file kept must equal the re-simulated ones, else `StoreError` says so.

A run stored by other code than this installation (its fingerprint differs: what
``flexarm show`` notes) is not re-simulated: its signals would be this code's, not the
run's (`StaleRun`; ``flexarm campaign`` reruns stale runs).  A re-simulation that fails
where the run did not (a torque file given by a path relative to another directory) says
why, naming the file.

Reading a folder runs no code it names: a run of a plug-in law or plant is not
re-simulated here (`resimulable`); ``flexarm run --like RESULTS/RUN`` re-runs it on
purpose.  Every reader of a run's signals (reports, ``show``, the claims, ``export
--signals``, calibration) calls `every_signal`.  Re-simulating loads the simulation code
(Exudyn for a truth-plant run)."""
from __future__ import annotations

import math
import os

import numpy as np

from ...run.results import RunResult
from .errors import StaleRun, StoreError
from ..fingerprint import is_fresh, plugin_kinds
from .index import finite_or_none, metric_values
from .runfiles import Keep

__all__ = ["every_signal", "resimulable", "STALE"]

#: What ``flexarm show`` and every re-simulation say of a run made by other code.
STALE = "stored by other code than this installation"


def resimulable(row) -> bool:
    """Whether ``row``'s run may be re-simulated while a folder is read: its laws and
    plant are built in (a plug-in's module is never imported by reading a folder)."""
    return not plugin_kinds({part: {"kind": getattr(row, part)}
                             for part in ("controller", "observer", "plant")})


def every_signal(store, row, names: tuple = ()) -> RunResult:
    """Every signal of stored run ``row`` of ``store`` at every sample: read from its file,
    or, where the file keeps less, re-simulated and checked (module docstring).  With
    ``names``, only those are asked for: a file that keeps them at every sample (a mesh
    check's, `validation.verdicts.mesh.CHECK_KEEP`) is read as it is."""
    result, meta = store.read(row.run_id)
    kept = meta.get("kept")
    if kept is None or (names and int(kept.get("every", 1)) == 1
                        and set(names) <= set(result.names)):
        return result
    where = f"{store.out}/{row.run_id}" if store.out else row.run_id
    if not resimulable(row):
        raise StoreError(f"run {row.run_id}: its file keeps {_what(result)} and its laws or "
                         f"plant are plug-ins, not re-simulated while reading a folder; "
                         f"'flexarm run --like {where}' reruns it")
    if not is_fresh(row):
        raise StaleRun(f"run {row.run_id}: {STALE}; its file keeps {_what(result)}, and "
                       "re-simulating it here would give this code's signals, not the run's "
                       "('flexarm campaign' reruns stale runs)")
    from ..worker import execute_run
    again, metrics = execute_run(row.config)
    if again.status == "failed" and row.status != "failed":
        raise StoreError(f"run {row.run_id}: re-simulating it failed here: {again.message}"
                         f"{_relative_files(row.config)}")
    keep = Keep(tuple(result.names), int(kept["every"]))
    same_signals = np.array_equal(keep.apply(again).signals, result.signals)
    if not (same_signals and _equal(metric_values(finite_or_none(metrics)), row.metrics)):
        raise StoreError(f"run {row.run_id}: re-simulating its scenario did not reproduce "
                         f"its stored {'metrics' if same_signals else 'signals'} (stored by "
                         "other code? 'flexarm campaign' reruns stale runs)")
    return again


def _relative_files(config: dict) -> str:
    """A note naming the files a scenario reads by a relative path (read from the
    directory the command runs in, not the one the run was stored from)."""
    files = [str(v) for part in ("controller", "observer", "plant")
             for k, v in config.get(part, {}).get("options", {}).items()
             if k == "file" and isinstance(v, str) and not os.path.isabs(v)]
    if not files:
        return ""
    return (f" ({', '.join(files)}: a relative path, read from {os.getcwd()}; run the "
            "command from the directory the run was stored from)")


def _what(result: RunResult) -> str:
    return f"{len(result.names)} signals at {result.time.size} samples" if result.names \
        else "no signals (metrics only)"


def _equal(a: dict, b: dict) -> bool:
    """Metrics equal value for value (NaN equals NaN: a metric that does not apply)."""
    same = lambda x, y: x == y or (isinstance(x, float) and isinstance(y, float)  # noqa: E731
                                   and math.isnan(x) and math.isnan(y))
    return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
