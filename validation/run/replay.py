"""The truth plant's floor: Exudyn alone replaying the torques a closed loop applied.

`bare_replay` starts the Exudyn plant of a scenario where the closed loop starts it and,
for each control period, holds the joint torques (`ExudynPlant.hold_loads`: the loads
and the exact zero-order hold) and calls `SolveSteps`: nothing else (no law, no readout, no recording unless asked).  It is what
a truth-plant run costs at least (``bench/bench_truth_loop.py`` times the closed loop
against it) and what the closed loop must reproduce exactly: the loop adds time, never
physics (tested on θ at every sample).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from reduced_model import check_sample_time

from .loop import build, initial_state, plant_state
from .scenario import Scenario

__all__ = ["Replay", "fresh_plant", "truth_now", "bare_replay"]


@dataclass
class Replay:
    """What `bare_replay` measured."""
    theta: np.ndarray  #: (periods, N): θ at the start of each period (``record``) or of the last
    truth: np.ndarray  #: the truth vector at the end
    seconds: float  #: wall time of the periods (loads and solves)
    newton_per_step: float  #: Newton iterations per solver step


def fresh_plant(scenario: Scenario):
    """The plant of ``scenario`` reset to the closed loop's initial state: one that holds
    its loads and solves in steps it can be asked for (`ExudynPlant`: ``hold_loads``,
    ``solver``)."""
    setup = build(scenario)
    if not hasattr(setup.plant, "hold_loads"):
        raise ValueError(f"a bare replay needs a plant with its own solver to replay on; "
                         f"plant.kind is {scenario.plant.kind!r}")
    setup.plant.reset(plant_state(initial_state(scenario, setup.model), setup.plant,
                                  setup.model))
    return setup.plant


def truth_now(plant) -> np.ndarray:
    """The plant's truth vector read now (not the copy it keeps for its last step)."""
    out = np.empty(plant.truth_size)
    plant.truth_into(out)
    return out


def bare_replay(scenario: Scenario, torques: np.ndarray, *, record: bool = False,
                exact_hold: bool = True) -> Replay:
    """Apply ``torques`` (periods, N) [N m] — what the plant received, disturbances
    included — one per control period of ``scenario`` to its fresh Exudyn plant.
    ``record``: read θ at the start of every period (costs a readout per period; off,
    only at the start of the last one, as the floor should be timed).  ``exact_hold``
    False replays with Exudyn's own first-order treatment of the torque jumps (what
    ``bench/bench_hold.py`` measures the exact hold against)."""
    p = scenario.true_params
    if any(j.torque_time_constant > 0 for j in p.joints):
        raise ValueError("a bare replay holds each period's torque as it is; an arm with "
                         "current-loop lags needs the plant's own advance")
    plant = fresh_plant(scenario)
    if not exact_hold:
        plant.hold = None
    mbs, solver, settings = plant.system.mbs, plant.solver, plant.settings
    hold_loads = plant.hold_loads
    steps_per_period = check_sample_time(scenario.Ts, plant.h)
    periods, N = torques.shape[0], plant.n_joints
    if torques.shape != (periods, N):
        raise ValueError(f"torques must be (periods, {N}), one per joint, got {torques.shape}")
    theta = np.empty((periods if record else 1, N))
    started = time.perf_counter()
    for k in range(periods):
        if record or k == periods - 1:
            theta[k if record else 0] = truth_now(plant)[:N]
        hold_loads([float(t) for t in torques[k]])
        solver.it.endTime = (k + 1) * steps_per_period * plant.h
        if not solver.SolveSteps(mbs, settings):
            raise RuntimeError(f"the bare replay's solver failed in period {k}")
    seconds = time.perf_counter() - started
    return Replay(theta, truth_now(plant), seconds,
                  solver.it.newtonStepsCount / (periods * steps_per_period))
