"""A results folder: an SQLite index of every run, and a file per run that keeps signals.

    OUT/index.sqlite        one row per run: id, name, campaign, sweep, status, message,
                            code fingerprint, what tables show of its scenario, every metric
                            and swept value in a typed column of its own, the scenario,
                            timings and environment compressed (decoded on demand), and
                            the run file's SHA-256 and size (`validation.batch.store.index`; WAL
                            journal; rows committed in batches: `validation.batch.store.committing`)
    OUT/runs/<run_id>.npz   signals (float32) and the same metadata (`RunResult.to_bytes`):
                            a file alone is enough to rebuild its row (`repair`).  A run
                            that keeps metrics only has no file: its row holds all of it.
    OUT/metrics.csv         exports, written from the index (`export`)
    OUT/manifest.json       (read back only to refuse an export that would lose runs)

Writers: any number of processes may store runs into one folder at once — SQLite
serialises their transactions, so every row arrives (the run file is written first, by
the worker that made the run, under a temporary name, then renamed; its row is committed
after, by the command: `validation.batch.store.writing`, `validation.batch.store.committing`).

The store trusts nothing it reads.  A row's run id must be 12 hex digits and its file
``runs/<id>.npz`` (or none) before either touches a path (else the index is refused, and
`repair` drops the row).  A run whose file is missing, not a regular file, of the wrong
size or checksum, or whose scenario does not hash to its id is *damaged*: reported by
id, never used, redone on resume.  A run file is adopted (by resume or `repair`) only if
its own scenario hashes to its name.  An index SQLite cannot read — a corrupt page, a
truncated or empty file — is named with the cure (`repair`, which rebuilds it from the
run files whatever the damage); a full disk and a read-only folder are named as such (a
healthy read-only folder can still be read).  Nothing here imports a plug-in or runs a
simulation.  The run id is a hash of the resolved scenario; the row also records the code
fingerprint (`validation.batch.fingerprint`), so a result made by other code is *stale*
and is not reused.

This module reads and writes through `BaseStore`'s methods; rebuilding the index
(`validation.batch.store.repair`) and the exports (`validation.batch.store.export`) use only them.
"""
from __future__ import annotations

import errno
import functools
import gc
import hashlib
import json
import os
import sqlite3
import time
from contextlib import contextmanager
from pathlib import Path

from ...run.results import STATUSES, LinkedFolder, RunResult, own_folder
from . import export, repair
from .base import BaseStore
from .errors import IndexBusy, IndexDamaged, ReadOnlyFolder, StoreError
from .index import (BUSY_TIMEOUT, INDEX_NAME, SCHEMA, SCHEMA_VERSION, dictionary_key,
                    insert_rows, is_run_id, json_table, metric_sets, mistyped, not_a_number,
                    open_read_only, reading, row_values, run_id, set_wal, transaction)
from ..provenance import environment
from .records import StoredRun, records
from .runfiles import write_run

__all__ = ["ResultStore", "StoredRun", "StoreError", "run_id", "is_run_id", "environment",
           "INDEX_NAME"]

