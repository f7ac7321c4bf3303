"""A results folder: one signal file per run, indexed by an SQLite database.

    OUT/index.sqlite        one row per run: id, name, campaign, sweep and swept values,
                            status, message, timings, versions, code fingerprint, the
                            resolved scenario, every metric, and the run file's SHA-256 and
                            size (WAL journal; rows committed in batches:
                            `validation.batch.committing`)
    OUT/runs/<run_id>.npz   signals (float32) and the same metadata (`RunResult.to_bytes`):
                            a file alone is enough to rebuild its row (`repair`)
    OUT/metrics.csv         exports, written from the index (`export`)
    OUT/manifest.json       (read back only to refuse an export that would lose runs)

Writers: any number of processes may store runs into one folder at once — SQLite
serialises their transactions, so every row arrives (the run file is written first, by
the worker that made the run, under a temporary name, then renamed; its row is committed
after, by the command: `validation.batch.storing`, `validation.batch.committing`).

The store trusts nothing it reads.  A row's run id must be 12 hex digits and its file
``runs/<id>.npz`` before either touches a path (else the index is refused, and `repair`
drops the row).  A run whose file is missing, not a regular file, of the wrong size or
checksum, or whose scenario does not hash to its id is *damaged*: reported by id, never
used, redone on resume.  A run file is adopted (by resume or `repair`) only if its own
scenario hashes to its name.  An index SQLite cannot read — a corrupt page, a truncated
or empty file — is named with the cure (`repair`, which rebuilds it from the run files
whatever the damage); a full disk and a read-only folder are named as such (a healthy
read-only folder can still be read).  Nothing here imports a plug-in.  The run id is a
hash of the resolved scenario; the row also records the code fingerprint
(`validation.batch.fingerprint`), so a result made by other code is *stale* and is not reused.

This module reads and writes; the index itself (schema, transactions, rows) is
`validation.batch.index`, a run's file `validation.batch.runfiles`, rebuilding the index
`validation.batch.repair`, the exports `validation.batch.export`.
"""
from __future__ import annotations

import errno
import functools
import hashlib
import json
import os
import platform
import sqlite3
import subprocess
import time
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from ..run.results import STATUSES, LinkedFolder, RunResult, own_folder
from . import export, repair
from .index import (BUSY_TIMEOUT, COLUMNS, INDEX_NAME, JSON_COLUMNS, SCHEMA, SCHEMA_VERSION,
                    StoreError, insert_row, insert_rows, is_run_id, json_table, metric_values,
                    run_id, set_wal, transaction)
from .resimulate import full_result
from .runfiles import write_run

__all__ = ["ResultStore", "StoredRun", "StoreError", "run_id", "is_run_id", "environment",
           "INDEX_NAME"]


@functools.lru_cache(maxsize=1)
def environment() -> dict:
    """Versions and git revision recorded with every run."""
    def pkg(name):
        try:
            return version(name)
        except PackageNotFoundError:
            return None
    from ..run.plants import ENGINE_PACKAGES
    env = {name: pkg(name) for name in ("flexarm-validation", *ENGINE_PACKAGES, "numpy",
                                        "numba", "scipy")}
    env["python"] = platform.python_version()
    try:
        env["git"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                    text=True, timeout=5, cwd=Path(__file__).parent
                                    ).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        env["git"] = None
    return env



@dataclass
class StoredRun:
    """One row of the index.  ``load()`` reads and verifies the run's file (every signal,
    re-simulated where the file keeps less)."""

    run_id: str
    name: str
    status: str
    message: str
    end_time: float | None
    fingerprint: str
    config: dict
    metrics: dict
    campaign: str = ""
    sweep: str = ""
    axes: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    environment: dict = field(default_factory=dict)
    file: str = ""
    sha256: str = ""
    size: int = 0
    finished: str = ""
    store: "ResultStore | None" = field(default=None, repr=False, compare=False)

    def load(self) -> RunResult:
        """Every signal of the run at every sample: from its file, or re-simulated where
        the file keeps less (`validation.batch.resimulate.full_result`)."""
        return full_result(self)

    @property
    def plant(self) -> str:
        return self.config.get("plant", {}).get("kind", "?")

    @property
    def role(self) -> str:
        """"truth" or "reduced" (`validation.run.plants.role_of`: no code imported)."""
        from ..run.plants import role_of
        return role_of(self.config)

    @property
    def plant_label(self) -> str:
        """How tables and figures name the run's plant."""
        from ..run.plants import label_of
        return label_of(self.config)



