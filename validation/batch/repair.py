"""Repairing a results folder: rebuild its index from the run files whatever the damage,
and adopt a run file that has no row (`ResultStore.repair`, `ResultStore.adopt`)."""
from __future__ import annotations

import sqlite3
from pathlib import Path

from ..run.results import RunResult
from .index import COLUMNS, INDEX_NAME, StoreError, insert_row, is_run_id, run_id, set_aside
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
    directories and files not named by a run id are skipped.  Returns the run ids (or
    names) per action."""
    report = {"rebuilt": [], "adopted": [], "dropped": [], "unreadable": [], "skipped": []}
    index = store.index_path
    odd = index.is_symlink() or (index.exists() and not index.is_file())
    if odd or (store.exists() and not _index_sound(store)):
        store.close()
        kept = set_aside(index)
        for suffix in ("-wal", "-shm"):
            Path(f"{index}{suffix}").unlink(missing_ok=True)
        why = "not a file" if odd else "unreadable"
        report["rebuilt"].append(f"{INDEX_NAME} ({why}; kept as {kept.name})")
    try:
        db = store._connect(create=True)
        for values in db.execute(f"SELECT {', '.join(COLUMNS)} FROM runs").fetchall():
            try:
                store._stored_run(values)
            except StoreError:  # no path is built from it: its id may be anything
                db.execute("DELETE FROM runs WHERE run_id = ?", (values[0],))
                report["dropped"].append(f"{str(values[0])[:40]!r} (not a stored run)")
        for rid, why in store.verify().items():  # the file, if intact, is adopted below
            db.execute("DELETE FROM runs WHERE run_id = ?", (rid,))
            report["dropped"].append(f"{rid} ({why})")
    except sqlite3.Error as exc:
        raise store._error(exc) from None
    for path in store._run_files():
        if not path.is_file() or not is_run_id(path.stem):
            report["skipped"].append(f"runs/{path.name} (not a run file)")
    for path in store.unindexed_files():
        try:
            adopt(store, path)
        except ValueError as exc:
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
        db = store._connect(create=False)
        sound = db.execute("PRAGMA quick_check").fetchone()[0] == "ok"
        db.execute(f"SELECT {', '.join(COLUMNS)} FROM runs").fetchall()
    except sqlite3.Error as exc:
        error = store._error(exc)
        if isinstance(error, OSError) or not store.writable():
            raise error from None
        return False
    except StoreError:
        if not store.writable():
            raise
        return False
    return sound

def adopt(store, path: Path):
    """Index a run file that has no row (its metadata holds everything); ValueError if
    it is not a readable run file, or its scenario does not hash to its name."""
    path = Path(path)
    if not is_run_id(path.stem):
        raise ValueError(f"{path.name} is not named by a run id")
    try:  # a FIFO, a device or a sparse giant is never read
        if not path.is_file() or path.stat().st_size > MAX_RUN_BYTES:
            raise ValueError(f"not a regular run file of at most {MAX_RUN_BYTES >> 30} GiB")
        data = path.read_bytes()
    except OSError as exc:
        raise ValueError(f"unreadable ({exc.strerror or exc})") from None
    result, meta = RunResult.from_bytes(data)
    if not isinstance(result.config, dict) or run_id(result.config) != path.stem:
        raise ValueError(f"its scenario does not hash to its name {path.stem} (a copy of "
                         "another run's file?)")
    insert_row(store._connect(create=True), run_row(path.stem, result, meta, data))
    return store.row(path.stem)
