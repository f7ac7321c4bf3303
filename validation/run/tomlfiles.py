"""TOML files with ``include``: scenario and campaign files can extend base files.

``include = "base.toml"`` (or a list) names files, relative to the including file, whose
contents are merged first; the including file's own keys then override them (tables are
merged key by key, everything else replaced).  Values nested deeper than
`MAX_NESTING` lists or tables are refused as they are read, naming their key, so that
nothing downstream recurses into them.
"""
from __future__ import annotations

import collections
import copy
import json
import re
import tomllib
from pathlib import Path

from .config import ConfigError

__all__ = ["load_toml", "deep_merge", "set_dotted", "get_dotted", "flatten", "parse_value",
           "check_nesting", "MAX_NESTING", "toml_value", "toml_text"]

#: The deepest nesting of lists and tables a value may have (a campaign's deepest,
#: ``sweep.zip.controller.options = [{gains = [[...]]}]``, has 6).
MAX_NESTING = 32


def deep_merge(base: dict, override: dict) -> dict:
    """A new dict: ``base`` with ``override`` merged in (tables recursively)."""
    out = copy.deepcopy(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


#: Caps on what an include chain may load: depth, number of files, number of includes
#: (a file counted each time it is included), bytes per file and in all (4 MiB of TOML
#: parse in about a second).
MAX_INCLUDE_DEPTH = 16
MAX_INCLUDED_FILES = 64
MAX_INCLUDES = 256
MAX_FILE_BYTES = 1 << 20
MAX_TOTAL_BYTES = 4 << 20


def load_toml(path: str | Path) -> dict:
    """Read ``path`` and its includes; errors name the file.  Each file is parsed once
    however often it is included, and merged without copying (the result is copied
    once); chains deeper than `MAX_INCLUDE_DEPTH`, more than `MAX_INCLUDED_FILES` files
    or `MAX_INCLUDES` includes, a file named twice in one ``include``, files over 1 MiB
    and more than 4 MiB in all are refused.

    Parameters
    ----------
    path : str or pathlib.Path
        A scenario, campaign or baselines file.

    Returns
    -------
    dict
        Its tables, the included files' keys merged under its own.
    """
    return copy.deepcopy(_load(Path(path), (), {}, {"includes": 0, "bytes": 0}))


def check_nesting(value, where: str = "") -> None:
    """`ConfigError` naming the key if ``value`` nests lists or tables deeper than
    `MAX_NESTING` (checked without recursion)."""
    todo = [(value, where, 0)]
    while todo:
        item, path, depth = todo.pop()
        if depth > MAX_NESTING:
            raise ConfigError(path, f"nested deeper than {MAX_NESTING} lists or tables")
        if isinstance(item, dict):
            # The key path grows only over the first levels: enough to find the value.
            todo.extend((v, f"{path}.{k}" if path and depth < 4 else (path or k), depth + 1)
                        for k, v in item.items())
        elif isinstance(item, list):
            todo.extend((v, path, depth + 1) for v in item)


def _read(path: Path, budget: dict) -> dict:
    """The tables of one file; ``budget["bytes"]`` (`_load`) counts what an include
    chain has read."""
    if path.exists() and not path.is_file():
        raise ConfigError("", f"{path}: not a regular file")
    try:
        with path.open("rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ConfigError("", f"{path}: cannot read ({exc.strerror or exc})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ConfigError("", f"{path}: larger than {MAX_FILE_BYTES >> 20} MiB")
    budget["bytes"] += len(raw)
    if budget["bytes"] > MAX_TOTAL_BYTES:
        raise ConfigError("include", f"{path}: the included files exceed "
                                     f"{MAX_TOTAL_BYTES >> 20} MiB in all")
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError:
        raise ConfigError("", f"{path}: not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", f"{path}: invalid TOML ({exc})") from None
    except RecursionError:
        raise ConfigError("", f"{path}: a value nested deeper than {MAX_NESTING} lists or "
                              "tables") from None
    try:
        check_nesting(data)
    except ConfigError as exc:
        raise ConfigError(exc.path, f"{exc.message} (in {path})") from None
    return data


def _load(path: Path, seen: tuple[Path, ...], cache: dict, budget: dict) -> dict:
    """``path`` merged over its includes; the result shares values with ``cache`` (whose
    entries are never changed) — `load_toml` copies it.  ``budget`` counts the includes
    and bytes read so far."""
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError) as exc:  # RuntimeError: a symbolic link loop (< 3.13)
        raise ConfigError("", f"{path}: cannot read ({exc})") from None
    if resolved in seen:
        raise ConfigError("include", f"{path} includes itself (cycle: "
                                     f"{' -> '.join(p.name for p in (*seen, resolved))})")
    if len(seen) >= MAX_INCLUDE_DEPTH:
        raise ConfigError("include", f"{path}: includes nested deeper than {MAX_INCLUDE_DEPTH}")
    if resolved not in cache:
        if len(cache) >= MAX_INCLUDED_FILES:
            raise ConfigError("include", f"{path}: more than {MAX_INCLUDED_FILES} files included")
        data = _read(path, budget)
        includes = data.pop("include", [])
        if isinstance(includes, str):
            includes = [includes]
        if not isinstance(includes, list) or not all(isinstance(i, str) for i in includes):
            raise ConfigError("include", f"{path}: must be a file name or a list of them")
        twice = sorted(i for i, count in collections.Counter(includes).items() if count > 1)
        if twice:
            raise ConfigError("include", f"{path}: names {', '.join(map(repr, twice[:3]))}"
                                         f"{', ...' if len(twice) > 3 else ''} more than once")
        budget["includes"] += len(includes)
        if budget["includes"] > MAX_INCLUDES:
            raise ConfigError("include", f"{path}: more than {MAX_INCLUDES} includes (a file "
                                         "counts each time it is included)")
        merged: dict = {}
        for inc in includes:
            merged = _merged(merged, _load(path.parent / inc, (*seen, resolved), cache,
                                           budget))
        cache[resolved] = _merged(merged, data)
    return cache[resolved]


def _merged(base: dict, override: dict) -> dict:
    """`deep_merge` without copies: a new table sharing the values of both."""
    out = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merged(out[key], value)
        else:
            out[key] = value
    return out


_SEGMENT = re.compile(r"^([^\[\]]+)((?:\[\d+\])*)$")


def _parts(key: str) -> list:
    """"a.b[0].c" → ["a", "b", 0, "c"]: table keys and list indices."""
    parts: list = []
    for segment in key.split("."):
        match = _SEGMENT.match(segment)
        if match is None:
            raise ConfigError(key, "not a valid dotted key")
        parts.append(match.group(1))
        parts += [int(i) for i in re.findall(r"\[(\d+)\]", match.group(2))]
    return parts


def _key(parts: list) -> str:
    return "".join(f"[{p}]" if isinstance(p, int) else ("." if i else "") + p
                   for i, p in enumerate(parts))


def get_dotted(data: dict, key: str):
    """The value at a dotted key (``disturbances[0].start``); KeyError if there is none."""
    node = data
    for part in _parts(key):
        if isinstance(part, int) and isinstance(node, list) and part < len(node):
            node = node[part]
        elif isinstance(part, str) and isinstance(node, dict) and part in node:
            node = node[part]
        else:
            raise KeyError(key)
    return node


def set_dotted(data: dict, key: str, value, *, defaults: dict | None = None) -> None:
    """data[a][b][c] = value for key "a.b.c" (creating tables on the way); ``[i]`` indexes
    a list (``disturbances[0].amplitude``), copied from ``defaults`` (e.g. the resolved
    scenario) when ``data`` does not hold it."""
    parts = _parts(key)
    node = data
    for i, (part, following) in enumerate(zip(parts[:-1], parts[1:])):
        where = _key(parts[:i + 1])
        child = _child(node, part, where)
        if isinstance(following, int) and not isinstance(child, list):
            try:
                child = copy.deepcopy(get_dotted(defaults or {}, where))
            except KeyError:
                raise ConfigError(where, "is not a list here") from None
            if not isinstance(child, list):
                raise ConfigError(where, "is not a list")
        elif not isinstance(following, int) and not isinstance(child, dict):
            if child is not None:
                raise ConfigError(where, "is a list: index it, e.g. [0]"
                                  if isinstance(child, list) else "is a value, not a table")
            child = {}
        node[part] = child
        node = child
    _child(node, parts[-1], key)  # the place exists (a list element) or can (a table key)
    node[parts[-1]] = value


def _child(node, part, where: str):
    """node[part]: a list element that must exist, or a table's key (None if absent)."""
    if isinstance(part, int):
        if not isinstance(node, list) or part >= len(node):
            raise ConfigError(where, "no such list element")
        return node[part]
    if not isinstance(node, dict):
        raise ConfigError(where, "is inside a list: index it, e.g. [0]")
    return node.get(part)


def flatten(table: dict, prefix: str = "", *, leaf=lambda value: False) -> dict[str, object]:
    """{"a": {"b": 1}} → {"a.b": 1}: every value by its dotted key; a table for which
    ``leaf(table)`` is true stays a value (e.g. a sweep's ``{scale = [...]}``)."""
    out = {}
    for key, value in table.items():
        path = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and not leaf(value):
            out.update(flatten(value, path, leaf=leaf))
        else:
            out[path] = value
    return out


def parse_value(text: str, key: str = ""):
    """A TOML literal ("0.5", "[8, 8]", "true", '"ancf"'), or the text itself; a value
    nested deeper than `MAX_NESTING` is a `ConfigError` naming ``key``."""
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
    except RecursionError:
        raise ConfigError(key, f"nested deeper than {MAX_NESTING} lists or tables") from None
    check_nesting(value, key)
    return value


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
    if isinstance(v, dict):  # None: a key the table's kind does not use (TOML has no null)
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()
                                if x is not None) + " }"
    raise TypeError(f"cannot write {v!r} as TOML")


def toml_text(mapping: dict) -> str:
    """A TOML document of ``mapping`` with dotted keys (``plant.kind = "exudyn"``) that
    `load_toml` reads back to the same values (floats exactly: ``repr``); None (a key
    its table's kind does not use) is left out."""
    return "".join(f"{key} = {toml_value(v)}\n" for key, v in flatten(mapping).items()
                   if v is not None)
