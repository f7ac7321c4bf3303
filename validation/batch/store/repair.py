"""Repairing a results folder: rebuild its index from the run files whatever the damage,
and adopt a run file that has no row (`ResultStore.repair`, `ResultStore.adopt`).  Uses
only the store's public methods."""
from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path

from ...run.results import RunResult
from .errors import NotARunFile, StoreError
from .index import (FIXED, INDEX_NAME, decode_detail, detail_rest, is_run_id, metric_sets,
                    row_values, run_id, set_aside)
from .runfiles import run_row

__all__ = ["repair", "adopt", "MAX_RUN_BYTES"]

#: The largest run file adopted: the largest run a scenario may ask for (5e6 samples of
#: ~60 float32 signals, `validation.run.scenario.MAX_SAMPLES`) takes 1.2 GB.
MAX_RUN_BYTES = 4 << 30


def repair(store) -> dict[str, list[str]]:
    """Rebuild the index from the run files, whatever the damage: an index that is not a
    file (a folder, a link) or that SQLite cannot read or check (a corrupt page, an empty
    or truncated file) is set aside as ``index.sqlite.damaged`` and rebuilt; rows that
    are not stored runs are dropped without touching any path; rows whose file is
    missing or damaged are dropped; every run file without a row (those included) is
    adopted if it is a readable run file whose scenario hashes to its name — an intact
    file is kept whatever its row said — else kept as ``runs/<id>.npz.damaged``;
    directories and files not named by a run id are skipped.  The runs that keep metrics
    only (no file) of an index set aside are copied from it where SQLite can still read
    them and their scenario hashes to their id ("salvaged").  Returns the run ids (or
    names) per action."""
    report = {"rebuilt": [], "adopted": [], "dropped": [], "unreadable": [], "skipped": [],
              "salvaged": []}
    index = store.index_path
    odd = index.is_symlink() or (index.exists() and not index.is_file())
    if odd or (store.exists() and not _index_sound(store)):
        store.close()
        kept = set_aside(index)
        for suffix in ("-wal", "-shm"):
            Path(f"{index}{suffix}").unlink(missing_ok=True)
        why = "not a file" if odd else "unreadable"
        report["rebuilt"].append(f"{INDEX_NAME} ({why}; kept as {kept.name})")
        store.prepare()
        if not odd:
            report["salvaged"] = _salvage(store, kept)
    store.prepare()
    bad = {rid: row for rid, row in store.scan() if isinstance(row, str)}
    store.discard(bad)  # no path is built from them: their ids may be anything
    report["dropped"] += [f"{str(rid)[:40]!r} (not a stored run: {why})"
                          for rid, why in bad.items()]
    damaged = store.verify()
    damaged |= _unlike_their_files(store, [r for r in store.rows()
                                           if r.has_file and r.run_id not in damaged])
    store.discard(damaged)  # the file, if intact, is adopted below
    report["dropped"] += [f"{rid} ({why})" for rid, why in damaged.items()]
    for path in store.run_files():
        if not path.is_file() or not is_run_id(path.stem):
            report["skipped"].append(f"runs/{path.name} (not a run file)")
    for path in store.unindexed_files():
        try:
            adopt(store, path)
        except NotARunFile as exc:
            set_aside(path)
            report["unreadable"].append(f"{path.stem} ({exc})")
            continue
        report["adopted"].append(path.stem)
    return report


def _index_sound(store) -> bool:
    """Whether SQLite can open the index, finds every page of it sound and can read
    every row (a full disk or a read-only folder is raised, not taken for damage)."""
    store.close()
    try:
        db = store.connection(create=False)
        sound = db.execute("PRAGMA quick_check").fetchone()[0] == "ok"
        db.execute("SELECT * FROM runs").fetchall()
    except sqlite3.Error as exc:
        error = store.error(exc)
        if isinstance(error, OSError) or not store.writable():
            raise error from None
        return False
    except StoreError:
        if not store.writable():
            raise
        return False
    return sound


