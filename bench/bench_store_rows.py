"""The coordinating process's cost per stored row, before and after (issue 46: it must
stay flat as the store changes; the whole command's is `bench_workers.py coordinator`).

    python bench/bench_store_rows.py REV

One metrics-only run (0.3 s reduced, PBC + sign SMO, noisy encoders) is made and its
row encoded as a worker encodes it; then 20,480 rows of distinct ids go the way a
campaign's rows go through the coordinator — unpickled as from a worker's pipe, committed
512 to a transaction (`validation.batch.store.committing.MAX_ROWS`) — in REV's tree and in this
one, each in a fresh interpreter: CPU milliseconds per row and bytes per row on the wire.
Prints the table, writes bench/results/store_rows.json.
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _report import report, target
from _workloads import ROOT, extract

ROWS = 20_480
#: Run in the measured tree: prints "CPU ms per row, bytes per row".
MEASURE = """import pickle, sys, time
from validation.batch.store.runfiles import Keep, run_file
from validation.batch.store.folder import ResultStore
from validation.batch.worker import execute_run
from validation.batch.store import index
from validation.run.scenario import scenario_from_mapping
s = scenario_from_mapping({"duration": 0.3, "transient": 0.1, "observer": {"kind": "smo-paper"},
                           "sensors": {"encoder_noise": 1e-4}})
result, metrics = execute_run(s)
_, row = run_file("0123456789ab", result, metrics, env={}, keep=Keep(()))
values = index.row_values(row)
def with_id(v, rid):
    return ((rid,) + v[0][1:],) + v[1:] if isinstance(v[0], tuple) else (rid,) + v[1:]
rows = [pickle.dumps(with_id(values, f"{i:012x}")) for i in range(ROWS)]
store = ResultStore(sys.argv[1])
store.prepare()
t = time.process_time()
for k in range(0, ROWS, 512):
    store.insert([pickle.loads(r) for r in rows[k:k + 512]])
print((time.process_time() - t) / ROWS * 1e3, len(rows[0]))
""".replace("ROWS", str(ROWS))


def measure(tree: Path, out: Path) -> tuple[float, int]:
    done = subprocess.run([sys.executable, "-c", MEASURE, str(out)], cwd=tree, text=True,
                          capture_output=True, env={**os.environ, "PYTHONPATH": str(tree)})
    if done.returncode != 0:
        raise SystemExit(f"{tree}: {done.stderr[-2000:]}")
    ms, size = done.stdout.split()
    return float(ms), int(size)


def main(rev: str) -> None:
    rows = []
    with tempfile.TemporaryDirectory(prefix="flexarm-store-rows-") as tmp:
        before = extract(rev, Path(tmp) / "before")
        for label, tree in ((f"{rev} (before)", before), ("this tree", ROOT)):
            ms, size = measure(tree, Path(tmp) / label.split()[0])
            rows.append({"tree": label, "cpu_ms_per_row": ms, "bytes_per_row_sent": size})
    rows[-1] |= target(rows[-1]["cpu_ms_per_row"], "<=", 0.1)
    report("store_rows", rows, title=f"the coordinator's cost per stored row ({ROWS} rows)",
           columns=["tree", "cpu_ms_per_row", "bytes_per_row_sent", "target", "met"])


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python bench/bench_store_rows.py REV")
    main(sys.argv[1])
