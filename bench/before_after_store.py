"""Stored results before and after, for every choice of what a run keeps (issue 35):

    python bench/before_after_store.py REV

Extracts REV (``git archive``, no worktree) into a temporary folder and runs the same
campaign — 4 × 2 s reduced runs and 2 × 1 s truth-plant runs, noisy sensors, PBC + sign
SMO — with REV's command line and with this tree's, the latter once per ``[keep]``
choice that keeps signals (every signal; compressed; two named signals every 5th
sample).  Every metric of every run must be equal, and every signal this tree keeps
bit-identical to REV's value at the same sample.  Prints the table, writes
bench/results/before_after_store.json.
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from _report import report, target
from _workloads import CLI, extract

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from campaign_testing import campaign_toml  # noqa: E402

from validation.batch.store.folder import ResultStore  # noqa: E402

CAMPAIGN = {"name": "identity", "scenario": {"duration": 2.0, "transient": 1.0,
                                             "observer": {"kind": "smo-paper"},
                                             "sensors": {"encoder_noise": 1e-4,
                                                         "modal_noise": 1e-5}},
            "sweep": [{"name": "reduced", "grid": {"seed": [1, 2], "true_params.Mp": [0.0, 0.5]}},
                      {"name": "truth", "grid": {"seed": [1, 2], "plant.kind": ["exudyn"],
                                                 "duration": [1.0], "transient": [0.5]}}]}
CHOICES = {"every signal": {}, "compressed": {"compress": True},
           "theta1, tau2 every 5th": {"signals": ["theta1", "tau2"], "every": 5}}


def run(tree: Path, spec: dict, out: Path) -> None:
    path = out.with_suffix(".toml")
    path.write_text(campaign_toml(spec))
    done = subprocess.run([sys.executable, "-c", CLI, "campaign", str(path), "--out", str(out),
                           "--workers", "2", "--force-workers", "--no-progress"], cwd=tree,
                          capture_output=True, text=True, env={**os.environ,
                                                               "PYTHONPATH": str(tree)})
    if done.returncode != 0:
        raise SystemExit(f"{tree}: campaign exited {done.returncode}:\n{done.stderr[-2000:]}")


def same_metrics(a: dict, b: dict) -> bool:
    nan = lambda v: isinstance(v, float) and math.isnan(v)  # noqa: E731
    return a.keys() == b.keys() and all(a[k] == b[k] or (nan(a[k]) and nan(b[k])) for k in a)


def main(rev: str) -> None:
    rows = []
    with tempfile.TemporaryDirectory(prefix="flexarm-store-ab-") as tmp:
        tmp = Path(tmp)
        before = extract(rev, tmp / "before")
        run(before, CAMPAIGN, tmp / "reference")
        old = ResultStore(tmp / "reference")
        for label, keep in CHOICES.items():
            out = tmp / f"after-{len(rows)}"
            run(ROOT, dict(CAMPAIGN, keep=keep) if keep else CAMPAIGN, out)
            new = ResultStore(out)
            metrics = signals = True
            for row in new.rows():
                was = old.row(row.run_id)
                metrics &= was is not None and same_metrics(row.metrics, was.metrics)
                a, b = new.load(row.run_id), old.load(row.run_id)
                every = keep.get("every", 1)
                signals &= np.array_equal(a.signals, b.select(a.names)[:, ::every]) \
                    and np.array_equal(a.time, b.time[::every])
            ok = metrics and signals and len(new.rows()) == len(old.rows())
            rows.append({"keep": label, "runs": len(new.rows()),
                         "metrics_equal": "yes" if metrics else "NO",
                         "signals_bit_identical": "yes" if signals else "NO",
                         **target(float(ok), ">=", 1.0)})
    report("before_after_store", rows, title=f"{rev} (before) against this tree, per [keep] "
                                             "choice that keeps signals",
           columns=["keep", "runs", "metrics_equal", "signals_bit_identical", "target", "met"])


if __name__ == "__main__":
    if len(sys.argv) < 2:
        raise SystemExit("usage: python bench/before_after_store.py REV")
    main(sys.argv[1])
