"""A Dask cluster against the local pool, the same work on the same machine (issue 35):
``flexarm campaign`` with ``--executor dask`` on a cluster of N single-threaded workers
(``dask scheduler`` + ``dask worker --nworkers N --nthreads 1`` on localhost, started
here; the workers see the results folder and store the runs themselves) against
``--workers N``, whole command lines, paired repeats; and the two folders' metrics and
signals compared (bit-identical).

    python bench/bench_dask.py [WORKERS] [REPEATS] [WORKLOAD]

WORKLOAD: ``reduced`` (48 × 5 s reduced runs, the default) or ``truth`` (8 × 20 s truth
runs, `_workloads.TRUTH_8`).  Target: Dask within 10 % of the local pool (wall time
ratio ≤ 1.10).
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _report import report, target
from _workloads import CLI, REDUCED_48, TRUTH_8

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from campaign_testing import dask_cluster, metrics_table  # noqa: E402

from validation.batch.store.folder import ResultStore  # noqa: E402

WORKLOADS = {"reduced": REDUCED_48, "truth": TRUTH_8}


def timed(*args: str) -> float:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CLI, *args, "--no-progress"], cwd=ROOT,
                          capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"flexarm {' '.join(args)} exited {done.returncode}:\n"
                         f"{done.stderr[-2000:]}")
    return seconds


def identical(a: Path, b: Path) -> bool:
    if metrics_table(a) != metrics_table(b):
        return False
    sa, sb = ResultStore(a), ResultStore(b)
    return all(np.array_equal(sa.load(r.run_id).signals, sb.load(r.run_id).signals)
               for r in sa.rows())


def main(workers: int = 2, repeats: int = 3, workload: str = "reduced") -> dict:
    times = {"local": [], "dask": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        spec = tmp / "campaign.toml"
        spec.write_text(WORKLOADS[workload])
        timed("campaign", str(spec), "--out", str(tmp / "warm"), "--workers", "1",
              "--force-workers")  # the kernels, once
        with dask_cluster(tmp, workers) as address:
            for i in range(repeats):
                for kind in (("local", "dask") if i % 2 == 0 else ("dask", "local")):
                    out = tmp / f"{kind}{i}"
                    how = ["--workers", str(workers), "--force-workers"] if kind == "local" \
                        else ["--executor", "dask", "--scheduler", address]
                    times[kind].append(timed("campaign", str(spec), "--out", str(out), *how))
        same = identical(tmp / "local0", tmp / "dask0")
    local, dask = statistics.median(times["local"]), statistics.median(times["dask"])
    ratio = dask / local
    rows = [{"what": f"campaign {workload}, {workers} workers: local pool [s]", "seconds": local,
             "range": f"{min(times['local']):.3g}-{max(times['local']):.3g}"},
            {"what": f"campaign {workload}, {workers} workers: Dask cluster [s]", "seconds": dask,
             "range": f"{min(times['dask']):.3g}-{max(times['dask']):.3g}"},
            {"what": "Dask / local", "seconds": ratio, **target(ratio, "<=", 1.10)},
            {"what": "metrics and signals bit-identical", "seconds": None,
             "range": "yes" if same else "NO"}]
    report(f"dask_{workload}_{workers}", rows,
           title=f"Dask against the local pool, {workers} single-threaded workers, medians of "
                 f"{repeats} paired repeats (load {os.getloadavg()[0]:.1f})",
           columns=["what", "seconds", "range", "target", "met"])
    return {"local_s": local, "dask_s": dask, "ratio": ratio, "identical": same,
            "times": times}


if __name__ == "__main__":
    result = main(*(int(a) for a in sys.argv[1:3]), *sys.argv[3:4])
    print(json.dumps({k: v for k, v in result.items() if k != "times"}))
