"""The result of one closed-loop run: named signals, status, configuration, timings.

Arrays of time series are ``(n_signals, n_samples)`` with a tuple of names (SI units,
radians).  A result unpacks like python-control's responses: ``t, y = result``.
Stored as one ``.npz`` per run (no pickle; metadata as a JSON string; the signals packed
without loss where a campaign asks: `validation.run.packing`),
written atomically (`validation.batch.store.runfiles`; the store: `validation.batch.store.folder`).
"""
from __future__ import annotations

import io
import json
import math
import os
import secrets
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["RunResult", "STATUSES", "write_atomic", "own_folder", "LinkedFolder",
           "read_json", "conforms"]

STATUSES = ("ok", "diverged", "failed")


@dataclass
class RunResult:
    """Signals of one run at the control instants t_k = k·Ts.

    Parameters
    ----------
    time : ndarray (n_samples,)
        The control instants [s].
    names : tuple of str
        The signals' names (the signal reference), one per row of ``signals``.
    signals : ndarray (n_signals, n_samples)
        SI units, radians.
    status : {"ok", "diverged", "failed"}
        "diverged": the state left its bounds or became non-finite; "failed": the plant's
        solver gave up.  Signals then end at the last sample before that.
    message : str
        Why the run stopped early ("" if ok).
    end_time : float
        Simulated time reached [s].
    config : dict
        The fully resolved scenario.
    timings : dict
        Wall-clock seconds (total, plant, controller, observer) and the real-time factor.
    traceback : str
        Where a law or plug-in plant raised, if it did: the frames of its own code (its
        module and package, file and line) as Python prints them
        (`validation.run.tracebacks`); "" otherwise.  The message names the innermost.

    Examples
    --------
    >>> import numpy as np
    >>> from validation import RunResult
    >>> result = RunResult(time=np.array([0.0, 1e-3]), names=("theta1", "theta2"),
    ...                    signals=np.array([[0.0, 0.1], [0.0, -0.1]]))
    >>> t, y = result                     # unpacks like python-control's responses
    >>> y.shape, result["theta2"][-1], result.ok
    ((2, 2), np.float64(-0.1), True)
    """

    time: np.ndarray
    names: tuple[str, ...]
    signals: np.ndarray
    status: str = "ok"
    message: str = ""
    end_time: float = 0.0
    config: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    traceback: str = ""

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {STATUSES}, got {self.status!r}")
        if self.signals.shape != (len(self.names), len(self.time)):
            raise ValueError(f"signals have shape {self.signals.shape}, expected "
                             f"({len(self.names)}, {len(self.time)})")
        self._index = {name: i for i, name in enumerate(self.names)}

    def __iter__(self):
        return iter((self.time, self.signals))

    def __contains__(self, name: str) -> bool:
        return name in self._index

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.signals[self._index[name]]
        except KeyError:
            raise KeyError(f"no signal {name!r} in this result") from None

    def select(self, names) -> np.ndarray:
        """Rows ``names`` as an array (len(names), n_samples)."""
        return self.signals[[self._index[n] for n in names]]

    def names_with(self, prefix: str) -> tuple[str, ...]:
        return tuple(n for n in self.names if n.startswith(prefix))

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    # --- looking at it --------------------------------------------------------------
    def plot(self, *others: "RunResult", transient: float | None = None):
        """The paper's Figs. 3–4 layout: θ per joint with the reference, θ − θ_d [mrad]
        and the tip deflections [mm], with ``others`` overlaid (the same scenario on the
        other plant, say: the reduced plant wide and light, the truth plant thin and dark).

        Parameters
        ----------
        *others : RunResult
            Results drawn on the same axes.
        transient : float, optional
            The error axes are scaled to the samples after it [s] (default: the
            scenario's transient).

        Returns
        -------
        matplotlib.figure.Figure
            Made with pyplot (a notebook shows it; ``fig.savefig(path)`` writes it).
        """
        from .plotting import plot_results
        return plot_results([self, *others], transient=transient)

    def to_dataframe(self):
        """The signals as a pandas DataFrame: a column per signal name, indexed by time
        ``t`` [s] (pandas is optional: ``pip install pandas``).

        Returns
        -------
        pandas.DataFrame
            ``(n_samples, n_signals)``; the status, message and scenario in ``attrs``.
        """
        try:
            import pandas as pd
        except ImportError:
            raise ImportError("RunResult.to_dataframe needs pandas, which flexarm-validation "
                              "does not install: pip install pandas (or use result.time, "
                              "result.names and result.signals, numpy arrays)") from None
        frame = pd.DataFrame(self.signals.T, columns=list(self.names),
                             index=pd.Index(self.time, name="t"))
        frame.attrs.update(status=self.status, message=self.message, config=self.config)
        return frame

    # --- storage --------------------------------------------------------------------
    def to_bytes(self, extra: dict | None = None, *, packed: bool = False) -> bytes:
        """The result as an uncompressed ``.npz`` (no pickle): arrays ``time``,
        ``signals``, ``names`` and ``meta`` (JSON: status, message, end time, scenario,
        timings, plus ``extra`` — the store adds the metrics and its bookkeeping, so a
        file alone is enough to rebuild its index row).  ``packed``: the float32 signals
        compressed without loss (`validation.run.packing`; ``meta["packed"]`` says how,
        and their shape)."""
        meta = {"status": self.status, "message": self.message, "end_time": self.end_time,
                "config": self.config, "timings": self.timings,
                **({"traceback": self.traceback} if self.traceback else {}), **(extra or {})}
        signals = self.signals
        if packed:
            from .packing import CODEC, pack
            meta["packed"] = {"codec": CODEC, "shape": list(signals.shape)}
            signals = np.frombuffer(pack(signals), np.uint8)
        buf = io.BytesIO()
        # The metadata as UTF-8 bytes: a numpy string array holds 4 bytes per character
        # (30 KB of a metrics-only run's 37 KB; files written so still read).
        np.savez(buf, time=self.time, signals=signals, names=np.array(self.names, dtype=str),
                 meta=np.frombuffer(json.dumps(meta).encode(), np.uint8))
        return buf.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> tuple["RunResult", dict]:
        """(result, meta) from `to_bytes` output; ValueError if it is not one (an array
        whose header declares more data than its file holds included: checked before
        anything is allocated)."""
        try:
            _check_declared_sizes(data)
            with np.load(io.BytesIO(data), allow_pickle=False) as npz:
                text = npz["meta"]
                meta = json.loads(text.tobytes().decode() if text.dtype == np.uint8
                                  else str(text))
                signals, times, names = npz["signals"], npz["time"], npz["names"]
                if "packed" in meta:
                    from .packing import CODEC, unpack
                    if meta["packed"]["codec"] != CODEC:
                        raise ValueError(f"signals packed as {meta['packed']['codec']!r}")
                    # The shape the file declares must be the run's own (its names and
                    # samples, held uncompressed) before anything is inflated: a crafted
                    # shape would otherwise be inflated up to the packer's 4 GiB cap.
                    shape = meta["packed"]["shape"]
                    if list(shape) != [names.size, times.size]:
                        raise ValueError(f"packed signals of shape {shape}, the run has "
                                         f"{names.size} signals at {times.size} samples")
                    signals = unpack(signals.tobytes(), shape)
                result = cls(time=times, names=tuple(str(n) for n in names),
                             signals=signals, status=meta["status"],
                             message=meta["message"], end_time=meta["end_time"],
                             config=meta["config"], timings=meta["timings"],
                             traceback=str(meta.get("traceback", "")))
        except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"not a stored run ({type(exc).__name__}: {exc})") from None
        return result, meta

    def save(self, path: str | Path) -> Path:
        """Write ``path`` (.npz) atomically: a reader never sees a partial file."""
        path = Path(path)
        data = self.to_bytes()
        write_atomic(path, lambda fh: fh.write(data), binary=True)
        return path

    @classmethod
    def load(cls, path: str | Path) -> "RunResult":
        return cls.from_bytes(Path(path).read_bytes())[0]


