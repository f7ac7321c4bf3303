"""
Your own controller, as a plug-in
=================================

A controller is any class built as ``Cls(model, *, Ts, **options)`` and called as
``tau = controller(t, x, ref)``.  Written in a module Python can import, a scenario names
it ``"package.module:Class"`` — in a TOML file, on the command line, in a campaign — and it
runs wherever the built-in laws run.  Here a joint PID, written to a module in a temporary
folder, runs on both plants next to the paper's PBC.
"""
import importlib
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from validation import all_metrics, run_scenario, scenario_from_mapping

lab = Path(tempfile.mkdtemp(prefix="flexarm-plugin-"))
(lab / "mylab_pid.py").write_text('''
import numpy as np


class JointPID:
    """A joint PID: tau = kp e + ki ∫e + kd ė (no feedforward)."""

    def __init__(self, model, *, Ts, kp=(30.0, 15.0), ki=(5.0, 2.0), kd=(18.1, 8.2)):
        self.kp, self.ki, self.kd = (np.asarray(g, float) for g in (kp, ki, kd))
        self.Ts, self.integral = Ts, np.zeros(2)   # Ts: the control period, set once

    def __call__(self, t, x, ref):
        n = x.shape[0] // 2                       # x = [Q, Qdot] in the model's coordinates
        theta_d, dtheta_d, _ = ref(t)
        e, de = theta_d - x[:2], dtheta_d - x[n:n + 2]
        self.integral += self.Ts * e
        return self.kp * e + self.ki * self.integral + self.kd * de
''')

# %%
# The same scenario with each controller, on each plant.  The plug-in has no compiled
# form, so its runs take the Python path of the loop (``timings["paths"]`` says so).
sys.path.insert(0, str(lab))  # flexarm does this for the folder it runs in
importlib.invalidate_caches()  # a module written while Python runs: let the importer see it
runs = {}
for kind in ("mylab_pid:JointPID", "pbc"):
    for plant in ("reduced", "exudyn"):
        scenario = scenario_from_mapping({
            "duration": 4.0, "plant": {"kind": plant},
            "controller": {"kind": kind,
                           "options": {"ki": [2.0, 1.0]} if "PID" in kind else {}}})
        r = runs[kind, plant] = run_scenario(scenario)
        m = all_metrics(r)
        worst = max(m["track_max_1"], m["track_max_2"])
        print(f"{kind:20s} {plant:8s} max |θ − θd| = {1e3 * worst:6.2f} mrad   "
              f"paths: {r.timings['paths']}")

# %%
fig, ax = plt.subplots(figsize=(7, 3.5))
for (kind, plant), r in runs.items():
    style = dict(lw=4, alpha=0.35) if plant == "reduced" else dict(lw=1.2)
    ax.plot(r.time, 1e3 * (r["theta2"] - r["theta2_ref"]),
            label=f"{kind.split(':')[-1]}, {plant}", **style)
ax.set_xlabel("t [s]")
ax.set_ylabel("θ2 − θ2d [mrad]")
ax.set_title("A plug-in PID and the PBC, both plants, from rest")
ax.legend(fontsize=8)
fig.tight_layout()
