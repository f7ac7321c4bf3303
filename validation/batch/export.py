"""Exports of a results folder: ``metrics.csv`` (one row per run: what was run, swept
values, status, every metric) and ``manifest.json``, written from the index."""
from __future__ import annotations

import csv
import io
import json
import sqlite3
from pathlib import Path

from ..run.results import write_atomic
from .index import StoreError, is_run_id, transaction

__all__ = ["export", "export_row", "IDENTITY_COLUMNS"]

#: The largest manifest read back (~1 KB a run: 10⁵ runs are ~100 MB).
MAX_MANIFEST_BYTES = 1 << 30


def export(store, *, allow_fewer: bool = False) -> tuple[Path, Path]:
    """Write metrics.csv (one row per run: identity, what was run, swept values,
    status, every metric) and manifest.json from the index, holding its write lock
    (of two processes exporting at once, the later one reads every row the earlier
    one wrote).  An index that lacks runs the previous export listed (a damaged
    index reads as fewer runs) is refused (StoreError, the old export kept) unless
    ``allow_fewer`` (after `repair`, which says what it dropped)."""
    db = store._connect(create=False)
    if not store.writable():
        raise StoreError(f"{store.out}: read-only, metrics.csv and manifest.json cannot "
                         "be written here")
    try:
        with transaction(db, commit=False):  # the write lock; nothing is written to it
            return _export(store, allow_fewer)
    except sqlite3.Error as exc:
        raise store._error(exc) from None


def _export(store, allow_fewer: bool) -> tuple[Path, Path]:
    rows = store.rows()
    csv_path, json_path = store.out / "metrics.csv", store.out / "manifest.json"
    if not allow_fewer:
        lost = _previous_runs(json_path) - {r.run_id for r in rows}
        if lost:
            raise StoreError(f"{store.out}: the index lacks {len(lost)} of the runs the "
                             f"last export listed (e.g. {min(lost)}); metrics.csv and "
                             f"manifest.json kept; 'flexarm repair {store.out}' rebuilds "
                             "the index from runs/")
    table = [export_row(r) for r in rows]
    columns: dict[str, None] = {}  # first-seen order; a list would be quadratic
    for r in table:
        columns.update(dict.fromkeys(r))
    buf = io.StringIO()
    # csv writes None as "" and a float as its repr ("nan" too); every key is a column.
    writer = csv.DictWriter(buf, fieldnames=columns, restval="", lineterminator="\n",
                            extrasaction="ignore")
    writer.writeheader()
    writer.writerows(table)
    write_atomic(csv_path, lambda fh: fh.write(buf.getvalue()))
    # One run a line, each encoded by json's C encoder (an indented dump goes through
    # its pure-Python one: ~30x slower, 3 s for 10^4 runs).
    runs = ",\n".join(f"  {json.dumps(r.run_id)}: " + json.dumps(
        {"name": r.name, "campaign": r.campaign, "sweep": r.sweep, "axes": r.axes,
         "status": r.status, "message": r.message, "end_time": r.end_time,
         "fingerprint": r.fingerprint, "timings": r.timings, "environment": r.environment,
         "file": r.file, "sha256": r.sha256, "size": r.size, "finished": r.finished})
        for r in rows)
    text = (f'{{"campaigns": {json.dumps(store.campaigns())},\n"runs": {{\n'
            f'{runs}\n}}}}\n')
    write_atomic(json_path, lambda fh: fh.write(text))
    return csv_path, json_path


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


#: Columns of metrics.csv that say what was run, before the swept values and metrics.
IDENTITY_COLUMNS = ("run_id", "name", "campaign", "sweep", "arm", "plant", "controller",
                    "observer", "Ts", "initial_state", "status", "message")


def export_row(r) -> dict:
    """A stored run as a row of metrics.csv."""
    c = r.config
    out = {"run_id": r.run_id, "name": r.name, "campaign": r.campaign, "sweep": r.sweep,
           "arm": c.get("arm", "default"), "plant": r.plant,
           "controller": c.get("controller", {}).get("kind", ""),
           "observer": c.get("observer", {}).get("kind", ""), "Ts": c.get("Ts"),
           "initial_state": c.get("initial_state", ""), "status": r.status,
           "message": r.message}
    out |= {f"axis:{k}": json.dumps(v) if isinstance(v, (list, dict)) else v
            for k, v in r.axes.items()}
    out |= {k: v for k, v in r.metrics.items() if k != "status"}
    return out

