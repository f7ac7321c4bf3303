"""Runs and wall time of ``flexarm stability`` for the paper's cases, bisected to 10 %,
1 % and 0.5 % (issue 43).

Each tolerance maps ``campaigns/paper.toml`` (every distinct controller + observer, plant
and arm of the paper reproduction; ``--quick``: the paper's system alone, PBC + sign SMO)
into a fresh folder with the command line a user types, so every number includes
process start, the numba cache check, the predictions and the reports.  Per tolerance:
the wall time, the runs the map took (every level of the refined sequence), the widest
bracket of a limit that has one, and the limits' verdicts on the refined sequence.  The
machine's load average is printed before and after each map: the 2-core machine is
shared, and a wall time is only comparable with its load.

Target: every bracketed limit within the tolerance it was bisected to.  The runs at 1 %
and 0.5 % against 10 % are printed (a bisection costs one run per halving of the bracket,
a refined level two runs when its bracket keeps both outcomes).
"""
from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from _report import report, target

ROOT = Path(__file__).resolve().parents[1]
TOLERANCES = (0.1, 0.01, 0.005)
QUICK = """\
[controller]
kind = "pbc"
[observer]
kind = "smo-paper"
"""


def map_once(file: Path, out: Path, tolerance: float, workers: int) -> dict:
    """One ``flexarm stability`` into ``out``: its wall time and what stability.csv says."""
    load = os.getloadavg()[0]
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "validation.cli", "stability", str(file),
                           "--tolerance", str(tolerance), "--out", str(out), "--workers",
                           str(workers), "--no-progress"], cwd=ROOT, capture_output=True,
                          text=True)
    wall = time.perf_counter() - started
    if done.returncode not in (0, 1):
        raise SystemExit(f"flexarm stability failed ({done.returncode}):\n{done.stderr}")
    with (out / "stability.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    widths = [float(r[f"{limit}_width"]) for r in rows for limit in ("divergence", "tracking")
              if r[f"{limit}_width"] not in ("", "nan")]
    verdicts = Counter(r[f"{limit}_convergence"] for r in rows
                       for limit in ("divergence", "tracking"))
    return {"tolerance": tolerance, "cases": len(rows),
            "runs": sum(int(r["runs"]) for r in rows), "wall_s": wall,
            "widest": max(widths, default=float("nan")),
            "verdicts": ", ".join(f"{n} {v}" for v, n in sorted(verdicts.items())),
            "load_before": load, "load_after": os.getloadavg()[0], "exit": done.returncode}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="the paper's system alone (PBC + sign SMO) on both plants and arms")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-stability-") as tmp:
        tmp = Path(tmp)
        file = ROOT / "campaigns" / "paper.toml"
        if args.quick:
            file = tmp / "paper-system.toml"
            file.write_text(QUICK)
        rows = []
        for tolerance in TOLERANCES:
            row = map_once(file, tmp / f"map-{tolerance:g}", tolerance, args.workers)
            row |= target(row["widest"], "<=", tolerance)
            rows.append(row)
            print(f"  {tolerance:g}: {row['runs']} runs, {row['wall_s']:.0f} s (load "
                  f"{row['load_before']:.1f} -> {row['load_after']:.1f})", flush=True)
    for row in rows:
        row["runs_vs_10%"] = row["runs"] / rows[0]["runs"]
    report("bench_stability" + ("_quick" if args.quick else ""), rows,
           columns=["tolerance", "cases", "runs", "runs_vs_10%", "wall_s", "widest",
                    "verdicts", "load_before", "load_after", "target", "met"],
           title=f"flexarm stability of {'the paper system' if args.quick else 'paper.toml'} "
                 f"at {', '.join(f'{t:.1%}' for t in TOLERANCES)} ({args.workers} workers, "
                 f"{os.cpu_count()} cores)")


if __name__ == "__main__":
    main()
