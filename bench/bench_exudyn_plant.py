"""Speed of the Exudyn truth plant: 20 s of the paper's reference under a joint PD at 1 kHz.

Targets (issue 3): ANCF at the default mesh (4 el/link) ≥ 8× real time; each doubling of
elements costs ≤ 1.6× time.  Each configuration runs in its own process so that its peak
memory (max RSS) is its own.
"""
from __future__ import annotations

import json
import resource
import subprocess
import sys
import time

import numpy as np

from _report import report, target

SECONDS, TS = 20.0, 1e-3
CONFIGS = [("ancf", 4), ("ancf", 8), ("ancf", 16), ("geometrically_exact", 16)]


def run_one(element: str, n_el: int) -> dict:
    from controllers import JointPD, PaperReference
    from plant_exudyn import ExudynPlant, Mesh

    plant = ExudynPlant(mesh=Mesh(element=element, elements_per_link=(n_el, n_el)))
    from reduced_model import ArmModel
    pd, ref = JointPD(ArmModel(), Ts=1e-3), PaperReference()
    plant.reset()
    steps = int(round(SECONDS / TS))
    t_plant = t_truth = 0.0
    t0 = time.perf_counter()
    for k in range(steps):
        a = time.perf_counter()
        truth = plant.truth()
        b = time.perf_counter()
        plant.step(pd(k * TS, truth.x, ref), TS)
        t_truth += b - a
        t_plant += time.perf_counter() - b
    wall = time.perf_counter() - t0
    err = np.abs(ref(SECONDS - TS)[0] - plant.truth().theta).max()
    return {"element": element, "el_per_link": n_el, "wall_s": wall, "realtime_x": SECONDS / wall,
            "step_us": t_plant / steps * 1e6, "truth_us": t_truth / steps * 1e6,
            "peak_rss_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "final_err_rad": float(err)}


def main():
    rows = []
    for element, n_el in CONFIGS:
        out = subprocess.run([sys.executable, __file__, "--one", element, str(n_el)],
                             check=True, capture_output=True, text=True).stdout
        rows.append(json.loads(out.strip().splitlines()[-1]))
    ancf = [r for r in rows if r["element"] == "ancf"]
    for prev, row in zip(ancf, ancf[1:]):
        row["x_per_doubling"] = row["wall_s"] / prev["wall_s"]
    rows[0] |= target(rows[0]["realtime_x"], ">=", 8.0)
    for r in ancf[1:]:
        r |= target(r["x_per_doubling"], "<=", 1.6)
    report("exudyn_plant", rows,
           title=f"Exudyn plant: {SECONDS:g} s paper reference, joint PD at {1 / TS:g} Hz",
           columns=["element", "el_per_link", "wall_s", "realtime_x", "x_per_doubling",
                    "target", "met", "step_us", "truth_us", "peak_rss_MB", "final_err_rad"])


if __name__ == "__main__":
    if sys.argv[1:2] == ["--one"]:
        print(json.dumps(run_one(sys.argv[2], int(sys.argv[3]))))
    else:
        main()
