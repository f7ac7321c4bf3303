"""The main job, before and after: ``flexarm reproduce-paper`` of this tree against an
earlier revision, one after the other in the same session (issue 46, 1).

    python bench/bench_paper.py REV

Checks REV out in a temporary git worktree and runs the command as a user would (its
defaults: report and animation included; ``--no-progress`` so that the log is lines),
this tree first, each in a fresh process with its own results folder and numba cache
(compilation counted: a fresh clone compiles).  Per tree: the exit status, the wall time,
the time at which each line of the command's summary was printed (the phases: the
paper's runs, the stability map, the mesh checks, the claims, the report) and the disk
the results folder takes, by sub-folder.  Targets: after ≤ 0.4× before's wall time,
exit 0, ≤ 300 MB.  Writes bench/results/bench_paper.json.  The machine drifts: the ratio
is of two runs minutes apart, not of interleaved repeats (each takes minutes).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _report import report, target
from _workloads import CLI

ROOT = Path(__file__).resolve().parent.parent
MB = 1e6


def disk(folder: Path) -> dict:
    """Bytes under ``folder`` and under each of its sub-folders."""
    def size(p: Path) -> int:
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return {"total": size(folder), **{p.name: size(p) for p in folder.iterdir() if p.is_dir()}}


def reproduce(tree: Path, scratch: Path) -> dict:
    """One ``reproduce-paper`` of ``tree``: status, wall time, timed lines, disk."""
    out = scratch / f"paper-{tree.name}"
    env = {**os.environ, "PYTHONPATH": str(tree),
           "NUMBA_CACHE_DIR": str(scratch / f"numba-{tree.name}")}
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", CLI, "reproduce-paper", "--out", str(out),
                             "--no-progress"], cwd=scratch,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in proc.stdout:
        lines.append((time.perf_counter() - t0, line.rstrip()))
        print(f"  [{tree.name} {lines[-1][0]:7.1f} s] {line.rstrip()}", flush=True)
    status = proc.wait()
    return {"status": status, "seconds": time.perf_counter() - t0, "lines": lines,
            "disk": disk(out) if out.exists() else {"total": 0}}


#: How each phase's summary line starts (its end), in order: what `JobClock.PAPER` holds.
PHASE_ENDS = (("the paper's runs", "paper: "), ("the stability map", "stability map: "),
              ("the mesh checks", "mesh-check: "), ("the claims", "the paper's claims"),
              ("the report", "report: "))


def phases(lines: list) -> dict:
    """{phase: seconds} from a run's timed lines, in the order the run had them (an
    earlier revision ran the mesh checks before the map); "cold start": up to the last
    compile line."""
    compiled = [t for t, line in lines if "groups ready" in line]
    out = {"cold start": compiled[-1] if compiled else 0.0}
    ends = sorted((t, phase) for phase, start in PHASE_ENDS
                  for t in [next((t for t, line in lines if line.startswith(start)), None)]
                  if t is not None)
    last = out["cold start"]
    for end, phase in ends:
        out[phase], last = end - last, end
    return out


def main(rev: str) -> None:
    with tempfile.TemporaryDirectory(prefix="flexarm-paper-") as tmp:
        scratch = Path(tmp)
        before = scratch / "before"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(before), rev],
                       cwd=ROOT, check=True)
        after = scratch / "after"
        after.symlink_to(ROOT)
        try:
            runs = {"after": reproduce(after, scratch),
                    "before": reproduce(before, scratch)}
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(before)], cwd=ROOT,
                           check=False)
    b, a = runs["before"], runs["after"]
    rows = [{"measure": "reproduce-paper wall time [s]", "before": b["seconds"],
             "after": a["seconds"]},
            {"measure": "after / before wall time", "after": a["seconds"] / b["seconds"],
             **target(a["seconds"] / b["seconds"], "<=", 0.4)},
            {"measure": "exit status", "before": b["status"], "after": a["status"],
             **target(a["status"], "<=", 0)},
            {"measure": "results folder [MB]", "before": b["disk"]["total"] / MB,
             "after": a["disk"]["total"] / MB, **target(a["disk"]["total"] / MB, "<=", 300)}]
    for which in ("before", "after"):
        for phase, seconds in phases(runs[which]["lines"]).items():
            rows.append({"measure": f"  {phase} [s] ({which})", which: seconds})
        for name, size in runs[which]["disk"].items():
            if name != "total":
                rows.append({"measure": f"  {name}/ [MB] ({which})", which: size / MB})
    report("bench_paper", rows + [{"measure": f"log ({w})", "lines": runs[w]["lines"]}
                                  for w in ("before", "after")],
           title=f"flexarm reproduce-paper, {rev} (before) against this tree (after), "
                 "its default workers, one run each, same session",
           columns=["measure", "before", "after", "target", "met"])


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rev")
    main(parser.parse_args().rev)
