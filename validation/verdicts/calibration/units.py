"""Data in degrees refused before a calibration runs (``flexarm calibrate``; checked by
`plan_calibration`).

An angle recorded in degrees is 57.3 (180/π) times its value in radians.  Where the motion
is large the magnitude check of the experiment's reader catches it (an angle beyond the
divergence bound); where it is small (sines of 0.2 rad read 11.5 "rad") it does not,
and a fit would run for minutes and explain the factor by an absurd arm.  The torques
are in N m either way, so the arm itself tells: each experiment's recorded torques are
replayed open loop on the scenario at its starting values, and an angle or rate channel
whose measured range is within a factor `SPREAD` of 57.3 times the range the model
reaches is refused in one line, naming the file and the column.  A model at its starting
values is wrong by tens of per cent, not by a factor 19 (57.3 / `SPREAD`): measured on
the shipped experiments replayed from their owners' starts (EI 10 against 9.2-10.6 N m²,
a payload of 0.1 against 0.23 kg, friction 0.3/0.2 against 0.25/0.15), the ratio of the
measured to the simulated ranges of theta1 and theta2 lies in 0.86-1.19.  A channel whose
simulated range is within `NOISE_MARGIN` stated noise levels is not judged (the ratio of
two noise ranges says nothing of units).
"""
from __future__ import annotations

import math
import re

import numpy as np

from ...run.config import ConfigError
from ...run.loop import build, simulate
from ...run.scenario import scenario_from_mapping
from ...run.tomlfiles import deep_merge

__all__ = ["check_units", "DEGREE", "SPREAD"]

#: A degree's worth of radians, inverted: what an angle in degrees is multiplied by.
DEGREE = 180.0 / math.pi
#: Ratios of measured to simulated ranges within this factor of `DEGREE` are degrees.
SPREAD = 3.0
#: A simulated range below this many noise levels is not judged.
NOISE_MARGIN = 20.0
#: The channels that carry a joint angle (or its rate) [rad, rad/s]: theta1, theta2_dot, …
_ANGULAR = re.compile(r"theta\d+(_dot)?")
#: What the replay leaves out of the experiment's scenario: its own noise, laws and limits.
_OPEN_LOOP = {"observer": {"kind": "none", "options": {}, "initial_error": []},
              "feedback": "true", "disturbances": [], "torque_limit": 0.0, "requirement": [],
              "sensors": {"encoder_noise": 0.0, "modal_noise": 0.0, "rate_noise": 0.0}}


class _Replayed:
    """The recorded torques, row k held over [t_k, t_k+1) (`controllers.TorqueReplay`
    without its file: nothing is written before the check)."""

    name = "replay"

    def __init__(self, torques: np.ndarray, Ts: float) -> None:
        self.torques, self.Ts = torques, Ts

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        k = int(round(t / self.Ts))
        return self.torques[k].copy() if k < len(self.torques) else \
            np.full(self.torques.shape[1], np.nan)


def _simulated(target) -> dict[str, np.ndarray]:
    """Target's angular channels simulated at the start values, torques replayed."""
    scenario = scenario_from_mapping(deep_merge(target.scenario, _OPEN_LOOP))
    setup = build(scenario)
    exp = target.experiment
    result = simulate(setup.plant, _Replayed(np.asarray(exp.torques, dtype=float), exp.Ts),
                      None, scenario, reference=setup.reference, model=setup.model)
    done = len(result.time)
    return {name: result[name][:done] for name in exp.names
            if _ANGULAR.fullmatch(name) and name in result.names}


def check_units(targets) -> None:
    """ConfigError naming the file and column of an angle or rate recorded in degrees
    (module docstring); nothing is written.

    Parameters
    ----------
    targets : sequence of Target
        The experiments of a plan (`plan_calibration` checks them so).
    """
    for target in targets:
        exp = target.experiment
        if not any(_ANGULAR.fullmatch(name) for name in exp.names):
            continue
        simulated = _simulated(target)
        for i, name in enumerate(exp.names):
            if name not in simulated:
                continue
            sim = simulated[name]
            span = float(np.ptp(sim)) if sim.size else 0.0
            if not span > NOISE_MARGIN * max(float(target.noise[i]), 0.0) or span == 0.0:
                continue
            measured = float(np.ptp(exp.signals[i, :sim.size]))
            ratio = measured / span
            if DEGREE / SPREAD <= ratio <= DEGREE * SPREAD:
                unit = "rad/s" if name.endswith("_dot") else "rad"
                raise ConfigError(
                    exp.column(name),
                    f"in degrees? its range {measured:.4g} is {ratio:.3g} times the "
                    f"{span:.3g} {unit} the scenario's arm reaches replaying the file's "
                    f"torques, near 180/pi = 57.3: give it in {unit}")