def _sqlite_errors(method):
    """``method`` with SQLite's errors turned into what they mean here
    (`ResultStore._error`): one line naming the folder."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.Error as exc:
            raise self._error(exc) from None
    return wrapper



class ResultStore:
    """Reads and writes one results folder (created on the first write).

    Parameters
    ----------
    out : str or pathlib.Path
        The results folder: ``index.sqlite`` and ``runs/``.
    """

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.runs_dir = self.out / "runs"
        self.index_path = self.out / INDEX_NAME
        self._db: sqlite3.Connection | None = None

    # --- the database ------------------------------------------------------------------
    def exists(self) -> bool:
        return self.index_path.is_file()

    def _connect(self, create: bool) -> sqlite3.Connection:
        """The connection to the index; ``create``: create the folder and the index if
        they do not exist (a writer), else the index must exist (a reader, who can also
        read a read-only folder)."""
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
                raise self._error(exc) from None
            try:  # a healthy folder, read-only or on a full disk: still readable
                db = self._open_read_only()
            except sqlite3.Error:
                raise self._error(exc) from None
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
            # last ones (they are then redone on resume: their files fail verification).
            db.execute("PRAGMA synchronous=NORMAL")
            tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master")}
            if "runs" not in tables and existed and self._run_files():
                # An index without its table (an empty or truncated file) next to run
                # files: not a new index but a lost one — never read as "no runs".
                raise sqlite3.DatabaseError("the index holds no table of runs")
            db.executescript(SCHEMA)
            db.execute("INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (str(SCHEMA_VERSION),))
            (schema,) = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
        except BaseException:
            db.close()
            raise
        if schema != str(SCHEMA_VERSION):
            db.close()
            raise StoreError(f"{self.index_path}: index schema {schema}, this version reads "
                             f"{SCHEMA_VERSION}; 'flexarm repair {self.out}' rebuilds the index "
                             "from the run files")
        return db

    def _open_read_only(self) -> sqlite3.Connection:
        """The index of a folder SQLite cannot write its shared-memory file into
        (read-only, or on a full disk).  With no WAL journal (or an empty one) every
        committed run is in the index itself, which no writer can change there: opened
        as immutable (SQLite needs no shared-memory file then)."""
        wal = Path(f"{self.index_path}-wal")
        if wal.exists() and wal.stat().st_size > 0:
            raise sqlite3.OperationalError("read-only folder whose journal (-wal) holds "
                                           "runs not yet in the index")
        uri = f"{self.index_path.resolve().as_uri()}?immutable=1"
        db = sqlite3.connect(uri, uri=True, isolation_level=None)
        try:
            tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master")}
            if "runs" not in tables:
                raise sqlite3.DatabaseError("the index holds no table of runs")
        except BaseException:
            db.close()
            raise
        return db

    def writable(self) -> bool:
        """Whether this process may write into the folder (and its runs/)."""
        return os.access(self.out, os.W_OK) and (not self.runs_dir.exists()
                                                 or os.access(self.runs_dir, os.W_OK))

    def _run_files(self) -> list[Path]:
        return sorted(self.runs_dir.glob("*.npz")) if self.runs_dir.is_dir() else []

    def _disk_full(self) -> bool:
        try:
            return os.statvfs(self.out).f_bavail == 0
        except (OSError, AttributeError):  # no folder yet, or no statvfs (Windows)
            return False

    def _error(self, exc: sqlite3.Error) -> Exception:
        """What an SQLite error means here, as one line naming the folder: a full disk
        (`OSError` ENOSPC), a read-only folder, or a damaged index and its cure."""
        name = getattr(exc, "sqlite_errorname", "") or ""
        if name == "SQLITE_FULL" or (self._disk_full() and name.startswith(
                ("SQLITE_IOERR", "SQLITE_CANTOPEN"))):
            return OSError(errno.ENOSPC, "No space left on device", str(self.out))
        if not self.writable():
            return StoreError(f"{self.out}: read-only, runs cannot be stored here ({exc})")
        if name == "SQLITE_BUSY":
            return StoreError(f"{self.index_path}: busy: another process kept it locked for "
                              f"{BUSY_TIMEOUT:g} s ({exc})")
        return StoreError(f"{self.index_path}: the index is damaged ({exc}); "
                          f"'flexarm repair {self.out}' rebuilds it from runs/")

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
            self._connect(create=True)
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
        db = self._connect(create=True)
        row = write_run(self.out, rid, result, metrics, campaign=campaign, sweep=sweep,
                        axes=axes, env=env or environment())
        insert_row(db, row)
        return self.out / row["file"]

    @_sqlite_errors
    def insert(self, rows: list[tuple]) -> None:
        """Commit the rows (`index.row_values`) of runs whose files are in place, in one
        transaction (`validation.batch.committing`)."""
        with transaction(self._connect(create=True)) as db:
            insert_rows(db, rows)

    @_sqlite_errors
    def set_campaign(self, name: str, info: dict) -> None:
        """Record a campaign that stores runs here (description, report settings, …);
        keys already recorded for it and not in ``info`` are kept."""
        with transaction(self._connect(create=True)) as db:
            old = db.execute("SELECT info FROM campaigns WHERE name = ?", (name,)).fetchone()
            merged = {**(json_table(old[0]) if old else {}), **info}
            db.execute("INSERT OR REPLACE INTO campaigns VALUES (?, ?)", (name, json.dumps(merged)))

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
    @_sqlite_errors
    def rows(self, *, where: str = "", params: tuple = ()) -> list[StoredRun]:
        """Index rows (``where`` is an SQL condition on the columns), sorted by name.
        A row whose id or file could name a path outside runs/, or whose contents are
        not what the store writes, is refused (StoreError naming it and the cure)."""
        db = self._connect(create=False)
        sql = f"SELECT {', '.join(COLUMNS)} FROM runs {'WHERE ' + where if where else ''} " \
              "ORDER BY name, run_id"
        return [self._stored_run(values) for values in db.execute(sql, params)]

    def _stored_run(self, values) -> StoredRun:
        row = dict(zip(COLUMNS, values))
        rid = row["run_id"]
        try:
            if not is_run_id(rid) or row["file"] != f"runs/{rid}.npz":
                raise ValueError("its id must be 12 hex digits and its file runs/<id>.npz")
            if row["status"] not in STATUSES:
                raise ValueError(f"status {str(row['status'])[:20]!r} is none of {STATUSES}")
            if not (isinstance(row["size"], int) and row["size"] > 0
                    and isinstance(row["sha256"], str) and len(row["sha256"]) == 64):
                raise ValueError("its file's size and checksum are not a size and a SHA-256")
            for c in JSON_COLUMNS:
                row[c] = json_table(row[c])
            row["metrics"] = metric_values(row["metrics"])
        except (ValueError, TypeError, AttributeError) as exc:
            raise StoreError(f"{self.index_path}: row {str(rid)[:40]!r} is not a stored run "
                             f"({exc}); 'flexarm repair {self.out}' drops it") from None
        row["config"] = row.pop("scenario")
        return StoredRun(**row, store=self)

    def rows_of(self, ids) -> list[StoredRun]:
        """The rows of the runs ``ids`` that the index holds (queried by id, in chunks: a
        search asking for a few runs of a large folder reads only those)."""
        ids = list(dict.fromkeys(ids))
        out = []
        for i in range(0, len(ids), 500):  # SQLite's limit on parameters is 999 or more
            chunk = tuple(ids[i:i + 500])
            out += self.rows(where=f"run_id IN ({', '.join('?' * len(chunk))})", params=chunk)
        return out

    def row(self, rid: str) -> StoredRun | None:
        found = self.rows(where="run_id = ?", params=(rid,))
        return found[0] if found else None

    @_sqlite_errors
    def campaigns(self) -> dict[str, dict]:
        db = self._connect(create=False)
        out = {}
        for name, info in db.execute("SELECT * FROM campaigns"):
            try:
                out[name] = json_table(info)
            except ValueError:
                out[name] = {}  # descriptive only: a damaged entry is left out
        return out

    def load(self, rid: str) -> RunResult:
        """The run's result as its file keeps it (every signal: `StoredRun.load`), verified against its row (StoreError
        naming the run if the file is missing or damaged)."""
        return self.read(rid)[0]

    def read(self, rid: str) -> tuple[RunResult, dict]:
        """(result, the file's metadata) of run ``rid`` (`load`); the metadata's ``kept``
        says what the file keeps of the run's signals when it is not all of them."""
        row = self.row(rid)
        if row is None:
            raise StoreError(f"{self.out}: no run {rid}")
        return RunResult.from_bytes(self._verified_bytes(row))

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
            path = self.out / row.file
            if run_id(row.config) != row.run_id:
                damaged[row.run_id] = "its scenario does not hash to its id"
                continue
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
        known = {r.file for r in self.rows()} if self.exists() else set()
        return [p for p in self._run_files()
                if p.is_file() and is_run_id(p.stem) and f"runs/{p.name}" not in known]

    # --- repair and export ----------------------------------------------------------------
    def repair(self) -> dict[str, list[str]]:
        """Rebuild the index from the run files, whatever the damage (`repair.repair`)."""
        return repair.repair(self)

    def adopt(self, path: Path) -> StoredRun:
        """Index a run file that has no row (`repair.adopt`)."""
        try:
            return repair.adopt(self, path)
        except sqlite3.Error as exc:
            raise self._error(exc) from None

    def export(self, *, allow_fewer: bool = False) -> tuple[Path, Path]:
        """Write metrics.csv and manifest.json from the index (`export.export`)."""
        return export.export(self, allow_fewer=allow_fewer)
