"""
Calibrate the plant to measured data
====================================

A calibration from data through the Python API: an "experiment" is made here by running
the reduced plant with parameters the calibration does not know (link stiffnesses 9.2
and 10.6 N m², a 0.23 kg payload, the campaigns' sensor noise), then the catalogue arm
(EI 10 N m², payload 0.1 kg) is fitted to it — the residual tests' verdict on the model,
estimates with their intervals, the measured against the fitted joint angle and their
difference.  ``flexarm calibrate`` does the same from CSV files (:doc:`../guide/calibrate`); on your arm, the data are your measurements and the
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
# The experiment's θ2 and the calibrated plant's in the same closed loop (the same
# controller and noise seed; top), and their difference (bottom): drawn on one axis the two curves coincide, so the residual
# is what shows the fit — noise at the encoder's level, no trend left.
fitted = run_scenario(scenario_from_mapping(
    {**common, "true_params": {k.split(".")[1]: p["estimate"]
                               for k, p in result["parameters"].items()}}))
measured = experiment.signals[experiment.names.index("theta2")]
t = [k * experiment.Ts for k in range(experiment.samples)]
fig, (ax, res) = plt.subplots(2, 1, figsize=(7, 4.4), sharex=True, layout="constrained",
                              height_ratios=(2, 1))
ax.plot(t, measured, lw=0.8, label="measured (synthetic, with encoder noise)")
ax.plot(fitted.time, fitted["theta2"], lw=1.5, ls="--", label="calibrated plant")
ax.set_ylabel("θ₂ [rad]")
ax.legend(fontsize=8)
ax.set_title("default controller (PBC), reduced plant, Ts = 1 ms, moving with the reference",
             fontsize=9)
n = min(len(t), len(fitted.time))
res.plot(t[:n], 1e3 * (measured[:n] - fitted["theta2"][:n]), lw=0.5, color="C3")
res.axhline(0.0, color="0.4", lw=0.6)
res.set_ylabel("measured − fitted\n[mrad]")
res.set_xlabel("t [s]")
plt.show()
