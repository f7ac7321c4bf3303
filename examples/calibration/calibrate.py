"""The calibration of the docs' guide (docs/guide/calibrate.rst, "Calibrate the truth
plant to your arm") through the Python API: the truth plant fitted to this folder's
synthetic experiments (two time series and a frequency response), the parameters with
their intervals, and the files `flexarm calibrate` writes.  Run from the repository root:
.venv/bin/python examples/calibration/calibrate.py"""
from pathlib import Path

from validation import (base_scenario, calibrate, calibration_settings, make_runner,
                        plan_calibration, read_experiment, read_frequency_response)

HERE = Path(__file__).resolve().parent

base, table = base_scenario(HERE / "arm.toml")          # the scenario and its [calibrate]
settings = calibration_settings(table, None, base)      # None: the file's fit = [...]
experiments = [(read_experiment(HERE / f"{name}.csv"), None) for name in ("tracking", "moving")]
responses = [read_frequency_response(HERE / "frf.csv")]
plan = plan_calibration(base, settings, experiments, responses)   # every check, nothing written
with make_runner("local", 2, scenarios=[base]) as runner:
    result = calibrate(plan, "results/calibrate-example", runner=runner)
print("model adequate:", result["model_adequate"], "-", result["adequacy"]["verdict"])
print("intervals:", result["interval_kind"])
for name, p in result["parameters"].items():
    print(name, p["estimate"], p["interval"] if p["identifiable"] else p["reason"])
print(result["iterations"], "iterations,", result["simulations"], "simulations")
