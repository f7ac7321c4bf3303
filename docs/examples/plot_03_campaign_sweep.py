"""
A campaign: a payload sweep and its report
==========================================

A campaign is a base scenario and sweeps over it, run on worker processes and stored as
each run finishes; the report is rendered from the stored runs.  Here the payload the arm
really carries is swept while the controller and the observer keep believing in the
nominal 0.1 kg, on the reduced plant.  The same campaign as a TOML file runs with
``flexarm campaign my.toml`` and reports with ``flexarm report``.
"""
import tempfile

import matplotlib.pyplot as plt

from validation import ResultStore, campaign_from_mapping, expand, make_runner, run_campaign
from validation.report.report import write_report

campaign = campaign_from_mapping({
    "name": "payload",
    "scenario": {"duration": 4.0, "controller": {"kind": "pbc"},
                 "observer": {"kind": "smo-bl"},
                 "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}},
    "sweep": [{"name": "payload", "grid": {"true_params": {"Mp": [0.0, 0.1, 0.3, 0.6, 1.0]}}}],
})
print(len(expand(campaign)), "runs planned")

out = tempfile.mkdtemp(prefix="flexarm-campaign-")
summary = run_campaign(campaign, out, runner=make_runner("local", workers=2), progress=False)
print(summary.line(campaign.name, out))

# %%
# The stored runs and their metrics, read back from the results store; the report
# (``report.html``, ``report.md``) is written next to them.
rows = sorted(ResultStore(out).rows(), key=lambda row: row.axes["true_params.Mp"])
payload = [row.axes["true_params.Mp"] for row in rows]
html, md = write_report(out, animate=False, progress=False)
print("report:", html.name, md.name)

fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(payload, [1e3 * r.metrics["track_max_1"] for r in rows], "o-", label="joint 1")
ax.plot(payload, [1e3 * r.metrics["track_max_2"] for r in rows], "s-", label="joint 2")
ax.axvline(0.1, color="grey", ls=":", label="nominal payload")
ax.set_xlabel("true payload [kg]")
ax.set_ylabel("max |θ − θd| after the transient [mrad]")
ax.set_title("PBC + boundary-layer SMO, laws built for 0.1 kg")
ax.legend()
fig.tight_layout()
