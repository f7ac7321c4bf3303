"""
Your arm: three links, and an arm in gravity
============================================

The same laws on other arms, from their descriptions alone: the paper's PBC fed by its
sliding-mode observer moves the three-link arm (a rigid base link and two flexible links)
on the reduced model and on the truth plant, with the gains the arm's rule gives it; then
the PBC holds the vertical two-link arm straight out against gravity, and — without its
gravity term — sags by the static moment over its gain.  ``campaigns/arms.toml`` runs the
PBC and the baselines on six arms and puts them side by side in its report.
"""
import matplotlib.pyplot as plt
import numpy as np

from validation import all_metrics, run_scenario, scenario_from_mapping

move = {"arm": "three-link", "duration": 5.0, "transient": 3.0,
        "controller": {"kind": "pbc"},
        "observer": {"kind": "smo-paper", "initial_error": [0.1, 5e-3, 0.3, 0.05]},
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3},
        "reference": {"kind": "quintic", "goal": [0.5, -0.5, 0.5], "move_time": 2.0}}
runs = {plant: run_scenario(scenario_from_mapping({**move, "plant": {"kind": plant}}))
        for plant in ("reduced", "exudyn")}

fig, axes = plt.subplots(1, 3, figsize=(9, 3), sharey=True, layout="constrained")
for joint, ax in enumerate(axes, start=1):
    for plant, result in runs.items():
        error = result[f"theta{joint}"] - result[f"theta{joint}_ref"]
        ax.plot(result.time, 1e3 * error, label=plant, lw=1.0 if plant == "exudyn" else 2.0,
                alpha=1.0 if plant == "exudyn" else 0.5)
    ax.set(title=f"joint {joint}", xlabel="t [s]", ylim=(-5, 5))
axes[0].set_ylabel("θ − θ_d [mrad]")
axes[0].legend(fontsize=8)
fig.suptitle("three-link arm, PBC fed by the SMO: tracking error on both plants", fontsize=10)
for plant, result in runs.items():
    m = all_metrics(result, 3.0)
    print(f"{plant}: tracking error RMS after 3 s, worst joint "
          f"{1e3 * max(m[f'track_rms_{i}'] for i in (1, 2, 3)):.2f} mrad")

# %%
# A vertical arm: the PBC's energy shaping with the arm's gravitational potential holds it
# horizontal; the law of a horizontal arm (``gravity_compensation = false``) lets each
# joint sag until K_v Λ e balances the static moment.
hold = {"arm": "vertical-two-link", "duration": 8.0, "feedback": "true",
        "observer": {"kind": "none"},
        "reference": {"kind": "quintic", "goal": [0.0, 0.0], "move_time": 2.0}}
fig, ax = plt.subplots(figsize=(6, 3), layout="constrained")
for compensate in (True, False):
    result = run_scenario(scenario_from_mapping({
        **hold, "plant": {"kind": "exudyn"},
        "controller": {"kind": "pbc", "options": {"gravity_compensation": compensate}}}))
    label = "with the gravity term" if compensate else "without it"
    for joint in (1, 2):
        ax.plot(result.time, 1e3 * result[f"theta{joint}"], label=f"θ{joint}, {label}")
    print(f"{label}: final angles {np.round(1e3 * result.select(['theta1', 'theta2'])[:, -1], 3)} "
          "mrad")
ax.set(xlabel="t [s]", ylabel="θ [mrad]",
       title="vertical two-link arm held horizontal, truth plant")
ax.legend(fontsize=8)
plt.show()
