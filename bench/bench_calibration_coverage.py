"""Do calibration's 95 % intervals cover at their stated rate?  Coverage studies over
noise seeds (issue 60).

Each case fixes an arm, an experiment and the torques it received (one noise-free run
of the PBC tracking the calibration examples' reference — sines of 0.2 rad whose joint
velocities pass through zero — fed the true state), then draws the measurement noise
again for every seed, at the stated levels (1e-4 rad on the angles, 1e-5 m on the modal
coordinates), white or coloured, and fits the stated parameters from the example's
starts.  A 95 % interval that is honest covers the truth in X ~ B(20, 0.95) of 20 seeds:
17-20 is the binomial range (P(X ≤ 16) = 0.016); the RMS of the standardised errors
(estimate − truth) / std is 1 ± 0.16 (its standard deviation over 20 seeds).

Cases (``--case``; each prints its table and appends its fits to bench/results/):

* ``friction``: the truth plant's default mesh with joint-1 friction (the calibration
  examples' arm: EI1 9.2, EI2 10.6 N m², Mp 0.23 kg, coulomb1 0.25 N m, viscous1 0.15
  N m s/rad), 2 s, white noise; EI1, EI2, Mp, coulomb1, viscous1 from
  examples/calibration/friction.toml's starts (the issue's case: coulomb1 covered 16 of
  20).
* ``lab``: the lab arm (Stribeck friction, drives with backlash, current loops) at
  EI1 8.6, EI2 11.3, Mp 0.37, coulomb1 0.3, viscous1 0.2, on the reduced plant
  (``--plant exudyn``: the truth plant), 2 s, white noise; the same five fitted.
* ``ar1``: ``friction``'s arm with AR(1) noise of ρ = 0.9 at the stated RMS; the verdict
  must say "noise coloured" and the model adequate.

Usage::

    .venv/bin/python bench/bench_calibration_coverage.py --case friction [--plant reduced]
        [--seeds 20] [--workers 2]
"""
from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.stats

from _report import RESULTS, report

REVERSALS = {"kind": "paper", "amplitude": [0.2, 0.2], "omega": [math.pi, 1.3 * math.pi]}
NOISE = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}
KEPT = ("theta1", "theta2", "q11", "q21")
LEVEL = {"theta1": 1e-4, "theta2": 1e-4, "q11": 1e-5, "q21": 1e-5}
CASES = {
    "friction": {"arm": "default", "noise": "white",
                 "truth": {"EI1": 9.2, "EI2": 10.6, "Mp": 0.23, "coulomb1": 0.25,
                           "viscous1": 0.15},
                 "start": {"EI1": 10.0, "EI2": 10.0, "Mp": 0.1, "coulomb1": 0.3,
                           "viscous1": 0.2},
                 "bounds": {"Mp": [0.0, 2.0], "coulomb1": [0.0, 2.0], "viscous1": [0.0, 2.0]}},
    "lab": {"arm": "lab", "noise": "white",
            "truth": {"EI1": 8.6, "EI2": 11.3, "Mp": 0.37, "coulomb1": 0.3, "viscous1": 0.2},
            "start": {"EI1": 9.5, "EI2": 10.0, "Mp": 0.3, "coulomb1": 0.25, "viscous1": 0.25},
            "bounds": {}},
}
CASES["ar1"] = {**CASES["friction"], "noise": "ar1"}
#: AR(1) noise's coefficient.
RHO = 0.9


def clean_run(case: dict, plant: str):
    """The noise-free experiment: its period, torques and kept signals."""
    from validation import run_scenario, scenario_from_mapping
    from validation.run.experiments import from_run
    arm = {} if case["arm"] == "default" else {"arm": case["arm"]}
    run = run_scenario(scenario_from_mapping({
        "duration": 2.0, "reference": REVERSALS, "plant": {"kind": plant}, **arm,
        "true_params": case["truth"], "nominal_params": case["truth"]}))
    full = from_run(run, "coverage", "bench")
    return full.Ts, full.torques, full.signals[[full.names.index(n) for n in KEPT]]


def noise(kind: str, seed: int, n: int) -> np.ndarray:
    """Measurement noise at the stated levels: white, or AR(1) of ρ = `RHO` scaled to
    the stated RMS (started from its stationary distribution)."""
    rng = np.random.default_rng(seed)
    out = []
    for name in KEPT:
        w = rng.standard_normal(n)
        if kind == "ar1":
            x = np.empty(n)
            x[0] = w[0]
            for k in range(1, n):
                x[k] = RHO * x[k - 1] + math.sqrt(1 - RHO ** 2) * w[k]
            w = x
        out.append(LEVEL[name] * w)
    return np.array(out)


