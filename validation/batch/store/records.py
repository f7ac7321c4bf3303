"""A stored run as the store hands it out: `StoredRun`, immutable, with no reference to
the store that read it (after Optuna's ``FrozenTrial``).  Reading one runs nothing: its
signals are the store's to give (`validation.batch.store.base.BaseStore.load`), re-simulating
them is an explicit call (`validation.batch.store.resimulate.every_signal`).

What a table or an export shows (identity, status, the columns of the scenario, the
metrics) is read with the row; the resolved scenario, the swept values as they were, the
timings and the environment are decoded from the row's compressed detail the first time
one of them is asked for (`validation.batch.store.index.decode_detail`)."""
from __future__ import annotations

import functools
import json
import math
import operator
from dataclasses import dataclass, field

from ...run.results import STATUSES
from .index import decode_detail, is_run_id, json_table, not_a_number

__all__ = ["StoredRun", "Detail", "records", "metric_matrix"]


class Detail:
    """A row's compressed detail and the dictionary it was compressed with, decoded once
    on demand; or the decoded values themselves (an in-memory store's rows)."""

    __slots__ = ("blob", "dictionary", "_decoded")

    def __init__(self, blob: bytes = b"", dictionary: bytes = b"", decoded=None) -> None:
        self.blob, self.dictionary, self._decoded = blob, dictionary, decoded

    def decoded(self) -> tuple[str, dict]:
        """(the scenario's canonical JSON, the rest); ValueError if it is damaged."""
        if self._decoded is None or isinstance(self._decoded[1], str):
            scenario, rest = self.text()
            self._decoded = (scenario, json_table(rest))
        return self._decoded

    def text(self) -> tuple[str, str]:
        """(the scenario's canonical JSON, the rest's JSON), the rest not parsed (what
        checking a run's id needs: `ResultStore.verify`)."""
        if self._decoded is None:
            self._decoded = decode_detail(self.blob, self.dictionary)
        scenario, rest = self._decoded
        return scenario, rest if isinstance(rest, str) else json.dumps(rest)


def _table(value, what: str) -> dict:
    if not isinstance(value, dict):
        raise ValueError(f"its {what} is not a table")
    return value


@dataclass(frozen=True)
class StoredRun:
    """One stored run (a row of the index): identity, status, the scenario's columns,
    metrics (NaN where a metric does not apply to the run), and on demand its scenario
    (``config``), swept values (``axes``), timings and environment."""

    run_id: str
    name: str
    campaign: str
    sweep: str
    status: str
    message: str
    end_time: float | None
    fingerprint: str
    arm: object
    plant: str
    role: str
    controller: str
    observer: str
    Ts: float | None
    initial_state: str
    file: str
    sha256: str
    size: int
    finished: str
    metric_names: tuple = ()
    metric_values: tuple = ()
    detail: Detail = field(default_factory=Detail, repr=False, compare=False)

    @functools.cached_property
    def metrics(self) -> dict:
        """Metric name → value (NaN where stored as NaN, ±∞ as ±∞), in the run's order."""
        return {k: math.nan if v is None else v
                for k, v in zip(self.metric_names, self.metric_values)}

    @functools.cached_property
    def config(self) -> dict:
        """The resolved scenario (decoded from the row's detail)."""
        return _table(json.loads(self.detail.decoded()[0]), "scenario")

    @functools.cached_property
    def scenario_text(self) -> str:
        """The scenario's canonical JSON (what the run id hashes)."""
        return self.detail.text()[0]

    @property
    def axes(self) -> dict:
        """The swept values, as the campaign gave them."""
        return _table(self.detail.decoded()[1].get("axes", {}), "swept values")

    @property
    def timings(self) -> dict:
        return _table(self.detail.decoded()[1].get("timings", {}), "timings")

    @property
    def environment(self) -> dict:
        """Versions and git revision of the code that made the run."""
        return _table(self.detail.decoded()[1].get("environment", {}), "environment")

    @property
    def kept(self) -> dict | None:
        """What the run's file keeps where it is less than every signal (`Keep.meta`),
        else None."""
        return self.detail.decoded()[1].get("kept")

    @property
    def has_file(self) -> bool:
        """Whether the run has a file in ``runs/`` (a metrics-only run has none: its row
        holds all of it)."""
        return bool(self.file)

    @property
    def plant_label(self) -> str:
        """How tables and figures name the run's plant."""
        from ...run.plants import label_of
        return label_of({"plant": {"kind": self.plant, "role": self.role}})

    def check(self) -> None:
        """ValueError unless the row is what the store writes (its id, file, status,
        size and checksum; its detail is checked when decoded)."""
        rid = self.run_id
        if not is_run_id(rid) or self.file not in ("", f"runs/{rid}.npz"):
            raise ValueError("its id must be 12 hex digits and its file runs/<id>.npz or none")
        if self.status not in STATUSES:
            raise ValueError(f"status {str(self.status)[:20]!r} is none of {STATUSES}")
        if self.file and not (isinstance(self.size, int) and self.size > 0
                              and isinstance(self.sha256, str) and len(self.sha256) == 64):
            raise ValueError("its file's size and checksum are not a size and a SHA-256")


