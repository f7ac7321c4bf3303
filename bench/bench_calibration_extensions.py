"""Does calibration name the physics an inadequate model lacks?  (issue 60)

Each case makes 2 s of data (the calibration examples' arm with joint-1 friction, the
reference with velocity reversals, the PBC fed the true state, white noise at the stated
levels, seed 3) with one effect the fitted model lacks, fits EI1, EI2, Mp, coulomb1 and
viscous1 from the example's starts, and reports: the verdict, the extension the search
names, whether every range the extended fit exports holds the truth, the simulations
and the wall time; then the known-bad — the same search with that extension removed
from the candidates — must find none.

Cases (``--case``):

* ``drive_backlash``: a drive on joint 1 (3000 N m/rad, rotor 0.05 kg m², damping 2 N m
  s/rad) with backlash 2e-4 rad (the issue's outside check);
* ``stribeck``: a breakaway of 0.375 N m above the Coulomb level 0.25 (Stribeck velocity
  0.01 rad/s; as tests/test_calibration_physics.py, whose docstring says why not 0.4);
* ``kinematics``: exact kinematics under the paper's reference from rest (large motion),
  fitted with the paper's linear kinematics (reduced plant only).

Usage::

    .venv/bin/python bench/bench_calibration_extensions.py --case drive_backlash
        [--plant exudyn] [--no-known-bad]
"""
from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from _report import report

REVERSALS = {"kind": "paper", "amplitude": [0.2, 0.2], "omega": [math.pi, 1.3 * math.pi]}
NOISE = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}
KEPT = ("theta1", "theta2", "q11", "q21")
LEVEL = np.array([1e-4, 1e-4, 1e-5, 1e-5])[:, None]
TRUE = {"EI1": 9.2, "EI2": 10.6, "Mp": 0.23, "coulomb1": 0.25, "viscous1": 0.15}
START = {"EI1": 10.0, "EI2": 10.0, "Mp": 0.2, "coulomb1": 0.3, "viscous1": 0.2}
CASES = {
    "drive_backlash": ({"gear_stiffness1": 3e3, "rotor_inertia1": 0.05, "gear_damping1": 2.0,
                        "backlash1": 2e-4}, "linear", REVERSALS, "joint 1 drive with backlash"),
    "stribeck": ({"breakaway1": 0.375, "stribeck_velocity1": 0.01}, "linear", REVERSALS,
                 "joint 1 Stribeck friction"),
    "kinematics": ({}, "exact", None, "exact kinematics"),
}


def experiment(plant: str, extra: dict, kinematics: str, reference):
    from validation import run_scenario, scenario_from_mapping
    from validation.run.experiments import Experiment, from_run
    spec = {"kind": plant, **({"kinematics": kinematics} if plant == "reduced" else {})}
    run = run_scenario(scenario_from_mapping({
        "duration": 2.0, **({"reference": reference} if reference else {}), "plant": spec,
        "true_params": {**TRUE, **extra}, "nominal_params": TRUE}))
    full = from_run(run, "data", "bench")
    clean = full.signals[[full.names.index(n) for n in KEPT]]
    noisy = clean + LEVEL * np.random.default_rng(3).standard_normal(clean.shape)
    return Experiment("data", "bench", full.Ts, full.torques, KEPT,
                      noisy.astype(np.float32).astype(np.float64))


def search(plant: str, data, folder: Path, without: str | None = None) -> tuple[dict, float]:
    from validation import scenario_from_mapping
    from validation.batch.executor import SerialRunner
    from validation.verdicts.calibration import (calibrate, calibration_settings,
                                                 plan_calibration, workflow)
    from validation.verdicts.calibration import extensions
    every = extensions.candidates
    fewer = (lambda plan, estimate: [e for e in every(plan, estimate) if e.name != without]) \
        if without else every
    extensions.candidates = workflow.candidates = fewer
    try:
        base = scenario_from_mapping({"plant": {"kind": plant}, "sensors": NOISE,
                                      "reference": REVERSALS, "nominal_params": TRUE,
                                      "true_params": {**TRUE, **START}})
        settings = calibration_settings({"bounds": {"true_params": {
            "Mp": [0.0, 2.0], "coulomb1": [0.0, 2.0], "viscous1": [0.0, 2.0]}}},
            [f"true_params.{n}" for n in TRUE], base)
        plan = plan_calibration(base, settings, [(data, None)])
        started = time.perf_counter()
        result = calibrate(plan, folder, runner=SerialRunner(), log=lambda *_: None)
        return result, time.perf_counter() - started
    finally:
        extensions.candidates = workflow.candidates = every


def exported(folder: Path) -> dict:
    from validation.run.tomlfiles import load_toml
    path = folder / "extended" / "uncertainty.toml"
    return {} if not path.is_file() else {
        n: v["uniform"] for n, v in load_toml(path)["uncertainty"].items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--case", choices=sorted(CASES), required=True)
    parser.add_argument("--plant", default="reduced")
    parser.add_argument("--no-known-bad", action="store_true")
    args = parser.parse_args()
    extra, kinematics, reference, named = CASES[args.case]
    data = experiment(args.plant, extra, kinematics, reference)
    truth = {**TRUE, **extra}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for without in [None] + ([] if args.no_known_bad else [named]):
            folder = Path(tmp) / ("blind" if without else "all")
            result, wall = search(args.plant, data, folder, without)
            found = result.get("extensions", {}).get("adequate")
            ranges = exported(folder)
            held = all(lo <= truth[n.split(".")[1]] <= hi for n, (lo, hi) in ranges.items())
            rows.append({"case": f"{args.case} ({args.plant})" + (
                f", without {named}" if without else ""),
                "adequate": result["model_adequate"], "named": found or "none",
                "exported": len(ranges), "exported_hold_truth": held if ranges else None,
                "simulations": result["simulations"], "wall_s": wall,
                "met": "yes" if (found is None if without else found == named and held)
                else "MISSED"})
    report(f"calibration_extensions_{args.case}_{args.plant}", rows,
           title="physics extensions named for an inadequate model (issue 60)",
           columns=["case", "adequate", "named", "exported", "exported_hold_truth",
                    "simulations", "wall_s", "met"])


if __name__ == "__main__":
    main()
