"""The SQLite index of a results folder: its schema, how it is opened (WAL, read-only
folders), one transaction helper, one row writer, and the JSON codecs of its columns.
Run ids live here too: the index is what they name runs in."""
from __future__ import annotations

import hashlib
import json
import math
import re
import sqlite3
import time
from contextlib import contextmanager
from pathlib import Path

__all__ = ["StoreError", "INDEX_NAME", "SCHEMA", "SCHEMA_VERSION", "COLUMNS", "JSON_COLUMNS", "BUSY_TIMEOUT", "run_id", "is_run_id",
           "set_wal", "transaction", "insert_row", "insert_rows", "row_values", "json_table", "finite_or_none",
           "metric_values", "RUN_ID", "set_aside"]

class StoreError(ValueError):
    """A results folder that cannot be used (one line naming the folder or file)."""


INDEX_NAME = "index.sqlite"
SCHEMA_VERSION = 1
SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS campaigns (name TEXT PRIMARY KEY, info TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    run_id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    campaign TEXT NOT NULL DEFAULT '',
    sweep TEXT NOT NULL DEFAULT '',
    axes TEXT NOT NULL DEFAULT '{}',
    status TEXT NOT NULL,
    message TEXT NOT NULL DEFAULT '',
    end_time REAL,
    fingerprint TEXT NOT NULL,
    scenario TEXT NOT NULL,
    metrics TEXT NOT NULL,
    timings TEXT NOT NULL DEFAULT '{}',
    environment TEXT NOT NULL DEFAULT '{}',
    file TEXT NOT NULL,
    sha256 TEXT NOT NULL,
    size INTEGER NOT NULL,
    finished TEXT NOT NULL
);
"""
COLUMNS = ("run_id", "name", "campaign", "sweep", "axes", "status", "message", "end_time",
            "fingerprint", "scenario", "metrics", "timings", "environment", "file", "sha256",
            "size", "finished")
JSON_COLUMNS = ("axes", "scenario", "metrics", "timings", "environment")
#: How long a writer waits for another process's transaction before giving up [s].
BUSY_TIMEOUT = 120.0
#: What `run_id` makes: 12 lowercase hex digits.
RUN_ID = re.compile(r"[0-9a-f]{12}")


def is_run_id(text) -> bool:
    """Whether ``text`` is a run id (12 lowercase hex digits): safe in a path."""
    return isinstance(text, str) and RUN_ID.fullmatch(text) is not None


def run_id(resolved_scenario: dict) -> str:
    """12 hex digits of the SHA-256 of the scenario's canonical JSON."""
    text = json.dumps(resolved_scenario, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]



def set_wal(db: sqlite3.Connection) -> None:
    """Switch ``db`` to a WAL journal.  SQLite refuses the switch with SQLITE_BUSY at once,
    without its busy handler, while another connection is making the same switch (two
    processes opening one new index together: 28 of 60 connections refused, measured),
    so it is retried here until `BUSY_TIMEOUT`."""
    deadline = time.monotonic() + BUSY_TIMEOUT
    while True:
        try:
            db.execute("PRAGMA journal_mode=WAL")
            return
        except sqlite3.OperationalError as exc:
            if exc.sqlite_errorname != "SQLITE_BUSY" or time.monotonic() > deadline:
                raise
            time.sleep(0.005)



@contextmanager
def transaction(db: sqlite3.Connection, *, commit: bool = True):
    """A write transaction on ``db`` (``BEGIN IMMEDIATE``: the index's write lock, waited
    for up to `BUSY_TIMEOUT`), committed at the end (rolled back instead if ``commit`` is
    false: a read under the write lock), rolled back on any exception."""
    db.execute("BEGIN IMMEDIATE")
    try:
        yield db
    except BaseException:
        db.execute("ROLLBACK")
        raise
    db.execute("COMMIT" if commit else "ROLLBACK")


def row_values(row: dict) -> tuple:
    """A run's row as the index stores it: its `COLUMNS` in order, JSON columns encoded
    (done where the run was made: the process inserting rows only inserts them)."""
    return tuple(json.dumps(row[c], allow_nan=False) if c in JSON_COLUMNS else row[c]
                 for c in COLUMNS)


_INSERT = (f"INSERT OR REPLACE INTO runs ({', '.join(COLUMNS)}) VALUES "
           f"({', '.join('?' * len(COLUMNS))})")


def insert_rows(db: sqlite3.Connection, rows: list[tuple]) -> None:
    """Write runs' rows (`row_values`), replacing older rows of the same ids."""
    db.executemany(_INSERT, rows)


def insert_row(db: sqlite3.Connection, row: dict) -> None:
    """Write one run's row (replacing an older row of the same id)."""
    insert_rows(db, [row_values(row)])


def json_table(text):
    """A JSON column's value; ValueError unless it is JSON of the kind the store writes."""
    value = json.loads(text)
    if not isinstance(value, dict):
        raise ValueError("a JSON column is not a table")
    return value



#: JSON has no infinities: a metric of ±∞ (a requirement's robustness can be: ``always``
#: over an empty window, a claim's "never") is stored as one of these strings.
_INFINITIES = {"inf": math.inf, "-inf": -math.inf}


def finite_or_none(metrics: dict) -> dict:
    """JSON has no NaN/inf: NaN is stored as null (read back as NaN), ±∞ as "inf"/"-inf"
    (read back as floats by `metric_values`)."""
    return {k: (None if math.isnan(v) else repr(v)) if isinstance(v, float)
            and not math.isfinite(v) else v for k, v in metrics.items()}


def metric_values(stored: dict) -> dict:
    """Metrics as read from the index: null → NaN, "inf"/"-inf" → ±∞."""
    return {k: math.nan if v is None else _INFINITIES.get(v, v) if isinstance(v, str) else v
            for k, v in stored.items()}


def set_aside(path: Path) -> Path:
    """Rename ``path`` (a file, a folder or a link: never followed) to the first free
    ``<name>.damaged[.k]`` beside it; returns the new path."""
    for k in range(1000):
        new = path.with_name(path.name + ".damaged" + (f".{k}" if k else ""))
        if not (new.exists() or new.is_symlink()):
            path.replace(new)
            return new
    raise StoreError(f"{path}: cannot be set aside (1000 damaged copies beside it)")