def _unlike_their_files(store, rows) -> dict[str, str]:
    """Run id → the columns in which its index row differs from its run file, of ``rows``
    (rows whose file verifies): a reader takes from the row what the file says, or the
    row is rebuilt from the file."""
    names, layouts, unlike = store.column_names(), store.layouts(), {}
    for row in rows:
        try:
            built, encoded = _file_row(store.out / row.file)
        except NotARunFile as exc:
            unlike[row.run_id] = str(exc)
            continue
        fixed, m_names, m_values, a_names, a_values = encoded
        (held,) = store.columns(["*"], where="run_id = ?", params=(row.run_id,))
        held = dict(zip(names, held))
        want = {**dict(zip(FIXED, fixed)), **{"m:" + n: v for n, v in zip(m_names, m_values)},
                **{"a:" + n: v for n, v in zip(a_names, a_values)}}
        wrong = [c for c, v in want.items() if c not in ("dictionary", "detail")
                 and not _same(held.get(c, ...), v)]
        if layouts.get(held["metric_set"]) != (a_names, m_names):
            wrong.append("metric_set")
        try:
            rest = row.detail.decoded()[1]
        except ValueError:
            rest = None
        if rest != json.loads(json.dumps(detail_rest(built))):
            wrong.append("detail")
        if wrong:
            unlike[row.run_id] = f"its row differs from its file: {', '.join(wrong[:4])}" \
                                 f"{', ...' if len(wrong) > 4 else ''}"
    return unlike


def _same(held, value) -> bool:
    """Whether an index column holds ``value`` (NULL for a NaN, which SQLite cannot hold)."""
    return held == value or (held is None and isinstance(value, float) and math.isnan(value))


def _file_row(path: Path) -> tuple[dict, tuple]:
    """(the index row, its encoding: `row_values`) that run file ``path`` makes;
    `NotARunFile` if it is not a readable run file, or its scenario does not hash to its
    name."""
    if not is_run_id(path.stem):
        raise NotARunFile(f"{path.name} is not named by a run id")
    try:  # a FIFO, a device or a sparse giant is never read
        if not path.is_file() or path.stat().st_size > MAX_RUN_BYTES:
            raise NotARunFile(f"not a regular run file of at most {MAX_RUN_BYTES >> 30} GiB")
        data = path.read_bytes()
    except OSError as exc:
        raise NotARunFile(f"unreadable ({exc.strerror or exc})") from None
    try:
        result, meta = RunResult.from_bytes(data)
        row = run_row(path.stem, result, meta, data)
        values = row_values(row)
    except (ValueError, TypeError, AttributeError) as exc:
        raise NotARunFile(str(exc)) from None
    if not isinstance(result.config, dict) or run_id(result.config) != path.stem:
        raise NotARunFile(f"its scenario does not hash to its name {path.stem} (a copy of "
                          "another run's file?)")
    return row, values


def adopt(store, path: Path):
    """Index a run file that has no row (its metadata holds everything); `NotARunFile` if
    it is not a readable run file, or its scenario does not hash to its name."""
    path = Path(path)
    store.insert([_file_row(path)[1]])
    return store.row(path.stem)


def _salvage(store, damaged: Path) -> list[str]:
    """Copy the runs without a file (metrics only) that SQLite can still read from the
    index set aside as ``damaged`` into the new one; their ids."""
    salvaged, rows, dictionaries = [], [], {}
    try:
        db = sqlite3.connect(f"{damaged.resolve().as_uri()}?mode=ro", uri=True)
        try:
            sets = {i: s for i, s in metric_sets(db).items() if not isinstance(s, str)}
            dictionaries = dict(db.execute("SELECT key, data FROM dictionaries"))
            cursor = db.execute("SELECT * FROM runs WHERE file = ''")
            names = [d[0] for d in cursor.description]
            for values in cursor:
                row = dict(zip(names, values))
                try:
                    scenario, _ = decode_detail(row["detail"], dictionaries[row["dictionary"]]
                                                if row["dictionary"] else b"")
                    a_names, m_names = sets[row["metric_set"]]
                except (KeyError, ValueError):
                    continue
                if not is_run_id(row["run_id"]) or run_id(json.loads(scenario)) != row["run_id"]:
                    continue
                rows.append((tuple(row[c] for c in FIXED), m_names,
                             tuple(row["m:" + n] for n in m_names), a_names,
                             tuple(row["a:" + n] for n in a_names)))
                salvaged.append(row["run_id"])
        finally:
            db.close()
    except sqlite3.Error:
        pass  # what was read before the damage is kept
    for key in {r[0][FIXED.index("dictionary")] for r in rows} - {""}:
        store.add_dictionary(dictionaries[key])
    store.insert(rows)
    return salvaged