#: StoredRun's fields read from a row of the index, in its order.
_RECORD_FIELDS = ("run_id", "name", "campaign", "sweep", "status", "message", "end_time",
                  "fingerprint", "arm", "plant", "role", "controller", "observer", "Ts",
                  "initial_state", "file", "sha256", "size", "finished")


def _picker(index: list[int]):
    """A function of a row's values to the tuple of those at ``index``."""
    if not index:
        return lambda values: ()
    if len(index) == 1:
        return lambda values, i=index[0]: (values[i],)
    return operator.itemgetter(*index)


def records(cursor, sets: dict, dictionary):
    """(run id, `StoredRun` or why the row is not one) of each row of ``cursor`` (what
    `index.reading` selects of the index's runs); ``sets``: metric set id → metric names,
    or why the set is damaged; ``dictionary``: key → the preset dictionary of a detail."""
    columns = [d[0] for d in cursor.description]
    position = {c: i for i, c in enumerate(columns)}
    record = operator.itemgetter(*(position[f] for f in _RECORD_FIELDS))
    at = {f: position[f] for f in ("metric_set", "dictionary", "detail", "mistyped")}
    pickers: dict = {}
    for values in cursor:
        try:
            names, wrong = sets[values[at["metric_set"]]], values[at["mistyped"]]
            if isinstance(names, str):
                raise ValueError(f"its metric set is damaged: {names}")
            if wrong is not None:
                raise ValueError(not_a_number(wrong, values[position[wrong]]))
            if names not in pickers:
                pickers[names] = _picker([position["m:" + n] for n in names])
            row = object.__new__(StoredRun)  # frozen: no __setattr__ per field (3x faster)
            row.__dict__.update(zip(_RECORD_FIELDS, record(values)))
            row.__dict__.update(metric_names=names, metric_values=pickers[names](values),
                                detail=Detail(values[at["detail"]],
                                              dictionary(values[at["dictionary"]])))
            row.check()
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            yield values[0], str(exc)
            continue
        yield values[0], row


def metric_matrix(rows, names):
    """The metrics ``names`` of ``rows`` as a float array (len(rows), len(names)): NaN
    where a run lacks a metric or its value is not a number (no dict built per row: runs
    of one metric layout share the positions of the names)."""
    import numpy as np
    names = list(names)
    out = np.full((len(rows), len(names)), np.nan)
    groups: dict = {}  # rows of one layout share its tuple
    for i, row in enumerate(rows):
        groups.setdefault(id(row.metric_names), (row.metric_names, []))[1].append(i)
    for layout, index in groups.values():
        found = [(j, layout.index(n)) for j, n in enumerate(names) if n in layout]
        if not found:
            continue
        pick = _picker([k for _, k in found])
        values = [pick(rows[i].metric_values) for i in index]
        try:  # None (a NaN stored) becomes NaN
            block = np.array(values, dtype=float).reshape(len(index), len(found))
        except (TypeError, ValueError):  # a text metric among them: not a number
            block = np.array([[v if isinstance(v, float) else np.nan for v in vs]
                              for vs in values]).reshape(len(index), len(found))
        out[np.ix_(index, [j for j, _ in found])] = block
    return out
