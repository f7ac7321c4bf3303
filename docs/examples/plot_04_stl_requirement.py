"""
A requirement in Signal Temporal Logic
======================================

A ``[[requirement]]`` is a built-in claim or an STL formula over the run's signal names;
every run carries its robustness ρ as the metric ``rho_<name>`` (ρ ≥ 0 holds, its size says by
how much).  Here: the paper's tracking claim, and "after 1 s, joint 1 stays within 5 mrad
of its reference and the link-2 tip deflection within 2 mm", on a torque pulse of growing
size.
"""
import matplotlib.pyplot as plt

from validation import all_metrics, run_scenario, scenario_from_mapping
from validation.run.requirements import requirement_metrics

requirements = [
    {"name": "tracking", "claim": "tracking"},
    {"name": "settle",
     "formula": "always[1,3](abs(theta1 - theta1_ref) <= 0.005 and abs(tip_defl2) <= 0.002)"},
]
runs = {}
for amplitude in (0.0, 0.5, 2.0):
    scenario = scenario_from_mapping({
        "duration": 3.0, "initial_state": "reference", "requirement": requirements,
        "disturbances": [{"kind": "pulse", "target": "tau1", "amplitude": amplitude,
                          "start": 1.5, "duration": 0.2}]})
    r = runs[amplitude] = run_scenario(scenario)
    rho = requirement_metrics(r, all_metrics(r))
    print(f"pulse {amplitude:3.1f} N m: rho_tracking = {1e3 * rho['rho_tracking']:+7.2f} mrad, "
          f"rho_settle = {1e3 * rho['rho_settle']:+7.2f} (mrad or mm: the tighter of the two)")

# %%
# ρ of ``settle`` is the smallest margin over the window and both conditions: the
# distance of the worst sample from its bound.
fig, ax = plt.subplots(figsize=(7, 3.5))
for amplitude, r in runs.items():
    ax.plot(r.time, 1e3 * (r["theta1"] - r["theta1_ref"]), label=f"pulse {amplitude:g} N m")
for bound in (-5, 5):
    ax.axhline(bound, color="k", ls="--", lw=0.8)
ax.axvspan(1, 3, color="grey", alpha=0.1, label="always[1,3]")
ax.set_xlabel("t [s]")
ax.set_ylabel("θ1 − θ1d [mrad]")
ax.set_title("The STL requirement's window and bound")
ax.legend(fontsize=8)
fig.tight_layout()
