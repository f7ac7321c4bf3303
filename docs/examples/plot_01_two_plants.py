"""
One scenario on both plants
===========================

The paper's controller (PBC, eq. 20) fed by a boundary-layer sliding-mode observer, on the
reduced plant (the paper's model) and on the truth plant (the Exudyn finite-element arm),
with the same scenario, then overlaid: the question this toolkit answers, on one run.
"""
import matplotlib.pyplot as plt

from validation import all_metrics, run_scenario, scenario_from_mapping

base = {"duration": 3.0, "initial_state": "reference",
        "controller": {"kind": "pbc"}, "observer": {"kind": "smo-bl"}}
results = {}
for plant in ("reduced", "exudyn"):
    scenario = scenario_from_mapping({**base, "plant": {"kind": plant}})
    results[plant] = run_scenario(scenario)
    metrics = all_metrics(results[plant])
    print(f"{plant:8s} {results[plant].status}: after {metrics['transient_s']:g} s, "
          f"max |θ1 − θ1d| = {metrics['track_max_1'] * 1e3:.3f} mrad, "
          f"vibration RMS = {metrics['vib_rms_1'] * 1e3:.4f} mm")

# %%
# The reduced plant is drawn wide and light under the truth plant, thin and dark, so that
# both stay visible where they agree.
fig, axes = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
for plant, style in (("reduced", dict(lw=4, alpha=0.35)), ("exudyn", dict(lw=1.2))):
    r = results[plant]
    axes[0].plot(r.time, 1e3 * (r["theta1"] - r["theta1_ref"]), label=plant, **style)
    axes[1].plot(r.time, 1e3 * r["tip_defl1"], label=plant, **style)
axes[0].set_ylabel("θ1 − θ1d [mrad]")
axes[1].set_ylabel("link-1 tip deflection [mm]")
axes[1].set_xlabel("t [s]")
axes[0].legend(title="plant")
fig.suptitle("PBC + boundary-layer SMO, default arm, Ts = 1 ms")
fig.tight_layout()
