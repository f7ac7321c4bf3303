"""Campaign throughput with 1 and 2 workers, and the orchestration overhead per run.

Targets (issue 14): a 48-run campaign of 5 s reduced runs with 2 workers ≥ 1.6× the
runs/min of 1 worker; 20 s Exudyn runs ≥ 1.8×; orchestration ≤ 10 ms per run.

Each sweep runs REPEATS times with 1 and 2 workers back to back; the table gives
medians and the range of the paired speed-ups.  On the serial runner (where the sums are
comparable with the wall time), after the kernels are loaded (`worker.warm_up`, timed and
shown apart as a once-per-process cost): overhead per run = (campaign wall time − Σ the
runs' simulation wall time) / runs; of it, the metrics are timed again on the stored
runs, and orchestration is the rest (expansion, checking, building plants and laws,
result transfer, storage).
"""
from __future__ import annotations

import statistics
import sys
import tempfile
import time
import tomllib

from _report import report, target
from _workloads import REDUCED_48, TRUTH_8
from validation.batch.campaign import campaign_from_mapping
from validation.batch.queue import run_campaign
from validation.batch.executor import make_runner
from validation.run.metrics import all_metrics
from validation.batch.store.folder import ResultStore
from validation.batch.worker import warm_up

REPEATS = 5  # the machines drift up to 2x within an hour: medians of paired repeats

SWEEPS = {  # label: (campaign, speed-up target of 2 workers, orchestration target [ms])
    "reduced, 48 runs x 5 s": (tomllib.loads(REDUCED_48), 1.6, 10.0),
    # its set-up includes assembling the Exudyn mesh: no orchestration target
    "exudyn, 8 runs x 20 s": (tomllib.loads(TRUTH_8), 1.8, None),
}


def _metrics_seconds(store: ResultStore) -> float:
    results = [store.load(run.run_id) for run in store.rows()]
    t0 = time.perf_counter()
    for result in results:
        all_metrics(result)
    return time.perf_counter() - t0


def _campaign(campaign, workers: int) -> dict:
    """One campaign into a fresh folder: its wall time and, serially, the overhead."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        with make_runner("local", workers) as runner:
            summary = run_campaign(campaign, tmp, runner=runner, progress=False)
        wall = time.perf_counter() - t0
        if summary.failed or summary.diverged:
            raise SystemExit(f"{campaign.name}, {workers} worker(s): {summary.failed} failed "
                             f"and {summary.diverged} diverged runs; no timing reported")
        store = ResultStore(tmp)
        n = summary.done
        out = {"runs": n, "wall_s": wall, "runs_per_min": 60 * n / wall}
        if workers == 1:
            overhead = (wall - sum(r.timings["wall_s"] for r in store.rows())) / n
            analysis = _metrics_seconds(store) / n
            out |= {"overhead_ms_per_run": 1e3 * overhead,
                    "metrics_ms_per_run": 1e3 * analysis,
                    "orchestration_ms_per_run": 1e3 * (overhead - analysis)}
        return out


def main(only: str | None = None, repeats: int = REPEATS):
    t0 = time.perf_counter()
    warm_up()
    print(f"kernels loaded in {time.perf_counter() - t0:.2f} s (once per process)")
    rows = []
    for label, (spec, speedup, orchestration) in SWEEPS.items():
        if only and only not in label:
            continue
        campaign = campaign_from_mapping(spec)
        pairs = []
        for i in range(repeats):  # 1 and 2 workers back to back, alternating which first
            order = (1, 2) if i % 2 == 0 else (2, 1)
            pair = {w: _campaign(campaign, w) for w in order}
            pairs.append(pair)
            print(f"{label}: repeat {i + 1} of {repeats}: 2 workers "
                  f"{pair[2]['runs_per_min'] / pair[1]['runs_per_min']:.2f}x", flush=True)
        for workers in (1, 2):
            runs = [p[workers] for p in pairs]
            row = {"sweep": label, "workers": workers, "runs": runs[0]["runs"]}
            row |= {k: statistics.median(r[k] for r in runs) for k in runs[0] if k != "runs"}
            if workers == 1:
                spread = [r["orchestration_ms_per_run"] for r in runs]
                row["orchestration_range"] = f"{min(spread):.3g}-{max(spread):.3g}"
                if orchestration is not None:
                    row |= target(row["orchestration_ms_per_run"], "<=", orchestration)
            else:
                ratios = [p[2]["runs_per_min"] / p[1]["runs_per_min"] for p in pairs]
                row["speedup"] = statistics.median(ratios)
                row["speedup_range"] = f"{min(ratios):.2f}-{max(ratios):.2f}"
                row |= target(row["speedup"], ">=", speedup)
            rows.append(row)
    report("campaign", rows, title=f"Campaign throughput (local runners), medians of {repeats} "
                                   "paired repeats",
           columns=["sweep", "workers", "runs", "wall_s", "runs_per_min", "speedup",
                    "speedup_range", "target", "met", "overhead_ms_per_run",
                    "metrics_ms_per_run", "orchestration_ms_per_run", "orchestration_range"])


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None,
         int(sys.argv[2]) if len(sys.argv) > 2 else REPEATS)
