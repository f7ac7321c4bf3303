"""
FMUs
====

The reduced plant exported as a co-simulation FMU (``flexarm export-fmu`` does the same
from the command line), driven by FMPy's ``simulate_fmu`` under a torque step, then run
back as the plant of a small campaign (``[plant] kind = "fmu"``), its payload varied
through the FMU's parameter ``Mp``.  Needs the ``fmi`` extra (``pip install -e
'.[fmi]'``); without it the example says so and stops.
"""
import importlib.util
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

if importlib.util.find_spec("fmpy") is None or importlib.util.find_spec("pythonfmu") is None:
    print("this example needs the fmi extra: pip install -e '.[fmi]'")
    sys.exit(0)

import fmpy  # noqa: E402

from validation import (ResultStore, campaign_from_mapping, make_runner,  # noqa: E402
                        run_campaign, scenario_from_mapping)
from validation.run.fmu.export import export_plant  # noqa: E402
folder = Path(tempfile.mkdtemp(prefix="flexarm-fmu-example-"))
paper = {"controller": {"kind": "pbc"}, "observer": {"kind": "smo-paper"}}
arm = export_plant(scenario_from_mapping(paper), folder / "arm.fmu")
print("FMPy's validation:", fmpy.validation.validate_fmu(str(arm)) or "no problem")

# %%
# FMPy alone: 0.2 N m on joint 1 for 2 s, the communication step 1 ms.
step = np.array([(0.0, 0.2, 0.0), (2.0, 0.2, 0.0)],
                dtype=[("time", float), ("tau1", float), ("tau2", float)])
out = fmpy.simulate_fmu(str(arm), stop_time=2.0, step_size=1e-3, output_interval=1e-3,
                        input=step, output=["theta1", "theta2", "tip_defl1"])
fig, ax = plt.subplots(1, 2, figsize=(8, 3))
ax[0].plot(out["time"], out["theta1"], label="θ1")
ax[0].plot(out["time"], out["theta2"], label="θ2")
ax[0].set_xlabel("t [s]")
ax[0].set_ylabel("[rad]")
ax[0].legend()
ax[1].plot(out["time"], 1e3 * out["tip_defl1"])
ax[1].set_xlabel("t [s]")
ax[1].set_ylabel("tip deflection, link 1 [mm]")
fig.tight_layout()

# %%
# The FMU as the plant of a campaign: PBC + SMO at three payloads, set on the FMU by
# name (``parameters``) — the nominal arm follows, so that the FMU's modal basis is the
# laws'.
plant = {"kind": "fmu", "fmu": str(arm), "role": "reduced", "parameters": {"Mp": "Mp"}}
payloads = [0.0, 0.1, 0.2]
campaign = campaign_from_mapping({
    "name": "fmu", "scenario": {**paper, "duration": 2.0, "plant": plant},
    "sweep": [{"zip": {"true_params.Mp": payloads, "nominal_params.Mp": payloads}}]})
out = folder / "results"
summary = run_campaign(campaign, out, runner=make_runner("local", workers=2), progress=False)
print(summary.line(campaign.name, out))
rows = sorted(ResultStore(out).rows(), key=lambda row: row.axes["true_params.Mp"])
for row in rows:
    print(f"Mp = {row.axes['true_params.Mp']:.1f} kg: {row.status}, max |θ1 − θ1d| = "
          f"{1e3 * row.metrics['track_max_1']:.3f} mrad ({row.plant_label})")
