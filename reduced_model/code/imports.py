"""What code a module can run, read without importing it: the import statements of a
source file (`ast`) or of a sourceless ``.pyc`` (its bytecode), and the walk from a module
to every file it can import.  The code fingerprint, the numba cache guard and the house
tests use it.

Modules are located the way ``import`` would find them (the finders on ``sys.meta_path``
for a top-level name, which is how an editable install is found; the path finder below
it) without executing any module: reading a results folder never runs a plug-in's code.
"""
from __future__ import annotations

import ast
import dis
import importlib.machinery
import importlib.util
import marshal
import site
import sys
import sysconfig
import types
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["imports", "Walk", "walk", "installed"]

#: The bytes of a ``.pyc`` before its marshalled code object (PEP 552).
_PYC_HEADER = 16


def imports(path: Path, module: str, *, nested: bool = True) -> list[tuple[str, tuple[str, ...]]]:
    """(absolute module, names imported from it) of each import statement of the file
    ``path``, the module ``module`` (a package's name for its ``__init__``): relative
    imports resolved; ``import X`` gives (X, ()).  ``nested``: statements inside functions
    too (lazy imports), else the module level only.  A ``.pyc`` is read from its bytecode
    (every import it executes, nested or not); any other file (an extension module)
    imports nothing that can be read."""
    path = Path(path)
    package = module if path.stem == "__init__" else module.rpartition(".")[0]
    if path.suffix == ".pyc":
        code = marshal.loads(path.read_bytes()[_PYC_HEADER:])
        return [(_absolute(package, level, name), names)
                for level, name, names in _bytecode_imports(code)]
    if path.suffix != ".py":
        return []
    tree = ast.parse(path.read_bytes(), filename=str(path))
    out = []
    for node in (_statements(tree.body) if nested else tree.body):
        if isinstance(node, ast.Import):
            out += [(alias.name, ()) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            out.append((_absolute(package, node.level, node.module or ""),
                        tuple(alias.name for alias in node.names)))
    return out


#: The fields of a node that hold statements: an import is a statement, so it stands only
#: in these (a function's or class's body, a branch, a handler, a ``case``), never in an
#: expression.
_STATEMENT_LISTS = ("body", "orelse", "finalbody", "handlers", "cases")


def _statements(body: list):
    """Every statement of ``body`` and of the statement lists nested in it, expressions
    not entered (a tenth of the nodes of a whole-tree walk)."""
    for node in body:
        yield node
        for name in _STATEMENT_LISTS:
            inner = getattr(node, name, None)
            if isinstance(inner, list):
                yield from _statements(inner)


def _absolute(package: str, level: int, name: str) -> str:
    if not level:
        return name
    base = package.split(".")[:len(package.split(".")) - level + 1]
    return ".".join(base + ([name] if name else []))


def _bytecode_imports(code: types.CodeType):
    """(level, module, fromlist) of every IMPORT_NAME in ``code`` and its nested code:
    the compiler emits ``LOAD_CONST level; LOAD_CONST fromlist; IMPORT_NAME module``."""
    consts: list = []
    for ins in dis.get_instructions(code):
        if ins.opname == "LOAD_CONST":
            consts.append(ins.argval)
        elif ins.opname == "IMPORT_NAME" and len(consts) >= 2:
            level, fromlist = consts[-2], consts[-1]
            names = tuple(n for n in (fromlist or ()) if isinstance(n, str) and n != "*")
            yield (level if isinstance(level, int) else 0), ins.argval, names
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            yield from _bytecode_imports(const)


def installed(path: Path) -> bool:
    """Whether ``path`` belongs to the Python installation (the standard library, or a
    package installed into site-packages, the user's included), not to code on a path
    of the user's own."""
    roots = {sysconfig.get_paths()[k] for k in ("stdlib", "platstdlib", "purelib", "platlib")}
    roots |= set(site.getsitepackages()) | {site.getusersitepackages()}
    return any(path.is_relative_to(Path(r).resolve()) for r in roots if r)


def _locate(name: str) -> Path | None:
    """The file of module ``name`` (source, sourceless bytecode or extension), found as
    ``import`` would find it but without executing anything; None if there is none."""
    parts = name.split(".")
    try:
        if parts[0] in sys.modules:  # already imported: where it came from
            spec = getattr(sys.modules[parts[0]], "__spec__", None)
        else:
            spec = importlib.util.find_spec(parts[0])
        for i in range(1, len(parts)):
            if spec is None or spec.submodule_search_locations is None:
                return None
            spec = importlib.machinery.PathFinder.find_spec(
                ".".join(parts[:i + 1]), spec.submodule_search_locations)
    except (ImportError, ValueError, AttributeError):
        return None
    origin = getattr(spec, "origin", None)
    if not origin or not spec.has_location:
        return None
    # A module in a zip archive on sys.path (zipimport) has no file of its own: the
    # archive stands for it (hashed whole; what it imports is not followed).
    return Path(getattr(spec.loader, "archive", None) or origin).resolve()


@dataclass
class Walk:
    """The result of `walk`: module name → file of every module reached, and the
    top-level names of the installed packages reached (not walked into)."""

    files: dict[str, Path] = field(default_factory=dict)
    packages: set[str] = field(default_factory=set)


def walk(start: list[str], inside: tuple[Path, ...] | None, *, skip: tuple[str, ...] = (),
         declared=lambda top: True) -> Walk:
    """Every module ``start`` can import, transitively, at module level or in a function.

    ``inside``: only modules whose top-level package is one of these folders are walked
    (a project's own code); any other non-standard name reached is an installed package.
    None: every module that is not part of the Python installation is walked (a plug-in
    and its helpers, wherever they live); an installed one reached is recorded as a
    package if ``declared(top)`` (a distribution installed it, so its version and record
    stand for it), else walked like the user's own files (a module copied into
    site-packages by hand has nothing else to stand for it).  The standard library is skipped by name, and so are the modules ``skip``
    (what they import is not followed).  A package's ``__init__`` is walked before its
    modules, as ``import`` runs it."""
    out = Walk()
    seen: set[str] = set()
    local = None if inside is None else {root.name: root for root in inside}
    todo = list(start)
    while todo:
        name = todo.pop()
        if not name or name in seen or name in skip:
            continue
        seen.add(name)
        top = name.partition(".")[0]
        if top in sys.stdlib_module_names or top in sys.builtin_module_names:
            continue
        if local is not None and top not in local:
            out.packages.add(top)
            continue
        path = _locate(name)
        if path is None:
            continue
        if local is not None and not path.is_relative_to(local[top]):
            continue
        if local is None and installed(path) and declared(top):
            out.packages.add(top)
            continue
        out.files[name] = path
        todo.append(name.rpartition(".")[0])
        try:
            for source, names in imports(path, name):
                todo.append(source)
                todo.extend(f"{source}.{n}" for n in names)
        except (SyntaxError, ValueError, OSError, EOFError, TypeError):
            pass  # a file Python cannot parse imports nothing (and runs nothing); hashed
    return out
