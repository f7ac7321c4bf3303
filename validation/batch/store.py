"""A results folder: one signal file per run, indexed by an SQLite database.

    OUT/index.sqlite        one row per run: id, name, campaign, sweep and swept values,
                            status, message, timings, versions, code fingerprint, the
                            resolved scenario, every metric, and the run file's SHA-256 and
                            size (WAL journal; one transaction per stored run)
    OUT/runs/<run_id>.npz   signals (float32) and the same metadata (`RunResult.to_bytes`):
                            a file alone is enough to rebuild its row (`repair`)
    OUT/metrics.csv         exports, written from the index (`export`)
    OUT/manifest.json       (read back only to refuse an export that would lose runs)

Writers: any number of processes may store runs into one folder at once — SQLite
serialises their transactions, so every row arrives (the run file is written first,
under a temporary name, then renamed; its row is committed after).

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
(`validation.fingerprint`), so a result made by other code is *stale* and is not reused.
"""
from __future__ import annotations

import csv
import errno
import functools
import hashlib
import io
import json
import math
import os
import platform
import re
import sqlite3
import subprocess
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from .fingerprint import run_fingerprint
from ..run.results import RunResult, write_atomic

__all__ = ["ResultStore", "StoredRun", "StoreError", "run_id", "is_run_id", "environment",
           "INDEX_NAME"]

