"""Run files: one per run that keeps signals, ``runs/<run id>.npz``, holding them — all,
or what its campaign keeps (`Keep`) — and everything its index row holds (so that a file
alone rebuilds its row).  A run that keeps metrics only has no file: its row holds all
of it (a file would cost 9 KB on disk for ~1 KB of metrics).  `run_file` makes a run's bytes and its row (checksum and size
computed where the bytes are); `write_file` puts them in place under a temporary name,
then renamed; `run_row` is the one place a row is made, for a new run and for an
adopted file."""
from __future__ import annotations

import hashlib
import dataclasses
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ...run.config import check, check_known, did_you_mean
from ...run.results import RunResult, write_atomic
from ..fingerprint import run_fingerprint
from .index import finite_or_none, set_aside

__all__ = ["write_run", "run_file", "write_file", "run_row", "META_KEYS", "Keep", "KEEP_ALL",
           "KEEP_NONE", "keep_from_mapping", "KEEP_KEYS"]

#: What a run file's metadata holds beside the result (`RunResult.to_bytes`); ``kept``
#: only where the file keeps less than every signal at every sample (`Keep.meta`).
META_KEYS = ("campaign", "sweep", "axes", "fingerprint", "metrics", "environment", "finished",
             "kept")
#: The keys of a campaign's ``[keep]`` table.
KEEP_KEYS = ("signals", "every", "compress")


@dataclass(frozen=True)
class Keep:
    """What a run's file keeps of its signals: ``signals`` — None for every signal (the
    default), a tuple of names for those (in the run's own order; a name the run does
    not record is left out), () for none (metrics only) — at every ``every``-th control
    instant (t_0, t_every, …: the recorded values themselves, nothing filtered),
    compressed without loss if ``compress`` (`validation.run.packing`: about half the
    bytes, ~20 ms more per 5 s run for its worker).  The scenario, the metrics and the checksum are always kept: ``flexarm run --like``
    re-simulates any run's signals bit for bit (`validation.batch.store.resimulate`)."""

    signals: tuple[str, ...] | None = None
    every: int = 1
    compress: bool = False

    @property
    def everything(self) -> bool:
        return self.signals is None and self.every == 1

    @property
    def metrics_only(self) -> bool:
        """Whether no signal is kept (the run then has no file)."""
        return self.signals == ()

    def apply(self, result: RunResult) -> RunResult:
        """``result`` reduced to what is kept (itself if everything is)."""
        if self.everything:
            return result
        names = result.names if self.signals is None else \
            tuple(n for n in result.names if n in self.signals)
        rows = [result.names.index(n) for n in names]
        time = result.time[::self.every] if names else result.time[:0]  # metrics only
        return dataclasses.replace(
            result, time=time, names=names,
            signals=np.ascontiguousarray(result.signals[rows, ::self.every][:, :time.size]))

    def meta(self, result: RunResult) -> dict:
        """The file's note of what it keeps of ``result`` (nothing if everything): the
        names and number of samples the run recorded, and the decimation."""
        if self.everything:
            return {}
        return {"kept": {"every": self.every, "names": list(result.names),
                         "samples": int(result.time.size)}}


KEEP_ALL = Keep()
#: Metrics only.
KEEP_NONE = Keep(())


def keep_from_mapping(table: dict, known: tuple[str, ...]) -> Keep:
    """A campaign's ``[keep]`` table: ``signals = "all" | "none" | [names]``, ``every = k``
    (k ≥ 1) and ``compress = true | false``; ``known``: the signals of the campaign's base scenario
    (a name none of its runs records is refused).  ConfigError naming the key."""
    check(isinstance(table, dict), "keep", "must be a table")
    for key in table:
        check_known(key, KEEP_KEYS, f"keep.{key}")
    signals = table.get("signals", "all")
    if isinstance(signals, list):
        check(all(isinstance(n, str) for n in signals), "keep.signals",
              "must be \"all\", \"none\" or a list of signal names")
        for name in signals:
            check(name in known, "keep.signals", f"no signal {name!r} in the runs (signals: "
                                                 f"{', '.join(known)})"
                                                 f"{did_you_mean(name, known, quote=True)}")
        names = tuple(dict.fromkeys(signals))
    else:
        check(signals in ("all", "none"), "keep.signals",
              f"must be \"all\", \"none\" or a list of signal names, got {signals!r}")
        names = None if signals == "all" else ()
    every = table.get("every", 1)
    check(isinstance(every, int) and not isinstance(every, bool) and every >= 1,
          "keep.every", f"must be an integer >= 1 (every k-th sample), got {every!r}")
    compress = table.get("compress", False)
    check(isinstance(compress, bool), "keep.compress", f"must be true or false, got {compress!r}")
    return Keep(names, every, compress)


def run_row(rid: str, result: RunResult, meta: dict, data: bytes | None) -> dict:
    """The index row of run ``rid``: its result, the file's metadata ``meta`` (`META_KEYS`)
    and the file's bytes ``data`` (checksum and size; None: the run has no file)."""
    return {"run_id": rid, "name": result.config.get("name", ""),
            "campaign": meta.get("campaign", ""), "sweep": meta.get("sweep", ""),
            "axes": meta.get("axes", {}), "status": result.status, "message": result.message,
            "end_time": result.end_time, "fingerprint": meta.get("fingerprint", ""),
            "scenario": result.config, "metrics": meta.get("metrics", {}),
            "timings": finite_or_none(result.timings),
            "environment": meta.get("environment", {}), "kept": meta.get("kept"),
            "file": f"runs/{rid}.npz" if data is not None else "",
            "sha256": hashlib.sha256(data).hexdigest() if data is not None else "",
            "size": len(data) if data is not None else 0, "finished": meta.get("finished", "")}


def run_file(rid: str, result: RunResult, metrics: dict, *, campaign: str = "",
             sweep: str = "", axes: dict | None = None, env: dict,
             keep: Keep = KEEP_ALL) -> tuple[bytes | None, dict]:
    """The bytes of run ``rid``'s file (None if it keeps metrics only: no file) and its
    index row.  Signals are stored as float32 (7 digits, for plots; metrics come from the
    float64 signals), those ``keep`` keeps."""
    meta = {"campaign": campaign, "sweep": sweep, "axes": axes or {},
            "fingerprint": run_fingerprint(result.config),
            "metrics": finite_or_none(metrics), "environment": env,
            "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            **keep.meta(result)}
    if keep.metrics_only:
        return None, run_row(rid, result, meta, None)
    result.signals = result.signals.astype("float32", copy=False)
    data = keep.apply(result).to_bytes(meta, packed=keep.compress)
    return data, run_row(rid, result, meta, data)


def write_file(out: Path, rid: str, data: bytes) -> None:
    """Put run ``rid``'s file ``data`` in place in the results folder ``out``."""
    path = Path(out) / "runs" / f"{rid}.npz"
    if path.is_symlink() or (path.exists() and not path.is_file()):
        set_aside(path)  # a folder, link or FIFO in the run's place: kept, never followed
    write_atomic(path, lambda fh: fh.write(data), binary=True, sync=False)


def write_run(out: Path, rid: str, result: RunResult, metrics: dict, *, campaign: str = "",
              sweep: str = "", axes: dict | None = None, env: dict,
              keep: Keep = KEEP_ALL) -> dict:
    """Write run ``rid``'s file (if it has one) into the results folder ``out`` and return
    its index row."""
    data, row = run_file(rid, result, metrics, campaign=campaign, sweep=sweep, axes=axes,
                         env=env, keep=keep)
    if data is not None:
        write_file(out, rid, data)
    return row