def fit(case: dict, plant: str, Ts, torques, signals, folder: Path, runner) -> dict:
    from validation import scenario_from_mapping
    from validation.batch.store.memory import MemoryStore
    from validation.run.experiments import Experiment
    from validation.verdicts.calibration import (calibrate, calibration_settings,
                                                 plan_calibration)
    arm = {} if case["arm"] == "default" else {"arm": case["arm"]}
    names = [f"true_params.{n}" for n in case["truth"]]
    exp = Experiment("coverage", "bench", Ts, torques, KEPT,
                     signals.astype(np.float32).astype(np.float64))
    base = scenario_from_mapping({"plant": {"kind": plant}, **arm, "sensors": NOISE,
                                  "reference": REVERSALS, "true_params": case["start"],
                                  "nominal_params": case["truth"]})
    bounds = {f"true_params.{k}": v for k, v in case["bounds"].items()}
    settings = calibration_settings({"bounds": bounds}, names, base)
    plan = plan_calibration(base, settings, [(exp, None)])
    return calibrate(plan, folder, runner=runner, log=lambda *_: None, store=MemoryStore())


def summary(case_name: str, plant: str, fits: list[dict], truth: dict) -> list[dict]:
    rows = []
    low = int(scipy.stats.binom.ppf(0.025, len(fits), 0.95))
    for name, value in truth.items():
        z, covered = [], 0
        for f in fits:
            p = f["parameters"][name]
            covered += p["interval"] is not None and p["interval"][0] <= value <= p["interval"][1]
            if p["std"]:
                z.append((p["estimate"] - value) / p["std"])
        rows.append({"case": f"{case_name} ({plant})", "parameter": name,
                     "covered": f"{covered}/{len(fits)}", "binomial_95": f"{low}-{len(fits)}",
                     "rms_z": float(np.sqrt(np.mean(np.square(z)))) if z else None,
                     "largest_z": float(np.max(np.abs(z))) if z else None,
                     "met": "yes" if covered >= low else "MISSED"})
    verdicts = {}
    for f in fits:
        key = "coloured" if f["adequacy"].get("noise_coloured") and f["model_adequate"] \
            else str(f["model_adequate"])
        verdicts[key] = verdicts.get(key, 0) + 1
    rows.append({"case": f"{case_name} ({plant})", "parameter": "verdicts",
                 "covered": ", ".join(f"{k}: {v}" for k, v in sorted(verdicts.items())),
                 "wall_s": sum(f["wall_s"] for f in fits) / len(fits),
                 "simulations": sum(f["simulations"] for f in fits) / len(fits)})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--case", choices=sorted(CASES), required=True)
    parser.add_argument("--plant", default=None, help="reduced or exudyn (default: the "
                                                      "case's: exudyn, lab: reduced)")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    case = CASES[args.case]
    plant = args.plant or ("reduced" if args.case == "lab" else "exudyn")
    from validation.batch.executor import SerialRunner, make_runner
    Ts, torques, clean = clean_run(case, plant)
    log = RESULTS / f"calibration_coverage_{args.case}_{plant}.jsonl"
    RESULTS.mkdir(exist_ok=True)
    truth = {f"true_params.{k}": v for k, v in case["truth"].items()}
    fits = []
    runner = SerialRunner() if args.workers == 1 else make_runner("local", args.workers)
    with tempfile.TemporaryDirectory() as tmp, log.open("a") as out:
        for seed in range(args.first, args.first + args.seeds):
            started = time.perf_counter()
            y = clean + noise(case["noise"], seed, clean.shape[1])
            result = fit(case, plant, Ts, torques, y, Path(tmp) / str(seed), runner)
            result["wall_s"], result["seed"] = time.perf_counter() - started, seed
            fits.append(result)
            out.write(json.dumps({"seed": seed, "wall_s": result["wall_s"],
                                  "simulations": result["simulations"],
                                  "model_adequate": result["model_adequate"],
                                  "verdict": result["adequacy"]["verdict"],
                                  "parameters": result["parameters"]}) + "\n")
            out.flush()
    report(f"calibration_coverage_{args.case}_{plant}", summary(args.case, plant, fits, truth),
           title=f"95 % interval coverage, {args.case} on the {plant} plant, "
                 f"{len(fits)} noise seeds (issue 60)",
           columns=["case", "parameter", "covered", "binomial_95", "rms_z", "largest_z",
                    "wall_s", "simulations", "met"])


if __name__ == "__main__":
    main()
