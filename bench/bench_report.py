"""How long a report takes: ``flexarm report`` of one 5 s run (PBC + sign SMO on the
reduced plant, the issue's case), rendered in full and when nothing changed.

    python bench/bench_report.py [REPEATS] [--against TREE]

Each tree makes its own results folder (a stored run is only reported by the code that
made it), uncounted; then the report commands run alternately, each in a fresh process
(start-up included, as a user sees it): ``--force`` (a full render, with the animation)
and the unchanged case (nothing rendered).  Prints the median wall time of REPEATS
(default 3) per tree and its range, the median CPU time (user + system, the drawing
workers included: on a machine shared with other work it says what the wall time would
be on an idle one, up to the parallel drawing), the load average while measuring, and
the target (a full one-run report in <= 5 s wall); writes bench/results/report.json.
"""
from __future__ import annotations

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import report, target
from _workloads import CLI

ROOT = Path(__file__).resolve().parent.parent


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)  # every waited-for descendant
    return usage.ru_utime + usage.ru_stime


def _flexarm(tree: Path, *args: str) -> tuple[float, float]:
    """(wall, CPU) seconds of one command in a fresh process (its workers included)."""
    start, cpu = time.perf_counter(), _cpu()
    subprocess.run([sys.executable, "-c", CLI, *args], cwd=tree, check=True,
                   capture_output=True, env={**os.environ, "PYTHONPATH": str(tree)})
    return time.perf_counter() - start, _cpu() - cpu


def main() -> None:
    args = sys.argv[1:]
    trees = {"this tree": ROOT}
    if "--against" in args:
        i = args.index("--against")
        trees = {"against": Path(args[i + 1]).resolve(), **trees}
        del args[i:i + 2]
    repeats = int(args[0]) if args else 3
    with tempfile.TemporaryDirectory(prefix="bench-report-") as tmp:
        folders = {}
        for label, tree in trees.items():
            folders[label] = Path(tmp) / label.replace(" ", "-")
            _flexarm(tree, "run", "--duration", "5", "--observer", "smo-paper",
                     "--out", str(folders[label]))
            _flexarm(tree, "report", str(folders[label]), "--no-progress")  # warm caches
        times = {(label, kind): [] for label in trees for kind in ("full", "unchanged")}
        load = []
        for _ in range(repeats):
            for label, tree in trees.items():
                load.append(os.getloadavg()[0])
                ours = label == "this tree"  # earlier code renders always, has no --force
                times[(label, "full")].append(_flexarm(
                    tree, "report", str(folders[label]), "--no-progress",
                    *(["--force"] if ours else [])))
                if ours:
                    times[(label, "unchanged")].append(_flexarm(
                        tree, "report", str(folders[label]), "--no-progress"))
    rows = []
    for (label, kind), measured in times.items():
        if not measured:
            continue
        values = [wall for wall, _ in measured]
        median = statistics.median(values)
        row = {"tree": label, "report": kind, "median_s": median,
               "range_s": f"{min(values):.2f}-{max(values):.2f}",
               "cpu_s": statistics.median(cpu for _, cpu in measured), "repeats": len(values)}
        if label == "this tree" and kind == "full":
            row |= target(median, "<=", 5.0)
        rows.append(row)
    print(f"load average while measuring: {statistics.median(load):.2f} "
          f"(median of {len(load)}; {os.cpu_count()} cores)")
    report("report", rows, columns=["tree", "report", "median_s", "range_s", "cpu_s",
                                    "repeats", "target", "met"],
           title="flexarm report of one 5 s run (fresh process each, start-up included)")


if __name__ == "__main__":
    main()
