"""The result of one closed-loop run: named signals, status, configuration, timings.

Arrays of time series are ``(n_signals, n_samples)`` with a tuple of names (SI units,
radians).  A result unpacks like python-control's responses: ``t, y = result``.
Stored as one uncompressed ``.npz`` per run (no pickle; metadata as a JSON string),
written atomically.
"""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["RunResult", "STATUSES", "write_atomic"]

STATUSES = ("ok", "diverged", "failed")
_UMASK = os.umask(0)
os.umask(_UMASK)


@dataclass
class RunResult:
    """Signals of one run at the control instants t_k = k·Ts.

    Attributes
    ----------
    time : ndarray (n_samples,)
    names : tuple of str
    signals : ndarray (n_signals, n_samples)
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
    """

    time: np.ndarray
    names: tuple[str, ...]
    signals: np.ndarray
    status: str = "ok"
    message: str = ""
    end_time: float = 0.0
    config: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

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

    # --- storage --------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write ``path`` (.npz) atomically: a reader never sees a partial file."""
        path = Path(path)
        meta = {"status": self.status, "message": self.message, "end_time": self.end_time,
                "config": self.config, "timings": self.timings}

        def write(fh):
            np.savez(fh, time=self.time, signals=self.signals,
                                names=np.array(self.names, dtype=str),
                                meta=np.array(json.dumps(meta)))
        write_atomic(path, write, binary=True)
        return path

    @classmethod
    def load(cls, path: str | Path) -> "RunResult":
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            return cls(time=data["time"], names=tuple(str(n) for n in data["names"]),
                       signals=data["signals"], status=meta["status"], message=meta["message"],
                       end_time=meta["end_time"], config=meta["config"], timings=meta["timings"])


def write_atomic(path: Path, write, *, binary: bool = False) -> None:
    """Call ``write(file)`` on a temporary file next to ``path``, fsync it, and rename it
    over ``path`` (atomic on POSIX): the file is either the old or the new one, whole."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb" if binary else "w") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; results are for sharing
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
