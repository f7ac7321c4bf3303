"""Calibration speed and honesty (issue 34): the truth plant fitted to 10 s of data.

- A 3-parameter truth-plant fit (EI1, EI2 and the payload Mp) on 10 s of synthetic data
  (the truth plant at EI1 = 9.2, EI2 = 10.6 N m², Mp = 0.23 kg, the PBC tracking
  eq. (37) from rest, the campaigns' sensor noise, theta1, theta2, q11, q21 kept), from
  the catalogue values of ``examples/calibration/arm.toml`` (EI 10, Mp 0.1): the whole
  command, ``flexarm calibrate --workers 1`` and ``--workers 2``, each into a fresh
  folder — iterations, truth-plant simulations, wall time, the largest error of the
  estimates, and whether every 95 % interval holds the true value.
- Interval coverage over 20 noise seeds on the reduced plant (0.5 s records, EI1, EI2,
  Mp): how many of the 20 intervals of each parameter hold the truth.

Targets (issue 34): the 3-parameter truth fit within 3 min on 2 cores with 2 workers;
coverage 17-20 of 20; recovery of the true values (errors small against the intervals).
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from _report import report, target

ROOT = Path(__file__).resolve().parent.parent
ARM = ROOT / "examples" / "calibration" / "arm.toml"
TRUE = {"EI1": 9.2, "EI2": 10.6, "Mp": 0.23}
NOISE = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}
KEPT = ("theta1", "theta2", "q11", "q21")


def make_data(folder: Path) -> Path:
    """10 s of the truth plant at TRUE, written as an experiment CSV."""
    from validation import run_scenario, scenario_from_mapping
    from validation.run.experiments import Experiment, from_run, write_experiment
    scenario = scenario_from_mapping({"duration": 10.0, "plant": {"kind": "exudyn"},
                                      "true_params": TRUE, "seed": 7, "sensors": NOISE})
    full = from_run(run_scenario(scenario), "ten", "bench")
    rows = [full.names.index(n) for n in KEPT]
    path = folder / "ten.csv"
    with path.open("w") as fh:
        write_experiment(Experiment("ten", "bench", full.Ts, full.torques, KEPT,
                                    full.signals[rows]), fh, "synthetic, bench_calibration.py")
    return path


def truth_fit(data: Path, folder: Path, workers: int) -> dict:
    out = folder / f"out{workers}"
    config = folder / "arm.toml"
    config.write_text(ARM.read_text().replace("duration = 2.0", "duration = 10.0")
                      .split("[calibrate.experiment.moving]")[0])
    started = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "validation.cli", "calibrate", str(data),
                           "--config", str(config), "--out", str(out), "--workers",
                           str(workers), "--no-progress"], capture_output=True, text=True)
    wall = time.perf_counter() - started
    if proc.returncode != 0:
        raise SystemExit(proc.stderr[-2000:])
    result = json.loads((out / "calibration.json").read_text())
    params = result["parameters"]
    errors = [abs(params[f"true_params.{k}"]["estimate"] - v) / v for k, v in TRUE.items()]
    held = sum(p["interval"][0] <= TRUE[n.split(".")[1]] <= p["interval"][1]
               for n, p in params.items() if p["identifiable"])
    return {"case": f"3-parameter truth fit, 10 s, {workers} worker(s)", "workers": workers,
            "wall_s": wall, "iterations": result["iterations"],
            "simulations": result["simulations"], "max_rel_error": max(errors),
            "intervals_holding_truth": f"{held}/3",
            **(target(wall, "<=", 180.0) if workers == 2 else {})}


def coverage(folder: Path) -> list[dict]:
    from validation import run_scenario, scenario_from_mapping
    from validation.batch.executor import SerialRunner
    from validation.run.experiments import from_run
    from validation import calibrate, calibration_settings, plan_calibration
    names = ["true_params.EI1", "true_params.EI2", "true_params.Mp"]
    truth = {"true_params.EI1": 10.0, "true_params.EI2": 10.0, "true_params.Mp": 0.1}
    held = {n: 0 for n in names}
    started = time.perf_counter()
    for seed in range(20):
        run = run_scenario(scenario_from_mapping({"duration": 0.5, "seed": seed,
                                                  "sensors": NOISE}))
        run.signals = run.signals.astype(np.float32)
        base = scenario_from_mapping({"sensors": NOISE, "true_params": {
            "EI1": 10.5, "EI2": 9.5, "Mp": 0.105}})
        settings = calibration_settings({"horizon": 0.5}, names, base)
        plan = plan_calibration(base, settings, [(from_run(run, "e", "e"), None)])
        result = calibrate(plan, folder / f"cov{seed}", runner=SerialRunner(),
                           log=lambda *_: None)
        for n in names:
            lo, hi = result["parameters"][n]["interval"]
            held[n] += lo <= truth[n] <= hi
    wall = time.perf_counter() - started
    return [{"case": f"95 % intervals holding the truth, 20 seeds, reduced: {n}",
             "covered": held[n], "wall_s": wall, **target(held[n], ">=", 17)} for n in names]


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        data = make_data(folder)
        rows = [truth_fit(data, folder, w) for w in (1, 2)]
        rows[1]["speed_up"] = rows[0]["wall_s"] / rows[1]["wall_s"]
        rows += coverage(folder)
    report("calibration", rows, title="calibration (issue 34)",
           columns=["case", "wall_s", "iterations", "simulations", "max_rel_error",
                    "intervals_holding_truth", "speed_up", "covered", "target", "met"])


if __name__ == "__main__":
    main()
