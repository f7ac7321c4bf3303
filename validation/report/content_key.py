"""Whether a report shows what its results folder holds now: its *content key* hashes
the stored runs it reads (ids, checksums, whether each is fresh), the campaigns' report
settings, the stability map's runs, the calibration and validity files, the code and
library versions that draw it, and the options; an unchanged key leaves the report as it
is (`validation.report.report.write_report`)."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ..batch.fingerprint import fingerprint_of, source_fingerprint
from ..batch.store.folder import ResultStore
from .record import RECORD_FILE

__all__ = ["content_key", "report_is_current", "paths"]

_KEY_FILE = ".content-key"


def _drawing_code() -> str:
    """A hash of the code and libraries that turn stored runs into a report."""
    from ..run.plants import ENGINE_PACKAGES
    return source_fingerprint(("matplotlib", "jinja2", "numpy", "scipy", *ENGINE_PACKAGES))


#: The columns of a stored run its content key hashes (its detail whole: swept values
#: included, never decoded), in `StoredRun` 's field names.
_KEY_COLUMNS = ("run_id", "sha256", "size", "status", "name", "sweep", "fingerprint",
                "controller", "observer", "plant")


def _rows_digest(store: ResultStore, rows: list | None = None) -> str:
    """A hash of what the report reads of each stored run of ``store``: from ``rows``,
    every row of it already read (`StoredRun` s), or else read in one query (~0.25 s for
    40,000 runs, against 0.4 s to read their `StoredRun` s first)."""
    if rows is not None:
        values = sorted((*(getattr(r, c) for c in _KEY_COLUMNS), r.detail.blob) for r in rows)
    elif not store.exists():
        return ""
    else:
        store.rows(where="0")  # refuses an index it cannot read
        values = store.columns([*_KEY_COLUMNS, "detail"], where="1 ORDER BY run_id")
    now, parts = {}, []
    for run, sha, size, status, name, sweep, made_by, *kinds, detail in values:
        kinds = tuple(kinds)
        if kinds not in now:  # the fingerprint each kind of run gets from this code
            now[kinds] = fingerprint_of(*kinds)
        parts.append(f"{run}\0{sha}\0{size}\0{status}\0{name}\0{sweep}\0{made_by}\0"
                     f"{made_by == now[kinds]}\0".encode())
        parts.append(detail)
    return hashlib.sha256(b"".join(parts)).hexdigest()


def content_key(results_dir, *, animate: bool, rows: list | None = None) -> str:
    """The hash of everything a report of ``results_dir`` shows (module docstring);
    ``rows``: every stored run of it, if already read (the same key, sooner)."""
    store = ResultStore(results_dir)
    validity = store.out / "validity" / "validity.json"
    calibration = store.out / "calibration.json"
    parts = {"runs": _rows_digest(store, rows), "campaigns": store.campaigns(),
             "calibration": hashlib.sha256(calibration.read_bytes()).hexdigest()
             if calibration.is_file() else "",
             "stability": _rows_digest(ResultStore(store.out / "stability")),
             "validity": hashlib.sha256(validity.read_bytes()).hexdigest()
             if validity.is_file() else "",
             "code": _drawing_code(), "animate": animate}
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def paths(results_dir) -> tuple[Path, Path, Path, Path]:
    """report.html, report.md, the report's record (`record.RECORD_FILE`) and its
    content key's file in ``results_dir``."""
    out = ResultStore(results_dir).out
    return (out / "report" / "report.html", out / "report" / "report.md", out / RECORD_FILE,
            out / "report" / _KEY_FILE)


def report_is_current(results_dir, *, animate: bool = True) -> bool:
    """Whether the report of ``results_dir`` exists and shows what the folder holds now
    (the same content key)."""
    *reports, key_path = paths(results_dir)
    return (all(p.is_file() for p in reports) and key_path.is_file()
            and key_path.read_text().strip() == content_key(results_dir, animate=animate))