INDEX_NAME = "index.sqlite"
_SCHEMA_VERSION = 1
_SCHEMA = """
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
_COLUMNS = ("run_id", "name", "campaign", "sweep", "axes", "status", "message", "end_time",
            "fingerprint", "scenario", "metrics", "timings", "environment", "file", "sha256",
            "size", "finished")
_JSON_COLUMNS = ("axes", "scenario", "metrics", "timings", "environment")
#: How long a writer waits for another process's transaction before giving up [s].
_BUSY_TIMEOUT = 120.0
#: What `run_id` makes: 12 lowercase hex digits.
_RUN_ID = re.compile(r"[0-9a-f]{12}")


class StoreError(ValueError):
    """A results folder that cannot be used (one line naming the folder or file)."""


def is_run_id(text) -> bool:
    """Whether ``text`` is a run id (12 lowercase hex digits): safe in a path."""
    return isinstance(text, str) and _RUN_ID.fullmatch(text) is not None


def run_id(resolved_scenario: dict) -> str:
    """12 hex digits of the SHA-256 of the scenario's canonical JSON."""
    text = json.dumps(resolved_scenario, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


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
    """One row of the index.  ``load()`` reads and verifies the run's file."""

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
        return self.store.load(self.run_id)

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


def _set_wal(db: sqlite3.Connection) -> None:
    """Switch ``db`` to a WAL journal.  SQLite refuses the switch with SQLITE_BUSY at once,
    without its busy handler, while another connection is making the same switch (two
    processes opening one new index together: 28 of 60 connections refused, measured),
    so it is retried here until `_BUSY_TIMEOUT`."""
    deadline = time.monotonic() + _BUSY_TIMEOUT
    while True:
        try:
            db.execute("PRAGMA journal_mode=WAL")
            return
        except sqlite3.OperationalError as exc:
            if exc.sqlite_errorname != "SQLITE_BUSY" or time.monotonic() > deadline:
                raise
            time.sleep(0.005)


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
        if not create and not self.exists():
            raise StoreError(f"{self.out}: not a results folder (no {INDEX_NAME}; "
                             f"'flexarm repair {self.out}' rebuilds it from runs/)")
        if create:
            self.runs_dir.mkdir(parents=True, exist_ok=True)
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

    def _open(self) -> sqlite3.Connection:
        existed = self.exists()
        db = sqlite3.connect(self.index_path, timeout=_BUSY_TIMEOUT, isolation_level=None)
        try:
            _set_wal(db)
            # NORMAL: a transaction is durable once the WAL is checkpointed; an
            # application crash never loses a committed run, a power cut may lose the
            # last ones (they are then redone on resume: their files fail verification).
            db.execute("PRAGMA synchronous=NORMAL")
            tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master")}
            if "runs" not in tables and existed and self._run_files():
                # An index without its table (an empty or truncated file) next to run
                # files: not a new index but a lost one — never read as "no runs".
                raise sqlite3.DatabaseError("the index holds no table of runs")
            db.executescript(_SCHEMA)
            db.execute("INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (str(_SCHEMA_VERSION),))
            (schema,) = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
        except BaseException:
            db.close()
            raise
        if schema != str(_SCHEMA_VERSION):
            db.close()
            raise StoreError(f"{self.index_path}: index schema {schema}, this version reads "
                             f"{_SCHEMA_VERSION}; 'flexarm repair {self.out}' rebuilds the index "
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
                              f"{_BUSY_TIMEOUT:g} s ({exc})")
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
        """Store one run: its file (written under a temporary name, then renamed), then
        its row, in one transaction (replacing an older row of the same id).  Signals are
        stored as float32 (7 digits, for plots; metrics come from the float64 signals)."""
        if not is_run_id(rid):
            raise StoreError(f"{rid!r} is not a run id (12 hex digits)")
        db = self._connect(create=True)
        fingerprint = run_fingerprint(result.config)
        row = {"run_id": rid, "name": result.config.get("name", ""), "campaign": campaign,
               "sweep": sweep, "axes": axes or {}, "status": result.status,
               "message": result.message, "end_time": result.end_time,
               "fingerprint": fingerprint, "scenario": result.config,
               "metrics": _finite_or_none(metrics), "timings": _finite_or_none(result.timings),
               "environment": env or environment(), "file": f"runs/{rid}.npz",
               "finished": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        result.signals = result.signals.astype("float32", copy=False)
        extra = {k: row[k] for k in ("campaign", "sweep", "axes", "fingerprint", "metrics",
                                     "environment", "finished")}
        data = result.to_bytes(extra)
        row["sha256"], row["size"] = hashlib.sha256(data).hexdigest(), len(data)
        path = self.out / row["file"]
        write_atomic(path, lambda fh: fh.write(data), binary=True, sync=False)
        self._insert(db, row)
        return path

    def _insert(self, db: sqlite3.Connection, row: dict) -> None:
        values = [json.dumps(row[c], allow_nan=False) if c in _JSON_COLUMNS else row[c]
                  for c in _COLUMNS]
        db.execute(f"INSERT OR REPLACE INTO runs ({', '.join(_COLUMNS)}) VALUES "
                   f"({', '.join('?' * len(_COLUMNS))})", values)

    @_sqlite_errors
    def set_campaign(self, name: str, info: dict) -> None:
        """Record a campaign that stores runs here (description, report settings, …);
        keys already recorded for it and not in ``info`` are kept."""
        db = self._connect(create=True)
        db.execute("BEGIN IMMEDIATE")
        try:
            old = db.execute("SELECT info FROM campaigns WHERE name = ?", (name,)).fetchone()
            merged = {**(_json_table(old[0]) if old else {}), **info}
            db.execute("INSERT OR REPLACE INTO campaigns VALUES (?, ?)", (name, json.dumps(merged)))
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise

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
        sql = f"SELECT {', '.join(_COLUMNS)} FROM runs {'WHERE ' + where if where else ''} " \
              "ORDER BY name, run_id"
        return [self._stored_run(values) for values in db.execute(sql, params)]

    def _stored_run(self, values) -> StoredRun:
        row = dict(zip(_COLUMNS, values))
        rid = row["run_id"]
        try:
            if not is_run_id(rid) or row["file"] != f"runs/{rid}.npz":
                raise ValueError("its id must be 12 hex digits and its file runs/<id>.npz")
            for c in _JSON_COLUMNS:
                row[c] = _json_table(row[c])
            row["metrics"] = _metric_values(row["metrics"])
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
                out[name] = _json_table(info)
            except ValueError:
                out[name] = {}  # descriptive only: a damaged entry is left out
        return out

    def load(self, rid: str) -> RunResult:
        """The run's result, verified against its row (StoreError naming the run if the
        file is missing or damaged)."""
        row = self.row(rid)
        if row is None:
            raise StoreError(f"{self.out}: no run {rid}")
        data = self._verified_bytes(row)
        return RunResult.from_bytes(data)[0]

    def _verified_bytes(self, row: StoredRun) -> bytes:
        path = self.out / row.file
        try:
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
        """Rebuild the index from the run files, whatever the damage: an index SQLite
        cannot read or check (a corrupt page, an empty or truncated file) is set aside
        as ``index.sqlite.damaged`` and rebuilt; rows that are not stored runs are
        dropped without touching any path; rows whose file is missing or damaged are
        dropped (their files kept as ``runs/<id>.npz.damaged``); every readable run file
        without a row is adopted if its scenario hashes to its name; directories and
        files not named by a run id are skipped.  Returns the run ids (or names) per
        action."""
        report = {"rebuilt": [], "adopted": [], "dropped": [], "unreadable": [], "skipped": []}
        if self.exists() and not self._index_sound():
            self.close()
            self.index_path.replace(self.index_path.with_name(INDEX_NAME + ".damaged"))
            for suffix in ("-wal", "-shm"):
                Path(f"{self.index_path}{suffix}").unlink(missing_ok=True)
            report["rebuilt"].append(f"{INDEX_NAME} (unreadable; kept as {INDEX_NAME}.damaged)")
        try:
            db = self._connect(create=True)
            for values in db.execute(f"SELECT {', '.join(_COLUMNS)} FROM runs").fetchall():
                try:
                    self._stored_run(values)
                except StoreError:  # no path is built from it: its id may be anything
                    db.execute("DELETE FROM runs WHERE run_id = ?", (values[0],))
                    report["dropped"].append(f"{str(values[0])[:40]!r} (not a stored run)")
            for rid, why in self.verify().items():
                db.execute("DELETE FROM runs WHERE run_id = ?", (rid,))
                path = self.runs_dir / f"{rid}.npz"
                if path.is_file():
                    path.replace(path.with_name(path.name + ".damaged"))
                report["dropped"].append(f"{rid} ({why})")
        except sqlite3.Error as exc:
            raise self._error(exc) from None
        for path in self._run_files():
            if not path.is_file() or not is_run_id(path.stem):
                report["skipped"].append(f"runs/{path.name} (not a run file)")
        for path in self.unindexed_files():
            try:
                self.adopt(path)
            except ValueError as exc:
                path.replace(path.with_name(path.name + ".damaged"))
                report["unreadable"].append(f"{path.stem} ({exc})")
                continue
            report["adopted"].append(path.stem)
        return report

    def _index_sound(self) -> bool:
        """Whether SQLite can open the index, finds every page of it sound and can read
        every row (a full disk or a read-only folder is raised, not taken for damage)."""
        self.close()
        try:
            db = self._connect(create=False)
            sound = db.execute("PRAGMA quick_check").fetchone()[0] == "ok"
            db.execute(f"SELECT {', '.join(_COLUMNS)} FROM runs").fetchall()
        except sqlite3.Error as exc:
            error = self._error(exc)
            if isinstance(error, OSError) or not self.writable():
                raise error from None
            return False
        except StoreError:
            if not self.writable():
                raise
            return False
        return sound

    @_sqlite_errors
    def adopt(self, path: Path) -> StoredRun:
        """Index a run file that has no row (its metadata holds everything); ValueError if
        it is not a readable run file, or its scenario does not hash to its name."""
        path = Path(path)
        if not is_run_id(path.stem):
            raise ValueError(f"{path.name} is not named by a run id")
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ValueError(f"unreadable ({exc.strerror or exc})") from None
        result, meta = RunResult.from_bytes(data)
        if not isinstance(result.config, dict) or run_id(result.config) != path.stem:
            raise ValueError(f"its scenario does not hash to its name {path.stem} (a copy of "
                             "another run's file?)")
        row = {"run_id": path.stem, "name": result.config.get("name", ""),
               "campaign": meta.get("campaign", ""), "sweep": meta.get("sweep", ""),
               "axes": meta.get("axes", {}), "status": result.status,
               "message": result.message, "end_time": result.end_time,
               "fingerprint": meta.get("fingerprint", ""), "scenario": result.config,
               "metrics": meta.get("metrics", {}), "timings": result.timings,
               "environment": meta.get("environment", {}), "file": f"runs/{path.name}",
               "sha256": hashlib.sha256(data).hexdigest(), "size": len(data),
               "finished": meta.get("finished", "")}
        self._insert(self._connect(create=True), row)
        return self.row(path.stem)

    def export(self, *, allow_fewer: bool = False) -> tuple[Path, Path]:
        """Write metrics.csv (one row per run: identity, what was run, swept values,
        status, every metric) and manifest.json from the index, holding its write lock
        (of two processes exporting at once, the later one reads every row the earlier
        one wrote).  An index that lacks runs the previous export listed (a damaged
        index reads as fewer runs) is refused (StoreError, the old export kept) unless
        ``allow_fewer`` (after `repair`, which says what it dropped)."""
        db = self._connect(create=False)
        if not self.writable():
            raise StoreError(f"{self.out}: read-only, metrics.csv and manifest.json cannot "
                             "be written here")
        try:
            db.execute("BEGIN IMMEDIATE")
        except sqlite3.Error as exc:
            raise self._error(exc) from None
        try:
            return self._export(allow_fewer)
        finally:
            db.execute("ROLLBACK")  # nothing was written to the index

    def _export(self, allow_fewer: bool) -> tuple[Path, Path]:
        rows = self.rows()
        csv_path, json_path = self.out / "metrics.csv", self.out / "manifest.json"
        if not allow_fewer:
            lost = _previous_runs(json_path) - {r.run_id for r in rows}
            if lost:
                raise StoreError(f"{self.out}: the index lacks {len(lost)} of the runs the "
                                 f"last export listed (e.g. {min(lost)}); metrics.csv and "
                                 f"manifest.json kept; 'flexarm repair {self.out}' rebuilds "
                                 "the index from runs/")
        table = [export_row(r) for r in rows]
        columns: dict[str, None] = {}  # first-seen order; a list would be quadratic
        for r in table:
            columns.update(dict.fromkeys(r))
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=columns, restval="", lineterminator="\n")
        writer.writeheader()
        for r in table:
            writer.writerow({k: _format(v) for k, v in r.items()})
        write_atomic(csv_path, lambda fh: fh.write(buf.getvalue()))
        manifest = {"campaigns": self.campaigns(), "runs": {
            r.run_id: {"name": r.name, "campaign": r.campaign, "sweep": r.sweep,
                       "axes": r.axes, "status": r.status, "message": r.message,
                       "end_time": r.end_time, "fingerprint": r.fingerprint,
                       "timings": r.timings, "environment": r.environment, "file": r.file,
                       "sha256": r.sha256, "size": r.size, "finished": r.finished}
            for r in rows}}
        write_atomic(json_path, lambda fh: json.dump(manifest, fh, indent=1))
        return csv_path, json_path


def _previous_runs(manifest: Path) -> set[str]:
    """Run ids the manifest of the last export lists (none if there is none, or it cannot
    be read)."""
    try:
        runs = json.loads(manifest.read_text())["runs"]
    except (OSError, ValueError, KeyError, TypeError):
        return set()
    return {rid for rid in runs if is_run_id(rid)} if isinstance(runs, dict) else set()


def _json_table(text):
    """A JSON column's value; ValueError unless it is JSON of the kind the store writes."""
    value = json.loads(text)
    if not isinstance(value, dict):
        raise ValueError("a JSON column is not a table")
    return value


#: Columns of metrics.csv that say what was run, before the swept values and metrics.
IDENTITY_COLUMNS = ("run_id", "name", "campaign", "sweep", "arm", "plant", "controller",
                    "observer", "Ts", "initial_state", "status", "message")


def export_row(r: StoredRun) -> dict:
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


#: JSON has no infinities: a metric of ±∞ (a requirement's robustness can be: ``always``
#: over an empty window, a claim's "never") is stored as one of these strings.
_INFINITIES = {"inf": math.inf, "-inf": -math.inf}


def _finite_or_none(metrics: dict) -> dict:
    """JSON has no NaN/inf: NaN is stored as null (read back as NaN), ±∞ as "inf"/"-inf"
    (read back as floats by `_metric_values`)."""
    return {k: (None if math.isnan(v) else repr(v)) if isinstance(v, float)
            and not math.isfinite(v) else v for k, v in metrics.items()}


def _metric_values(stored: dict) -> dict:
    """Metrics as read from the index: null → NaN, "inf"/"-inf" → ±∞."""
    return {k: math.nan if v is None else _INFINITIES.get(v, v) if isinstance(v, str) else v
            for k, v in stored.items()}


def _format(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)
    return str(value)
