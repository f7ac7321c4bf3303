"""The SQLite index of a results folder: its schema, one transaction helper, one row
writer, and how a row is encoded.  Run ids live here too: the index is what they name
runs in.

The index is columnar where it is read in bulk: every metric is a ``REAL`` column of its
own (``"m:<name>"``, added the first time a run brings it), every swept value a column
(``"a:<name>"``), and what tables and exports show of a scenario (arm, plant, laws,
``Ts``, start) a column each; which swept values and metrics a run has, in its order, is
its ``metric_set`` (a metric the run has as NaN is NULL in it; one it lacks is not in its
set).
The resolved scenario, the swept values as they were, the timings, the environment and
what the run's file keeps are one compressed ``detail`` (`encode_detail`), decoded only
when a run's detail is asked for: compressed with a preset dictionary (`dictionaries`,
content-addressed: the campaign's base scenario and environment), a run's detail takes
~100 bytes instead of ~2 KB of JSON.
"""
from __future__ import annotations

import hashlib
import json
import math
import re
import sqlite3
import time
import zlib
from contextlib import contextmanager
from pathlib import Path

from .errors import StoreError

__all__ = ["INDEX_NAME", "SCHEMA", "SCHEMA_VERSION", "FIXED", "BUSY_TIMEOUT", "run_id",
           "is_run_id", "set_wal", "transaction", "insert_rows", "row_values",
           "finite_or_none", "metric_values", "RUN_ID", "set_aside", "metric_column",
           "axis_column", "encode_detail", "decode_detail", "dictionary_key", "json_table",
           "STATUS", "scenario_columns", "MAX_COLUMNS", "open_read_only", "NUMBER_COLUMNS",
           "TEXT_METRICS", "mistyped", "not_a_number", "detail_rest", "layout", "metric_sets",
           "reading"]

