"""Mappings (TOML, JSON) ⇄ frozen dataclasses, with errors that name the dotted path.

Types are read from the dataclass annotations: bool, int, float, str, tuples of those
(fixed length ``tuple[float, float]`` or variable ``tuple[float, ...]``), nested
dataclasses, tuples of dataclasses, ``X | None``, tagged choices ``A | B`` between
dataclasses (picked by their ``kind``), and ``dict`` (a free table of plain values —
numbers, strings, booleans, lists and tables — checked by whoever consumes it).  Unknown
keys (including keys the chosen kind does not take) and values of the wrong type are
rejected; the dataclasses' own ``__post_init__`` checks ranges.
"""
from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import types
from typing import Any, Union, get_args, get_origin, get_type_hints


__all__ = ["ConfigError", "from_mapping", "to_mapping", "check", "check_label", "short_repr",
           "short_str", "did_you_mean", "check_known", "fraction_hint"]


class ConfigError(ValueError):
    """A bad configuration value.

    Parameters
    ----------
    path : str
        The dotted key (e.g. ``plant.mesh.element``).
    message : str
        What is wrong with it.
    """

    def __init__(self, path: str, message: str) -> None:
        self.path, self.message = path, message
        super().__init__(f"{path}: {message}" if path else message)

    def under(self, prefix: str) -> "ConfigError":
        """The same error with ``prefix`` in front of its path."""
        return ConfigError(f"{prefix}.{self.path}" if self.path else prefix, self.message)


def check(condition: bool, path: str, message: str) -> None:
    """Raise `ConfigError(path, message)` unless ``condition``."""
    if not condition:
        raise ConfigError(path, message)


def did_you_mean(given: Any, choices, prefix: str = "", *, quote: bool = False) -> str:
    """"; did you mean X?" for a misspelt ``given`` (a key, a flag, a value) closest to one
    of ``choices`` (`difflib.get_close_matches`), named with ``prefix`` (a dotted key's
    table) or ``quote``d (a value), else "": the one place a check of a key, flag or value
    suggests one."""
    if not isinstance(given, str):
        return ""
    found = difflib.get_close_matches(given, [str(c) for c in choices], n=1)
    if not found:
        return ""
    return f"; did you mean {found[0]!r}?" if quote else f"; did you mean {prefix}{found[0]}?"


def check_known(key: Any, allowed, path: str, what: str = "unknown key") -> None:
    """`ConfigError` at ``path`` (the dotted key) unless ``key`` is one of ``allowed``:
    ``what``, the closest allowed key (`did_you_mean`), then every allowed key."""
    if key not in allowed:
        table = path.rpartition(".")[0]
        raise ConfigError(path, f"{what}{did_you_mean(key, allowed, table + '.' if table else '')}"
                                f" (allowed: {', '.join(sorted(map(str, allowed)))})")


def fraction_hint(value: Any) -> str:
    """"; did you mean 0.05?" for a share written as a percentage ("5%", "5 %"), else ""."""
    text = value.strip() if isinstance(value, str) else ""
    try:
        share = float(text[:-1]) / 100 if text.endswith("%") else math.nan
    except ValueError:
        return ""
    return f"; did you mean {share:g}?" if math.isfinite(share) else ""


