"""Before and after, measured in the same session: this tree against an earlier revision.

    python bench/before_after.py REV [REPEATS]

Checks REV out in a temporary git worktree and times the two trees alternately, each
measurement in a fresh process (so neither profits from the other's caches; each tree
compiles its own numba kernels once, in an uncounted warm-up round):

- the 20 s PBC + SMO closed loop (paper scenario, noisy sensors) on the reduced plant and
  on the Exudyn plant: wall time of ``run_scenario`` after a 10 ms warm-up run, and the
  largest difference of the two trees' θ over the run (target ≤ 1e-12 rad: a speed-up
  changes no result);
- the whole command line for a 48-run campaign of 5 s reduced runs (the sweep of
  `bench_campaign.py`) with 1 and with 2 workers: process wall time, start-up included.

Prints, per measure, the median of REPEATS (default 5) for each tree, their ratio
before / after, and the range; writes bench/results/before_after.json.  The machines
these run on drift up to 2x within an hour: only ratios of interleaved runs are compared.
"""
from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _report import report, target
from _workloads import CLI, REDUCED_48

ROOT = Path(__file__).resolve().parent.parent

CLOSED_LOOP = """
import json, sys, time
import numpy as np
try:
    from validation.run.loop import run_scenario
    from validation.run.scenario import scenario_from_mapping
except ImportError:  # a revision before validation/ moved into rooms
    from validation.loop import run_scenario
    from validation.scenario import scenario_from_mapping
m = {"plant": {"kind": sys.argv[1]}, "observer": {"kind": "smo-paper"},
     "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}}
run_scenario(scenario_from_mapping({**m, "duration": 0.01, "transient": 0.0}))
t0 = time.perf_counter()
r = run_scenario(scenario_from_mapping(m))
seconds = time.perf_counter() - t0
np.save(sys.argv[2], np.stack([r["theta1"], r["theta2"]]))
print(json.dumps({"seconds": seconds, "status": r.status}))
"""


def _python(tree: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], cwd=tree, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(tree)})


def _theta_file(which: str, plant: str, scratch: Path) -> Path:
    """Where the closed loop of tree ``which`` ("before", "after") on ``plant`` leaves θ."""
    return scratch / f"theta-{plant}-{which}.npy"


def closed_loop(tree: Path, plant: str, scratch: Path) -> float:
    which = "after" if tree == ROOT else "before"
    done = _python(tree, "-c", CLOSED_LOOP, plant, str(_theta_file(which, plant, scratch)))
    if done.returncode != 0:
        raise SystemExit(f"{tree}: closed loop on {plant} failed:\n{done.stderr[-2000:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    if out["status"] != "ok":
        raise SystemExit(f"{tree}: closed loop on {plant} ended {out['status']}: no timing")
    return out["seconds"]


def campaign(tree: Path, workers: int, scratch: Path) -> float:
    spec = scratch / "campaign.toml"
    spec.write_text(REDUCED_48)
    out = Path(tempfile.mkdtemp(dir=scratch))
    t0 = time.perf_counter()
    done = _python(tree, "-c", CLI, "campaign", str(spec), "--out", str(out / "r"),
                   "--workers", str(workers), "--no-progress")
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{tree}: campaign with {workers} worker(s) exited "
                         f"{done.returncode}:\n{done.stderr[-2000:]}")
    return seconds


MEASURES = {
    "20 s PBC + SMO, reduced plant [s]": lambda tree, scratch: closed_loop(tree, "reduced",
                                                                          scratch),
    "20 s PBC + SMO, Exudyn plant [s]": lambda tree, scratch: closed_loop(tree, "exudyn",
                                                                        scratch),
    "campaign 48 x 5 s reduced, CLI, 1 worker [s]": lambda tree, scratch: campaign(tree, 1, scratch),
    "campaign 48 x 5 s reduced, CLI, 2 workers [s]": lambda tree, scratch: campaign(tree, 2, scratch),
}


def main(rev: str, repeats: int) -> None:
    with tempfile.TemporaryDirectory(prefix="flexarm-ab-") as tmp:
        before = Path(tmp) / "before"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(before), rev],
                       cwd=ROOT, check=True)
        try:
            trees = {"before": before, "after": ROOT}
            print("warm-up (compiles each tree's kernels once) ...", flush=True)
            for tree in trees.values():
                for measure in MEASURES.values():
                    measure(tree, Path(tmp))
            times = {(m, t): [] for m in MEASURES for t in trees}
            for i in range(repeats):
                for label, measure in MEASURES.items():
                    for which, tree in (trees.items() if i % 2 == 0 else reversed(trees.items())):
                        times[label, which].append(measure(tree, Path(tmp)))
                print(f"repeat {i + 1} of {repeats} done", flush=True)
            identity = [_theta_difference(plant, Path(tmp)) for plant in ("reduced", "exudyn")]
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(before)], cwd=ROOT,
                           check=False)
    rows = []
    for label in MEASURES:
        b, a = times[label, "before"], times[label, "after"]
        rows.append({"measure": label, "before": statistics.median(b),
                     "after": statistics.median(a),
                     "before_over_after": statistics.median(b) / statistics.median(a),
                     "before_range": f"{min(b):.3g}-{max(b):.3g}",
                     "after_range": f"{min(a):.3g}-{max(a):.3g}"})
    rows += identity
    for workers_label in ("before", "after"):
        one = statistics.median(times["campaign 48 x 5 s reduced, CLI, 1 worker [s]", workers_label])
        two = statistics.median(times["campaign 48 x 5 s reduced, CLI, 2 workers [s]", workers_label])
        rows.append({"measure": f"CLI campaign speed-up, 2 workers vs 1 ({workers_label})",
                     workers_label: one / two})
    report("before_after", rows, title=f"{rev} (before) against this tree (after): medians of "
                                       f"{repeats}, interleaved, same session",
           columns=["measure", "before", "after", "before_over_after", "before_range",
                    "after_range", "target", "met"])


def _theta_difference(plant: str, scratch: Path) -> dict:
    """The row comparing the two trees' θ over the 20 s run on ``plant``."""
    before, after = (np.load(_theta_file(which, plant, scratch)) for which in ("before", "after"))
    worst = float(np.abs(before - after).max()) if before.shape == after.shape else math.inf
    return {"measure": f"20 s PBC + SMO, {plant} plant: max |θ after - θ before| [rad]",
            "after": worst, **target(worst, "<=", 1e-12)}


if __name__ == "__main__":
    if len(sys.argv) < 2:
        raise SystemExit("usage: python bench/before_after.py REV [REPEATS]")
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 5)
