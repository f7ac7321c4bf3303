"""TOML files with ``include``: scenario and campaign files can extend base files.

``include = "base.toml"`` (or a list) names files, relative to the including file, whose
contents are merged first; the including file's own keys then override them (tables are
merged key by key, everything else replaced).
"""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path

from ._config import ConfigError

__all__ = ["load_toml", "deep_merge", "set_dotted", "parse_value"]


def deep_merge(base: dict, override: dict) -> dict:
    """A new dict: ``base`` with ``override`` merged in (tables recursively)."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def load_toml(path: str | Path, _seen: tuple[Path, ...] = ()) -> dict:
    """Read ``path`` and its includes; errors name the file."""
    path = Path(path)
    resolved = path.resolve()
    if resolved in _seen:
        raise ConfigError("include", f"{path} includes itself (cycle: "
                                     f"{' -> '.join(p.name for p in (*_seen, resolved))})")
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except OSError as exc:
        raise ConfigError("", f"{path}: cannot read ({exc.strerror or exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", f"{path}: invalid TOML ({exc})") from None
    includes = data.pop("include", [])
    if isinstance(includes, str):
        includes = [includes]
    if not isinstance(includes, list) or not all(isinstance(i, str) for i in includes):
        raise ConfigError("include", f"{path}: must be a file name or a list of them")
    merged: dict = {}
    for inc in includes:
        merged = deep_merge(merged, load_toml(path.parent / inc, (*_seen, resolved)))
    return deep_merge(merged, data)


def set_dotted(data: dict, key: str, value) -> None:
    """data[a][b][c] = value for key "a.b.c" (creating tables on the way)."""
    parts = key.split(".")
    if not all(parts):
        raise ConfigError(key, "not a valid dotted key")
    for i, part in enumerate(parts[:-1]):
        node = data.setdefault(part, {})
        if not isinstance(node, dict):
            raise ConfigError(".".join(parts[:i + 1]), "is a value, not a table")
        data = node
    data[parts[-1]] = value


def parse_value(text: str):
    """A TOML literal ("0.5", "[8, 8]", "true", '"ancf"'), or the text itself."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
