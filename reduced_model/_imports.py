"""The import statements of a Python file, read without importing it (`ast`): what the
code fingerprint, the numba cache guard and the house tests walk."""
from __future__ import annotations

import ast
from pathlib import Path

__all__ = ["imports"]


def imports(path: Path, module: str, *, nested: bool = True) -> list[tuple[str, tuple[str, ...]]]:
    """(absolute module, names imported from it) of each import statement of the file
    ``path``, the module ``module`` (a package's name for its ``__init__.py``): relative
    imports resolved; ``import X`` gives (X, ()).  ``nested``: statements inside functions
    too (lazy imports), else the module level only."""
    tree = ast.parse(Path(path).read_bytes(), filename=str(path))
    package = module if Path(path).name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in (ast.walk(tree) if nested else tree.body):
        if isinstance(node, ast.Import):
            out += [(alias.name, ()) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            out.append((source, tuple(alias.name for alias in node.names)))
    return out
