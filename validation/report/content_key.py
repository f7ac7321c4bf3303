"""Whether a report shows what its results folder holds now: its *content key* hashes
the stored runs it reads (ids, checksums, whether each is fresh), the campaigns' report
settings, the stability map's runs, the calibration and validity files, the code and
library versions that draw it, and the options; an unchanged key leaves the report as it
is (`validation.report.report.write_report`)."""
from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

from ..batch.fingerprint import run_fingerprint
from ..batch.store import ResultStore

__all__ = ["content_key", "report_is_current", "paths"]

_KEY_FILE = ".content-key"


@functools.lru_cache(maxsize=1)
def _drawing_code() -> str:
    """A hash of the code and libraries that turn stored runs into a report."""
    from importlib.metadata import version

    from ..run.plants import ENGINE_PACKAGES
    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[2]
    for package in ("validation", "reduced_model", "plant_exudyn", "controllers"):
        for path in sorted((root / package).rglob("*")):
            if path.suffix in (".py", ".j2") and "__pycache__" not in path.parts:
                h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    for name in ("matplotlib", "jinja2", "numpy", "scipy", *ENGINE_PACKAGES):
        h.update(f"{name}={version(name)}".encode())
    return h.hexdigest()


def _rows_digest(store: ResultStore) -> list:
    if not store.exists():
        return []
    return sorted([r.run_id, r.sha256, r.size, r.status, r.name, r.sweep, r.axes,
                   r.fingerprint == run_fingerprint(r.config)] for r in store.rows())


def content_key(results_dir, *, animate: bool) -> str:
    """The hash of everything a report of ``results_dir`` shows (module docstring)."""
    store = ResultStore(results_dir)
    validity = store.out / "validity" / "validity.json"
    calibration = store.out / "calibration.json"
    parts = {"runs": _rows_digest(store), "campaigns": store.campaigns(),
             "calibration": hashlib.sha256(calibration.read_bytes()).hexdigest()
             if calibration.is_file() else "",
             "stability": _rows_digest(ResultStore(store.out / "stability")),
             "validity": hashlib.sha256(validity.read_bytes()).hexdigest()
             if validity.is_file() else "",
             "code": _drawing_code(), "animate": animate}
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def paths(results_dir) -> tuple[Path, Path, Path]:
    out = ResultStore(results_dir).out / "report"
    return out / "report.html", out / "report.md", out / _KEY_FILE


def report_is_current(results_dir, *, animate: bool = True) -> bool:
    """Whether the report of ``results_dir`` exists and shows what the folder holds now
    (the same content key)."""
    html_path, md_path, key_path = paths(results_dir)
    return (html_path.is_file() and md_path.is_file() and key_path.is_file()
            and key_path.read_text().strip() == content_key(results_dir, animate=animate))

