"""A results folder: one signal file per run, indexed by an SQLite database.

    OUT/index.sqlite        one row per run: id, name, campaign, sweep and swept values,
                            status, message, timings, versions, code fingerprint, the
                            resolved scenario, every metric, and the run file's SHA-256 and
                            size (WAL journal; one transaction per stored run)
    OUT/runs/<run_id>.npz   signals (float32) and the same metadata (`RunResult.to_bytes`):
                            a file alone is enough to rebuild its row (`repair`)
    OUT/metrics.csv         exports, written from the index (`export`): never read back
    OUT/manifest.json

Writers: any number of processes may store runs into one folder at once — SQLite
serialises their transactions, so every row arrives (the run file is written first,
under a temporary name, then renamed; its row is committed after).  Readers verify what
they load: a run whose file is missing, of the wrong size or checksum is *damaged* and
is reported by id, never used.  The run id is a hash of the resolved scenario; the row
also records the code fingerprint (`validation.fingerprint`), so a result made by other
code is *stale* and is not reused.
"""
from __future__ import annotations

import csv
import functools
import hashlib
import io
import json
import math
import platform
import sqlite3
import subprocess
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from .fingerprint import run_fingerprint
from ..run.results import RunResult, write_atomic

__all__ = ["ResultStore", "StoredRun", "StoreError", "run_id", "environment", "INDEX_NAME"]

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


class StoreError(ValueError):
    """A results folder that cannot be used (one line naming the folder or file)."""


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
    env = {name: pkg(name) for name in ("flexarm-validation", "exudyn", "numpy", "numba",
                                        "scipy")}
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


