"""Keep numba's on-disk caches consistent with the compiled code, the project's and the
plug-ins'.

Numba keys a cached function on its *own* source file, but the machine code it caches
contains what it inlined or called from other files (the laws call the model's kernels,
the compiled sample calls the references and the plant's kernels, the kernels call the
intrinsics of `reduced_model._views`, a plug-in calls its helpers).  After a callee's
file changes, a cached caller would silently run the old callee.  So every file that
uses numba gets a key: its own text and the keys of the files whose names it imports
(found from its import statements, through package re-exports); a plug-in's files share
one key, made of all its files and of the project's keys.  Where a file's caches carry
another key they are deleted, so an edit recompiles what depends on it and nothing else.
Laws that compiled loops call through function pointers (`controllers._compiled`) are
not linked into them, so editing a law recompiles that law alone.

Caches are looked for wherever numba may have written them: the ``__pycache__`` beside
the source, the folder ``NUMBA_CACHE_DIR`` names, and numba's user-wide cache folder; each
holds a record of the keys its caches were built with (`KEYS_FILE`).  The project's
packages are the folders beside this package's that are packages; the check runs once per
process, when the first model is built (`fresh_kernel_caches`: every kernel works on a
model), never when a package is imported.
"""
from __future__ import annotations

import ast
import functools
import hashlib
import json
import os
import re
from pathlib import Path

from .imports import imports, walk

__all__ = ["kernel_keys", "fresh_kernel_caches", "invalidate_stale_plugin_caches",
           "cache_dirs", "KEYS_FILE"]

_ROOT = Path(__file__).resolve().parents[2]
#: The project's packages: this one and the package folders beside it.
_PACKAGES = tuple(sorted(p.name for p in _ROOT.iterdir() if (p / "__init__.py").is_file()))
#: A file that can define compiled code: it imports numba (njit, intrinsic, cfunc …).
_USES_NUMBA = re.compile(rb"^\s*(from|import)\s+numba\b", re.M)
#: The record, in a cache folder, of the key each source's caches were built with.
KEYS_FILE = "flexarm-numba-keys.json"


def _module_file(name: str) -> Path | None:
    path = _ROOT.joinpath(*name.split("."))
    for candidate in (path.with_suffix(".py"), path / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _imported_files(path: Path) -> set[Path]:
    """Project files defining the names ``path`` imports (following ``from .x import``
    re-exports of package ``__init__`` files)."""
    module = ".".join(path.relative_to(_ROOT).with_suffix("").parts).removesuffix(".__init__")
    out = set()
    for source, names in imports(path, module):
        if source.split(".")[0] not in _PACKAGES:
            continue
        for name in names:  # ``import X`` names none: only ``from X import name`` counts
            found = _defining_file(source, name, depth=0)
            if found is not None:
                out.add(found)
    return out


def _defining_file(module: str, name: str, depth: int) -> Path | None:
    """The file that defines ``name`` imported from ``module`` (a submodule named
    ``name``, the module itself, or — for a package — where its ``__init__`` takes it from)."""
    sub = _module_file(f"{module}.{name}")
    if sub is not None:
        return sub
    path = _module_file(module)
    if path is None or path.name != "__init__.py" or depth > 8:
        return path
    for node in ast.walk(ast.parse(path.read_bytes())):  # the names an alias re-exports
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module and any(
                (a.asname or a.name) == name for a in node.names):
            return _defining_file(f"{module}.{node.module}", name, depth + 1)
    return path


def _uses_numba(path: Path) -> bool:
    return path.suffix == ".py" and bool(_USES_NUMBA.search(path.read_bytes()))


def kernel_keys() -> dict[str, str]:
    """Relative path → key of every project file that uses numba."""
    sources = {p for package in _PACKAGES for p in (_ROOT / package).rglob("*.py")
               if _uses_numba(p)}
    deps = {p: {d for d in _imported_files(p) if d in sources and d != p} for p in sources}
    keys: dict[Path, str] = {}

    def key(p: Path, seen: tuple) -> str:
        if p not in keys:
            h = hashlib.sha256(p.read_bytes())
            for d in sorted(deps[p]):
                if d not in seen:  # an import cycle adds nothing new
                    h.update(key(d, (*seen, p)).encode())
            keys[p] = h.hexdigest()
        return keys[p]

    return {str(p.relative_to(_ROOT)): key(p, ()) for p in sorted(sources)}


def cache_dirs(source: Path) -> list[Path]:
    """Every folder numba may cache ``source``'s functions in, in the order numba tries
    them: under ``NUMBA_CACHE_DIR`` if it is set, beside the source, in numba's user-wide
    cache folder (numba's own locators name the first and the last)."""
    from numba.core import config
    from numba.core.caching import _CacheLocator
    from numba.misc.appdirs import AppDirs
    sub = _CacheLocator.get_suitable_cache_subpath(str(source))
    dirs = [source.parent / "__pycache__",
            Path(AppDirs(appname="numba", appauthor=False).user_cache_dir) / sub]
    if config.CACHE_DIR:
        dirs.insert(0, Path(config.CACHE_DIR) / sub)
    return dirs


def _invalidate(keys: dict[Path, str]) -> None:
    """Delete the caches of each source whose folder records another key for it, in
    every cache folder that exists, and record the keys there; the folder numba will
    write to is made first, so that what it caches next is recorded with its key."""
    by_dir: dict[Path, dict[str, str]] = {}
    first: set[Path] = set()
    for source, key in keys.items():
        dirs = cache_dirs(source)
        first.add(dirs[0])
        for folder in dirs:
            by_dir.setdefault(folder, {})[source.name] = key
    for folder, wanted in by_dir.items():
        record = folder / KEYS_FILE
        try:
            if folder in first:
                folder.mkdir(parents=True, exist_ok=True)
            elif not folder.is_dir():
                continue
            old = json.loads(record.read_text()) if record.is_file() else {}
            stale = [name for name, key in wanted.items() if old.get(name) != key]
            for name in stale:
                for pattern in ("*.nbi", "*.nbc"):
                    for cached in folder.glob(f"{Path(name).stem}.{pattern}"):
                        cached.unlink(missing_ok=True)
            if stale:
                temporary = record.with_name(f"{KEYS_FILE}.{os.getpid()}")
                temporary.write_text(json.dumps({**old, **wanted}, indent=0, sort_keys=True))
                temporary.replace(record)  # atomic: a process starting beside reads one
        except (OSError, ValueError):  # a folder it cannot read or write: numba cannot either
            continue


@functools.cache  # once per process, before its first kernel runs
def fresh_kernel_caches() -> None:
    """Delete the cached kernels of every project file whose key changed since its caches
    were built (module docstring)."""
    try:
        keys = kernel_keys()
    except (OSError, SyntaxError):  # a tree that cannot be read cannot be compiled either
        return
    _invalidate({_ROOT / rel: key for rel, key in keys.items()})


@functools.cache
def invalidate_stale_plugin_caches(module: str) -> None:
    """The same for the plug-in module ``module`` and the files it imports from outside
    the Python installation, before it is imported (once per process): their caches are
    kept only if none of those files and none of the project's compiled files changed."""
    try:
        files = [p for p in walk([module], None).files.values()
                 if not p.is_relative_to(_ROOT)]
        compiled = [p for p in files if _uses_numba(p)]
        if not compiled:
            return
        h = hashlib.sha256(json.dumps(kernel_keys(), sort_keys=True).encode())
        for path in sorted(files):
            h.update(str(path).encode() + b"\0" + path.read_bytes() + b"\0")
    except (OSError, SyntaxError):
        return
    _invalidate({p: h.hexdigest() for p in compiled})
