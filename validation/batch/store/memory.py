"""An in-memory store for inner loops (a calibration's residuals, a search's trial points):
the runs of a campaign runner kept in this process — every signal in float64, as the run
made it — with the same rows a results folder would hold, and nothing written anywhere.
Its runs are lost with the process: a loop that must resume stores into a folder
(`validation.batch.store.folder.ResultStore`) instead."""
from __future__ import annotations

from .base import BaseStore
from .errors import StoreError
from .index import FIXED
from .records import Detail, StoredRun

__all__ = ["MemoryStore"]


class MemoryStore(BaseStore):
    """Runs kept in memory (module docstring).  The queue hands it each result whole
    (`keep`), then the row its worker encoded (`insert`)."""

    def __init__(self) -> None:
        self._rows: dict[str, StoredRun] = {}
        self._results: dict[str, tuple] = {}
        self._campaigns: dict[str, dict] = {}

    @property
    def out(self) -> None:
        return None

    def keep(self, rid: str, result, metrics: dict) -> None:
        """Hold run ``rid``'s result (float64 signals) and metrics until its row comes."""
        self._results[rid] = (result, metrics)

    def insert(self, rows: list[tuple]) -> None:
        for fixed, m_names, m_values, _, _ in rows:
            values = dict(zip(FIXED, fixed))
            rid = values["run_id"]
            if rid not in self._results:
                raise StoreError(f"in-memory store: run {rid} has a row but no result")
            result, _ = self._results[rid]
            self._rows[rid] = StoredRun(
                **{k: values[k] for k in StoredRun.__dataclass_fields__
                   if k in values and k != "detail"}, metric_names=m_names,
                metric_values=m_values,
                detail=Detail(values["detail"]))

    def rows(self, *, where: str = "", params: tuple = ()) -> list[StoredRun]:
        if where:
            raise StoreError("the in-memory store takes no SQL condition")
        return sorted(self._rows.values(), key=lambda r: (r.name, r.run_id))

    def rows_of(self, ids) -> list[StoredRun]:
        return [self._rows[i] for i in dict.fromkeys(ids) if i in self._rows]

    def read(self, rid: str) -> tuple:
        if rid not in self._rows:
            raise StoreError(f"in-memory store: no run {rid}")
        return self._results[rid][0], {}

    def verify(self, rows=None, *, checksum: bool = True) -> dict[str, str]:
        return {}  # nothing left this process: nothing to damage

    def campaigns(self) -> dict[str, dict]:
        return {k: dict(v) for k, v in self._campaigns.items()}

    def set_campaign(self, name: str, info: dict) -> None:
        self._campaigns[name] = {**self._campaigns.get(name, {}), **info}

    def export(self, **_) -> None:
        """Nothing to export: an in-memory store writes no file."""
