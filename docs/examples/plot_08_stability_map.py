"""
The sampled-data stability map
===============================

A controller designed in continuous time meets the arm through a sampler and a
zero-order hold.  The stability map predicts each limit from the exact zero-order-hold
eigenvalues of the linearised sampled loop, runs short closed loops at the two control
periods around the prediction (a law fed the true state; a case with an observer starts
from a grid of 0.1–10 ms), steps outwards until each limit is bracketed, and bisects it
until its bracket is within a tolerance (here 1 %): a handful of runs per case.
Here the PBC and a joint PD on the reduced plant of the default arm (the truth plant's
map is the same call: ``flexarm stability FILE``, which also checks its convergence).
"""
import tempfile

import matplotlib.pyplot as plt

from validation import make_runner, scenario_from_mapping
from validation.verdicts.stability import OUTCOMES, cases_from_scenarios, stability_map

scenarios = [scenario_from_mapping({"name": kind, "controller": {"kind": kind}})
             for kind in ("pbc", "pd")]
cases = cases_from_scenarios(scenarios, plants=["reduced"], arms=["default"])
out = tempfile.mkdtemp(prefix="flexarm-stability-")
results, summary = stability_map(cases, out, runner=make_runner("local", workers=2),
                                 progress=False, tolerance=0.01)
for r in results:
    print(f"{r.case.label:4s} no divergence up to {1e3 * r.divergence.largest:.4g} ms "
          f"(first divergence {1e3 * r.divergence.first_bad:.4g} ms, {r.divergence.width:.2%}"
          f" wide, {r.runs} runs), keeps tracking up to {1e3 * r.tracking.largest:.4g} ms; "
          f"predicted {1e3 * r.predicted:.4g} ms")

# %%
# Every tested control period with its outcome; the dashed line is the prediction the
# search started from.
colours = dict(zip(OUTCOMES, ("tab:green", "tab:orange", "tab:red", "black")))
fig, ax = plt.subplots(figsize=(7, 2.8))
for row, r in enumerate(results):
    for Ts, (outcome, _) in sorted(r.tested.items()):
        ax.plot(1e3 * Ts, row, "o", color=colours[outcome], ms=8)
    ax.plot([1e3 * r.predicted] * 2, [row - 0.3, row + 0.3], "k--")
for outcome, colour in colours.items():
    ax.plot([], [], "o", color=colour, label=outcome)
ax.set_xscale("log")
ax.set_yticks(range(len(results)), [r.case.label for r in results])
ax.set_ylim(-0.6, len(results) - 0.4)
ax.set_xlabel("control period Ts [ms]")
ax.set_title("Reduced plant, default arm, 2 s runs moving with the reference", fontsize=10)
ax.legend(fontsize=8, ncol=4, loc="upper left", bbox_to_anchor=(0, -0.3))
fig.tight_layout()
