"""The code fingerprint stored with every run: a hash of the code that produced it.

A stored result may be reused only if it was made by the same code: every module (source
or bytecode), every package version and every compiled artefact that produced it.  The
files hashed are found, not listed: every project module that executing one run
(`validation.batch.worker`) can import — at module level or inside a function, directly
or through other modules — found by a static walk of the import statements
(`reduced_model.code.imports`), plus the ``__init__`` of every package on the way.  A module
that can change a stored signal or metric is imported by the run path, so none can be
left out; modules the run path never imports (the command line, the store, the reports,
the verdicts computed from stored metrics) stay out, and so does what it imports only to
show a result (`PRESENTATION`, with the packages only it imports): editing them leaves
stored runs valid.  Every installed package the run path imports (numpy, scipy, numba, Exudyn …)
enters with its version and its installed files' record (``RECORD``: a hash per file).

A plug-in law adds its own module and every module that one imports that is not part of
the Python installation (its helpers, wherever they live: a folder on ``PYTHONPATH``,
inside one of the project's packages, a sourceless ``.pyc``, an extension module, a zip
archive on ``sys.path`` — hashed whole, what it imports not followed), found the same
way, and every installed package it imports, the same way as the project's: a plug-in
installed with ``pip`` and upgraded is new code; a module in site-packages that no
distribution declares is hashed by its files, as the user's own.  Files are located without
importing anything, so reading a results folder never runs a plug-in's code.  Numba's
compiled artefacts are kept consistent with these sources by `reduced_model.code.cache_guard`.
"""
from __future__ import annotations

import functools
import hashlib
import re
from importlib.metadata import PackageNotFoundError, distribution, packages_distributions
from importlib.util import find_spec
from pathlib import Path

from reduced_model.code import walk

__all__ = ["code_fingerprint", "source_fingerprint", "run_fingerprint", "result_sources",
           "module_sources", "computed_by", "plugin_sources", "plugin_kinds",
           "forget_plugins", "is_fresh", "fingerprint_of", "fmu_of"]

_ROOT = Path(__file__).resolve().parents[2]
#: Where executing a run starts: everything it can import decides results.
RUN_ENTRY = "validation.batch.worker"
#: What the run path imports only to show a result, never to make one (`RunResult.plot`
#: draws with it): not walked, so that editing a figure (or upgrading matplotlib) leaves
#: stored runs valid.
PRESENTATION = ("validation.run.plotting",)
_PROJECT_PACKAGES = ("reduced_model", "plant_exudyn", "controllers", "validation")
#: The distribution name a requirement string starts with (PEP 508).
_REQUIREMENT = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")


@functools.lru_cache(maxsize=8)
def _module_walk(modules: tuple[str, ...]):
    return walk(list(modules), tuple(_ROOT / p for p in _PROJECT_PACKAGES), skip=PRESENTATION)


@functools.lru_cache(maxsize=8)
def module_sources(modules: tuple[str, ...]) -> tuple[Path, ...]:
    """The project files ``modules`` can import (module docstring: a static walk),
    sorted."""
    return tuple(sorted(set(_module_walk(modules).files.values())))


def result_sources() -> tuple[Path, ...]:
    """The project files the run path can import (module docstring), sorted."""
    return module_sources((RUN_ENTRY,))


def _hash_code(h, modules: tuple[str, ...]) -> None:
    """Hash into ``h`` the project files ``modules`` can import and the installed
    packages they reach."""
    _hash_files(h, module_sources(modules))
    _hash_packages(h, _module_walk(modules).packages)


@functools.cache
def _top_levels() -> dict:
    return packages_distributions()  # ~0.3 s: asked only for a module not named as its package


@functools.cache
def _distributions(top: str) -> tuple[str, ...]:
    """The distributions that install the top-level module ``top`` and, transitively,
    the ones they require (numba's llvmlite, say), sorted."""
    try:
        names = [distribution(top).name]
    except PackageNotFoundError:  # not installed (pandas, optional), or named otherwise
        names = list(_top_levels().get(top, ())) if find_spec(top) is not None else []
    found: set[str] = set()
    while names:
        name = _REQUIREMENT.match(names.pop()).group(0).lower().replace("_", "-")
        if name in found:
            continue
        try:
            requires = distribution(name).requires or []
        except PackageNotFoundError:
            continue
        found.add(name)
        names += [r for r in requires if "extra ==" not in r and _REQUIREMENT.match(r)]
    return tuple(sorted(found))


@functools.cache
def _distribution_record(name: str) -> str:
    """A distribution's name, version and the hash of its ``RECORD`` (a hash of every
    file it installed)."""
    dist = distribution(name)
    record = dist.read_text("RECORD") or ""
    return f"{name}=={dist.version}:{hashlib.sha256(record.encode()).hexdigest()[:16]}"