def _sqlite_errors(method):
    """``method`` with SQLite's errors turned into what they mean here (`ResultStore.error`):
    one line naming the folder."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.Error as exc:
            raise self.error(exc) from None
    return wrapper


class ResultStore(BaseStore):
    """Reads and writes one results folder (created on the first write).

    Parameters
    ----------
    out : str or pathlib.Path
        The results folder: ``index.sqlite`` and ``runs/``.
    """

    def __init__(self, out: str | Path) -> None:
        self._out = Path(out)
        self.runs_dir = self._out / "runs"
        self.index_path = self._out / INDEX_NAME
        self._db: sqlite3.Connection | None = None
        self._dictionaries: dict[str, bytes] = {}

    out = property(lambda self: self._out, doc="The results folder.")

    # --- the database ------------------------------------------------------------------
    def exists(self) -> bool:
        return self.index_path.is_file()

    def connection(self, *, create: bool) -> sqlite3.Connection:
        """The connection to the index; ``create``: create the folder and the index if
        they do not exist (a writer), else the index must exist (a reader, who can also
        read a read-only folder).  sqlite3.Error as SQLite raises it (`error` says what
        it means)."""
        if self._db is not None:
            return self._db
        if not create:
            self.check()
        self._check_layout()
        if create:
            self.out.mkdir(parents=True, exist_ok=True)
            try:
                own_folder(self.out, "runs")
            except LinkedFolder as exc:
                raise StoreError(str(exc)) from None
        try:
            db = self._open()
        except sqlite3.Error as exc:
            if create or (self.writable() and not self._disk_full()):
                raise self.error(exc) from None
            try:  # a healthy folder, read-only or on a full disk: still readable
                db = open_read_only(self.index_path)
            except sqlite3.Error:
                raise self.error(exc) from None
        self._db = db
        return db

    def check(self) -> None:
        """StoreError unless this is a results folder that can be read (its own index and
        runs/, no links in their place)."""
        self._check_layout()
        if not self.exists():  # the repair suggested only where it has run files to read
            why = (f"no {INDEX_NAME}; 'flexarm repair {self.out}' rebuilds it from runs/"
                   if self.runs_dir.is_dir() else
                   f"no {INDEX_NAME}, no runs/" if self.out.is_dir() else "no such folder")
            raise StoreError(f"{self.out}: not a results folder ({why})")

    def _check_layout(self) -> None:
        """The folder's own files are its own: the index and runs/ are no symbolic links
        (reading or writing would go through them, out of the folder), and the index is a
        file (StoreError naming what to move away otherwise)."""
        for path in (self.index_path, self.runs_dir):
            if path.is_symlink():
                raise StoreError(f"{path}: a symbolic link where the results folder keeps "
                                 "its own; nothing is read or written through it")
        if self.index_path.exists() and not self.index_path.is_file():
            raise StoreError(f"{self.index_path}: not a file; move it away, then "
                             f"'flexarm repair {self.out}' rebuilds the index from runs/")

    def _open(self) -> sqlite3.Connection:
        existed = self.exists()
        db = sqlite3.connect(self.index_path, timeout=BUSY_TIMEOUT, isolation_level=None)
        try:
            set_wal(db)
            # NORMAL: a transaction is durable once the WAL is checkpointed; an
            # application crash never loses a committed run, a power cut may lose the
            # last ones (they are then redone on resume).
            db.execute("PRAGMA synchronous=NORMAL")
            tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master")}
            if "runs" not in tables and existed and self.run_files():
                # An index without its table (an empty or truncated file) next to run
                # files: not a new index but a lost one — never read as "no runs".
                raise sqlite3.DatabaseError("the index holds no table of runs")
            if "meta" in tables:
                found = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
                if found and found[0] != str(SCHEMA_VERSION):
                    raise StoreError(
                        f"{self.index_path}: index schema {found[0]}, this version reads "
                        f"{SCHEMA_VERSION}; 'flexarm repair {self.out}' rebuilds the index "
                        "from the run files")
            db.executescript(SCHEMA)
            db.execute("INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (str(SCHEMA_VERSION),))
        except BaseException:
            db.close()
            raise
        return db

    def writable(self) -> bool:
        """Whether this process may write into the folder (and its runs/)."""
        return os.access(self.out, os.W_OK) and (not self.runs_dir.exists()
                                                 or os.access(self.runs_dir, os.W_OK))

    def run_files(self) -> list[Path]:
        """Every ``runs/*.npz`` entry, sorted (whatever it is: `unindexed_files` keeps
        the run files)."""
        return sorted(self.runs_dir.glob("*.npz")) if self.runs_dir.is_dir() else []

    def _disk_full(self) -> bool:
        try:
            return os.statvfs(self.out).f_bavail == 0
        except (OSError, AttributeError):  # no folder yet, or no statvfs (Windows)
            return False

    def error(self, exc: sqlite3.Error) -> Exception:
        """What an SQLite error means here, as one line naming the folder: a full disk
        (`OSError` ENOSPC), a read-only folder, a busy index, or a damaged index and its
        cure."""
        name = getattr(exc, "sqlite_errorname", "") or ""
        if name == "SQLITE_FULL" or (self._disk_full() and name.startswith(
                ("SQLITE_IOERR", "SQLITE_CANTOPEN"))):
            return OSError(errno.ENOSPC, "No space left on device", str(self.out))
        if not self.writable():
            return ReadOnlyFolder(f"{self.out}: read-only, runs cannot be stored here ({exc})")
        if name == "SQLITE_BUSY":
            return IndexBusy(f"{self.index_path}: busy: another process kept it locked for "
                             f"{BUSY_TIMEOUT:g} s ({exc})")
        return IndexDamaged(f"{self.index_path}: the index is damaged ({exc}); "
                            f"'flexarm repair {self.out}' rebuilds it from runs/")

    @contextmanager
    def locked(self):
        """Hold the index's write lock while the caller reads (nothing is written: of two
        processes exporting at once, the later one reads every row the earlier wrote)."""
        try:
            with transaction(self.connection(create=False), commit=False):
                yield self
        except sqlite3.Error as exc:
            raise self.error(exc) from None

    def close(self) -> None:
        if self._db is not None:
            try:
                self._db.close()
            except sqlite3.Error:
                pass  # a damaged index: nothing left to save
            self._db = None

    def prepare(self) -> None:
        """Create the folder and its index (StoreError naming the folder if it cannot)."""
        try:
            self.connection(create=True)
        except OSError as exc:
            if exc.errno == errno.ENOSPC:
                raise
            raise StoreError(f"{self.out}: cannot create the results folder "
                             f"({exc.strerror or exc})") from None

    # --- writing ------------------------------------------------------------------------
    @_sqlite_errors
    def add(self, rid: str, result: RunResult, metrics: dict, *, campaign: str = "",
            sweep: str = "", axes: dict | None = None, env: dict | None = None) -> Path:
        """Store one run: its file (`runfiles.write_run`: written under a temporary name,
        then renamed), then its row (replacing an older row of the same id)."""
        if not is_run_id(rid):
            raise StoreError(f"{rid!r} is not a run id (12 hex digits)")
        db = self.connection(create=True)
        row = write_run(self.out, rid, result, metrics, campaign=campaign, sweep=sweep,
                        axes=axes, env=env or environment())
        with transaction(db):
            insert_rows(db, [row_values(row)])
        return self.out / row["file"]

    @_sqlite_errors
    def insert(self, rows: list[tuple]) -> None:
        with transaction(self.connection(create=True)) as db:
            insert_rows(db, rows)

    @_sqlite_errors
    def add_dictionary(self, data: bytes) -> str:
        """Keep a preset dictionary of rows' details (`index.dictionary_for`); its key."""
        key = dictionary_key(data)
        with transaction(self.connection(create=True)) as db:
            db.execute("INSERT OR IGNORE INTO dictionaries VALUES (?, ?)", (key, data))
            (kept,) = db.execute("SELECT data FROM dictionaries WHERE key = ?",
                                 (key,)).fetchone()
        if kept != data:
            raise IndexDamaged(f"{self.index_path}: dictionary {key} differs from its key")
        return key

    @_sqlite_errors
    def set_campaign(self, name: str, info: dict) -> None:
        with transaction(self.connection(create=True)) as db:
            old = db.execute("SELECT info FROM campaigns WHERE name = ?", (name,)).fetchone()
            merged = {**(json_table(old[0]) if old else {}), **info}
            db.execute("INSERT OR REPLACE INTO campaigns VALUES (?, ?)", (name, json.dumps(merged)))

    @_sqlite_errors
    def discard(self, ids) -> None:
        """Delete the rows of ``ids`` (their files, if any, are left where they are), and
        the metric sets no row has any more."""
        with transaction(self.connection(create=True)) as db:
            db.executemany("DELETE FROM runs WHERE run_id = ?", [(i,) for i in ids])
            db.execute("DELETE FROM metric_sets WHERE id NOT IN (SELECT metric_set FROM runs)")

    def remove_stale_temporaries(self, older_than: float = 3600.0) -> int:
        """Delete temporary files a killed writer left behind more than ``older_than``
        seconds ago (younger ones may belong to a writer still running)."""
        now, removed = time.time(), 0
        for path in [*self.out.glob(".*.tmp"), *self.runs_dir.glob(".*.tmp")]:
            try:
                if path.is_file() and now - path.stat().st_mtime > older_than:
                    path.unlink()
                    removed += 1
            except FileNotFoundError:
                pass
        return removed

    # --- reading ------------------------------------------------------------------------
    def _dictionary(self, db, key: str) -> bytes:
        if key and key not in self._dictionaries:
            found = db.execute("SELECT data FROM dictionaries WHERE key = ?", (key,)).fetchone()
            if found is None:
                raise ValueError(f"its detail's dictionary {key[:20]!r} is not in the index")
            self._dictionaries[key] = found[0]
        return self._dictionaries.get(key, b"")

    def scan(self, *, where: str = "", params: tuple = (), metrics=None, order: str = ""):
        """(run id, `StoredRun` or why the row is not a stored run) of every row, in no
        order (or SQL's ``ORDER BY order``): what `rows` refuses, `repair` drops;
        ``metrics``: as `rows`'."""
        db = self.connection(create=False)
        try:
            columns, sets = reading(db, metrics)
            cursor = db.execute(f"SELECT {columns} FROM runs "
                                f"{'WHERE ' + where if where else ''}"
                                f"{' ORDER BY ' + order if order else ''}", params)
            yield from records(cursor, sets, lambda key: self._dictionary(db, key))
        except sqlite3.Error as exc:
            raise self.error(exc) from None

    def rows(self, *, where: str = "", params: tuple = (), metrics=None) -> list[StoredRun]:
        """Index rows (``where`` is an SQL condition on the columns, nothing after it:
        `index.metric_column` names a metric's), sorted by name and id; with only the ``metrics`` named (None: every
        one; reading 10^5 runs' ~140 metrics each is most of reading their rows).  A row
        whose id or file could name a path outside runs/, or whose contents are not what
        the store writes, is refused (StoreError naming it and the cure)."""
        out = []
        collecting = gc.isenabled()
        gc.disable()  # rows are no cyclic garbage: no pass over 10^5 of them while read
        try:
            # sorted by SQLite: 0.15 s less than sorting 40,000 rows here
            for rid, row in self.scan(where=where, params=params, metrics=metrics,
                                      order="name, run_id"):
                if isinstance(row, str):
                    raise self._not_a_stored_run(rid, row)
                out.append(row)
        finally:
            if collecting:
                gc.enable()
        return out

    @_sqlite_errors
    def check_pages(self) -> None:
        """`IndexDamaged` unless SQLite finds every page of the index sound
        (``PRAGMA quick_check``: a damaged page a query does not read is found too)."""
        found = self.connection(create=False).execute("PRAGMA quick_check(1)").fetchone()[0]
        if found != "ok":
            found = " ".join(found.replace("*** in database main ***", "").split())
            raise IndexDamaged(f"{self.index_path}: the index is damaged ({found}); "
                               f"'flexarm repair {self.out}' rebuilds it from runs/")

    def refuse_malformed(self) -> None:
        """`IndexDamaged` naming the first row that is not a stored run, checked in SQL
        (what `StoredRun.check` checks of every row, without reading them into Python)."""
        statuses, typed = ", ".join(f"'{s}'" for s in STATUSES), mistyped(self.column_names())
        bad = self.columns(["run_id", typed, mistyped(self.column_names(), value=True)], where=(
            "typeof(run_id) != 'text' OR length(run_id) != 12 OR run_id GLOB '*[^0-9a-f]*' "
            f"OR status NOT IN ({statuses}) OR (file != '' AND (file != 'runs/' || run_id "
            "|| '.npz' OR typeof(size) != 'integer' OR size <= 0 OR length(sha256) != 64)) "
            f"OR metric_set NOT IN (SELECT id FROM metric_sets) OR {typed} IS NOT NULL LIMIT 1"))
        if bad:
            (rid, column, value), = bad
            raise self._not_a_stored_run(rid, column and not_a_number(column, value))

    def _not_a_stored_run(self, rid, why: str | None) -> IndexDamaged:
        return IndexDamaged(f"{self.index_path}: row {str(rid)[:40]!r} is not a stored run"
                            f"{f' ({why})' if why else ''}; 'flexarm repair {self.out}' drops "
                            "it (and indexes its run file again, if intact)")

    def rows_of(self, ids) -> list[StoredRun]:
        """The rows of the runs ``ids`` that the index holds (queried by id, in chunks: a
        search asking for a few runs of a large folder reads only those)."""
        ids = list(dict.fromkeys(ids))
        out = []
        for i in range(0, len(ids), 500):  # SQLite's limit on parameters is 999 or more
            chunk = tuple(ids[i:i + 500])
            out += self.rows(where=f"run_id IN ({', '.join('?' * len(chunk))})", params=chunk)
        return out

    @_sqlite_errors
    def columns(self, names, *, where: str = "", params: tuple = ()) -> list[tuple]:
        """The values of the index's columns ``names`` (quoted identifiers, e.g.
        `index.metric_column`) of every row (or those ``where`` selects), as tuples:
        a table of many runs read without building a record per run."""
        db = self.connection(create=False)
        sql = f"SELECT {', '.join(names)} FROM runs {'WHERE ' + where if where else ''}"
        return db.execute(sql, params).fetchall()

    @_sqlite_errors
    def layouts(self) -> dict[int, tuple[tuple, tuple]]:
        """``metric_set`` id → (swept names, metric names), each in its runs' order."""
        found = metric_sets(self.connection(create=False))
        for why in (s for s in found.values() if isinstance(s, str)):
            raise IndexDamaged(f"{self.index_path}: {why}; 'flexarm repair {self.out}' "
                               "rebuilds the index from the run files")
        return found

    @_sqlite_errors
    def column_names(self) -> list[str]:
        """The index's columns (metrics ``m:<name>``, swept values ``a:<name>``)."""
        return [row[1] for row in self.connection(create=False).execute(
            "PRAGMA table_info(runs)")]

    @_sqlite_errors
    def campaigns(self) -> dict[str, dict]:
        db = self.connection(create=False)
        out = {}
        for name, info in db.execute("SELECT * FROM campaigns"):
            try:
                out[name] = json_table(info)
            except ValueError:
                out[name] = {}  # descriptive only: a damaged entry is left out
        return out

    def read(self, rid: str) -> tuple[RunResult, dict]:
        row = self.row(rid)
        if row is None:
            raise StoreError(f"{self.out}: no run {rid}")
        if not row.has_file:  # metrics only: the row is all of it
            return self._from_row(row), {"kept": row.kept or {}}
        try:
            return RunResult.from_bytes(self._verified_bytes(row))
        except ValueError as exc:
            raise StoreError(f"run {row.run_id}: {self.out / row.file}: {exc}") from None

    @staticmethod
    def _from_row(row: StoredRun) -> RunResult:
        import numpy as np
        try:
            return RunResult(time=np.zeros(0), names=(), signals=np.zeros((0, 0), np.float32),
                             status=row.status, message=row.message, end_time=row.end_time,
                             config=row.config, timings=row.timings)
        except ValueError as exc:
            raise IndexDamaged(f"run {row.run_id}: {exc}") from None

    def _verified_bytes(self, row: StoredRun) -> bytes:
        path = self.out / row.file
        try:  # a FIFO, a device or a sparse giant in its place is never read
            if not path.is_file() or path.stat().st_size != row.size:
                raise StoreError(f"run {row.run_id}: {path} is damaged (not a regular file "
                                 "of the size the index records)")
            data = path.read_bytes()
        except OSError as exc:
            raise StoreError(f"run {row.run_id}: {path} unreadable ({exc.strerror or exc})") from None
        if len(data) != row.size or hashlib.sha256(data).hexdigest() != row.sha256:
            raise StoreError(f"run {row.run_id}: {path} is damaged (size or checksum differs "
                             "from the index)")
        return data

    def verify(self, rows: list[StoredRun] | None = None, *, checksum: bool = True) -> dict[str, str]:
        """run id → why it is damaged, for every row whose scenario does not hash to its
        id, or whose file is missing, not a regular file, of the wrong size, or (with
        ``checksum``) of the wrong SHA-256."""
        damaged = {}
        for row in self.rows() if rows is None else rows:
            try:
                text = row.scenario_text
            except ValueError as exc:
                damaged[row.run_id] = str(exc)
                continue
            if hashlib.sha256(text.encode()).hexdigest()[:12] != row.run_id:
                damaged[row.run_id] = "its scenario does not hash to its id"
                continue
            if not row.has_file:
                continue
            path = self.out / row.file
            try:
                info = path.stat()
            except OSError:
                damaged[row.run_id] = "file missing"
                continue
            if not path.is_file():
                damaged[row.run_id] = "not a regular file"
            elif info.st_size != row.size:
                damaged[row.run_id] = f"file size {info.st_size} != {row.size}"
            elif checksum:
                with path.open("rb") as fh:
                    digest = hashlib.file_digest(fh, "sha256").hexdigest()
                if digest != row.sha256:
                    damaged[row.run_id] = "checksum differs"
        return damaged

    def unindexed_files(self) -> list[Path]:
        """Run files (regular files named ``<run id>.npz``) with no row in the index
        (e.g. a row lost with a deleted index)."""
        known = {f for (f,) in self.columns(["file"])} if self.exists() else set()
        return [p for p in self.run_files()
                if p.is_file() and is_run_id(p.stem) and f"runs/{p.name}" not in known]

    # --- repair and export ----------------------------------------------------------------
    def repair(self) -> dict[str, list[str]]:
        """Rebuild the index from the run files, whatever the damage (`repair.repair`)."""
        return repair.repair(self)

    def adopt(self, path: Path) -> StoredRun:
        """Index a run file that has no row (`repair.adopt`); `NotARunFile` if it is not
        an intact run file of its name."""
        return repair.adopt(self, path)

    def export(self, *, allow_fewer: bool = False) -> tuple[Path, Path]:
        """Write metrics.csv and manifest.json from the index (`export.export`)."""
        return export.export(self, allow_fewer=allow_fewer)
