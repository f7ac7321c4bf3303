"""The store's own exceptions: what a results folder cannot do, named in one line.

None of them is a `ValueError`: code that catches a bad value (a run file that is not
one, a scenario that does not parse) never swallows a busy, damaged or read-only index
by accident (after Optuna's `DuplicatedStudyError`, `StorageInternalError`)."""
from __future__ import annotations

__all__ = ["StoreError", "IndexBusy", "IndexDamaged", "ReadOnlyFolder", "NotARunFile",
           "StaleRun"]


class StoreError(Exception):
    """A results folder that cannot be used (one line naming the folder or file)."""


class IndexBusy(StoreError):
    """Another process kept the index locked longer than the store waits."""


class IndexDamaged(StoreError):
    """The index cannot be read (``flexarm repair`` rebuilds it from the run files)."""


class ReadOnlyFolder(StoreError):
    """The folder cannot be written by this process."""


class NotARunFile(StoreError):
    """A file in ``runs/`` that is not an intact run file of the name it has (never
    adopted; the run is redone)."""


class StaleRun(StoreError):
    """A run stored by other code than this installation whose signals were asked for
    by re-simulation: the signals would be this code's, not the run's."""
