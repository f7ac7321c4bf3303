"""A 10⁵-run campaign (issue 35): short reduced runs keeping metrics only, killed with
SIGKILL part-way and resumed; then how fast its index answers.

    python bench/campaign_1e5.py [RUNS] [WORKERS]

(not one of `make bench`'s bench_*.py: 10⁵ runs take about an hour on 2 busy cores)

1. ``flexarm campaign`` of RUNS (default 100 000, the most a campaign may expand to)
   0.1 s reduced runs (PBC + sign SMO, noisy encoders, one noise seed each; ``[keep]
   signals = "none"``), killed with SIGKILL once a third of the runs are stored: what was stored
   (rows, and files whose rows the kill caught, adopted by the resume).
2. The same command again: it resumes, runs what is left, and completes; the index then
   holds every run once and every file verifies.
3. The size on disk (runs/, the index, the exports) and bytes per run.
4. How fast the index answers: ``flexarm export`` (metrics.csv and manifest.json from the
   index), a query of the runs that fail a bound (SQL on the metrics column), reading
   every row, and ``flexarm report`` (whole command lines).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import report, target
from _workloads import CLI, METRICS_ONLY

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from campaign_testing import stored_count  # noqa: E402

from validation.batch.store.index import metric_column  # noqa: E402
from validation.batch.store.folder import ResultStore  # noqa: E402

#: 0.1 s runs, no requirement.
CAMPAIGN = METRICS_ONLY.replace("{duration}", "0.1").replace("{transient}", "0.05") \
    .replace("{requirement}", "")


def command(*args: str, timeout: float = 7200) -> tuple[float, subprocess.CompletedProcess]:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CLI, *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)
    return time.perf_counter() - t0, done


def folder_bytes(out: Path) -> dict:
    runs = sum(p.stat().st_size for p in (out / "runs").iterdir() if p.is_file())
    index = sum(p.stat().st_size for p in out.glob("index.sqlite*"))
    exports = sum((out / n).stat().st_size for n in ("metrics.csv", "manifest.json")
                  if (out / n).exists())
    return {"runs": runs, "index": index, "exports": exports}


def main(runs: int = 100_000, workers: int = 2) -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        spec, out = tmp / "large.toml", tmp / "out"
        spec.write_text(CAMPAIGN.format(seeds=list(range(runs))))
        args = ["campaign", str(spec), "--out", str(out), "--workers", str(workers),
                "--no-progress"]
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", CLI, *args], cwd=ROOT,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        while stored_count(out) < runs // 3 and proc.poll() is None:
            time.sleep(1.0)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        killed_after = time.perf_counter() - t0
        store = ResultStore(out)
        indexed, orphans = len(store.rows()), len(store.unindexed_files())
        store.close()
        rows.append({"what": f"killed (SIGKILL) after {killed_after:.0f} s", "value": indexed,
                     "unit": "rows", "note": f"and {orphans} files whose rows the kill caught"})
        seconds, done = command(*args)
        rows.append({"what": "resumed to completion", "value": seconds, "unit": "s",
                     "note": done.stdout.strip().splitlines()[-1] if done.stdout else
                     done.stderr[-300:]})
        store = ResultStore(out)
        t0 = time.perf_counter()
        every = store.rows()
        read_s = time.perf_counter() - t0
        damaged = store.verify(every)
        complete = len(every) == runs == len({r.run_id for r in every}) and not damaged \
            and done.returncode == 0
        rows.append({"what": "every run stored once, every file verifies", "value": len(every),
                     "unit": "rows", "note": "yes" if complete else "NO",
                     **target(float(complete), ">=", 1.0)})
        sizes = folder_bytes(out)
        total = sum(sizes.values())
        rows.append({"what": "size on disk", "value": total / 2**20, "unit": "MiB",
                     "note": f"{total / runs:.0f} bytes per run: run files "
                             f"{sizes['runs'] / runs:.0f}, index {sizes['index'] / runs:.0f}, "
                             f"exports {sizes['exports'] / runs:.0f}"})
        rows.append({"what": "read every row of the index", "value": read_s, "unit": "s"})
        t0 = time.perf_counter()
        failing = store.rows(where=metric_column("track_max_1") + " > ?", params=(0.01,))
        rows.append({"what": "query: runs with track_max_1 > 10 mrad", "unit": "s",
                     "value": time.perf_counter() - t0, "note": f"{len(failing)} runs"})
        store.close()
        for what in (["export", str(out)], ["report", str(out), "--no-animation",
                                            "--no-progress"]):
            seconds, done = command(*what, timeout=1800)
            rows.append({"what": f"flexarm {what[0]}", "value": seconds, "unit": "s",
                         "note": "ok" if done.returncode == 0 else
                         f"exit {done.returncode}: {done.stderr.strip()[-200:]}"})
    report("large", rows, title=f"A {runs}-run campaign, {workers} workers, metrics only "
                                f"(load {os.getloadavg()[0]:.1f})",
           columns=["what", "value", "unit", "target", "met", "note"])


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
