"""
A regression bound for CI
=========================

``baselines.toml`` pins what a design achieves today, so that a change that degrades it
fails the test suite.  A check names a short scenario, a metric key (or several: their
maximum), ``<=`` or ``>=`` and a bound; ``flexarm baseline update`` measures it and sets
the bound with the margin policy, ``flexarm baseline check`` compares (exit 1 when one
fails).  Here a file of our own with two checks on a 3 s scenario.
"""
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from validation.cli import main
from validation.verdicts.baselines import load_baselines

folder = Path(tempfile.mkdtemp(prefix="flexarm-baseline-"))
path = folder / "my-baselines.toml"
path.write_text("""
[policy]
relative = 0.25          # bound = measured x 1.25
absolute = 0.0

[scenarios.pbc-smo-bl]
duration = 3.0
observer.kind = "smo-bl"
sensors.encoder_noise = 1e-4

[[check]]
name = "tracking"
scenario = "pbc-smo-bl"
metric = ["track_max_1", "track_max_2"]
op = "<="
bound = 1.0              # a first guess: update measures and tightens it

[[check]]
name = "angle-estimate"
scenario = "pbc-smo-bl"
metric = ["est_rms_theta1", "est_rms_theta2"]
op = "<="
bound = 1.0
""")

# %%
# Measure and set the bounds (tightening needs no flag; loosening would need
# ``--allow-loosen``), then check — what CI runs.
main(["baseline", "update", "--file", str(path), "--out", str(folder / "runs")])
status = main(["baseline", "check", "--file", str(path), "--out", str(folder / "runs")])
print("exit status of the check:", status)

# %%
checks = load_baselines(path).checks
fig, ax = plt.subplots(figsize=(6, 3))
names = [c.name for c in checks]
ax.barh(names, [c.bound for c in checks], color="lightgrey", label="bound")
ax.barh(names, [c.measured for c in checks], height=0.4, color="tab:blue", label="measured")
ax.set_xscale("log")
ax.set_xlabel("metric value [rad]")
ax.set_title("The checks of my-baselines.toml after update")
ax.legend(fontsize=8)
fig.tight_layout()
