"""What a store of runs promises, whatever keeps them (after Optuna's ``BaseStorage``):
`BaseStore`, every method abstract and documented with what it raises.  Two backends:
`validation.batch.store.folder.ResultStore` (a results folder: SQLite index and run files) and
`validation.batch.store.memory.MemoryStore` (a process's memory: an inner loop's runs, every
signal in float64, nothing written).  Records are `validation.batch.store.records.StoredRun`:
immutable, never simulating when read."""
from __future__ import annotations

import abc
from pathlib import Path

__all__ = ["BaseStore"]


class BaseStore(abc.ABC):
    """Stored runs: rows to query, results to load."""

    @abc.abstractmethod
    def rows(self, *, where: str = "", params: tuple = ()) -> list:
        """Every stored run (`StoredRun`), sorted by name then id.

        Parameters
        ----------
        where : str
            An SQL condition on the index's columns (`validation.batch.store.index`:
            `metric_column` names a metric's); the in-memory store takes none.
        params : tuple
            Its parameters.

        Returns
        -------
        list of StoredRun

        Raises
        ------
        StoreError
            The store cannot be read (no index, a damaged one: one line naming the cure).
        """

    @abc.abstractmethod
    def rows_of(self, ids) -> list:
        """The rows of the runs ``ids`` that the store holds (any order; absent ones left
        out).

        Raises
        ------
        StoreError
            As `rows`.
        """

    def row(self, rid: str):
        """The row of run ``rid``, or None.

        Raises
        ------
        StoreError
            As `rows`.
        """
        found = self.rows_of([rid])
        return found[0] if found else None

    @abc.abstractmethod
    def read(self, rid: str) -> tuple:
        """(result, metadata) of run ``rid`` as the store keeps it — what its file keeps
        of the signals, or all of them; never re-simulated.  ``metadata["kept"]`` says
        what is kept where it is less than every signal.

        Raises
        ------
        StoreError
            No such run, or its file is missing or damaged (naming the run).
        """

    def load(self, rid: str):
        """The run's result as the store keeps it (`read`; never re-simulated).

        Raises
        ------
        StoreError
            As `read`.
        """
        return self.read(rid)[0]

    @abc.abstractmethod
    def insert(self, rows: list[tuple]) -> None:
        """Commit the encoded rows (`validation.batch.store.index.row_values`) of runs whose
        files, if they have any, are in place.

        Raises
        ------
        StoreError
            The store cannot be written (read-only, busy, damaged).
        OSError
            The disk is full (ENOSPC, naming the folder).
        """

    @abc.abstractmethod
    def verify(self, rows=None, *, checksum: bool = True) -> dict[str, str]:
        """Run id → why it is damaged, of ``rows`` (default: every row).

        Raises
        ------
        StoreError
            As `rows`.
        """

    @abc.abstractmethod
    def campaigns(self) -> dict[str, dict]:
        """Campaign name → what was recorded of it (description, report settings).

        Raises
        ------
        StoreError
            As `rows`.
        """

    @abc.abstractmethod
    def set_campaign(self, name: str, info: dict) -> None:
        """Record a campaign that stores runs here (keys recorded before kept).

        Raises
        ------
        StoreError
            As `insert`.
        """

    def close(self) -> None:
        """Release what the store holds open (nothing by default)."""

    @property
    @abc.abstractmethod
    def out(self) -> Path | None:
        """The results folder (None: nothing on disk)."""
