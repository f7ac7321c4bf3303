"""The truth plant's closed loop against Exudyn's own step, side by side in one process.

Three ways to spend the same 20 s of the paper's scenario (default arm, ANCF 4 el/link,
PBC + smo-paper with the campaigns' noise and initial observer error), interleaved,
medians of ``REPEATS``:

- **closed loop**: `run_scenario` (per 1 ms sample: the truth readout, one compiled
  sample with the laws, three `SetLoadParameter`, one `SolveSteps`);
- **replay (floor)**: a bare plant replaying the torque sequence the closed loop applied
  (`SetLoadParameter` ×3 + `SolveSteps` per period, nothing else) — the same solver work,
  checked by its final state equalling the closed loop's;
- **single solve**: one `SolveDynamic` replaying the same torques from a pre-step user
  function (the alternative to a `SolveSteps` per period), with its Newton iterations.

Target (issue 24): closed loop ≤ 1.15 × replay.  A load user function reading a buffer
would cost a Python call per load per residual evaluation; `SetLoadParameter` (≈1 µs) is
the cheapest way Exudyn offers to change a load, timed here too.
"""
from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from _report import report, target
from validation.run.loop import run_scenario
from validation.run.replay import bare_replay, fresh_plant, truth_now
from validation.run.scenario import scenario_from_mapping

REPEATS = 5
SCENARIO = {"plant": {"kind": "exudyn"}, "duration": 20.0,
            "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3},
            "observer": {"kind": "smo-paper", "initial_error": [0.1, 5e-3, 0.3, 0.05]}}


def single_solve(s, torques: np.ndarray) -> tuple[float, np.ndarray, float]:
    """(seconds, final truth, Newton iterations per step) of one SolveDynamic whose
    pre-step function sets the next period's torques."""
    import exudyn as exu
    plant = fresh_plant(s)
    mbs = plant.system.mbs
    l1, l2, l2r = plant.system.loads
    h, steps = plant.h, torques.shape[0]

    def pre_step(mbs_, t):  # Exudyn passes the step's end time
        k = min(int(round(t / h)) - 1, steps - 1)
        t1, t2 = float(torques[k, 0]), float(torques[k, 1])
        mbs_.SetLoadParameter(l1, "loadVector", [0.0, 0.0, t1])
        mbs_.SetLoadParameter(l2, "loadVector", [0.0, 0.0, t2])
        mbs_.SetLoadParameter(l2r, "loadVector", [0.0, 0.0, -t2])
        return True

    mbs.SetPreStepUserFunction(pre_step)
    settings = plant.settings
    settings.timeIntegration.endTime = steps * h
    settings.timeIntegration.numberOfSteps = steps
    solver = exu.MainSolverImplicitSecondOrder()
    t0 = time.perf_counter()
    solver.SolveSystem(mbs, settings)
    seconds = time.perf_counter() - t0
    return seconds, truth_now(plant), solver.it.newtonStepsCount / steps


def main(repeats: int = REPEATS) -> None:
    s = scenario_from_mapping(SCENARIO)
    run_scenario(scenario_from_mapping({**SCENARIO, "duration": 0.01, "transient": 0.0}))
    loop_s, replay_s, single_s, newton = [], [], [], {}
    for _ in range(repeats):
        result = run_scenario(s)
        torques = (result.select(["tau1", "tau2"]) + result.select(["dist_tau1", "dist_tau2"])).T
        loop_s.append(result.timings["wall_s"])
        floor = bare_replay(s, torques)
        replay_s.append(floor.seconds)
        truth, newton["replay"] = floor.truth, floor.newton_per_step
        gap = np.abs(floor.theta[0] - result.select(["theta1", "theta2"])[:, -1]).max()
        seconds, truth_single, newton["single solve"] = single_solve(s, torques)
        single_s.append(seconds)
        single_gap = np.abs(truth_single[:2] - truth[:2]).max()
    steps = torques.shape[0]
    ratio = statistics.median(a / b for a, b in zip(loop_s, replay_s))
    rows = [
        {"what": "closed loop (PBC + smo-paper)", "s": statistics.median(loop_s),
         "us_per_step": 1e6 * statistics.median(loop_s) / steps, "vs_replay": ratio,
         **target(ratio, "<=", 1.15)},
        {"what": "replay: SetLoadParameter x3 + SolveSteps", "s": statistics.median(replay_s),
         "us_per_step": 1e6 * statistics.median(replay_s) / steps, "vs_replay": 1.0,
         "newton_per_step": newton["replay"],
         "note": f"final theta equals the closed loop's to {gap:.1e} rad"},
        {"what": "one SolveDynamic, pre-step replay", "s": statistics.median(single_s),
         "us_per_step": 1e6 * statistics.median(single_s) / steps,
         "vs_replay": statistics.median(a / b for a, b in zip(single_s, replay_s)),
         "newton_per_step": newton["single solve"],
         "note": f"final theta differs from the replay by {single_gap:.1e} rad"},
    ]
    report("truth_loop", rows, title=f"Truth plant, 20 s, Ts = 1 ms, ANCF 4 el/link, "
                                     f"medians of {repeats} interleaved repeats",
           columns=["what", "s", "us_per_step", "vs_replay", "target", "met",
                    "newton_per_step", "note"])


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else REPEATS)
