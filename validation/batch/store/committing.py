"""Index rows committed in batches, without losing "stored as soon as it finishes".

A worker puts a run's file in place (`validation.batch.store.writing`) before its row reaches
the coordinating process; the row is then committed here with the others that arrived
meanwhile, in one transaction — at the latest `INTERVAL` seconds after it arrived while
the command runs (the runner asks before each wait: `Committer.idle`), when `MAX_ROWS`
are waiting, and whenever the command stops (end, error, SIGINT/SIGTERM: `flush`).

What a crash leaves: a process killed between a file and its row (``kill -9``, a power
cut) leaves the file in ``runs/`` without a row — an intact run that the next
``flexarm campaign`` (resume) adopts without running it again (`campaign.classify`),
and that ``flexarm repair`` adopts as well; a worker killed while writing leaves a
hidden temporary file (``runs/.<id>.npz.*.tmp``), never read, removed an hour later.
"""
from __future__ import annotations

import time

__all__ = ["Committer", "INTERVAL", "MAX_ROWS"]

#: The longest a row waits for its commit while the command runs [s]: commits at most
#: ~10 per second, however many runs finish (each commit costs ~0.1-1 ms).
INTERVAL = 0.1
#: The most rows one transaction commits.
MAX_ROWS = 512


class Committer:
    """Rows (`index.row_values`) of runs whose files are in place, committed into
    ``store`` in batches (module docstring)."""

    def __init__(self, store) -> None:
        self.store = store
        self.pending: list[tuple] = []
        self.last = time.monotonic()

    def add(self, values: tuple) -> None:
        self.pending.append(values)
        if len(self.pending) >= MAX_ROWS:
            self.flush()

    def idle(self) -> float | None:
        """Called before the runner waits: commit if the oldest waiting row is due; the
        longest the runner may wait before calling again (None: nothing waits)."""
        if not self.pending:
            return None
        left = self.last + INTERVAL - time.monotonic()
        if left > 0:
            return left
        self.flush()
        return None

    def flush(self) -> None:
        """Commit every waiting row now (one transaction)."""
        if self.pending:
            self.store.insert(self.pending)
            self.pending = []
        self.last = time.monotonic()
