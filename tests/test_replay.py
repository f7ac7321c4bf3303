"""The truth plant's closed loop adds time, never physics: θ at every sample of a
closed-loop Exudyn run equals Exudyn alone replaying the torques the plant received
(`validation.run.replay.bare_replay`, also the floor `bench/bench_truth_loop.py` times)."""
import numpy as np
import pytest

from validation.run.loop import run_scenario
from validation.run.replay import bare_replay
from validation.run.scenario import scenario_from_mapping

# 1 s of the paper's loop (PBC + sign SMO, noisy sensors) with a torque pulse at 0.5 s:
# the laws, the noise and the disturbance all shape the torques the plant receives.
SCENARIO = {"plant": {"kind": "exudyn"}, "duration": 1.0, "transient": 0.2,
            "observer": {"kind": "smo-paper"},
            "disturbances": [{"kind": "pulse", "target": "tau1", "amplitude": 1.0,
                              "start": 0.5, "duration": 0.1}]}


@pytest.fixture(scope="module")
def closed_loop():
    s = scenario_from_mapping(SCENARIO)
    result = run_scenario(s)
    assert result.status == "ok", result.message
    return s, result


def test_the_closed_loop_equals_exudyn_replaying_its_torques(closed_loop):
    s, result = closed_loop
    applied = (result.select(["tau1", "tau2"]) + result.select(["dist_tau1", "dist_tau2"])).T
    replay = bare_replay(s, applied, record=True)
    # Bit for bit: the same loads in the same order through the same solver calls.
    np.testing.assert_array_equal(replay.theta, result.select(["theta1", "theta2"]).T)


def test_a_replay_of_other_torques_differs(closed_loop):
    """Known bad: the commanded torques without the pulse are not what the plant got;
    the comparison above sees the difference."""
    s, result = closed_loop
    commanded = result.select(["tau1", "tau2"]).T
    replay = bare_replay(s, commanded, record=True)
    after_pulse = result.time > 0.5 + s.Ts
    gap = np.abs(replay.theta[after_pulse] - result.select(["theta1", "theta2"]).T[after_pulse])
    # A 1 N m pulse for 0.1 s moves θ1 by milliradians: far beyond rounding.
    assert gap.max() > 1e-4
