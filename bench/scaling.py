"""Scaling with the cores (issue 35), whole command lines on one many-core machine, in one
go: ``python3 bench/scaling.py OUT`` (from a checkout: it reads campaigns/robust.toml).

- ``flexarm campaign`` of 96 × 5 s truth-plant runs with 1, 16, 8, 4 and 2 local workers,
  and with 16 single-threaded workers of a Dask cluster on localhost (``dask scheduler``
  + ``dask worker --nworkers 16 --nthreads 1``, started here; the workers store the runs
  into the folder themselves);
- ``flexarm campaign`` of 960 × 5 s reduced runs with 1, 16 and 4 workers;
- ``flexarm verify campaigns/robust.toml --mode estimate`` with 16 workers: its busy
  fraction, the workers' CPU seconds over 16 × the wall time.

``python3 bench/scaling.py OUT FRACTION`` runs FRACTION of every workload (0.1: a
smoke test of the script on a small machine).  For each: wall seconds, speed-up over one worker, the command's own CPU seconds and its
workers'.  The kernels are compiled first (not counted).  The whole script keeps within
`BUDGET` seconds: a measurement that would not fit is left out (or verify's draws
trimmed), and the output says so.  Writes OUT/scaling.json and OUT/scaling.txt.
Targets: truth ≥ 13× one worker with 16, reduced ≥ 11×, verify ≥ 80 % busy, Dask within
10 % of the local pool.
"""
from __future__ import annotations

import json
import os
import platform
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BUDGET = 450.0  # s: the script must end within 8 minutes
START = time.monotonic()
CORES = len(os.sched_getaffinity(0))

TRUTH = """name = "scaling-truth"
[scenario]
duration = 5.0
plant.kind = "exudyn"
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0]
grid.seed = [1, 2, 3, 4, 5, 6, 7, 8]
"""
REDUCED = """name = "scaling-reduced"
[scenario]
duration = 5.0
observer.kind = "smo-paper"
[[sweep]]
grid."true_params.Mp" = [0.0, 0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 1.0]
grid.seed = {seeds}
""".format(seeds=list(range(1, 81)))
WARM = """name = "scaling-warm"
[scenario]
duration = 0.05
transient = 0.0
observer.kind = "smo-paper"
[[sweep]]
grid."plant.kind" = ["reduced", "exudyn"]
"""
#: Runs the command line in this interpreter and prints its CPU split on stderr.
CPU = """
import json, resource, sys
from validation.cli import main
try:
    raise SystemExit(main(sys.argv[1:]))
finally:
    own, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    print("CPU " + json.dumps([own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime]),
          file=sys.stderr)
"""


def left() -> float:
    return BUDGET - (time.monotonic() - START)


