"""Exports of a results folder: ``metrics.csv`` (one row per run: what was run, swept
values, status, every metric) and ``manifest.json``, written from the index's columns
(no run's detail decoded: 10^5 runs in seconds) through the store's public methods."""
from __future__ import annotations

import csv
import functools
import io
import json
import operator
from pathlib import Path

from ...run.results import write_atomic
from ..beside import beside
from .errors import ReadOnlyFolder, StoreError
from .index import axis_column, is_run_id, metric_column

__all__ = ["export", "IDENTITY_COLUMNS"]

#: Rows of metrics.csv a worker writes as text (`_csv_text`): fewer are written here.
_ROWS_A_WORKER = 10_000

#: The largest manifest read back (~0.3 KB a run: 10⁶ runs are ~300 MB).
MAX_MANIFEST_BYTES = 1 << 30
#: Columns of metrics.csv that say what was run, before the swept values and metrics.
IDENTITY_COLUMNS = ("run_id", "name", "campaign", "sweep", "arm", "plant", "controller",
                    "observer", "Ts", "initial_state", "status", "message")
#: What manifest.json lists of each run, where not empty (its metrics and swept values:
#: metrics.csv; its scenario, timings and environment: the index).
_MANIFEST = ("name", "campaign", "sweep", "status", "message", "fingerprint", "file",
             "sha256", "size", "finished")


def export(store, *, allow_fewer: bool = False) -> tuple[Path, Path]:
    """Write metrics.csv (one row per run: identity, what was run, swept values,
    status, every metric) and manifest.json from the index, holding its write lock
    (of two processes exporting at once, the later one reads every row the earlier
    one wrote).  An index that lacks runs the previous export listed (a damaged
    index reads as fewer runs) is refused (StoreError, the old export kept) unless
    ``allow_fewer`` (after `repair`, which says what it dropped)."""
    store.check()
    if not store.writable():
        raise ReadOnlyFolder(f"{store.out}: read-only, metrics.csv and manifest.json cannot "
                             "be written here")
    with store.locked():  # the write lock; nothing is written to it
        return _export(store, allow_fewer)


def _export(store, allow_fewer: bool) -> tuple[Path, Path]:
    store.check_pages()  # metrics.csv is never rewritten from a damaged index
    store.refuse_malformed()
    layouts = store.layouts()
    axes = list(dict.fromkeys(a for names, _ in layouts.values() for a in names))
    metrics = list(dict.fromkeys(m for _, names in layouts.values() for m in names))
    head = [*IDENTITY_COLUMNS, "metric_set", *_MANIFEST[5:]]
    # csv writes None as "" and a float as its repr; a metric stored as NaN is NULL.
    table = store.columns([*head, *(axis_column(a) for a in axes),
                           *(f"IFNULL({metric_column(m)}, 'nan')" for m in metrics)],
                          where="1 ORDER BY name, run_id")
    csv_path, json_path = store.out / "metrics.csv", store.out / "manifest.json"
    if not allow_fewer:
        lost = _previous_runs(json_path) - {row[0] for row in table}
        if lost:
            raise StoreError(f"{store.out}: the index lacks {len(lost)} of the runs the "
                             f"last export listed (e.g. {min(lost)}); metrics.csv and "
                             f"manifest.json kept; 'flexarm repair {store.out}' rebuilds "
                             "the index from runs/")
    selected = [*head, *(f"axis:{a}" for a in axes), *metrics]
    at: dict[str, int] = {}
    for i, name in enumerate(selected):  # the metric "status" is the identity's
        at.setdefault(name, i)
    blank = len(selected)  # the index of "" appended to a row: a column the run lacks
    columns: dict[str, None] = dict.fromkeys(IDENTITY_COLUMNS)  # first-seen order
    for set_id in dict.fromkeys(row[12] for row in table):  # layouts as rows first show them
        a_names, m_names = layouts[set_id]
        columns.update(dict.fromkeys(f"axis:{a}" for a in a_names))
        columns.update(dict.fromkeys(m for m in m_names if m != "status"))
    pickers = {}
    for set_id, (a_names, m_names) in layouts.items():
        has = {f"axis:{a}" for a in a_names} | set(m_names) | set(IDENTITY_COLUMNS)
        pickers[set_id] = operator.itemgetter(*(at[c] if c in has else blank
                                                for c in columns))
    # The table as text in slices, each in a worker (writing a float is most of an
    # export: 40,000 runs' 140 metrics), while this process writes the manifest.
    from ..executor import available_cores  # the run path: not for reading a folder
    slices = max(1, min(available_cores(), len(table) // _ROWS_A_WORKER))
    bounds = [len(table) * k // slices for k in range(slices + 1)]
    with beside([functools.partial(_csv_text, table, a, b, pickers)
                 for a, b in zip(bounds, bounds[1:])], progress=False) as written:
        # One run a line, each encoded by json's C encoder.
        fields = [at[f] for f in _MANIFEST]
        runs = ",\n".join(f"  {json.dumps(row[0])}: " + json.dumps(
            {k: row[i] for k, i in zip(_MANIFEST, fields) if row[i] not in ("", 0)})
            for row in table)
        text = (f'{{"campaigns": {json.dumps(store.campaigns())},\n"runs": {{\n'
                f'{runs}\n}}}}\n')
        body = written()
    head = io.StringIO()
    csv.writer(head, lineterminator="\n").writerow(columns)
    write_atomic(csv_path, lambda fh: fh.writelines([head.getvalue(), *body]))
    write_atomic(json_path, lambda fh: fh.write(text))
    return csv_path, json_path


def _csv_text(table: list, start: int, stop: int, pickers: dict) -> str:
    """Rows ``start`` to ``stop`` of ``table`` as metrics.csv's lines (each row's values
    picked by its metric set's picker)."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(
        pickers[row[12]]((*row, "")) for row in table[start:stop])
    return buf.getvalue()


def _previous_runs(manifest: Path) -> set[str]:
    """Run ids the manifest of the last export lists (none if there is none, or it cannot
    be read)."""
    try:  # a FIFO, a device or a giant in its place is not read: no previous export
        if not manifest.is_file() or manifest.stat().st_size > MAX_MANIFEST_BYTES:
            return set()
        runs = json.loads(manifest.read_text())["runs"]
    except (OSError, ValueError, KeyError, TypeError):
        return set()
    return {rid for rid in runs if is_run_id(rid)} if isinstance(runs, dict) else set()
