"""The code fingerprint stored with every run: a hash of the code that produced it.

A stored result may be reused only if it was made by the same code.  The files hashed
are found, not listed: every project module that executing one run
(`validation.batch.worker`) can import — at module level or inside a function, directly
or through other modules — found by a static walk of the import statements (`ast`),
plus the ``__init__`` of every package on the way.  A module that can change a stored
signal or metric is imported by the run path, so none can be left out; modules the run
path never imports (the command line, the store, the reports, the verdicts computed
from stored metrics) stay out, and editing them leaves stored runs valid.

A plug-in law adds its own module and every module that one imports from outside the
Python installation (its helpers), found the same way: files are located on
``sys.path`` without importing anything, so reading a results folder never runs a
plug-in's code.  A plug-in imported from a zip archive is hashed as the whole archive.  The package and Exudyn versions enter too.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.machinery
import sys
import sysconfig
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from reduced_model._imports import imports

__all__ = ["code_fingerprint", "run_fingerprint", "result_sources", "plugin_sources"]

_ROOT = Path(__file__).resolve().parents[2]
#: Where executing a run starts: everything it can import decides results.
RUN_ENTRY = "validation.batch.worker"
_PROJECT_PACKAGES = ("reduced_model", "plant_exudyn", "controllers", "validation")


def _version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "?"


def _imports(path: Path, module: str) -> set[str]:
    """Absolute names of every module ``path`` (the module ``module``) imports, including
    the names ``from X import name`` may mean as submodules."""
    out = set()
    for source, names in imports(path, module):
        out.add(source)
        out.update(f"{source}.{name}" for name in names)
    return out


def _locate(name: str, inside: tuple[str, ...] | None) -> Path | None:
    """The source file of module ``name`` found on ``sys.path`` without importing it
    (None if there is none, or it is not under one of the roots ``inside``)."""
    parts = name.split(".")
    search = None
    spec = None
    for i in range(len(parts)):
        try:
            spec = importlib.machinery.PathFinder.find_spec(".".join(parts[:i + 1]), search)
        except (ImportError, ValueError):
            return None
        if spec is None:
            return None
        search = spec.submodule_search_locations
    origin = getattr(spec, "origin", None)
    if not origin or not origin.endswith(".py"):
        return None
    # A module in a zip archive on sys.path (zipimport) has no file of its own: the
    # archive stands for it, hashed whole (what it imports is not followed).
    path = Path(getattr(spec.loader, "archive", None) or origin).resolve()
    if inside is not None and not any(path.is_relative_to(root) for root in inside):
        return None
    return path


def _walk(start: list[str], inside) -> dict[str, Path]:
    """Module name → file of ``start`` and everything it imports (transitively) whose file
    lies under ``inside`` (None: anywhere but the Python installation).  Each name is
    looked up once; with ``inside``, only names of packages that live there are (the
    rest of the world cannot), without it the standard library is skipped by name."""
    found: dict[str, Path] = {}
    seen: set[str] = set()
    local = None if inside is None else {root.name for root in inside}
    todo = list(start)
    while todo:
        name = todo.pop()
        if not name or name in seen:
            continue
        seen.add(name)
        top = name.partition(".")[0]
        if (local is not None and top not in local) or top in sys.stdlib_module_names:
            continue
        path = _locate(name, inside)
        if path is None or (inside is None and _installed(path)):
            continue
        found[name] = path
        parent = name.rpartition(".")[0]
        todo.append(parent)  # a package's __init__ runs before its modules
        try:
            todo.extend(_imports(path, name))
        except (SyntaxError, ValueError, OSError):
            pass  # a file Python cannot parse imports nothing (and runs nothing); hashed
    return found


def _installed(path: Path) -> bool:
    """Whether ``path`` belongs to the Python installation (standard library or an
    installed package), not to the user's own code."""
    roots = {sysconfig.get_paths()[k] for k in ("stdlib", "platstdlib", "purelib", "platlib")}
    return any(path.is_relative_to(Path(r).resolve()) for r in roots if r)


@functools.lru_cache(maxsize=1)
def result_sources() -> tuple[Path, ...]:
    """The project files the run path can import (module docstring), sorted."""
    inside = tuple(_ROOT / p for p in _PROJECT_PACKAGES)
    return tuple(sorted(set(_walk([RUN_ENTRY], inside).values())))


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
    _hash_files(h, result_sources())
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=64)
def plugin_sources(kind: str) -> tuple[Path, ...]:
    """The files of a plug-in's module and of the modules it imports from outside the
    Python installation and outside this project (whose files `code_fingerprint`
    covers), sorted; () if its module cannot be found."""
    module = kind.partition(":")[0]
    project = tuple(_ROOT / p for p in _PROJECT_PACKAGES)
    files = _walk([module], None).values()
    return tuple(sorted(p for p in files if not any(p.is_relative_to(r) for r in project)))


def run_fingerprint(scenario: dict) -> str:
    """The fingerprint of one run's code: `code_fingerprint` plus its plug-ins' sources."""
    kinds = sorted(k for k in (scenario.get("controller", {}).get("kind", ""),
                               scenario.get("observer", {}).get("kind", "")) if ":" in k)
    if not kinds:
        return code_fingerprint()
    h = hashlib.sha256(code_fingerprint().encode())
    for kind in kinds:
        files = plugin_sources(kind)
        h.update(f"{kind}\0".encode())
        if files:
            _hash_files(h, files)
        else:
            h.update(b"unknown")
    return h.hexdigest()[:16]
