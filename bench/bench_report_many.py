"""``flexarm report``, ``export`` and a metric query on N stored metrics-only runs, without
simulating N runs (issue 46's outside check: 40,000 runs, report ≤ 5 s, ≤ 4 KB a run).

    python bench/bench_report_many.py [RUNS ...]        (default: 40000)

One real run (0.3 s reduced, PBC + sign SMO, noisy encoders, a requirement's ρ, keeping
metrics only) is stored by ``flexarm campaign``; its row is then written again for seeds
1..RUNS-1 — each a scenario of its own whose id is its hash, its metrics scaled by a
seed-dependent factor (distinct values for the distributions) — through the store's own
row encoding (`validation.batch.store.index.row_values`), in batches of 512 as the committer
writes them.  So the folder is what a seed sweep of RUNS runs stores, bit for bit in
form, without its hours of simulation on 2 cores (`bench/bench_many_runs.py` runs them
for real, before and after).  Then, in fresh interpreters: ``flexarm export`` (the
campaign's own end), ``flexarm report`` (first render), a query through the Python API,
and bytes per run on disk.  Prints the table, writes bench/results/report_many.json.
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import report, target
from _workloads import CLI, METRICS_ONLY

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from validation.batch.store.index import (dictionary_for, metric_column,  # noqa: E402
                                    row_values, run_id)
from validation.batch.store.folder import ResultStore  # noqa: E402

REQUIREMENT = """[[requirement]]
name = "track"
formula = "always[0.1,0.3](abs(theta1 - theta1_ref) <= 0.002)"
"""


def fill(out: Path, runs: int) -> None:
    """Rows for seeds 1..runs-1 beside the one real run of ``out`` (module docstring)."""
    store = ResultStore(out)
    (real,) = store.rows()
    rest = real.detail.decoded()[1]
    dictionary = dictionary_for(real.config, real.environment, tuple(
        (real.kept or {}).get("names", ())))
    store.add_dictionary(dictionary)
    batch = []
    for seed in range(1, runs):
        scenario = dict(real.config, seed=seed)
        factor = 1.0 + 1e-3 * ((seed * 7919) % 1000) / 1000
        metrics = {k: v * factor if isinstance(v, float) else v
                   for k, v in real.metrics.items()}
        metrics = {k: None if isinstance(v, float) and v != v else v
                   for k, v in metrics.items()}
        row = {"run_id": run_id(scenario), "name": real.name, "campaign": real.campaign,
               "sweep": real.sweep, "axes": {"seed": seed}, "status": real.status,
               "message": real.message, "end_time": real.end_time,
               "fingerprint": real.fingerprint, "scenario": scenario, "metrics": metrics,
               "timings": rest["timings"], "environment": rest["environment"],
               "kept": rest.get("kept"), "file": "", "sha256": "", "size": 0,
               "finished": real.finished}
        batch.append(row_values(row, dictionary))
        if len(batch) == 512:
            store.insert(batch)
            batch = []
    store.insert(batch)
    store.close()


def cli(*args: str) -> float:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CLI, *args], cwd=ROOT, capture_output=True,
                          text=True)
    if done.returncode != 0:
        raise SystemExit(f"flexarm {args[0]} exited {done.returncode}:\n{done.stderr[-2000:]}")
    return time.perf_counter() - t0


def main(counts: list[int]) -> None:
    rows = []
    for runs in counts:
        with tempfile.TemporaryDirectory(prefix="flexarm-report-many-") as tmp:
            tmp = Path(tmp)
            spec, out = tmp / "one.toml", tmp / "out"
            spec.write_text(METRICS_ONLY.format(duration=0.3, transient=0.1,
                                                requirement=REQUIREMENT, seeds=[0]))
            cli("campaign", str(spec), "--out", str(out), "--workers", "1", "--no-progress")
            t0 = time.perf_counter()
            fill(out, runs)
            fill_s = time.perf_counter() - t0
            export_s = cli("export", str(out))
            report_s = cli("report", str(out), "--no-progress", "--no-animation")
            store = ResultStore(out)
            t0 = time.perf_counter()
            found = store.rows(where=metric_column("track_max_1") + " > ?", params=(0.0496,))
            query_s = time.perf_counter() - t0
            t0 = time.perf_counter()
            every = store.rows()
            read_s = time.perf_counter() - t0
            files = [p for p in out.rglob("*") if p.is_file()]
            disk = sum(p.stat().st_blocks * 512 for p in files)
            rows.append({"runs": len(every), "fill_s": fill_s, "export_s": export_s,
                         "report_s": report_s, "read_rows_s": read_s, "query_s": query_s,
                         "query_note": f"{len(found)} runs",
                         "disk_bytes_per_run": disk / runs,
                         "report_target": target(report_s, "<=", 5.0 * max(1, runs / 40_000))
                         ["met"],
                         **target(disk / runs, "<=", 4096.0)})
    report("report_many", rows, title="metrics-only folders of RUNS runs (one real run, "
                                      "its row written again per seed)",
           columns=["runs", "fill_s", "export_s", "report_s", "report_target", "read_rows_s",
                    "query_s", "query_note", "disk_bytes_per_run", "target", "met"])


if __name__ == "__main__":
    main([int(n) for n in sys.argv[1:]] or [40_000])
