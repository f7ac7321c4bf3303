"""TOML files with ``include``: scenario and campaign files can extend base files.

``include = "base.toml"`` (or a list) names files, relative to the including file, whose
contents are merged first; the including file's own keys then override them (tables are
merged key by key, everything else replaced).
"""
from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path

from ._config import ConfigError

__all__ = ["load_toml", "deep_merge", "set_dotted", "parse_value", "toml_value",
           "flat_items", "toml_text"]


def deep_merge(base: dict, override: dict) -> dict:
    """A new dict: ``base`` with ``override`` merged in (tables recursively)."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


#: Caps on what an include chain may load: depth, number of files, bytes per file.
MAX_INCLUDE_DEPTH = 16
MAX_INCLUDED_FILES = 64
MAX_FILE_BYTES = 1 << 20


def load_toml(path: str | Path) -> dict:
    """Read ``path`` and its includes; errors name the file.  Each file is parsed once
    however often it is included; chains deeper than `MAX_INCLUDE_DEPTH`, more than
    `MAX_INCLUDED_FILES` files or files over 1 MiB are refused."""
    cache: dict[Path, dict] = {}
    try:
        return _load(Path(path), (), cache)
    except RecursionError:
        raise ConfigError("", f"{path}: nested too deeply") from None


def _read(path: Path) -> dict:
    if path.exists() and not path.is_file():
        raise ConfigError("", f"{path}: not a regular file")
    try:
        with path.open("rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError("", f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError("", f"{path}: larger than {MAX_FILE_BYTES >> 20} MiB")
    try:
        return tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError("", f"{path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", f"{path}: invalid TOML ({exc})") from None


def _load(path: Path, seen: tuple[Path, ...], cache: dict) -> dict:
    resolved = path.resolve()
    if resolved in seen:
        raise ConfigError("include", f"{path} includes itself (cycle: "
                                     f"{' -> '.join(p.name for p in (*seen, resolved))})")
    if len(seen) >= MAX_INCLUDE_DEPTH:
        raise ConfigError("include", f"{path}: includes nested deeper than {MAX_INCLUDE_DEPTH}")
    if resolved not in cache:
        if len(cache) >= MAX_INCLUDED_FILES:
            raise ConfigError("include", f"{path}: more than {MAX_INCLUDED_FILES} files included")
        data = _read(path)
        includes = data.pop("include", [])
        if isinstance(includes, str):
            includes = [includes]
        if not isinstance(includes, list) or not all(isinstance(i, str) for i in includes):
            raise ConfigError("include", f"{path}: must be a file name or a list of them")
        merged: dict = {}
        for inc in includes:
            merged = deep_merge(merged, _load(path.parent / inc, (*seen, resolved), cache))
        cache[resolved] = deep_merge(merged, data)
    return copy.deepcopy(cache[resolved])


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


def toml_value(v) -> str:
    """A TOML literal of a plain value (tables inline)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # JSON's escapes are TOML's
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {v!r} as TOML")


def flat_items(table: dict, prefix: str = "") -> list[tuple[str, object]]:
    """(dotted key, value) of every non-table value of ``table`` (empty tables vanish)."""
    out = []
    for k, v in table.items():
        key = f"{prefix}.{k}" if prefix else k
        out += flat_items(v, key) if isinstance(v, dict) else [(key, v)]
    return out


def toml_text(mapping: dict) -> str:
    """A TOML document of ``mapping`` with dotted keys (``plant.kind = "exudyn"``) that
    `load_toml` reads back to the same values (floats exactly: ``repr``)."""
    return "".join(f"{key} = {toml_value(v)}\n" for key, v in flat_items(mapping))
