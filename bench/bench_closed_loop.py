"""Speed of the closed loop: the paper's scenario, 20 s, PBC + SMO, on both plants.

Targets (issue 4): reduced plant ≤ 0.3 s warm; Exudyn plant (default mesh) ≥ 5× real
time; controller + observer ≤ 20 µs per control step from Python.
"""
from __future__ import annotations

import time

import numpy as np

from _report import report
from controllers import PaperReference, PassivityBasedController, SlidingModeObserver
from reduced_model import ArmModel
from validation.loop import run_scenario
from validation.scenario import scenario_from_mapping


def per_step_controller_observer_us(variant: str, n: int = 20000) -> float:
    model, ref = ArmModel(), PaperReference()
    pbc, obs = PassivityBasedController(model), SlidingModeObserver(model, variant)
    x = np.concatenate([[0.3, 0.7], np.full(4, 1e-3), np.full(6, 0.1)])
    y = x if variant != "position_only" else x[:6]
    obs.reset(x)
    tau = pbc(0.0, x, ref)
    obs.update(0.0, y, tau, 1e-3)
    t0 = time.perf_counter()
    for k in range(n):
        x_hat = obs.update(k * 1e-3, y, tau, 1e-3)
        tau = pbc(k * 1e-3, x_hat, ref)
    return (time.perf_counter() - t0) / n * 1e6


def main():
    rows = []
    for plant in ("reduced", "exudyn"):
        for observer in ("none", "smo-paper", "smo-bl", "smo-pos"):
            scenario = scenario_from_mapping({"plant": {"kind": plant},
                                              "observer": {"kind": observer}})
            if plant == "reduced":
                run_scenario(scenario_from_mapping({"duration": 0.01,
                                                    "observer": {"kind": observer}}))  # JIT
            best = min((run_scenario(scenario) for _ in range(3 if plant == "reduced" else 1)),
                       key=lambda r: r.timings["wall_s"])
            t = best.timings
            rows.append({"plant": plant, "observer": observer, "status": best.status,
                         "wall_s": t["wall_s"], "realtime_x": t["realtime_factor"],
                         "plant_s": t["plant_s"], "controller_s": t["controller_s"],
                         "observer_s": t["observer_s"], "loop_s": t["loop_s"],
                         "target": "<= 0.3 s" if plant == "reduced" else ">= 5x"})
    report("closed_loop", rows, title="Paper scenario, 20 s, PBC (+ SMO), Ts = 1 ms",
           columns=["plant", "observer", "status", "wall_s", "realtime_x", "target", "plant_s",
                    "controller_s", "observer_s", "loop_s"])
    costs = [{"observer": v, "pbc_plus_observer_us": per_step_controller_observer_us(v),
              "target_us": 20.0} for v in ("paper", "boundary_layer", "position_only")]
    report("controller_observer_step", costs, title="PBC + SMO per control step from Python",
           columns=["observer", "pbc_plus_observer_us", "target_us"])


if __name__ == "__main__":
    main()
