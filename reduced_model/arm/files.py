"""Arm files: the named arms shipped in ``reduced_model/arm/named/`` and a user's TOML
file, both in the table form of `reduced_model.arm.description`."""
from __future__ import annotations

import functools
import tomllib
from importlib import resources
from pathlib import Path

from .description import ArmFileError, ArmParameters, arm_from_table
from .parts import suggestion

__all__ = ["named_arms", "named_arm", "read_arm"]


def read_arm(path) -> ArmParameters:
    """The arm the TOML file ``path`` describes (`ArmFileError` naming the file and key).

    Parameters
    ----------
    path : str or Path
        An arm file (module docstring).

    Returns
    -------
    ArmParameters
    """
    path = Path(path)
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ArmFileError(f"{path}: no such arm file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ArmFileError(f"{path}: cannot be read ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ArmFileError(f"{path}: not TOML ({exc})") from None
    return arm_from_table(table, where=str(path))


@functools.cache
def _named_tables() -> dict[str, dict]:
    folder = resources.files(__package__) / "named"
    return {entry.name.removesuffix(".toml"): tomllib.loads(entry.read_text(encoding="utf-8"))
            for entry in folder.iterdir() if entry.name.endswith(".toml")}


def named_arms() -> dict[str, str]:
    """The shipped arms (read on first use).

    Returns
    -------
    dict
        Each shipped arm's name (for `named_arm`, ``--arm``) → its one-line description.
    """
    return {name: table.get("description", "")
            for name, table in sorted(_named_tables().items())}


@functools.cache
def named_arm(name: str) -> ArmParameters:
    """The shipped arm ``name`` (`named_arms`)."""
    tables = _named_tables()
    if name not in tables:
        raise ArmFileError(f"arm: {name!r} is not a shipped arm{suggestion(name, tables)} "
                           f"(shipped: {', '.join(sorted(tables))}; or give a file, "
                           "--arm FILE.toml)")
    return arm_from_table(tables[name], where=f"arm {name!r}")
