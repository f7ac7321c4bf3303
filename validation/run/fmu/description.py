"""An FMU as a plant table names it: the plant contract's names (`signal_names`), FMPy (the ``fmi`` extra) found when an FMU is first
read, the FMU's model description read and checked against the variables a table maps
(each refusal one `ConfigError` naming the key), its file hashed (for the run's
fingerprint) and its archive unpacked once per process."""
from __future__ import annotations

import atexit
import functools
import hashlib
import importlib
import os
import shutil
import tempfile
from pathlib import Path

from reduced_model import coordinate_names, truth_extras

from ..config import ConfigError, check, did_you_mean, short_str
from ..processes import at_child_exit

__all__ = ["fmpy", "read_description", "variable", "signal_names", "file_sha256", "unpacked", "REAL_TYPES",
           "FMI_VERSIONS"]

#: The FMI versions read (co-simulation): 2.0 and 3.0.
FMI_VERSIONS = ("2.0", "3.0")
#: The variable types a plant's signals travel in (FMI 2.0's Real, FMI 3.0's floats).
REAL_TYPES = ("Real", "Float64", "Float32")


def fmpy():
    """The ``fmpy`` package, or a ConfigError naming ``plant.kind`` with the install line.

    Imported by name, not by an import statement: only an FMU run depends on FMPy, and
    such a run's fingerprint adds FMPy's version and files itself
    (`validation.batch.fingerprint.run_fingerprint`); the static walk of the run path's
    imports would put them into every run's."""
    try:
        return importlib.import_module("fmpy")
    except ImportError:
        raise ConfigError("plant.kind", "'fmu' needs FMPy, the fmi extra: "
                                        "pip install -e '.[fmi]'") from None


def _stat_key(path: str) -> tuple:
    """What identifies a file's version cheaply (its size and modification time)."""
    st = os.stat(path)
    return str(Path(path).resolve()), st.st_size, st.st_mtime_ns


def read_description(path: str, key: str = "plant.fmu"):
    """The model description of the co-simulation FMU at ``path`` (an
    ``fmpy.model_description.ModelDescription``), or a ConfigError naming ``key``: not a
    file, not an FMU, no co-simulation (a model-exchange-only FMU), an FMI version other
    than 2.0 or 3.0."""
    check(isinstance(path, str) and Path(path).is_file(), key,
          f"{path!r} is not a file (a path to an .fmu, from the folder the command runs in)")
    return _description(*_stat_key(path), key)


@functools.lru_cache(maxsize=16)
def _description(path: str, size: int, mtime: int, key: str):
    try:
        md = fmpy().read_model_description(path)
    except ConfigError:
        raise
    except Exception as exc:  # noqa: BLE001 - any archive or XML error: not an FMU
        raise ConfigError(key, f"{path} is not an FMU FMPy can read ({short_str(exc)})") from None
    check(md.fmiVersion in FMI_VERSIONS, key,
          f"{Path(path).name} is an FMI {md.fmiVersion} FMU: FMI "
          f"{' and '.join(FMI_VERSIONS)} are read")
    check(md.coSimulation is not None, key,
          f"{Path(path).name} is a model-exchange FMU (no co-simulation): a plant FMU "
          "brings its own solver and steps in co-simulation")
    return md


def variable(md, name: str, key: str, causalities: tuple[str, ...], fmu: str):
    """The variable ``name`` of the model description ``md`` if it exists, is real and
    has one of ``causalities``; else a ConfigError naming ``key``."""
    found = {v.name: v for v in md.modelVariables}
    v = found.get(name)
    check(v is not None, key, f"{Path(fmu).name} has no variable {name!r}"
                              f"{did_you_mean(name, list(found), quote=True)}")
    check(v.causality in causalities, key,
          f"variable {name!r} of {Path(fmu).name} has causality {v.causality!r}, "
          f"needs {' or '.join(map(repr, causalities))}")
    check(v.type in REAL_TYPES, key, f"variable {name!r} of {Path(fmu).name} is of type "
                                     f"{v.type}, needs a real number")
    return v


def file_sha256(path: str) -> str:
    """The SHA-256 of the file at ``path`` ("missing" if there is none)."""
    try:
        return _sha256(*_stat_key(path))
    except OSError:
        return "missing"


@functools.lru_cache(maxsize=16)
def _sha256(path: str, size: int, mtime: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


_UNPACKED: dict[str, tuple[str, int]] = {}  # sha256 -> (folder, the pid that made it)


def unpacked(path: str) -> str:
    """A folder holding the FMU at ``path`` unpacked, once per FMU version: a worker
    forked after the scenario check (which unpacks it) reads its parent's; the process
    that made a folder removes it when it exits (a `contained` child too)."""
    sha = file_sha256(path)
    if sha not in _UNPACKED:
        folder = tempfile.mkdtemp(prefix="flexarm-fmu-")
        fmpy().extract(path, unzipdir=folder)
        if not any(pid == os.getpid() for _, pid in _UNPACKED.values()):
            atexit.register(_remove_own)
            at_child_exit(_remove_own)
        _UNPACKED[sha] = (folder, os.getpid())
    return _UNPACKED[sha][0]


def _remove_own() -> None:
    """Remove the folders this process unpacked (not those a worker shares with its
    parent)."""
    for folder, pid in list(_UNPACKED.values()):
        if pid == os.getpid():
            shutil.rmtree(folder, ignore_errors=True)


def signal_names(table: str, links: int, modes_per_link) -> tuple[str, ...]:
    """The contract names of ``table`` for an arm of ``links`` links whose laws' model
    has ``modes_per_link``: the torques in; the truth vector's entries out
    (`reduced_model.truth_extras`); the state for ``initial``."""
    if table == "inputs":
        return tuple(f"tau{i + 1}" for i in range(links))
    coords = coordinate_names(tuple(modes_per_link))
    state = coords + tuple(f"{c}_dot" for c in coords)
    return state if table == "initial" else state + truth_extras(links)
