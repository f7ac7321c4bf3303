"""
Verdicts over uncertainty: estimate and falsify
===============================================

``flexarm verify`` judges a design over a declared set of conditions: **estimate** gives
P(holds) with an exact interval over seeded draws; **falsify** searches the worst case on
the reduced plant (CMA-ES) and confirms it on the truth plant.  Here the PBC with a
boundary-layer SMO, 3 s runs, over the payload and a torque pulse, with a small budget.
"""
import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from validation.cli import main

folder = Path(tempfile.mkdtemp(prefix="flexarm-verify-"))
(folder / "robust.toml").write_text("""
duration = 3.0
transient = 1.0
initial_state = "reference"
plant.kind = "exudyn"
observer.kind = "smo-bl"
disturbances = [{ kind = "pulse", target = "tau1", amplitude = 1.0, start = 1.5, duration = 0.2 }]

[[requirement]]
name = "tracking"
formula = "always[1,3](abs(theta1 - theta1_ref) <= 0.02)"

[uncertainty]
"true_params.Mp" = { uniform = [0.0, 1.0] }                  # kg
"disturbances[0].amplitude" = { uniform = [0.0, 6.0] }       # N m

[verify]
sequential = false
""")

# %%
# **Estimate** on the file's plant (the truth plant here), 12 draws.
main(["verify", str(folder / "robust.toml"), "--mode", "estimate", "--samples", "12",
      "--workers", "2", "--no-progress", "--out", str(folder / "estimate")])
estimate = json.loads((folder / "estimate" / "verdict.json").read_text())

# %%
# **Falsify**: the search runs on the reduced plant; at most 3 truth-plant simulations
# confirm what it finds, and the counterexample's truth run is repeated on the refined
# sequence of meshes and steps.
main(["verify", str(folder / "robust.toml"), "--mode", "falsify", "--budget", "3",
      "--workers", "2", "--no-progress", "--out", str(folder / "falsify")])
falsify = json.loads((folder / "falsify" / "verdict.json").read_text())
print({k: falsify[k] for k in ("found", "rho_reduced", "rho_truth", "simulations")})

# %%
# The draws of the estimate, read back from its results store with their ρ, and the
# counterexample the falsification found, in the space of the uncertainty.
from validation import ResultStore  # noqa: E402

rows = [r for r in ResultStore(folder / "estimate").rows() if r.status == "ok"]
payload = [r.config["true_params"]["payload"]["mass"] for r in rows]  # Mp
pulse = [r.config["disturbances"][0]["amplitude"] for r in rows]
rho = np.array([r.metrics["rho_tracking"] for r in rows])
fig, ax = plt.subplots(figsize=(6, 4))
dots = ax.scatter(payload, pulse, c=1e3 * rho, cmap="RdYlGn", vmin=-40, vmax=40,
                  edgecolors="k")
fig.colorbar(dots, label="ρ of tracking [mrad]")
point = falsify["point"]
ax.plot(point["true_params.Mp"], point["disturbances[0].amplitude"], "kx", ms=12, mew=2,
        label="counterexample (truth-confirmed)")
ax.set_xlabel("true payload [kg]")
ax.set_ylabel("pulse amplitude [N m]")
p = estimate["requirements"]["tracking"]
ax.set_title(f"P(holds) in [{p['p_low']:.2f}, {p['p_high']:.2f}] "
             f"({p['n'] - p['failures']}/{p['n']} draws hold)")
ax.legend(loc="lower left", fontsize=8)
fig.tight_layout()