def flexarm(*args: str, timeout: float) -> dict:
    """Wall seconds and CPU split of ``flexarm ARGS`` in a fresh interpreter."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", CPU, *args, "--no-progress"], cwd=ROOT,
                          capture_output=True, text=True, timeout=max(timeout, 1.0))
    wall = time.perf_counter() - t0
    cpu = [line for line in done.stderr.splitlines() if line.startswith("CPU ")]
    own, workers = json.loads(cpu[-1][4:]) if cpu else (None, None)
    return {"wall_s": wall, "own_cpu_s": own, "workers_cpu_s": workers,
            "exit": done.returncode, "last_line": (done.stdout.strip().splitlines() or [""])[-1],
            "error": done.stderr.strip()[-500:] if done.returncode not in (0, 1) else ""}


def campaign(spec: Path, tmp: Path, how: list[str], *, timeout: float) -> dict:
    out = Path(tempfile.mkdtemp(dir=tmp))
    try:
        return flexarm("campaign", str(spec), "--out", str(out), *how, timeout=timeout)
    finally:
        shutil.rmtree(out, ignore_errors=True)


def local(n: int) -> list[str]:
    return ["--workers", str(n)] + (["--force-workers"] if n > CORES else [])


class Cluster:
    """``dask scheduler`` and ``dask worker --nworkers N --nthreads 1`` on localhost."""

    def __init__(self, tmp: Path, workers: int) -> None:
        dask = shutil.which("dask") or str(Path(sys.executable).with_name("dask"))
        info = tmp / "scheduler.json"
        common = ["--no-dashboard", "--host", "127.0.0.1"]
        self.procs = [subprocess.Popen([dask, "scheduler", "--port", "0", "--scheduler-file",
                                        str(info), *common], stdout=subprocess.DEVNULL,
                                       stderr=subprocess.DEVNULL, start_new_session=True)]
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        self.address = json.loads(info.read_text())["address"]
        self.procs.append(subprocess.Popen(
            [dask, "worker", "--scheduler-file", str(info), "--nworkers", str(workers),
             "--nthreads", "1", *common], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True, env={**os.environ, "OMP_NUM_THREADS": "1",
                                         "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}))
        from distributed import Client
        with Client(self.address, timeout="60s") as client:
            client.wait_for_workers(workers, timeout=120)

    def close(self) -> None:
        for proc in reversed(self.procs):
            try:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(timeout=30)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass


def _fraction(text: str, fraction: float) -> str:
    """``text`` with its seeds axis cut to ``fraction`` of its length (at least 1)."""
    head, _, seeds = text.rpartition("grid.seed = ")
    values = json.loads(seeds)
    return head + f"grid.seed = {values[:max(1, round(len(values) * fraction))]}\n"


def main(out: Path, fraction: float = 1.0) -> None:
    out.mkdir(parents=True, exist_ok=True)
    rows, notes = [], []
    top = min(16, CORES)
    if top < 16:
        notes.append(f"only {CORES} cores: 16 workers measured as {top}")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for name, text in (("truth.toml", _fraction(TRUTH, fraction)),
                           ("reduced.toml", _fraction(REDUCED, fraction)), ("warm.toml", WARM)):
            (tmp / name).write_text(text)
        truth_runs, reduced_runs = (len(json.loads((tmp / f"{w}.toml").read_text().rpartition(
            "grid.seed = ")[2])) * 12 for w in ("truth", "reduced"))
        if fraction != 1.0:
            notes.append(f"{fraction:g} of every workload (a smoke test)")
        warm = campaign(tmp / "warm.toml", tmp, local(1), timeout=left())
        notes.append(f"compiling the kernels first: {warm['wall_s']:.1f} s (not counted)")
        one = {}
        # the essential rows first: one worker (the base), then the many-core ones
        plan = [("truth", truth_runs, n) for n in dict.fromkeys((1, top, 8, 4, 2))] + \
               [("reduced", reduced_runs, n) for n in dict.fromkeys((1, top, 4))]
        # one worker on the machine [s]
        expected = {"truth": 80.0 * fraction, "reduced": 60.0 * fraction}
        for workload, runs, n in plan:
            guess = one[workload] / n * 2 + 5 if workload in one else 1.5 * expected[workload]
            if guess > left() - 150:  # keep ~150 s for Dask and verify
                notes.append(f"{workload} with {n} workers left out (budget)")
                continue
            r = campaign(tmp / f"{workload}.toml", tmp, local(n), timeout=left())
            if n == 1:
                one[workload] = r["wall_s"]
            rows.append({"workload": f"campaign {runs} x 5 s {workload}", "executor": "local",
                         "workers": n, **r,
                         "speedup": one[workload] / r["wall_s"] if workload in one else None})
        if left() > 100 and "truth" in one:
            cluster = Cluster(tmp, top)
            try:
                r = campaign(tmp / "truth.toml", tmp, ["--executor", "dask", "--scheduler",
                                                       cluster.address], timeout=left())
            finally:
                cluster.close()
            local_top = next((x["wall_s"] for x in rows if x["workload"].endswith("truth")
                              and x["executor"] == "local" and x["workers"] == top), None)
            rows.append({"workload": f"campaign {truth_runs} x 5 s truth", "executor": "dask",
                         "workers": top, **r, "speedup": one["truth"] / r["wall_s"],
                         "dask_over_local": r["wall_s"] / local_top if local_top else None})
        else:
            notes.append("Dask left out (budget)")
        robust = ROOT / "campaigns" / "robust.toml"
        # 3 systems × 59 draws of 20 s on the truth plant: ~283 CPU-s, ~25 s on 16 cores
        full = max(2, round(59 * fraction))
        samples = full if left() > 90 else max(2, min(full, int(59 * max(left() - 20, 0) / 90)))
        if robust.exists() and left() > 40:
            if samples < full:
                notes.append(f"verify trimmed to {samples} draws per system (budget)")
            r = flexarm("verify", str(robust), "--mode", "estimate", "--samples", str(samples),
                        "--workers", str(top), "--out", str(tmp / "verify"), timeout=left())
            busy = r["workers_cpu_s"] / (top * r["wall_s"]) if r["workers_cpu_s"] else None
            rows.append({"workload": f"verify robust.toml estimate ({samples} draws x 3)",
                         "executor": "local", "workers": top, **r, "busy": busy})
        else:
            notes.append("verify left out (budget, or no campaigns/robust.toml here)")
    targets = {f"campaign {truth_runs} x 5 s truth": ("speedup", 13.0),
               f"campaign {reduced_runs} x 5 s reduced": ("speedup", 11.0)}
    for r in rows:
        key = targets.get(r["workload"])
        if key and r["executor"] == "local" and r["workers"] == 16:
            r["target"] = f"{key[0]} >= {key[1]:g}"
            r["met"] = "yes" if (r.get(key[0]) or 0) >= key[1] else "MISSED"
        if "busy" in r:
            r["target"], r["met"] = "busy >= 0.8", "yes" if (r["busy"] or 0) >= 0.8 else "MISSED"
        if r.get("dask_over_local") is not None:
            r["target"] = "dask/local <= 1.1"
            r["met"] = "yes" if r["dask_over_local"] <= 1.1 else "MISSED"
    meta = {"cores": CORES, "python": platform.python_version(), "machine": platform.processor()
            or platform.machine(), "total_s": time.monotonic() - START,
            "load": os.getloadavg(), "peak_rss_mib": resource.getrusage(
                resource.RUSAGE_CHILDREN).ru_maxrss / 1024}
    (out / "scaling.json").write_text(json.dumps({"meta": meta, "notes": notes, "rows": rows},
                                                 indent=1))
    columns = ["workload", "executor", "workers", "wall_s", "speedup", "own_cpu_s",
               "workers_cpu_s", "busy", "dask_over_local", "target", "met", "exit"]
    fmt = lambda v: f"{v:.3g}" if isinstance(v, float) else "" if v is None else str(v)  # noqa: E731
    widths = [max(len(c), *(len(fmt(r.get(c))) for r in rows)) if rows else len(c)
              for c in columns]
    lines = ["  ".join(c.ljust(w) for c, w in zip(columns, widths))]
    lines += ["  ".join(fmt(r.get(c)).ljust(w) for c, w in zip(columns, widths)) for r in rows]
    lines += [f"note: {n}" for n in notes]
    lines.append(f"{CORES} cores, Python {meta['python']}, {meta['total_s']:.0f} s in all")
    (out / "scaling.txt").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else os.environ.get("OUT", "scaling-out")),
         float(sys.argv[2]) if len(sys.argv) > 2 else 1.0)
