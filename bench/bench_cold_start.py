"""The first run on a fresh clone: how long until `flexarm run` has simulated, numba's
caches empty (everything it needs compiles), and how long the same command takes once
compiled.

A clone of this checkout's HEAD is made in a temporary folder and the paper's system
(PBC + smo-paper, reduced plant, 5 s) is run there twice with ``python -m
validation.cli run``: cold (its ``__pycache__`` folders empty), then warm.  Target
(issue 18): the cold run ≤ 60 s on 2 cores.  The kernels of other laws and of the FE
plant compile when a run first uses them (`validation.batch.compiling` says so).
"""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import report, target

ROOT = Path(__file__).resolve().parent.parent
COMMAND = ["-m", "validation.cli", "run", "--observer", "smo-paper", "--duration", "5"]


def timed_run(clone: Path, out: Path) -> tuple[float, str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["PYTHONPATH"] = str(clone)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, *COMMAND, "--out", str(out)], cwd=clone, env=env,
                          capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"flexarm run failed in the clone:\n{done.stderr[-2000:]}")
    return seconds, done.stderr


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="flexarm-cold-") as tmp:
        clone = Path(tmp) / "clone"
        subprocess.run(["git", "clone", "--quiet", str(ROOT), str(clone)], check=True)
        load = os.getloadavg()[0]
        cold, progress = timed_run(clone, Path(tmp) / "cold")
        warm, _ = timed_run(clone, Path(tmp) / "warm")
    groups = [line.strip() for line in progress.splitlines() if line.strip().startswith("[")]
    rows = [{"what": "first flexarm run on a fresh clone (compiles)", "s": cold,
             **target(cold, "<=", 60.0), "note": f"load average {load:.1f} at the start"},
            {"what": "the same command once compiled", "s": warm}]
    rows += [{"what": f"  {g}"} for g in groups]
    report("cold_start", rows, title="flexarm run --observer smo-paper --duration 5, "
                                     "reduced plant, fresh clone",
           columns=["what", "s", "target", "met", "note"])


if __name__ == "__main__":
    main()
