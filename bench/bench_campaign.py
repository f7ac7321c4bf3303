"""Campaign throughput with 1 and 2 workers, and the orchestration overhead per run.

Targets (issue 14): a 48-run campaign of 5 s reduced runs with 2 workers ≥ 1.6× the
runs/min of 1 worker; 20 s Exudyn runs ≥ 1.8×.  Overhead per run = (campaign wall time −
Σ the runs' own simulation wall time) / runs on the serial runner, where the two are
comparable: expansion, checking, building plants and laws, metrics, storage.
"""
from __future__ import annotations

import sys
import tempfile
import time

from _report import report, target
from validation.campaign import campaign_from_mapping, run_campaign
from validation.executor import make_runner
from validation.store import ResultStore

SWEEPS = {
    "reduced, 48 runs x 5 s": ({
        "name": "bench-reduced", "scenario": {"duration": 5.0, "observer": {"kind": "smo-paper"}},
        "sweep": [{"grid": {"true_params.Mp": [0.0, 0.1, 0.2, 0.3, 0.5, 0.8],
                            "observer.kind": ["smo-paper", "smo-bl"],
                            "seed": [1, 2, 3, 4]}}]}, 1.6),
    "exudyn, 8 runs x 20 s": ({
        "name": "bench-exudyn", "scenario": {"plant": {"kind": "exudyn"},
                                             "observer": {"kind": "smo-paper"}},
        "sweep": [{"grid": {"true_params.Mp": [0.0, 0.1, 0.5, 1.0], "seed": [1, 2]}}]}, 1.8),
}


def main(only: str | None = None):
    rows = []
    for label, (spec, speedup) in SWEEPS.items():
        if only and only not in label:
            continue
        campaign = campaign_from_mapping(spec)
        per_min = {}
        for workers in (1, 2):
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                with make_runner("local", workers) as runner:
                    summary = run_campaign(campaign, tmp, runner=runner, progress=False)
                wall = time.perf_counter() - t0
                simulated = sum(r.timings["wall_s"] for r in ResultStore(tmp).rows())
                n = summary.done
                per_min[workers] = 60 * n / wall
                row = {"sweep": label, "workers": workers, "runs": n, "wall_s": wall,
                       "runs_per_min": per_min[workers], "sim_wall_sum_s": simulated}
                if workers == 1:
                    row["overhead_ms_per_run"] = 1e3 * (wall - simulated) / n
                else:
                    row["speedup"] = per_min[2] / per_min[1]
                    row |= target(row["speedup"], ">=", speedup)
                rows.append(row)
    report("campaign", rows, title="Campaign throughput (local runners)",
           columns=["sweep", "workers", "runs", "wall_s", "runs_per_min", "speedup", "target",
                    "met", "sim_wall_sum_s", "overhead_ms_per_run"])


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
