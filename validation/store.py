"""A results folder: one ``.npz`` per run, ``metrics.csv`` and ``manifest.json``.

    OUT/runs/<run_id>.npz   signals (float32), status, resolved scenario, timings (`RunResult`)
    OUT/metrics.csv         one row per run id (never duplicated), columns = metric names
    OUT/manifest.json       per run: scenario name, status, message, timings, versions

Every file is replaced atomically (temporary file + rename), so an interrupted process
leaves either the previous or the new version, never a truncated one; a killed process
may leave a hidden ``.<name>.*.tmp`` file, which the next campaign in the folder removes
(one campaign writes a folder at a time).  The run id is a
hash of the resolved scenario: the same scenario always maps to the same files.
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import platform
import subprocess
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from .results import RunResult, write_atomic

__all__ = ["ResultStore", "run_id", "environment"]


def run_id(resolved_scenario: dict) -> str:
    """12 hex digits of the SHA-256 of the scenario's canonical JSON."""
    text = json.dumps(resolved_scenario, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def environment() -> dict:
    """Versions and git revision recorded with every run."""
    def pkg(name):
        try:
            return version(name)
        except PackageNotFoundError:
            return None
    env = {name: pkg(name) for name in ("flexarm-validation", "exudyn", "numpy", "numba",
                                        "scipy")}
    env["python"] = platform.python_version()
    try:
        env["git"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                    text=True, timeout=5, cwd=Path(__file__).parent
                                    ).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        env["git"] = None
    return env


class ResultStore:
    """Reads and writes one results folder (created on first write)."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.runs = self.out / "runs"
        self.manifest_path = self.out / "manifest.json"
        self.metrics_path = self.out / "metrics.csv"

    # --- reading ----------------------------------------------------------------------
    def manifest(self) -> dict:
        if not self.manifest_path.exists():
            return {"runs": {}}
        return json.loads(self.manifest_path.read_text())

    def metrics(self) -> list[dict]:
        if not self.metrics_path.exists():
            return []
        with self.metrics_path.open(newline="") as fh:
            return [{k: v if k in _TEXT_COLUMNS else _parse(v) for k, v in row.items()}
                    for row in csv.DictReader(fh)]

    def load(self, rid: str) -> RunResult:
        return RunResult.load(self.runs / f"{rid}.npz")

    def completed(self) -> dict[str, str]:
        """run id → status of every run whose result file exists."""
        return {rid: entry["status"] for rid, entry in self.manifest()["runs"].items()
                if (self.runs / f"{rid}.npz").exists()}

    # --- writing ----------------------------------------------------------------------
    def prepare(self) -> None:
        """Create the folder (raises OSError with the reason if it cannot)."""
        self.runs.mkdir(parents=True, exist_ok=True)

    def remove_stale_temporaries(self) -> int:
        """Delete temporary files a killed writer left behind; returns how many."""
        stale = [*self.out.glob(".*.tmp"), *self.runs.glob(".*.tmp")]
        for path in stale:
            path.unlink(missing_ok=True)
        return len(stale)

    def add(self, rid: str, result: RunResult, metrics: dict, *, extra: dict | None = None,
            env: dict | None = None) -> Path:
        """Store one run: its .npz, then its metrics row, then its manifest entry (the
        manifest is written last, so an entry always has its files).  Signals are stored
        as float32 (7 digits, for plots; metrics are computed from float64 beforehand):
        half the size, and uncompressed writing stays at milliseconds per run."""
        self.prepare()
        result.signals = result.signals.astype(np.float32)
        path = result.save(self.runs / f"{rid}.npz")
        rows = [r for r in self.metrics() if r.get("run_id") != rid]
        rows.append({"run_id": rid, "name": result.config.get("name", ""), **metrics})
        self._write_metrics(rows)
        manifest = self.manifest()
        manifest["runs"][rid] = {
            "name": result.config.get("name", ""), "status": result.status,
            "message": result.message, "end_time": result.end_time, "timings": result.timings,
            "file": str(path.relative_to(self.out)),
            "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "environment": env or environment(), **(extra or {})}
        write_atomic(self.manifest_path, lambda fh: json.dump(manifest, fh, indent=1))
        return path

    def set_campaign(self, info: dict) -> None:
        """Record the campaign (name, description, report settings) in the manifest."""
        self.prepare()
        manifest = self.manifest()
        manifest["campaign"] = info
        write_atomic(self.manifest_path, lambda fh: json.dump(manifest, fh, indent=1))

    def _write_metrics(self, rows: list[dict]) -> None:
        columns = ["run_id", "name"]
        for row in rows:
            columns += [c for c in row if c not in columns]
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=columns, restval="", lineterminator="\n")
        writer.writeheader()
        for row in sorted(rows, key=lambda r: (str(r.get("name", "")), r["run_id"])):
            writer.writerow({k: _format(v) for k, v in row.items()})
        write_atomic(self.metrics_path, lambda fh: fh.write(buf.getvalue()))


# Identifiers stay text: a hex run id such as "1234567e8901" would otherwise read as a float.
_TEXT_COLUMNS = frozenset({"run_id", "name", "status"})


def _format(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)
    return str(value)


def _parse(text: str):
    if text == "":
        return None
    try:
        return float(text)
    except ValueError:
        return text
