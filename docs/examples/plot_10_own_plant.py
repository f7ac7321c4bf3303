"""
Your own plant
==============

A plant is one class: a subclass of ``reduced_model.Plant`` — or of a built-in plant —
that declares its role and takes its settings as keyword arguments.  Here the paper's
model with three modes per link and a finer step plays a "truth" beside the paper's own
two-mode model, under the same PBC and observer: the difference between the two is what
the paper's truncation to two modes costs on this scenario.
"""
import matplotlib.pyplot as plt

from reduced_model import ReducedPlant
from validation import all_metrics, run_scenario, scenario_from_mapping


class ThreeModeArm(ReducedPlant):
    """The paper's model with three assumed modes per link, RK4 at 0.25 ms."""

    role = "truth"  # declared: a plant's role is never defaulted

    def __init__(self, params, *, model, sensors, Ts, modes=3):
        super().__init__(params, model=model, sensors=sensors, Ts=Ts,
                         modes_per_link=(modes, modes), step=2.5e-4)


# %%
# The class itself is the plant's kind (a script's class is found as ``__main__:Class``;
# in a TOML file, name its module: ``kind = "mylab.plants:ThreeModeArm"``).
base = {"duration": 6.0, "controller": {"kind": "pbc"}, "observer": {"kind": "smo-bl"}}
runs = {
    "paper's model (2 modes)": run_scenario(scenario_from_mapping(
        {**base, "plant": {"kind": "reduced"}})),
    "three modes per link": run_scenario(scenario_from_mapping(
        {**base, "plant": {"kind": ThreeModeArm, "role": "truth"}})),
}
for label, r in runs.items():
    m = all_metrics(r)
    print(f"{label:24s} {r.status}: max |θ1 − θ1d| = {1e3 * m['track_max_1']:.4f} mrad, "
          f"tip-1 vibration RMS = {1e3 * m['vib_rms_1']:.4f} mm")
two, three = runs.values()
print(f"between the plants: max |Δθ1| = {abs(two['theta1'] - three['theta1']).max():.2g} rad, "
      f"max |Δq11| = {abs(two['q11'] - three['q11']).max():.2g} m")

# %%
fig, ax = plt.subplots(figsize=(7, 3.2))
for label, r in runs.items():
    ax.plot(r.time, 1e3 * r["q11"], label=label, lw=1)
ax.set_xlabel("t [s]")
ax.set_ylabel("q11 [mm]")
ax.set_title("PBC + boundary-layer SMO, default arm, Ts = 1 ms")
ax.legend(fontsize=8)
fig.tight_layout()
