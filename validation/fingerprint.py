"""The code fingerprint stored with every run: a hash of the code that produced it.

A stored result may be reused only if it was made by the same code.  The fingerprint
hashes the package version, the Exudyn version, and the source of every module that
decides a result (plants, models, laws, the closed loop, metrics) — the installed files
as they are, committed or not — plus, for a plug-in law, the source file of its module.
Reports, the CLI and the store do not enter it: changing them does not invalidate runs.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.util
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["code_fingerprint", "run_fingerprint"]

_ROOT = Path(__file__).resolve().parent.parent
#: Everything that decides a stored result (signals and metrics).
RESULT_SOURCES = ("reduced_model", "plant_exudyn", "controllers", "validation/loop.py",
                  "validation/laws.py", "validation/scenario.py", "validation/_config.py",
                  "validation/metrics.py", "validation/results.py")


def _version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "?"


def _hash_files(h, files) -> None:
    for path in files:
        h.update(str(path.relative_to(_ROOT) if path.is_relative_to(_ROOT) else path.name)
                 .encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """16 hex digits identifying the result-deciding code of this installation."""
    h = hashlib.sha256()
    h.update(f"flexarm-validation {_version('flexarm-validation')} exudyn "
             f"{_version('exudyn')}\0".encode())
    files = []
    for entry in RESULT_SOURCES:
        path = _ROOT / entry
        files += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    _hash_files(h, files)
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=64)
def _plugin_source(kind: str) -> str:
    module = kind.partition(":")[0]
    try:
        spec = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.origin or not Path(spec.origin).is_file():
        return f"{module}:unknown"
    h = hashlib.sha256()
    _hash_files(h, [Path(spec.origin)])
    return h.hexdigest()[:16]


def run_fingerprint(scenario: dict) -> str:
    """The fingerprint of one run's code: `code_fingerprint` plus its plug-ins' sources."""
    kinds = sorted(k for k in (scenario.get("controller", {}).get("kind", ""),
                               scenario.get("observer", {}).get("kind", "")) if ":" in k)
    if not kinds:
        return code_fingerprint()
    h = hashlib.sha256(code_fingerprint().encode())
    for kind in kinds:
        h.update(f"{kind}={_plugin_source(kind)}".encode())
    return h.hexdigest()[:16]
