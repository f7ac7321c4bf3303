"""Two workers against one, the whole command line, side by side: a campaign of short
reduced runs, `flexarm verify` on the truth plant, and each worker's peak memory.

- ``flexarm campaign`` of 48 × 5 s reduced runs (the sweep of `bench_campaign.py`) with 1
  and 2 workers, paired repeats: the speed-up, median and minimum.  Also the same
  command on a one-run campaign: the command's fixed start (imports, loading the compiled
  kernels, checking the scenarios, starting the workers, exporting), which no number of
  workers shortens and which bounds the speed-up (Amdahl).  Beside it, the floor of any
  such start: a fresh interpreter importing only the libraries a reduced run needs (no
  flexarm code), and the bound it would set; and the same campaign with 50 s runs (ten
  times the work, the same start).  For both campaigns with 2 workers, the CPU seconds
  of the workers and of the command itself: after its serial start, the command's own
  work (storing each run's file) competes with the two workers for the 2 cores, which
  bounds the wall time below by the start plus half of what remains (a prediction from
  medians of separate runs, not a strict bound).
- ``flexarm verify --mode estimate`` of 16 truth-plant draws (20 s, PBC + EKF), 1 and 2
  workers: the verdict workload, where each run is long.
- ``flexarm campaign`` of 8 × 20 s truth-plant runs with 2 workers: the peak resident
  memory (VmHWM) of each worker and of the command's own process, read from /proc while
  it runs.

- The command's own CPU per stored run (issue 35): ``getrusage`` of ``flexarm campaign``
  with 2 workers, N runs of one law pair (480 of 5 s, 192 of 50 s: ten times the
  signals), minus the same command's one-run start, over N − 1.  Beside it the marginal
  cost, (N runs − N/2 runs) / (N/2), which no fixed start enters; and the same measured
  inside the process: its CPU time around ``run_campaign`` with the workers started before
  (the start's jitter, ~0.3 s between command starts, does not enter).
  ``python bench/bench_workers.py coordinator`` measures only this.

Targets (issue 24): 2 workers ≥ 1.7× one, for the campaign and for verify.  Issue 35: the
command's own CPU ≤ 1 ms per stored run, for 5 s and for 50 s runs.
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

from _report import report, target
from _workloads import ONE_RUN, REDUCED_48, REDUCED_ONE_LAW, TRUTH_8

ROOT = Path(__file__).resolve().parent.parent
REPEATS = 5
LIBRARIES = "import numpy, numba, scipy.linalg, scipy.optimize, scipy.signal"
LONG_RUNS = REDUCED_48.replace("duration = 5.0", "duration = 50.0")
assert LONG_RUNS != REDUCED_48


def flexarm(*args: str, poll=None) -> float:
    """Wall seconds of ``flexarm ARGS`` in a fresh process (``poll(proc)`` called every
    0.2 s while it runs)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "validation.cli", *args, "--no-progress"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    while proc.poll() is None:
        if poll is not None:
            poll(proc)
        time.sleep(0.2)
    seconds = time.perf_counter() - t0
    out, err = proc.communicate()
    if proc.returncode != 0:
        raise SystemExit(f"flexarm {' '.join(args)} exited {proc.returncode}:\n{err[-2000:]}")
    return seconds


CPU_SPLIT = """
import json, resource, sys
from validation.cli import main
try:
    raise SystemExit(main(sys.argv[1:]))
finally:
    own, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    print(json.dumps([own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime]), file=sys.stderr)
"""


def cpu_split(*args: str) -> tuple[float, float]:
    """CPU seconds of ``flexarm ARGS``: (the command's own process, its workers)."""
    done = subprocess.run([sys.executable, "-c", CPU_SPLIT, *args, "--no-progress"], cwd=ROOT,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"flexarm {' '.join(args)} exited {done.returncode}:\n"
                         f"{done.stderr[-2000:]}")
    own, workers = json.loads(done.stderr.strip().splitlines()[-1])
    return own, workers


def cpu_row(what: str, spec: Path, one_worker: float, start: tuple[float, float]) -> dict:
    """The CPU split of campaign ``spec`` with 2 workers and the speed-up it allows: the
    command's fixed start (``start``: its wall and own CPU seconds, from a one-run
    campaign) is serial; after it, the workers and the rest of the command's own work
    (storing the runs) share 2 cores."""
    with tempfile.TemporaryDirectory() as tmp:
        own, workers = cpu_split("campaign", str(spec), "--out", tmp, "--workers", "2")
    start_wall, start_cpu = start
    floor = start_wall + (workers + own - start_cpu) / 2
    return {"what": f"  {what}: CPU s with 2 workers", "two_workers_s": floor,
            "note": f"workers {workers:.2f} s, the command {own:.2f} s ({start_cpu:.2f} s "
                    f"of it its start): wall >= {floor:.2f} s on 2 cores, which predicts "
                    f"{one_worker / floor:.2f}x"}