class ResultStore:
    """Reads and writes one results folder (created on the first write)."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.runs_dir = self.out / "runs"
        self.index_path = self.out / INDEX_NAME
        self._db: sqlite3.Connection | None = None

    # --- the database ------------------------------------------------------------------
    def exists(self) -> bool:
        return self.index_path.is_file()

    def _connect(self, create: bool) -> sqlite3.Connection:
        if self._db is not None:
            return self._db
        if not create and not self.exists():
            raise StoreError(f"{self.out}: not a results folder (no {INDEX_NAME}; "
                             f"'flexarm repair {self.out}' rebuilds it from runs/)")
        try:
            if create:
                self.runs_dir.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(self.index_path, timeout=_BUSY_TIMEOUT, isolation_level=None)
            db.execute("PRAGMA journal_mode=WAL")
            # NORMAL: a transaction is durable once the WAL is checkpointed; an
            # application crash never loses a committed run, a power cut may lose the
            # last ones (they are then redone on resume: their files fail verification).
            db.execute("PRAGMA synchronous=NORMAL")
            db.executescript(_SCHEMA)
            db.execute("INSERT OR IGNORE INTO meta VALUES ('schema', ?)", (str(_SCHEMA_VERSION),))
            (schema,) = db.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
        except sqlite3.DatabaseError as exc:
            raise StoreError(f"{self.index_path}: cannot open the index ({exc}); "
                             f"'flexarm repair {self.out}' rebuilds it from runs/") from None
        if schema != str(_SCHEMA_VERSION):
            db.close()
            raise StoreError(f"{self.index_path}: index schema {schema}, this version reads "
                             f"{_SCHEMA_VERSION}; 'flexarm repair {self.out}' rebuilds the index "
                             "from the run files")
        self._db = db
        return db

    def close(self) -> None:
        if self._db is not None:
            self._db.close()
            self._db = None

    def prepare(self) -> None:
        """Create the folder and its index (StoreError naming the folder if it cannot)."""
        try:
            self._connect(create=True)
        except OSError as exc:
            raise StoreError(f"{self.out}: cannot create the results folder "
                             f"({exc.strerror or exc})") from None

    # --- writing ------------------------------------------------------------------------
    def add(self, rid: str, result: RunResult, metrics: dict, *, campaign: str = "",
            sweep: str = "", axes: dict | None = None, env: dict | None = None) -> Path:
        """Store one run: its file (written under a temporary name, then renamed), then
        its row, in one transaction (replacing an older row of the same id).  Signals are
        stored as float32 (7 digits, for plots; metrics come from the float64 signals)."""
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

    def set_campaign(self, name: str, info: dict) -> None:
        """Record a campaign that stores runs here (description, report settings, …);
        keys already recorded for it and not in ``info`` are kept."""
        db = self._connect(create=True)
        db.execute("BEGIN IMMEDIATE")
        try:
            old = db.execute("SELECT info FROM campaigns WHERE name = ?", (name,)).fetchone()
            merged = {**(json.loads(old[0]) if old else {}), **info}
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
                if now - path.stat().st_mtime > older_than:
                    path.unlink()
                    removed += 1
            except FileNotFoundError:
                pass
        return removed

    # --- reading ------------------------------------------------------------------------
    def rows(self, *, where: str = "", params: tuple = ()) -> list[StoredRun]:
        """Index rows (``where`` is an SQL condition on the columns), sorted by name."""
        db = self._connect(create=False)
        sql = f"SELECT {', '.join(_COLUMNS)} FROM runs {'WHERE ' + where if where else ''} " \
              "ORDER BY name, run_id"
        out = []
        for values in db.execute(sql, params):
            row = dict(zip(_COLUMNS, values))
            for c in _JSON_COLUMNS:
                row[c] = json.loads(row[c])
            row["metrics"] = _metric_values(row["metrics"])
            row["config"] = row.pop("scenario")
            out.append(StoredRun(**row, store=self))
        return out

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

    def campaigns(self) -> dict[str, dict]:
        db = self._connect(create=False)
        return {name: json.loads(info) for name, info in db.execute("SELECT * FROM campaigns")}

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
        """run id → why it is damaged, for every row whose file is missing, of the wrong
        size, or (with ``checksum``) of the wrong SHA-256."""
        damaged = {}
        for row in self.rows() if rows is None else rows:
            path = self.out / row.file
            try:
                size = path.stat().st_size
            except OSError:
                damaged[row.run_id] = "file missing"
                continue
            if size != row.size:
                damaged[row.run_id] = f"file size {size} != {row.size}"
            elif checksum:
                with path.open("rb") as fh:
                    digest = hashlib.file_digest(fh, "sha256").hexdigest()
                if digest != row.sha256:
                    damaged[row.run_id] = "checksum differs"
        return damaged

    def unindexed_files(self) -> list[Path]:
        """Run files with no row in the index (e.g. a row lost with a deleted index)."""
        known = {r.file for r in self.rows()} if self.exists() else set()
        return sorted(p for p in self.runs_dir.glob("*.npz")
                      if f"runs/{p.name}" not in known)

    # --- repair and export ----------------------------------------------------------------
    def repair(self) -> dict[str, list[str]]:
        """Rebuild the index from the run files: adopt every readable file without a row,
        drop rows whose file is missing or damaged (their files are kept as
        ``runs/<id>.npz.damaged``).  Returns the run ids per action."""
        report = {"adopted": [], "dropped": [], "unreadable": []}
        if self.index_path.exists():
            try:
                self._connect(create=False).execute("SELECT count(*) FROM runs").fetchone()
            except (sqlite3.DatabaseError, StoreError):
                self.close()
                self.index_path.rename(self.index_path.with_suffix(".sqlite.damaged"))
                for suffix in ("-wal", "-shm"):
                    Path(str(self.index_path) + suffix).unlink(missing_ok=True)
        db = self._connect(create=True)
        for rid, why in self.verify().items():
            db.execute("DELETE FROM runs WHERE run_id = ?", (rid,))
            path = self.runs_dir / f"{rid}.npz"
            if path.exists():
                path.rename(path.with_suffix(".npz.damaged"))
            report["dropped"].append(f"{rid} ({why})")
        for path in self.unindexed_files():
            try:
                self.adopt(path)
            except ValueError as exc:
                path.rename(path.with_suffix(".npz.damaged"))
                report["unreadable"].append(f"{path.stem} ({exc})")
                continue
            report["adopted"].append(path.stem)
        return report

    def adopt(self, path: Path) -> StoredRun:
        """Index a run file that has no row (its metadata holds everything); ValueError if
        it is not a readable run file."""
        data = Path(path).read_bytes()
        result, meta = RunResult.from_bytes(data)
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

    def export(self) -> tuple[Path, Path]:
        """Write metrics.csv (one row per run: identity, what was run, swept values,
        status, every metric) and manifest.json from the index."""
        rows = self.rows()
        csv_path, json_path = self.out / "metrics.csv", self.out / "manifest.json"
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