def check_label(name: Any, path: str) -> None:
    """A name that also names a folder: letters, digits and ``. _ - + @``, not starting
    with a dot — never a path (no ``/``, no ``..``), never empty, no control characters."""
    ok = (isinstance(name, str) and 0 < len(name) <= 100 and not name.startswith(".")
          and all(c.isalnum() or c in "._-+@" for c in name) and name.isascii())
    check(ok, path, f"must be a plain name (letters, digits, '.', '_', '-', '+', '@'; not a "
                    f"path), got {name!r}")


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` on one line, at most ``limit`` characters, for a message; a value
    whose ``repr`` raises (a plug-in's object may) is named by its type."""
    try:
        text = " ".join(repr(value).split())
    except Exception as exc:  # noqa: BLE001 - any error of a foreign repr
        text = f"<{type(value).__name__} whose repr raised {type(exc).__name__}>"
    return text if len(text) <= limit else text[:limit - 3] + "..."


def short_str(exc: BaseException) -> str:
    """The first line of ``str(exc)`` for a message (its type's name if it has none, or
    if its ``str`` raises)."""
    try:
        lines = str(exc).strip().splitlines()
    except Exception as error:  # noqa: BLE001 - any error of a foreign __str__
        return f"{type(exc).__name__} (whose str raised {type(error).__name__})"
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def _convert(tp: Any, value: Any, path: str) -> Any:
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        members = [a for a in args if a is not type(None)]
        if len(members) > 1 and not any(dataclasses.is_dataclass(m) for m in members):
            return _first_fitting(members, value, path)
        if len(members) > 1:
            return _tagged(members, value, path)
        return _convert(members[0], value, path)
    if dataclasses.is_dataclass(tp):
        if dataclasses.is_dataclass(value) and isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise ConfigError(path, f"expected a table, got {short_repr(value)}")
        return from_mapping(tp, value, path)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(path, f"expected a list, got {short_repr(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(path, f"expected {len(args)} values, got {len(value)}")
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(path, f"expected true or false, got {short_repr(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(path, f"expected an integer, got {short_repr(value)}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(path, f"expected a number, got {short_repr(value)}")
        if math.isnan(value):
            raise ConfigError(path, "must be a number, got nan")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(path, f"expected a string, got {short_repr(value)}")
        return value
    if tp is dict or origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(path, f"expected a table, got {short_repr(value)}")
        return {k: _plain(v, f"{path}.{k}") for k, v in value.items()}
    raise TypeError(f"unsupported configuration type {tp!r} at {path}")


def _first_fitting(members: list, value: Any, path: str) -> Any:
    """A choice between plain types (``int | tuple[int, ...]``): the first that takes
    ``value``."""
    reasons = []
    for member in members:
        try:
            return _convert(member, value, path)
        except ConfigError as exc:
            reasons.append(exc.message)
    raise ConfigError(path, " or ".join(reasons))


def _tagged(members: list, value: Any, path: str) -> Any:
    """A tagged choice between dataclasses (``A | B``): each has a ``kind`` field whose
    default names it; the table's ``kind`` (default: the first member's) picks one, and
    keys the chosen kind does not take are refused by `from_mapping`."""
    kinds = {m.__dataclass_fields__["kind"].default: m for m in members}
    if isinstance(value, tuple(members)):
        return value
    if not isinstance(value, dict):
        raise ConfigError(path, f"expected a table, got {short_repr(value)}")
    kind = value.get("kind", next(iter(kinds)))
    # A member whose kind defaults to "" takes every "package.module:Class" (a plug-in).
    chosen = kinds.get(kind) or (kinds.get("") if isinstance(kind, str) and ":" in kind
                                 else None)
    if chosen is None:
        named = [k for k in kinds if k]
        plugin = ' or a plug-in "package.module:Class"' if "" in kinds else ""
        raise ConfigError(f"{path}.kind", f"must be one of {', '.join(map(repr, named))}"
                                          f"{plugin}, got {short_repr(kind)}"
                                          f"{did_you_mean(kind, named, quote=True)}")
    kinds = {**kinds, kind: chosen}
    takes = {f.name for f in dataclasses.fields(chosen)}
    for key in value:
        owners = [k for k, m in kinds.items() if k and key in m.__dataclass_fields__]
        check_known(key, takes, f"{path}.{key}", f"a setting of kind {owners[0]!r}, not of "
                                                 f"kind {kind!r}" if owners else
                    f"unknown key for kind {kind!r}")
    return from_mapping(chosen, value, path)


def _plain(value: Any, path: str) -> Any:
    """A copy of a plain TOML/JSON value (lists as lists), rejecting anything else."""
    if isinstance(value, dict):
        return {k: _plain(v, f"{path}.{k}") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v, f"{path}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(path, f"must be a finite number, got {value!r}")
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise ConfigError(path, f"expected a number, string, boolean, list or table, got "
                            f"{short_repr(value)}")


_type_hints = functools.cache(get_type_hints)  # resolving annotations costs ~0.5 ms a class


def from_mapping(cls, data: dict, path: str = ""):
    """Build dataclass ``cls`` from ``data``; missing keys take the defaults, a missing key
    without one is a `ConfigError` naming it."""
    hints = _type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for key, value in data.items():
        sub = f"{path}.{key}" if path else key
        check_known(key, fields, sub)
        kwargs[key] = _convert(hints[key], value, sub)
    for name, f in fields.items():
        if name not in kwargs and f.default is dataclasses.MISSING and \
                f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{path}.{name}" if path else name, "missing (required)")
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        raise (exc.under(path) if path else exc) from None
    except ValueError as exc:  # ArmParameters, Mesh, SensorConfig name their field
        from reduced_model import FieldError  # not on import: a report reads no model
        if not isinstance(exc, FieldError):
            raise
        raise ConfigError(f"{path}.{exc.field}" if path else exc.field, exc.reason) from None


@functools.cache
def _field_names(cls: type) -> tuple[str, ...] | None:
    """The field names of a dataclass type; None for any other type."""
    if not dataclasses.is_dataclass(cls):
        return None
    return tuple(f.name for f in dataclasses.fields(cls))


def to_mapping(obj) -> Any:
    """Plain JSON/TOML-able data (dicts, lists, numbers, strings) of a dataclass tree."""
    names = _field_names(type(obj))
    if names is not None:
        return {name: to_mapping(getattr(obj, name)) for name in names}
    if isinstance(obj, (tuple, list)):
        return [to_mapping(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_mapping(v) for k, v in obj.items()}
    return obj
