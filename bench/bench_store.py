"""Bookkeeping of the results store: milliseconds per stored run as the folder grows.

Target (issue 13): ≤ 5 ms per stored run at 10k stored runs (the run file and its index
row, one transaction); before the SQLite index, metrics.csv and manifest.json were
rewritten whole per run: 28 ms at 100 runs, 275 ms at 2000, 497 ms at 3000.  Also the
cost of deciding what to resume (reading and verifying every row: size and SHA-256).
"""
from __future__ import annotations

import tempfile
import time

import numpy as np

from _report import report, target
from validation.run.results import RunResult
from validation.batch.store.folder import ResultStore

SIZES = (100, 1_000, 10_000)
SAMPLES = 50  # adds timed at each size


def fake_result(i: int) -> tuple[RunResult, dict]:
    """A small stored run (a 0.5 s run's worth of signals: 62 × 500)."""
    t = np.arange(500) * 1e-3
    config = {"name": f"bench/run{i}", "plant": {"kind": "reduced"}, "Ts": 1e-3, "arm": "default",
              "controller": {"kind": "pbc"}, "observer": {"kind": "none"},
              "initial_state": "rest"}
    r = RunResult(time=t, names=tuple(f"s{k}" for k in range(62)),
                  signals=np.random.default_rng(i).standard_normal((62, 500)), config=config)
    metrics = {f"m{k}": float(k) for k in range(120)} | {"status": "ok"}
    return r, metrics


def main():
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        store = ResultStore(tmp)
        stored = 0
        for size in SIZES:
            while stored < size - SAMPLES:
                store.add(f"{stored:012x}", *fake_result(stored), env={})
                stored += 1
            t0 = time.perf_counter()
            for _ in range(SAMPLES):
                store.add(f"{stored:012x}", *fake_result(stored), env={})
                stored += 1
            per_run = (time.perf_counter() - t0) / SAMPLES * 1e3
            t0 = time.perf_counter()
            rows_read = store.rows()
            damaged = store.verify(rows_read)
            resume = time.perf_counter() - t0
            row = {"stored_runs": size, "ms_per_stored_run": per_run,
                   "resume_check_s": resume, "resume_ms_per_run": 1e3 * resume / size,
                   "damaged": len(damaged)}
            if size == 10_000:
                row |= target(per_run, "<=", 5.0)
            rows.append(row)
    report("store", rows, title="Results store bookkeeping (run file + index row, ms per run)",
           columns=["stored_runs", "ms_per_stored_run", "target", "met", "resume_check_s",
                    "resume_ms_per_run", "damaged"])


if __name__ == "__main__":
    main()