def _hash_files(h, files) -> None:
    for path in files:
        h.update(str(path.relative_to(_ROOT) if path.is_relative_to(_ROOT) else path.name)
                 .encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")


def _hash_packages(h, tops) -> None:
    for name in sorted({d for top in tops for d in _distributions(top)}):
        h.update(f"{_distribution_record(name)}\0".encode())
    if not all(_distributions(top) for top in tops):  # a module no distribution declares
        h.update(f"undeclared: {sorted(t for t in tops if not _distributions(t))}".encode())


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """16 hex digits identifying the result-deciding code of this installation."""
    h = hashlib.sha256(b"flexarm-validation\0")
    _hash_code(h, (RUN_ENTRY,))
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=8)
def source_fingerprint(libraries: tuple[str, ...]) -> str:
    """A hash of every source of the project's packages (and the report's templates) and
    the versions of ``libraries``: what made a value computed from stored runs (a
    report), which ``code_fingerprint`` (the run path alone) does not cover."""
    h = hashlib.sha256()
    for package in _PROJECT_PACKAGES:
        for path in sorted((_ROOT / package).rglob("*")):
            if path.suffix in (".py", ".j2") and "__pycache__" not in path.parts:
                h.update(str(path.relative_to(_ROOT)).encode() + b"\0" + path.read_bytes())
    for name in libraries:
        h.update(f"{name}={distribution(name).version}".encode())
    return h.hexdigest()


@functools.lru_cache(maxsize=8)
def computed_by(modules: tuple[str, ...]) -> str:
    """A hash of the code a value that only ``modules`` compute depends on (a stability
    map's predictions): the project files they can import (`module_sources`) and the
    installed packages they reach, as `code_fingerprint` hashes the run path's; editing
    another module (a report's) leaves the value valid."""
    h = hashlib.sha256("\0".join(modules).encode())
    _hash_code(h, modules)
    return h.hexdigest()


@functools.lru_cache(maxsize=64)
def _plugin_walk(module: str):
    # An installed module no distribution declares (copied into site-packages by hand)
    # has no version or record to stand for it: its files are hashed as the user's own.
    return walk([module], None, declared=lambda top: bool(_distributions(top)))


def forget_plugins() -> None:
    """Forget which files each plug-in imports and which distributions are installed
    (found once per process): for a caller that edits or installs plug-ins while it
    runs, such as a test."""
    for cached in (_plugin_walk, _top_levels, _distributions, _distribution_record):
        cached.cache_clear()


def plugin_sources(kind: str) -> tuple[Path, ...]:
    """The files of a plug-in's module and of the modules it imports from outside the
    Python installation, less the project files `code_fingerprint` covers, sorted;
    () if its module cannot be found."""
    covered = set(result_sources())
    files = _plugin_walk(kind.partition(":")[0]).files.values()
    return tuple(sorted(p for p in files if p not in covered))


def plugin_kinds(scenario: dict) -> list[str]:
    """The plug-ins ("package.module:Class") a scenario mapping names as its controller,
    observer or plant, sorted."""
    return sorted(k for k in (str(scenario.get(part, {}).get("kind", ""))
                              for part in ("controller", "observer", "plant")) if ":" in k)


def _fmu_of(scenario: dict) -> str | None:
    """The FMU file a scenario mapping's plant runs (``kind = "fmu"``), else None."""
    plant = scenario.get("plant", {})
    return str(plant.get("fmu") or "") if plant.get("kind") == "fmu" else None


def run_fingerprint(scenario: dict) -> str:
    """The fingerprint of one run's code: `code_fingerprint` plus its plug-ins' sources
    and installed packages, and an FMU plant's file (its SHA-256) and FMPy (its
    version and installed files)."""
    kinds, fmu = plugin_kinds(scenario), _fmu_of(scenario)
    if not kinds and fmu is None:
        return code_fingerprint()
    h = hashlib.sha256(code_fingerprint().encode())
    for kind in kinds:
        files = plugin_sources(kind)
        h.update(f"{kind}\0".encode())
        if files:
            _hash_files(h, files)
        else:
            h.update(b"unknown")
        _hash_packages(h, _plugin_walk(kind.partition(":")[0]).packages)
    if fmu is not None:
        from ..run.fmu import file_sha256  # hashes the file: runs none of its code
        h.update(f"fmu\0{file_sha256(fmu)}\0".encode())
        _hash_packages(h, ("fmpy",))
    return h.hexdigest()[:16]


def is_fresh(row) -> bool:
    """Whether the stored run ``row`` (`StoredRun`) was made by this installation's code:
    its fingerprint is the one its laws and plant would get now (their kinds are columns
    of the row: no scenario decoded, but for an FMU plant, whose file is in it)."""
    return row.fingerprint == fingerprint_of(row.controller, row.observer, row.plant,
                                             fmu_of(row))


def fmu_of(row) -> str | None:
    """The FMU file a stored run's plant ran (decoded from its scenario), else None."""
    return _fmu_of(row.config) if row.plant == "fmu" else None


def fingerprint_of(controller: str, observer: str, plant: str, fmu: str | None = None) -> str:
    """`run_fingerprint` of a run of these kinds of laws and plant (all that it reads of
    a scenario; ``fmu``: an FMU plant's file)."""
    return run_fingerprint({"controller": {"kind": controller}, "observer": {"kind": observer},
                            "plant": {"kind": plant, "fmu": fmu}})