def _check_declared_sizes(data: bytes) -> None:
    """ValueError unless every array of the .npz ``data`` declares no more bytes than its
    member of the archive holds (a crafted header could ask numpy for terabytes)."""
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        for info in archive.infolist():
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                        else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read(member)
                header = member.tell()
            if dtype.hasobject or math.prod(shape) * dtype.itemsize > info.file_size - header:
                raise ValueError(f"{info.filename}: its header declares {shape} of {dtype}, "
                                 f"more than its {info.file_size} bytes")


class LinkedFolder(ValueError):
    """A folder inside a results folder is a symbolic link (or not a folder): writing
    through it would write outside the folder the user chose."""


def own_folder(root: Path, *parts: str) -> Path:
    """``root``/``parts``, created if missing, after checking that nothing below ``root``
    on the way is a symbolic link or a file (`LinkedFolder` naming it otherwise): what is
    written there stays inside ``root`` (``root`` itself may be a link: the user chose it)."""
    path = Path(root)
    for part in parts:
        path = path / part
        if path.is_symlink() or (path.exists() and not path.is_dir()):
            raise LinkedFolder(f"{path}: a {'symbolic link' if path.is_symlink() else 'file'}"
                               " where the results folder keeps a folder of its own; "
                               "nothing is written through it")
        path.mkdir(exist_ok=True)
    return path