INDEX_NAME = "index.sqlite"
SCHEMA_VERSION = 2
SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS campaigns (name TEXT PRIMARY KEY, info TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS dictionaries (key TEXT PRIMARY KEY, data BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS metric_sets (id INTEGER PRIMARY KEY, names TEXT NOT NULL UNIQUE);
-- names: [[swept names], [metric names]] in a run's order
CREATE TABLE IF NOT EXISTS runs (
    run_id TEXT PRIMARY KEY,
    name TEXT NOT NULL,
    campaign TEXT NOT NULL DEFAULT '',
    sweep TEXT NOT NULL DEFAULT '',
    status TEXT NOT NULL,
    message TEXT NOT NULL DEFAULT '',
    end_time REAL,
    fingerprint TEXT NOT NULL,
    arm, plant, role, controller, observer, Ts, initial_state,
    dictionary TEXT NOT NULL DEFAULT '',
    detail BLOB NOT NULL,
    file TEXT NOT NULL DEFAULT '',
    sha256 TEXT NOT NULL DEFAULT '',
    size INTEGER NOT NULL DEFAULT 0,
    finished TEXT NOT NULL,
    metric_set INTEGER NOT NULL
);
"""
#: The columns every row has, in order (`metric_set` last: the inserting process sets it).
FIXED = ("run_id", "name", "campaign", "sweep", "status", "message", "end_time",
         "fingerprint", "arm", "plant", "role", "controller", "observer", "Ts",
         "initial_state", "dictionary", "detail", "file", "sha256", "size", "finished")
STATUS = FIXED.index("status")
#: SQLite's default limit is 2000 columns a table; the fixed ones and some room kept.
MAX_COLUMNS = 1900
#: How long a writer waits for another process's transaction before giving up [s].
BUSY_TIMEOUT = 120.0
#: What `run_id` makes: 12 lowercase hex digits.
RUN_ID = re.compile(r"[0-9a-f]{12}")


#: The columns of a row that hold numbers or NULL (`mistyped`): the control period (NULL: a
#: scenario without one), the time the run ended (NULL: not known), and every metric's but
#: those of `TEXT_METRICS` (NULL: NaN).
NUMBER_COLUMNS = ("Ts", "end_time")
#: The metrics whose value is text (`validation.run.metrics.all_metrics`); every other
#: metric is a number.
TEXT_METRICS = frozenset({"status", "est_worse", "est_worse_zero"})


def mistyped(columns, *, value: bool = False) -> str:
    """The one check of the columns of a row that hold numbers: an SQL expression that
    every reader of them selects beside them — the name (or with ``value``, the value) of
    the first of those among ``columns`` (names, unquoted: `NUMBER_COLUMNS` and the
    metrics' ``m:<name>``) whose value is neither a number nor NULL (none given: a NaN, a
    scenario without ``Ts``), else NULL (`not_a_number` says it).  SQLite keeps whatever
    it is given in a column: text in a metric's column is a damaged row, never a metric."""
    whens = []
    for name in columns:
        if name in NUMBER_COLUMNS or (name[:2] == "m:" and name[2:] not in TEXT_METRICS):
            quoted, text = '"' + name.replace('"', '""') + '"', name.replace("'", "''")
            then = quoted if value else f"'{text}'"
            whens.append(f"WHEN typeof({quoted}) NOT IN ('integer', 'real', 'null') "
                         f"THEN {then}")
    return f"CASE {' '.join(whens)} END" if whens else "NULL"


def not_a_number(column: str, value) -> str:
    """Why a row whose ``column`` holds ``value`` (`mistyped`) is not a stored run."""
    return f"its {column} holds {str(value)[:20]!r}, not a number"


def reading(db: sqlite3.Connection, metrics=None) -> tuple[str, dict]:
    """What a reader of whole rows selects: (the columns — every one, or the fixed ones
    and the ``metrics`` named — then their `mistyped` as ``mistyped``, as SQL; metric set
    id → the metric names of its layout among those read, or why the set is damaged)."""
    sets = {i: s if isinstance(s, str) else s[1] for i, s in metric_sets(db).items()}
    have = [c[1] for c in db.execute("PRAGMA table_info(runs)")]
    if metrics is None:
        return f"*, {mistyped(have)} AS mistyped", sets
    present = set(have)
    wanted = [m for m in dict.fromkeys(metrics) if "m:" + m in present]
    sets = {i: s if isinstance(s, str) else tuple(n for n in s if n in wanted)
            for i, s in sets.items()}
    columns = [*FIXED, "metric_set", *map(metric_column, wanted)]
    return f"{', '.join(columns)}, {mistyped([*FIXED, *('m:' + m for m in wanted)])} " \
           "AS mistyped", sets


def layout(names) -> tuple[tuple, tuple]:
    """(swept names, metric names) of a ``metric_sets`` row's ``names``; ValueError unless
    it is what the store writes there: ``[[names...], [names...]]``."""
    try:
        value = json.loads(names)
    except (TypeError, ValueError):
        value = None
    if not (isinstance(value, list) and len(value) == 2 and all(
            isinstance(part, list) and all(isinstance(n, str) for n in part) for part in value)):
        raise ValueError(f"names {str(names)[:40]!r} is not [[swept names], [metric names]]")
    return tuple(value[0]), tuple(value[1])


def metric_sets(db: sqlite3.Connection) -> dict[int, tuple[tuple, tuple] | str]:
    """Each row of table ``metric_sets``: its id → its layout (`layout`), or why it is
    damaged (naming the table and the row)."""
    out = {}
    for i, names in db.execute("SELECT id, names FROM metric_sets"):
        try:
            out[i] = layout(names)
        except ValueError as exc:
            out[i] = f"table metric_sets, row {i}: {exc}"
    return out


def is_run_id(text) -> bool:
    """Whether ``text`` is a run id (12 lowercase hex digits): safe in a path."""
    return isinstance(text, str) and RUN_ID.fullmatch(text) is not None


def canonical(scenario: dict) -> str:
    """The scenario's canonical JSON (what its run id hashes)."""
    return json.dumps(scenario, sort_keys=True, separators=(",", ":"))


def run_id(resolved_scenario: dict) -> str:
    """12 hex digits of the SHA-256 of the scenario's canonical JSON."""
    return hashlib.sha256(canonical(resolved_scenario).encode()).hexdigest()[:12]


def metric_column(name: str) -> str:
    """The quoted column of metric ``name`` (for a ``where`` of `ResultStore.rows`)."""
    return '"m:' + name.replace('"', '""') + '"'


def axis_column(name: str) -> str:
    """The quoted column of swept value ``name``."""
    return '"a:' + name.replace('"', '""') + '"'


def scenario_columns(config: dict) -> tuple:
    """What tables and exports show of a scenario mapping: arm, plant kind, plant role,
    controller and observer kinds, Ts, start (`FIXED` order)."""
    from ...run.plants import role_of  # reads the registry: no plug-in imported
    plant = config.get("plant", {})
    try:
        role = role_of(config)
    except (KeyError, AttributeError, TypeError):
        role = "truth"
    return (config.get("arm", "default"), plant.get("kind", "?") if isinstance(plant, dict)
            else "?", role, config.get("controller", {}).get("kind", ""),
            config.get("observer", {}).get("kind", ""), config.get("Ts"),
            config.get("initial_state", ""))


# --- the detail of a run -------------------------------------------------------------------
def dictionary_key(data: bytes) -> str:
    """The content address of a preset dictionary ('' for none)."""
    return hashlib.sha256(data).hexdigest()[:16] if data else ""


def encode_detail(scenario: dict, rest: dict, dictionary: bytes = b"") -> bytes:
    """A run's detail: its scenario's canonical JSON, a newline, then ``rest`` (swept
    values, timings, environment, what its file keeps) as JSON, compressed with the
    preset ``dictionary``."""
    text = canonical(scenario) + "\n" + json.dumps(rest, allow_nan=False)
    pack = zlib.compressobj(9, zdict=dictionary) if dictionary else zlib.compressobj(9)
    return pack.compress(text.encode()) + pack.flush()


def decode_detail(blob: bytes, dictionary: bytes = b"") -> tuple[str, str]:
    """(scenario's canonical JSON, the rest's JSON) of `encode_detail`'s ``blob``;
    ValueError if it is not one."""
    try:
        unpack = zlib.decompressobj(zdict=dictionary) if dictionary else zlib.decompressobj()
        text = unpack.decompress(blob, 64 << 20).decode()
        scenario, _, rest = text.partition("\n")
        return scenario, rest
    except (zlib.error, UnicodeDecodeError, TypeError) as exc:
        raise ValueError(f"its detail is not one ({exc})") from None


#: The timings a run records, as a detail spells them (values vary; keys do not).
_TIMINGS = {"wall_s": 0.0, "startup_s": 0.0, "loop_s": 0.0, "compiled_loop": True,
            "paths": {"loop": "compiled", "controller": "compiled", "observer": "compiled"},
            "observer_measured": [], "realtime_factor": 0.0}


def dictionary_for(scenario: dict, env: dict, names: tuple = ()) -> bytes:
    """The preset dictionary of a campaign's details: its first run's scenario, the
    environment, the timings' keys and the names of the signals a run records, as a
    run's detail spells them (what makes the detail of a run ~100 bytes)."""
    rest = {"axes": {}, "timings": _TIMINGS, "environment": env,
            "kept": {"every": 1, "names": list(names), "samples": 0}}
    return (canonical(scenario) + "\n" + json.dumps(rest)).encode()


# --- encoding and writing rows -----------------------------------------------------------
def row_values(row: dict, dictionary: bytes = b"") -> tuple:
    """A run's row as the index stores it (done where the run was made: the process
    inserting rows only inserts them): (`FIXED` values, metric names, metric values,
    swept names, swept values)."""
    detail = encode_detail(row["scenario"], detail_rest(row), dictionary)
    fixed = (row["run_id"], row["name"], row["campaign"], row["sweep"], row["status"],
             row["message"], row["end_time"], row["fingerprint"],
             *scenario_columns(row["scenario"]), dictionary_key(dictionary), detail,
             row["file"], row["sha256"], row["size"], row["finished"])
    # The metrics as a run file keeps them (`finite_or_none`: NaN as None, ±∞ as
    # strings); a column is NULL for NaN and holds ±∞ as a REAL.
    metrics = {k: _INFINITIES.get(v, v) if isinstance(v, str) else v
               for k, v in row["metrics"].items()}
    # A swept value as metrics.csv writes it where it is not a number or a string.
    axes = {k: json.dumps(v) if isinstance(v, (list, dict)) else str(v)
            if isinstance(v, bool) else v for k, v in row["axes"].items()}
    return fixed, tuple(metrics), tuple(metrics.values()), tuple(axes), tuple(axes.values())


def detail_rest(row: dict) -> dict:
    """What a run's detail holds beside its scenario (`encode_detail`'s ``rest``)."""
    rest = {"axes": row["axes"], "timings": row["timings"], "environment": row["environment"]}
    if row.get("kept"):
        rest["kept"] = row["kept"]
    return rest


def _columns(db: sqlite3.Connection) -> set[str]:
    return {name for (_, name, *_) in db.execute("PRAGMA table_info(runs)")}


def _metric_set(db: sqlite3.Connection, names: tuple, cache: dict) -> int:
    """The id of the layout ``names`` = (swept names, metric names)."""
    if names not in cache:
        text = json.dumps(names)
        db.execute("INSERT OR IGNORE INTO metric_sets (names) VALUES (?)", (text,))
        cache[names] = db.execute("SELECT id FROM metric_sets WHERE names = ?",
                                  (text,)).fetchone()[0]
    return cache[names]


def insert_rows(db: sqlite3.Connection, rows: list[tuple]) -> None:
    """Write runs' rows (`row_values`) inside the caller's transaction, replacing older
    rows of the same ids; a metric or swept value no row had before gets its column."""
    columns, sets = _columns(db), {}
    groups: dict[tuple, list] = {}
    for fixed, m_names, m_values, a_names, a_values in rows:
        groups.setdefault((m_names, a_names), []).append((fixed, m_values, a_values))
    for (m_names, a_names), items in groups.items():
        wanted = [metric_column(n) for n in m_names] + [axis_column(n) for n in a_names]
        for quoted, affinity in zip(wanted, ["REAL"] * len(m_names) + [""] * len(a_names)):
            if quoted[1:-1].replace('""', '"') not in columns:
                if len(columns) >= MAX_COLUMNS:
                    raise StoreError(f"more than {MAX_COLUMNS} metrics and swept values in "
                                     "one results folder")
                db.execute(f"ALTER TABLE runs ADD COLUMN {quoted} {affinity}")
                columns.add(quoted[1:-1].replace('""', '"'))
        set_id = _metric_set(db, (a_names, m_names), sets)
        names = [*FIXED, "metric_set"]
        sql = (f"INSERT OR REPLACE INTO runs ({', '.join([*names, *wanted])}) VALUES "
               f"({', '.join('?' * (len(names) + len(wanted)))})")
        db.executemany(sql, [(*fixed, set_id, *mv, *av) for fixed, mv, av in items])


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


def open_read_only(index: Path) -> sqlite3.Connection:
    """The index of a folder SQLite cannot write its shared-memory file into
    (read-only, or on a full disk).  With no WAL journal (or an empty one) every
    committed run is in the index itself, which no writer can change there: opened
    as immutable (SQLite needs no shared-memory file then)."""
    wal = Path(f"{index}-wal")
    if wal.exists() and wal.stat().st_size > 0:
        raise sqlite3.OperationalError("read-only folder whose journal (-wal) holds "
                                       "runs not yet in the index")
    uri = f"{index.resolve().as_uri()}?immutable=1"
    db = sqlite3.connect(uri, uri=True, isolation_level=None)
    try:
        tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master")}
        if "runs" not in tables:
            raise sqlite3.DatabaseError("the index holds no table of runs")
    except BaseException:
        db.close()
        raise
    return db


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


def json_table(text):
    """A JSON column's value; ValueError unless it is JSON of the kind the store writes."""
    value = json.loads(text)
    if not isinstance(value, dict):
        raise ValueError("a JSON column is not a table")
    return value


#: JSON has no infinities: a metric of ±∞ (a requirement's robustness can be: ``always``
#: over an empty window, a claim's "never") is stored as one of these strings in a run file.
_INFINITIES = {"inf": math.inf, "-inf": -math.inf}


def finite_or_none(metrics: dict) -> dict:
    """JSON has no NaN/inf: NaN is stored as null (read back as NaN), ±∞ as "inf"/"-inf"
    (read back as floats by `metric_values`)."""
    return {k: (None if math.isnan(v) else repr(v)) if isinstance(v, float)
            and not math.isfinite(v) else v for k, v in metrics.items()}


def metric_values(stored: dict) -> dict:
    """Metrics as read from a run file: null → NaN, "inf"/"-inf" → ±∞."""
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
