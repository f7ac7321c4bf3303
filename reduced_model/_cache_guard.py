"""Keep numba's on-disk caches consistent with the project's compiled code.

Numba keys a cached function on its *own* source file, but the machine code it caches
contains what it inlined or called from other files (the laws call the model's kernels,
the compiled sample calls the references and the plant's kernels).  After a callee's
file changes, a cached caller would silently run the old callee.  On import, each
project file that defines compiled code gets a key: its own text and the keys of the
project files whose compiled functions it imports (found from its import statements,
through package re-exports).  Only the caches of files whose key changed are deleted,
so an edit recompiles what depends on it and nothing else.  Laws that compiled loops
call through function pointers (`controllers._compiled`) are not linked into them, so
editing a law recompiles that law alone.
"""
from __future__ import annotations

import ast
import hashlib
import json
import re
from pathlib import Path

from ._imports import imports

_PACKAGES = ("reduced_model", "controllers", "plant_exudyn", "validation")
_ROOT = Path(__file__).resolve().parent.parent
_STAMP = Path(__file__).resolve().parent / "__pycache__" / "numba_kernels.json"
_COMPILED = re.compile(rb"^@njit", re.M)  # a file that defines compiled functions


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


def kernel_keys() -> dict[str, str]:
    """Relative path → key of every project file that defines compiled code."""
    sources = {p for package in _PACKAGES for p in (_ROOT / package).rglob("*.py")
               if _COMPILED.search(p.read_bytes())}
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


def invalidate_stale_kernel_caches() -> None:
    """Delete the cached kernels of every file whose key changed since the caches were
    built (module docstring)."""
    try:
        keys = kernel_keys()
        old = json.loads(_STAMP.read_text()) if _STAMP.exists() else {}
        for rel, key in keys.items():
            if old.get(rel) == key:
                continue
            source = _ROOT / rel
            for pattern in ("*.nbi", "*.nbc"):
                for cached in (source.parent / "__pycache__").glob(f"{source.stem}.{pattern}"):
                    cached.unlink(missing_ok=True)
        if keys != old:
            _STAMP.parent.mkdir(exist_ok=True)
            _STAMP.write_text(json.dumps(keys, indent=0))
    except (OSError, ValueError, SyntaxError):  # read-only install: nothing can go stale
        pass