IN_PROCESS = """
import json, sys, time
from validation.batch.campaign import load_campaign
from validation.batch.queue import run_campaign
from validation.batch.executor import make_runner
campaign = load_campaign(sys.argv[1])
with make_runner("local", 2, force=True) as runner:  # started: imports, kernels, workers
    cpu = time.process_time()
    summary = run_campaign(campaign, sys.argv[2], runner=runner, progress=False)
    cpu = time.process_time() - cpu
print(json.dumps([cpu, summary.ok]), file=sys.stderr)
"""


def coordinating_cpu(spec: Path) -> tuple[float, int]:
    """CPU seconds of the coordinating process alone while it runs campaign ``spec`` with
    2 workers started beforehand (expanding, checking, dispatching, committing rows,
    exporting; no start), and the runs stored."""
    with tempfile.TemporaryDirectory() as tmp:
        done = subprocess.run([sys.executable, "-c", IN_PROCESS, str(spec), tmp], cwd=ROOT,
                              capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{spec}: exited {done.returncode}:\n{done.stderr[-2000:]}")
    cpu, ok = json.loads(done.stderr.strip().splitlines()[-1])
    return cpu, ok


def _grown(text: str, seeds: int) -> str:
    """`REDUCED_ONE_LAW` with ``seeds`` seeds (6 × seeds runs)."""
    return text.replace("grid.seed = [1, 2, 3, 4, 5, 6, 7, 8]",
                        f"grid.seed = {list(range(1, seeds + 1))}")


#: Runs per coordinator measurement (6 payloads × seeds): (half, full) per run length;
#: enough that their own CPU (≤ 1 ms each) stands above the start's jitter (~0.1-0.2 s).
COORDINATOR_RUNS = {5.0: (240, 480), 50.0: (96, 192)}


def coordinator_rows(spec: Path, repeats: int) -> list[dict]:
    """The command's own CPU per stored run (module docstring), medians of ``repeats``."""
    rows = []
    for duration, (half, full) in COORDINATOR_RUNS.items():
        files = {}
        for n, text in ((1, ONE_RUN), (half, _grown(REDUCED_ONE_LAW, half // 6)),
                        (full, _grown(REDUCED_ONE_LAW, full // 6))):
            files[n] = spec / f"coordinator-{n}-{duration:g}.toml"
            files[n].write_text(text.replace("duration = 5.0", f"duration = {duration}"))
        own = {n: [] for n in files}
        for _ in range(repeats):
            for n, path in files.items():
                with tempfile.TemporaryDirectory() as tmp:
                    own[n].append(cpu_split("campaign", str(path), "--out", tmp,
                                            "--workers", "2")[0])
        med = {n: statistics.median(v) for n, v in own.items()}
        inside = [coordinating_cpu(files[full]) for _ in range(repeats)]
        assert all(ok == full for _, ok in inside), inside
        in_process = 1e3 * statistics.median(cpu for cpu, _ in inside) / full
        per_run = 1e3 * (med[full] - med[1]) / (full - 1)
        rows.append({"what": f"command's own CPU per stored run, {duration:g} s runs [ms]",
                     "two_workers_s": med[full], "ms_per_run": per_run,
                     **target(per_run, "<=", 1.0),
                     "note": f"{full} runs {med[full]:.3f} s, one-run start {med[1]:.3f} s; "
                             f"{half} runs {med[half]:.3f} s: marginal "
                             f"{1e3 * (med[full] - med[half]) / (full - half):.2f} ms/run"})
        rows.append({"what": "  the same, measured inside the command after its start [ms]",
                     "ms_per_run": in_process, **target(in_process, "<=", 1.0),
                     "note": f"time.process_time() of the coordinating process around "
                             f"run_campaign, {full} runs, 2 workers started before"})
    return rows


def bare_start(repeats: int) -> float:
    """Median wall seconds of a fresh interpreter importing `LIBRARIES`."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", LIBRARIES], check=True)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def bound(start: float, one_worker: float, fixed: float) -> float:
    """The most 2 workers can gain (Amdahl) when a command whose work alone takes
    ``one_worker - fixed`` on one worker starts in ``start`` seconds."""
    work = one_worker - fixed
    return (start + work) / (start + work / 2)


def paired(make_args, repeats: int) -> dict[int, list[float]]:
    times = {1: [], 2: []}
    for i in range(repeats):
        for workers in ((1, 2) if i % 2 == 0 else (2, 1)):
            with tempfile.TemporaryDirectory() as tmp:
                times[workers].append(flexarm(*make_args(Path(tmp)), "--workers", str(workers)))
    return times


def _peak_kib(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


COLUMNS = ["what", "one_worker_s", "two_workers_s", "speedup", "speedup_min", "ms_per_run",
           "target", "met", "note"]


def coordinator(repeats: int = REPEATS) -> None:
    """Only the command's own CPU per stored run."""
    with tempfile.TemporaryDirectory() as spec_dir:
        spec = Path(spec_dir)
        (spec / "c1.toml").write_text(ONE_RUN)
        flexarm("campaign", str(spec / "c1.toml"), "--out", str(spec / "warm"))  # kernels
        rows = coordinator_rows(spec, repeats)
    report("workers_coordinator", rows, title=f"The command's own CPU per stored run, 2 "
                                              f"workers (load {os.getloadavg()[0]:.1f})",
           columns=COLUMNS)


def main(repeats: int = REPEATS) -> None:
    rows = []
    with tempfile.TemporaryDirectory() as spec_dir:
        spec = Path(spec_dir)
        for name, text in (("c48.toml", REDUCED_48), ("c1.toml", ONE_RUN),
                           ("long.toml", LONG_RUNS), ("truth.toml", TRUTH_8)):
            (spec / name).write_text(text)
        flexarm("campaign", str(spec / "c1.toml"), "--out", str(spec / "warm"))  # kernels
        start = paired(lambda tmp: ("campaign", str(spec / "c1.toml"), "--out", str(tmp)),
                       repeats)
        campaign = paired(lambda tmp: ("campaign", str(spec / "c48.toml"), "--out", str(tmp)),
                          repeats)
        ratios = [a / b for a, b in zip(campaign[1], campaign[2])]
        fixed = statistics.median(start[1])
        serial = statistics.median(campaign[1])
        rows.append({"what": "campaign 48 x 5 s reduced, CLI", "one_worker_s": serial,
                     "two_workers_s": statistics.median(campaign[2]),
                     "speedup": statistics.median(ratios), "speedup_min": min(ratios),
                     **target(statistics.median(ratios), ">=", 1.7),
                     "note": f"fixed start {fixed:.2f} s of {serial:.2f} s: at most "
                             f"{bound(fixed, serial, fixed):.2f}x with 2 workers"})
        rows.append({"what": "  its fixed start (a one-run campaign)", "one_worker_s": fixed,
                     "two_workers_s": statistics.median(start[2])})
        floor = bare_start(repeats)
        rows.append({"what": "  floor: python importing the libraries only", "one_worker_s": floor,
                     "note": f"{LIBRARIES[7:]}; a start this short would allow at most "
                             f"{bound(floor, serial, fixed):.2f}x"})
        with tempfile.TemporaryDirectory() as tmp:
            start_cpu = cpu_split("campaign", str(spec / "c1.toml"), "--out", tmp,
                                  "--workers", "2")[0]
        rows.append(cpu_row("48 x 5 s", spec / "c48.toml", serial, (fixed, start_cpu)))
        long = paired(lambda tmp: ("campaign", str(spec / "long.toml"), "--out", str(tmp)),
                      repeats)
        ratios = [a / b for a, b in zip(long[1], long[2])]
        rows.append({"what": "campaign 48 x 50 s reduced, CLI (10x the work)",
                     "one_worker_s": statistics.median(long[1]),
                     "two_workers_s": statistics.median(long[2]),
                     "speedup": statistics.median(ratios), "speedup_min": min(ratios),
                     "note": "the same fixed start"})
        rows.append(cpu_row("48 x 50 s", spec / "long.toml", statistics.median(long[1]),
                            (fixed, start_cpu)))
        rows += coordinator_rows(spec, repeats)
        verify = paired(lambda tmp: ("verify", "campaigns/robust.toml", "--mode", "estimate",
                                     "--system", "pbc+ekf", "--samples", "16",
                                     "--out", str(tmp)), max(1, repeats // 2))
        ratios = [a / b for a, b in zip(verify[1], verify[2])]
        rows.append({"what": "verify estimate, 16 truth draws x 20 s, CLI",
                     "one_worker_s": statistics.median(verify[1]),
                     "two_workers_s": statistics.median(verify[2]),
                     "speedup": statistics.median(ratios), "speedup_min": min(ratios),
                     **target(statistics.median(ratios), ">=", 1.7)})
        peaks: dict[str, dict[int, int]] = {"command": {}, "workers": {}}

        def watch(proc):
            peaks["command"][proc.pid] = max(peaks["command"].get(proc.pid, 0),
                                             _peak_kib(proc.pid))
            for child in _children(proc.pid):
                peaks["workers"][child] = max(peaks["workers"].get(child, 0), _peak_kib(child))

        with tempfile.TemporaryDirectory() as tmp:
            flexarm("campaign", str(spec / "truth.toml"), "--out", tmp, "--workers", "2",
                    poll=watch)
        workers = sorted(peaks["workers"].values())
        rows.append({"what": "peak RSS, truth campaign 8 x 20 s, 2 workers [MiB]",
                     "note": f"each worker {', '.join(f'{w / 1024:.0f}' for w in workers)}; "
                             f"the command {max(peaks['command'].values()) / 1024:.0f}"})
    report("workers", rows, title=f"Whole command line, 1 vs 2 workers, medians of paired "
                                  f"repeats (load {os.getloadavg()[0]:.1f})",
           columns=COLUMNS)


if __name__ == "__main__":
    if sys.argv[1:2] == ["coordinator"]:
        coordinator(int(sys.argv[2]) if len(sys.argv) > 2 else REPEATS)
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else REPEATS)
