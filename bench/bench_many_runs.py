"""Many metrics-only runs, before and after (issue 46): campaign, report, export, a metric
query through the Python API, bytes per run.

    python bench/bench_many_runs.py REV [RUNS ...]      (default RUNS: 10000)

Extracts REV (``git archive``, no worktree) into a temporary folder and, for each number
of runs and each tree (REV's, then this one), runs in fresh interpreters: ``flexarm
campaign`` of RUNS 0.3 s reduced runs keeping metrics only (PBC + sign SMO, noisy
encoders, one seed each, a requirement's ρ; 2 workers), ``flexarm report``, ``flexarm
export``, reading every row and a query of the runs whose ``track_max_1`` exceeds
1 mrad through `ResultStore.rows` (REV: ``json_extract`` on its metrics JSON; this tree:
the metric's column), and the folder's size: bytes per run as files hold them
(``st_size``) and as the disk holds them (blocks, as ``du``).  metrics.csv must be
byte-identical between the trees (or, where the resolved scenario gained fields since
REV, the same rows but for their run ids).  Targets (issue 46): ``flexarm report`` ≤ 5 s at
40,000 runs (here: scaled to RUNS, linear), ≤ 4 KB on disk per run.  Prints the table,
writes bench/results/many_runs_RUNS.json.  10^5 runs take ~15 min a tree on 2 idle cores.
"""
from __future__ import annotations

import filecmp
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import report, target
from _workloads import CLI, METRICS_ONLY, extract

ROOT = Path(__file__).resolve().parent.parent

#: A requirement, so that every run carries a robustness ρ to summarise.
REQUIREMENT = """[[requirement]]
name = "track"
formula = "always[0.1,0.3](abs(theta1 - theta1_ref) <= 0.002)"
"""

#: Read every row, then the query, in the tree's own interpreter; prints two times.
QUERY = """import sys, time
from validation.batch.store.folder import ResultStore
store = ResultStore(sys.argv[1])
t = time.perf_counter(); every = store.rows(); read = time.perf_counter() - t
try:
    from validation.batch.store.index import metric_column
    where = metric_column("track_max_1") + " > ?"
except ImportError:
    where = "json_extract(metrics, '$.track_max_1') > ?"
t = time.perf_counter(); found = store.rows(where=where, params=(1e-3,))
print(read, time.perf_counter() - t, len(every), len(found))
"""


def timed(tree: Path, *args: str) -> tuple[float, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, *args], cwd=tree, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(tree)})
    if done.returncode != 0:
        raise SystemExit(f"{tree}: {' '.join(args[:3])} exited {done.returncode}:\n"
                         f"{done.stderr[-2000:]}")
    return time.perf_counter() - t0, done


def sizes(out: Path) -> tuple[int, int]:
    """(bytes the files hold, bytes the disk holds for them) under ``out``."""
    files = [p for p in out.rglob("*") if p.is_file()]
    return (sum(p.stat().st_size for p in files),
            sum(p.stat().st_blocks * 512 for p in files) + 4096 * sum(
                1 for p in out.rglob("*") if p.is_dir()))


def measure(tree: Path, runs: int, tmp: Path, label: str) -> dict:
    spec, out = tmp / f"{label}-{runs}.toml", tmp / f"{label}-{runs}"
    spec.write_text(METRICS_ONLY.format(duration=0.3, transient=0.1, requirement=REQUIREMENT,
                                        seeds=list(range(runs))))
    row = {"tree": label, "runs": runs}
    row["campaign_s"], _ = timed(tree, "-c", CLI, "campaign", str(spec), "--out", str(out),
                                 "--workers", "2", "--no-progress")
    row["report_s"], _ = timed(tree, "-c", CLI, "report", str(out), "--no-progress",
                               "--no-animation")
    row["export_s"], _ = timed(tree, "-c", CLI, "export", str(out))
    _, done = timed(tree, "-c", QUERY, str(out))
    read, query, every, found = done.stdout.split()
    row |= {"read_rows_s": float(read), "query_s": float(query),
            "query_note": f"{found} of {every} runs"}
    apparent, disk = sizes(out)
    row |= {"bytes_per_run": apparent / runs, "disk_bytes_per_run": disk / runs}
    return row


def same_but_ids(a: Path, b: Path) -> bool:
    """Whether two metrics.csv hold the same rows but for the run ids (a change of the
    resolved scenario, e.g. a new arm field, renames every run: ids and so row order)."""
    def rows(path):
        with path.open() as fh:
            lines = fh.read().splitlines()
        return lines[0], sorted(line.partition(",")[2] for line in lines[1:])
    return rows(a) == rows(b)


def main(rev: str, counts: list[int]) -> None:
    rows = []
    with tempfile.TemporaryDirectory(prefix="flexarm-many-") as tmp:
        tmp = Path(tmp)
        before = extract(rev, tmp / "before")
        for runs in counts:
            old = measure(before, runs, tmp, "before")
            new = measure(ROOT, runs, tmp, "after")
            paths = [tmp / f"{t}-{runs}" / "metrics.csv" for t in ("before", "after")]
            same = filecmp.cmp(*paths, shallow=False)
            new["metrics_csv_identical"] = old["metrics_csv_identical"] = \
                "yes" if same else "same but run ids" if same_but_ids(*paths) else "NO"
            scale = runs / 40_000  # the report's target is at 40,000 runs, time linear
            rows += [old | target(old["report_s"], "<=", 5.0 * max(scale, 1.0)),
                     new | target(new["report_s"], "<=", 5.0 * max(scale, 1.0))]
            rows.append({"tree": "after (disk)", "runs": runs,
                         **target(new["disk_bytes_per_run"], "<=", 4096.0)})
            for r in (old, new):  # the tree's campaign folder is not kept
                subprocess.run(["rm", "-rf", str(tmp / f"{r['tree']}-{runs}")], check=True)
    report("many_runs_" + "_".join(map(str, counts)), rows, title=f"{rev} (before) against this tree: metrics-only runs",
           columns=["tree", "runs", "campaign_s", "report_s", "export_s", "read_rows_s",
                    "query_s", "query_note", "bytes_per_run", "disk_bytes_per_run",
                    "metrics_csv_identical", "target", "met"])


if __name__ == "__main__":
    if len(sys.argv) < 2:
        raise SystemExit("usage: python bench/bench_many_runs.py REV [RUNS ...]")
    main(sys.argv[1], [int(n) for n in sys.argv[2:]] or [10_000])
