"""Run files: one per run, ``runs/<run id>.npz``, holding its signals and everything its
index row holds (so that a file alone rebuilds its row).  `write_run` writes one — under a
temporary name, then renamed, its checksum computed where the bytes are — and returns the
row; `run_row` is the one place a row is made, for a new run and for an adopted file."""
from __future__ import annotations

import hashlib
from datetime import datetime, timezone
from pathlib import Path

from ..run.results import RunResult, write_atomic
from .fingerprint import run_fingerprint
from .index import finite_or_none, set_aside

__all__ = ["write_run", "run_row", "META_KEYS"]

#: What a run file's metadata holds beside the result (`RunResult.to_bytes`).
META_KEYS = ("campaign", "sweep", "axes", "fingerprint", "metrics", "environment", "finished")


def run_row(rid: str, result: RunResult, meta: dict, data: bytes) -> dict:
    """The index row of run ``rid``: its result, the file's metadata ``meta`` (`META_KEYS`)
    and the file's bytes ``data`` (checksum and size)."""
    return {"run_id": rid, "name": result.config.get("name", ""),
            "campaign": meta.get("campaign", ""), "sweep": meta.get("sweep", ""),
            "axes": meta.get("axes", {}), "status": result.status, "message": result.message,
            "end_time": result.end_time, "fingerprint": meta.get("fingerprint", ""),
            "scenario": result.config, "metrics": meta.get("metrics", {}),
            "timings": finite_or_none(result.timings),
            "environment": meta.get("environment", {}), "file": f"runs/{rid}.npz",
            "sha256": hashlib.sha256(data).hexdigest(), "size": len(data),
            "finished": meta.get("finished", "")}


def write_run(out: Path, rid: str, result: RunResult, metrics: dict, *, campaign: str = "",
              sweep: str = "", axes: dict | None = None, env: dict) -> dict:
    """Write run ``rid``'s file into the results folder ``out`` and return its index row.
    Signals are stored as float32 (7 digits, for plots; metrics come from the float64
    signals)."""
    meta = {"campaign": campaign, "sweep": sweep, "axes": axes or {},
            "fingerprint": run_fingerprint(result.config),
            "metrics": finite_or_none(metrics), "environment": env,
            "finished": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    result.signals = result.signals.astype("float32", copy=False)
    data = result.to_bytes(meta)
    path = Path(out) / "runs" / f"{rid}.npz"
    if path.is_symlink() or (path.exists() and not path.is_file()):
        set_aside(path)  # a folder, link or FIFO in the run's place: kept, never followed
    write_atomic(path, lambda fh: fh.write(data), binary=True, sync=False)
    return run_row(rid, result, meta, data)
