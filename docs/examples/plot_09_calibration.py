"""
Calibrate the plant to measured data
====================================

A calibration from data through the Python API: an "experiment" is made here by running
the reduced plant with parameters the calibration does not know (link stiffnesses 9.2
and 10.6 N m², a 0.23 kg payload, the campaigns' sensor noise), then the catalogue arm
(EI 10 N m², payload 0.1 kg) is fitted to it — the residual tests' verdict on the model,
estimates with their intervals, and the measured against the fitted joint angle.  ``flexarm calibrate`` does the same from CSV
files (:doc:`../guide/calibrate`); on your arm, the data are your measurements and the
plant the truth plant.
"""
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from validation import (calibrate, calibration_settings, make_runner, plan_calibration,
                        run_scenario, scenario_from_mapping)
from validation.run.experiments import from_run

noise = {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}
common = {"duration": 1.0, "transient": 0.5, "initial_state": "reference",
          "sensors": noise, "observer": {"kind": "none"}}
measured_arm = {"EI1": 9.2, "EI2": 10.6, "Mp": 0.23}
experiment = from_run(run_scenario(scenario_from_mapping(
    {**common, "true_params": measured_arm})), "lab", "a synthetic experiment")

base = scenario_from_mapping(common)  # the arm as believed: the catalogue values
settings = calibration_settings(
    {"fit": ["true_params.EI1", "true_params.EI2", "true_params.Mp"]}, None, base)
plan = plan_calibration(base, settings, [(experiment, None)])
out = Path(tempfile.mkdtemp()) / "calibration"
with make_runner("local", 1, scenarios=[base]) as runner:
    result = calibrate(plan, out, runner=runner, log=lambda line: None)
print(f"the model: {result['adequacy']['verdict']}")  # the residual tests' verdict
for name, p in result["parameters"].items():
    lo, hi = p["interval"]  # a 95 % interval when the model is adequate
    print(f"{name}: {p['estimate']:.4g} ({lo:.4g} .. {hi:.4g}); "
          f"the experiment's arm: {measured_arm[name.split('.')[1]]}")

# %%
# The experiment's θ2 and the calibrated plant's, replaying the same torques.
fitted = run_scenario(scenario_from_mapping(
    {**common, "true_params": {k.split(".")[1]: p["estimate"]
                               for k, p in result["parameters"].items()}}))
fig, ax = plt.subplots(figsize=(7, 3.2), layout="constrained")
t = [k * experiment.Ts for k in range(experiment.samples)]
ax.plot(t, experiment.signals[experiment.names.index("theta2")], lw=0.8,
        label="measured (synthetic, with encoder noise)")
ax.plot(fitted.time, fitted["theta2"], lw=1.5, ls="--", label="calibrated plant")
ax.set_xlabel("t [s]")
ax.set_ylabel("θ₂ [rad]")
ax.legend(fontsize=8)
ax.set_title("default controller (PBC), reduced plant, Ts = 1 ms, moving with the reference",
             fontsize=9)
plt.show()
