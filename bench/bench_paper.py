"""The main job, before and after: ``flexarm reproduce-paper`` of this tree against an
earlier revision, one after the other in the same session (issue 46, 1).

    python bench/bench_paper.py REV
    python bench/bench_paper.py --lab REV    # reproduce-paper --lab: the lab arm's job

Checks REV out in a temporary git worktree and runs the command as a user would (its
defaults: report and animation included; ``--no-progress`` so that the log is lines),
this tree first, each in a fresh process with its own results folder and numba cache
(compilation counted: a fresh clone compiles).  Per tree: the exit status, the wall time,
the time at which each line of the command's summary was printed (the phases: the
paper's runs, the stability map, the mesh checks, the claims, the report) and the disk
the results folder takes, by sub-folder.  Targets: after ≤ 0.4× before's wall time,
exit 0, ≤ 300 MB (the paper's job only: with ``--lab`` the phases are what is measured,
for `validation.cli.job_clock.LAB`).  Writes bench/results/bench_paper.json
(bench_paper_lab.json).  The machine drifts: the ratio
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

from validation.cli.job_clock import LAB, PAPER

ROOT = Path(__file__).resolve().parent.parent
MB = 1e6


def disk(folder: Path) -> dict:
    """Bytes under ``folder`` and under each of its sub-folders."""
    def size(p: Path) -> int:
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return {"total": size(folder), **{p.name: size(p) for p in folder.iterdir() if p.is_dir()}}


def reproduce(tree: Path, scratch: Path, lab: bool) -> dict:
    """One ``reproduce-paper`` (``--lab``) of ``tree``: status, wall time, timed lines,
    disk."""
    out = scratch / f"paper-{tree.name}"
    env = {**os.environ, "PYTHONPATH": str(tree),
           "NUMBA_CACHE_DIR": str(scratch / f"numba-{tree.name}")}
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", CLI, "reproduce-paper", "--out", str(out),
                             "--no-progress", *(["--lab"] if lab else [])], cwd=scratch,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    for line in proc.stdout:
        lines.append((time.perf_counter() - t0, line.rstrip()))
        print(f"  [{tree.name} {lines[-1][0]:7.1f} s] {line.rstrip()}", flush=True)
    status = proc.wait()
    return {"status": status, "seconds": time.perf_counter() - t0, "lines": lines,
            "disk": disk(out) if out.exists() else {"total": 0}}


def phase_ends(lab: bool) -> tuple:
    """(phase, how the summary line that ends it starts), in order: the phases of
    `validation.cli.job_clock.PAPER` (``lab``: `LAB`); the runs' line starts with the
    campaign's name."""
    profile = LAB if lab else PAPER
    starts = ("lab: " if lab else "paper: ", "stability map: ", "mesh-check: ",
              "the paper's claims", "report: ")
    return tuple(zip((phase for phase, _ in profile), starts))


def phases(lines: list, lab: bool = False) -> dict:
    """{phase: seconds} from a run's timed lines, in the order the run had them (an
    earlier revision ran the mesh checks before the map); "cold start": up to the last
    compile line."""
    compiled = [t for t, line in lines if "groups ready" in line]
    out = {"cold start": compiled[-1] if compiled else 0.0}
    ends = sorted((t, phase) for phase, start in phase_ends(lab)
                  for t in [next((t for t, line in lines if line.startswith(start)), None)]
                  if t is not None)
    last = out["cold start"]
    for end, phase in ends:
        out[phase], last = end - last, end
    return out


def main(rev: str, lab: bool) -> None:
    with tempfile.TemporaryDirectory(prefix="flexarm-paper-") as tmp:
        scratch = Path(tmp)
        before = scratch / "before"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(before), rev],
                       cwd=ROOT, check=True)
        after = scratch / "after"
        after.symlink_to(ROOT)
        try:
            runs = {"after": reproduce(after, scratch, lab),
                    "before": reproduce(before, scratch, lab)}
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(before)], cwd=ROOT,
                           check=False)
    b, a = runs["before"], runs["after"]
    judged = (lambda value, op, bound: {}) if lab else target  # the paper's job's targets
    rows = [{"measure": "reproduce-paper wall time [s]", "before": b["seconds"],
             "after": a["seconds"]},
            {"measure": "after / before wall time", "after": a["seconds"] / b["seconds"],
             **judged(a["seconds"] / b["seconds"], "<=", 0.4)},
            {"measure": "exit status", "before": b["status"], "after": a["status"],
             **target(a["status"], "<=", 0)},
            {"measure": "results folder [MB]", "before": b["disk"]["total"] / MB,
             "after": a["disk"]["total"] / MB, **judged(a["disk"]["total"] / MB, "<=", 300)}]
    for which in ("before", "after"):
        for phase, seconds in phases(runs[which]["lines"], lab).items():
            rows.append({"measure": f"  {phase} [s] ({which})", which: seconds})
        for name, size in runs[which]["disk"].items():
            if name != "total":
                rows.append({"measure": f"  {name}/ [MB] ({which})", which: size / MB})
    report("bench_paper_lab" if lab else "bench_paper", rows + [{"measure": f"log ({w})", "lines": runs[w]["lines"]}
                                  for w in ("before", "after")],
           title=f"flexarm reproduce-paper{' --lab' * lab}, {rev} (before) against this tree (after), "
                 "its default workers, one run each, same session",
           columns=["measure", "before", "after", "target", "met"])


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rev")
    parser.add_argument("--lab", action="store_true",
                        help="time reproduce-paper --lab (the lab arm's job) instead")
    args = parser.parse_args()
    main(args.rev, args.lab)
