"""The truth plant's zero-order hold, before (Exudyn's own: the new torque blended in over
the first step, first order) and after (`plant_exudyn`'s `ExactHold`: second order), side
by side in one process.

- **Accuracy**: the torques a closed loop applied, replayed on the truth plant at steps
  Ts, Ts/2, Ts/4 against Ts/64 (max |θ − θ_ref| over the run, rad) and the observed
  order.  Two loops: the issue's (3 s PBC + sign SMO, default arm, Ts = 1 ms, moving with
  the reference, a 1 N m pulse on joint 1) and a harsher one (5 s from rest, the observer
  0.1 rad off: large sign-observer chatter at the Nyquist frequency).
- **Cost**: replay time per solver step with and without the hold (interleaved medians
  of ``REPEATS``), and the real-time factor of a 20 s closed loop at the default step.

Targets (issue 31): error ≤ 2e-5 rad at the default step on the issue's loop, observed
order ≥ 1.8 over Ts, Ts/2, Ts/4, cost per step ≤ 1.3× without the hold.
"""
from __future__ import annotations

import math
import statistics
import sys

import numpy as np

from _report import report, target
from validation.run.loop import run_scenario
from validation.run.replay import bare_replay
from plant_exudyn import ExudynPlant
from validation.run.scenario import scenario_from_mapping

REPEATS = 5
TS = 1e-3
LOOPS = {
    "issue's loop (3 s, moving, pulse)": {
        "duration": 3.0, "initial_state": "reference", "observer": {"kind": "smo-paper"},
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3},
        "disturbances": [{"kind": "pulse", "target": "tau1", "amplitude": 1.0,
                          "start": 1.0, "duration": 0.1}]},
    "chattering loop (5 s from rest)": {
        "duration": 5.0, "observer": {"kind": "smo-paper",
                                      "initial_error": [0.1, 0.005, 0.3, 0.05]},
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}},
}


def scenario(loop: dict, step: float, duration: float | None = None):
    data = {**loop, "plant": {"kind": "exudyn", "step": step}}
    if duration is not None:
        data["duration"] = duration
    return scenario_from_mapping(data)


def applied_torques(loop: dict) -> np.ndarray:
    result = run_scenario(scenario(loop, TS / 2))
    return (result.select(["tau1", "tau2"]) + result.select(["dist_tau1", "dist_tau2"])).T


def accuracy_rows() -> list[dict]:
    rows = []
    default = ExudynPlant.Settings.step
    for name, loop in LOOPS.items():
        torques = applied_torques(loop)
        for exact in (False, True):
            theta = {d: bare_replay(scenario(loop, TS / d), torques, record=True,
                                    exact_hold=exact).theta for d in (1, 2, 4, 64)}
            errors = [float(np.abs(theta[d] - theta[64]).max()) for d in (1, 2, 4)]
            orders = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
            row = {"loop": name, "hold": "exact" if exact else "blended (before)",
                   "err_Ts": errors[0], "err_Ts/2": errors[1], "err_Ts/4": errors[2],
                   "order": min(orders)}
            if exact and name.startswith("issue"):
                at_default = errors[[TS, TS / 2, TS / 4].index(default)]
                row.update(target(at_default, "<=", 2e-5))
                row["note"] = f"default step {default * 1e3:g} ms: {at_default:.2g} rad"
            rows.append(row)
    return rows


def cost_rows(repeats: int) -> list[dict]:
    loop = LOOPS["issue's loop (3 s, moving, pulse)"]
    torques = applied_torques(loop)
    s = scenario(loop, TS)
    bare_replay(s, torques[:10])  # compile once
    seconds = {True: [], False: []}
    for _ in range(repeats):
        for exact in (False, True):
            seconds[exact].append(bare_replay(s, torques, exact_hold=exact).seconds)
    per_step = {k: 1e6 * statistics.median(v) / len(torques) for k, v in seconds.items()}
    ratio = per_step[True] / per_step[False]
    rows = [{"what": "replay per step, blended hold (before)", "us": per_step[False]},
            {"what": "replay per step, exact hold", "us": per_step[True], "ratio": ratio,
             **target(ratio, "<=", 1.3)}]
    for step in (TS, ExudynPlant.Settings.step):  # the closed loop holds exactly at both
        run = scenario(loop, step, duration=20.0)
        walls = [run_scenario(run).timings["wall_s"] for _ in range(max(1, repeats // 2))]
        rows.append({"what": f"20 s closed loop, step {step * 1e3:g} ms",
                     "s": statistics.median(walls), "realtime": 20.0 / statistics.median(walls)})
    return rows


def main(repeats: int = REPEATS, accuracy: bool = True) -> None:
    if accuracy:
        report("hold_accuracy", accuracy_rows(),
               title="Replay error against Ts/64 (max |theta - theta_ref|, rad), default "
                     "arm, ANCF 4 el/link, Ts = 1 ms",
               columns=["loop", "hold", "err_Ts", "err_Ts/2", "err_Ts/4", "order",
                        "target", "met", "note"])
    report("hold_cost", cost_rows(repeats),
           title=f"Cost of the exact hold, medians of {repeats} interleaved repeats",
           columns=["what", "us", "ratio", "target", "met", "s", "realtime"])


if __name__ == "__main__":  # bench_hold.py [REPEATS] [--cost-only]
    numbers = [a for a in sys.argv[1:] if a.isdigit()]
    main(int(numbers[0]) if numbers else REPEATS, accuracy="--cost-only" not in sys.argv)