def write_atomic(path: Path, write, *, binary: bool = False, sync: bool = True) -> None:
    """Call ``write(file)`` on a temporary file next to ``path``, fsync it (unless
    ``sync`` is false: the caller verifies a checksum instead), and rename it over
    ``path`` (atomic on POSIX): the file is either the old or the new one, whole.  The
    file gets the permissions the process's umask gives new files (results are for
    sharing), without reading or changing the umask."""
    path = Path(path)
    tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(fd, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8"})) as fh:
            write(fh)
            fh.flush()
            if sync:
                os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


#: The largest JSON file a command reads back from a results folder (verdict.json,
#: validity.json): what it writes is far smaller.
MAX_JSON_BYTES = 16 << 20


def read_json(path: Path, schema) -> dict:
    """The JSON table of a file a command wrote into a results folder, checked against
    ``schema`` before anyone reads it (a folder may come from someone else): ValueError,
    one line naming the file and the key, if it is too large, not JSON or not what the
    schema says.

    ``schema`` is a type or a tuple of types (``isinstance``; an ``int`` is no ``bool``),
    ``[item]`` for a list of items, or a dict of keys to schemas — a key ending in "?"
    may be absent, the key ``str`` stands for any key."""
    path = Path(path)
    with path.open("rb") as fh:
        raw = fh.read(MAX_JSON_BYTES + 1)
    if len(raw) > MAX_JSON_BYTES:
        raise ValueError(f"{path}: larger than {MAX_JSON_BYTES >> 20} MiB")
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"{path}: not JSON ({exc.__class__.__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    conforms(data, schema, path)
    return data


def conforms(value, schema, path: Path, where: str = "") -> None:
    """ValueError naming ``path`` and the key ``where`` (dotted) if ``value`` is not what
    ``schema`` says (`read_json`)."""
    def refuse(what: str):
        raise ValueError(f"{path}: {where + ': ' if where else ''}{what} (not a file this "
                         "program wrote)")

    def inner(key) -> str:
        return f"{where}.{key}" if where else str(key)
    if isinstance(schema, dict):
        if not isinstance(value, dict):
            refuse(f"expected a table, got {type(value).__name__}")
        for key, sub in schema.items():
            if key is str:
                for name, item in value.items():
                    conforms(item, sub, path, inner(name))
            elif key.rstrip("?") in value:
                conforms(value[key.rstrip("?")], sub, path, inner(key.rstrip("?")))
            elif not key.endswith("?"):
                refuse(f"no key {key!r}")
    elif isinstance(schema, list):
        if not isinstance(value, list):
            refuse(f"expected a list, got {type(value).__name__}")
        for i, item in enumerate(value):
            conforms(item, schema[0], path, f"{where}[{i}]")
    else:
        types = schema if isinstance(schema, tuple) else (schema,)
        if not isinstance(value, types) or (isinstance(value, bool) and bool not in types):
            refuse(f"expected {' or '.join(t.__name__ for t in types)}, got "
                   f"{type(value).__name__}")
