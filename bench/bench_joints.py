"""How accurately the truth plant holds the torque with the arm's joints (issue 41:
friction with stiction, drives, current loops) on, against the reduced plant (what the
joints cost: `bench_plants.py`).

- **ZOH replay order with friction**: the torques of a 5 s closed loop on the arm with the
  lab arm's friction (no drive), replayed on the truth plant at steps Ts, Ts/2, Ts/4
  against Ts/64: max |θ − θ_ref| before the first stick–slip transition of the reference
  run (a joint's velocity through zero) and over the whole run, and the observed orders.
- **Stiction band** (issue 59): with the lab arm's friction, a constant torque of
  ``BAND`` × breakaway on one joint for 5 s from rest, each plant at its default step: how
  far the joint moves.  Target: the truth plant holds (≤ 1e-6 rad) wherever the reduced
  plant's exact stick does, and slides wherever it slides.
"""
from __future__ import annotations

import math

import numpy as np

from _report import report, target
from plant_exudyn import ExudynPlant
from reduced_model import ArmParameters, ReducedPlant, named_arm
from validation.run.loop import run_scenario
from validation.run.replay import bare_replay
from validation.run.scenario import scenario_from_mapping

TS = 1e-3
BAND = (0.99, 0.998, 0.999, 0.9999, 0.99999, 1.00001, 1.0001, 1.01)
LOOP = {"duration": 5.0, "initial_state": "reference", "observer": {"kind": "smo-paper"},
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}}
_LAB = named_arm("lab")
_FRICTION = {f"{n}{i}": getattr(_LAB, f"{n}{i}") for i in (1, 2)
             for n in ("coulomb", "breakaway", "stribeck_velocity", "viscous")}


def scenario(extra: dict, kind: str, step: float | None = None):
    plant = {"kind": kind} if step is None else {"kind": kind, "step": step}
    return scenario_from_mapping(LOOP | extra | {"plant": plant})


def order_rows() -> list[dict]:
    extra = {"true_params": _FRICTION}
    result = run_scenario(scenario(extra, "exudyn", TS / 2))
    torques = (result.select(["tau1", "tau2"]) + result.select(["dist_tau1", "dist_tau2"])).T
    theta = {d: bare_replay(scenario(extra, "exudyn", TS / d), torques, record=True).theta
             for d in (1, 2, 4, 64)}
    rate = np.diff(theta[64], axis=0)
    turns = np.nonzero(np.any(rate[1:] * rate[:-1] <= 0, axis=1))[0]
    first = int(turns[0]) if len(turns) else len(rate)
    rows = []
    for label, stop in ((f"before the first stick-slip ({first * TS:.3g} s)", first),
                        ("whole run", len(rate) + 1)):
        errors = [float(np.abs(theta[d][:stop] - theta[64][:stop]).max()) for d in (1, 2, 4)]
        orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
        row = {"window": label, "err_Ts": errors[0], "err_Ts/2": errors[1],
               "err_Ts/4": errors[2], "order": min(orders)}
        if stop == first:
            row.update(target(min(orders), ">=", 1.8))
        rows.append(row)
    rows.append({"window": f"stick-slip transitions in the reference run: {len(turns)}"})
    return rows


def band_rows() -> list[dict]:
    params = ArmParameters(**_FRICTION)
    rows = []
    for joint in (1, 2):
        for fraction in BAND:
            torque = np.zeros(2)
            torque[joint - 1] = fraction * params.joints[joint - 1].static_friction
            moved = {}
            for kind, plant in (("reduced", ReducedPlant(params)),
                                ("truth", ExudynPlant(params))):
                plant.reset()
                start = plant.truth_vector()[joint - 1]
                largest = 0.0
                for _ in range(int(round(5.0 / TS))):
                    plant.advance(torque, TS)
                    largest = max(largest, abs(plant.truth_vector()[joint - 1] - start))
                moved[kind] = largest
            holds = {kind: value <= 1e-6 for kind, value in moved.items()}
            rows.append({"joint": joint, "x breakaway": f"{fraction:g}",
                         "reduced (rad)": moved["reduced"], "truth (rad)": moved["truth"],
                         "target": "as reduced",
                         "met": "yes" if holds["truth"] == holds["reduced"] else "MISSED"})
    return rows


def main() -> None:
    report("joints_hold_order", order_rows(),
           title="Replay error with the lab arm's friction against Ts/64 (max |theta - "
                 "theta_ref|, rad), truth plant ANCF 4 el/link, Ts = 1 ms",
           columns=["window", "err_Ts", "err_Ts/2", "err_Ts/4", "order", "target", "met"])
    report("joints_stiction_band", band_rows(),
           title="Largest joint motion in 5 s under a constant torque near breakaway, "
                 "lab arm's friction, default steps",
           columns=["joint", "x breakaway", "reduced (rad)", "truth (rad)", "target", "met"])


if __name__ == "__main__":
    main()
