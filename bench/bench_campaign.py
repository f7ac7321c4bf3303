"""Campaign throughput: a 24-run reduced-plant sweep and an 8-run Exudyn sweep, each
with 1 and 2 workers, and the orchestration overhead per run.

Overhead per run (target ≤ 50 ms) = (campaign wall time − Σ the runs' own simulation
wall time) / runs, on the serial executor where the two are comparable; it covers
expansion, checking, building plants, metrics, storage and bookkeeping.  With a process
pool the worker start-up (imports, numba cache loads) adds a one-off cost per worker.
"""
from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path

from _report import report
from validation.campaign import campaign_from_mapping, make_executor, run_campaign

SWEEPS = {
    "reduced, 24 runs x 5 s": {
        "name": "bench-reduced", "scenario": {"duration": 5.0, "observer": {"kind": "smo-paper"}},
        "sweep": [{"grid": {"true_params.Mp": [0.0, 0.1, 0.3, 0.5, 0.8, 1.0],
                            "observer.kind": ["smo-paper", "smo-bl"], "seed": [1, 2]}}]},
    "exudyn, 8 runs x 5 s": {
        "name": "bench-exudyn", "scenario": {"duration": 5.0, "plant": {"kind": "exudyn"},
                                             "observer": {"kind": "smo-paper"}},
        "sweep": [{"grid": {"true_params.Mp": [0.0, 0.1, 0.5, 1.0], "seed": [1, 2]}}]},
}


def main():
    rows = []
    for label, spec in SWEEPS.items():
        campaign = campaign_from_mapping(spec)
        for workers in (1, 2):
            with tempfile.TemporaryDirectory() as tmp:
                executor, close = make_executor("local", workers)
                t0 = time.perf_counter()
                try:
                    summary = run_campaign(campaign, tmp, executor=executor, progress=False)
                finally:
                    close()
                wall = time.perf_counter() - t0
                manifest = json.loads((Path(tmp) / "manifest.json").read_text())["runs"]
                simulated = sum(e["timings"]["wall_s"] for e in manifest.values())
                n = summary.ok + summary.diverged + summary.failed
                row = {"sweep": label, "workers": workers, "runs": n, "wall_s": wall,
                       "runs_per_min": 60 * n / wall, "sim_wall_sum_s": simulated,
                       "bytes_per_run": sum(p.stat().st_size for p in
                                            (Path(tmp) / "runs").glob("*.npz")) / n}
                if workers == 1:
                    row["overhead_ms_per_run"] = 1e3 * (wall - simulated) / n
                    row["target_ms"] = 50
                rows.append(row)
    report("campaign", rows, title="Campaign throughput (local executor)",
           columns=["sweep", "workers", "runs", "wall_s", "runs_per_min", "sim_wall_sum_s",
                    "overhead_ms_per_run", "target_ms", "bytes_per_run"])


if __name__ == "__main__":
    main()
