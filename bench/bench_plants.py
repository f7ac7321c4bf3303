"""What the plants' physics costs, side by side in one process: a 5 s closed loop (PBC +
sign SMO from the reference, the campaigns' sensor noise) on the reduced plant with the
paper's kinematics, with exact kinematics, with the lab arm's joint friction, with its
drives and current loops, and with every joint effect against the same arm's ideal
joints, and on the truth plant (Exudyn) with and without the lab arm's joints.

Each row is the best of ``REPEATS`` runs, interleaved (a load drift hits every row
alike), timed from the second sample to the last (``wall_s − startup_s``: kernel
loading and the scenario's set-up excluded).  On a shared machine read the ratios.

Targets (issue 61): exact kinematics ≤ 1.5 × the paper's kinematics; the lab arm with
every joint effect ≤ 1.2 × its ideal joints, on the reduced plant and on the truth plant.

    python bench/bench_plants.py [REPEATS] [--reduced-only]
"""
from __future__ import annotations

import sys

import numpy as np

from _report import report, target
from reduced_model import named_arm
from validation.run.loop import run_scenario
from validation.run.scenario import scenario_from_mapping

REPEATS = 3
LOOP = {"duration": 5.0, "initial_state": "reference", "observer": {"kind": "smo-paper"},
        "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}}
_LAB = named_arm("lab")
_FRICTION = ("coulomb", "breakaway", "stribeck_velocity", "viscous")
_DRIVES = ("gear_stiffness", "gear_damping", "rotor_inertia", "backlash",
           "torque_time_constant")


def _joints(fields, lab: bool = True) -> dict:
    """The lab arm's values of the joint ``fields`` (``lab`` False: zero, ideal)."""
    return {f"{n}{i}": getattr(_LAB, f"{n}{i}") if lab else 0.0 for i in (1, 2)
            for n in fields}


_IDEAL_LAB = {"arm": "lab", "true_params": _joints(_FRICTION + _DRIVES, lab=False)}
#: name: (scenario keys beyond `LOOP`, the row it is compared with, target ratio or None)
ROWS = {
    "reduced, paper's kinematics": ({}, None, None),
    "reduced, exact kinematics": ({"plant": {"kind": "reduced", "kinematics": "exact"}},
                                  "reduced, paper's kinematics", 1.5),
    "reduced + joint friction": ({"true_params": _joints(_FRICTION)},
                                 "reduced, paper's kinematics", None),
    "reduced + drives and current loops": ({"true_params": _joints(_DRIVES)},
                                           "reduced, paper's kinematics", None),
    "reduced, lab arm, ideal joints": (_IDEAL_LAB, None, None),
    "reduced, lab arm, every joint effect": ({"arm": "lab"},
                                             "reduced, lab arm, ideal joints", 1.2),
    "truth": ({"plant": {"kind": "exudyn"}}, None, None),
    "truth, lab arm, ideal joints": (_IDEAL_LAB | {"plant": {"kind": "exudyn"}}, None, None),
    "truth, lab arm, friction + drives + current loops": (
        {"arm": "lab", "plant": {"kind": "exudyn"}}, "truth, lab arm, ideal joints", 1.2),
}


def loop_seconds(names: list[str], repeats: int) -> dict[str, float]:
    """Best loop time of each row's 5 s closed loop, the rows interleaved."""
    scenarios = {name: scenario_from_mapping(LOOP | ROWS[name][0]) for name in names}
    best = dict.fromkeys(names, np.inf)
    for _ in range(repeats):
        for name, scenario in scenarios.items():
            result = run_scenario(scenario)
            assert result.status == "ok", f"{name}: {result.message}"
            t = result.timings
            best[name] = min(best[name], t["wall_s"] - t["startup_s"])
    return best


def main(repeats: int = REPEATS, truth: bool = True) -> None:
    names = [n for n in ROWS if truth or not n.startswith("truth")]
    for name in names:  # compile and load every kernel before timing any
        run_scenario(scenario_from_mapping(LOOP | ROWS[name][0] | {"duration": 0.01}))
    seconds = loop_seconds(names, repeats)
    rows = []
    for name in names:
        _, against, bound = ROWS[name]
        row = {"plant": name, "s": seconds[name], "realtime": LOOP["duration"] / seconds[name]}
        if against is not None:
            row |= {"ratio": seconds[name] / seconds[against], "against": against}
            if bound is not None:
                row |= target(row["ratio"], "<=", bound)
        rows.append(row)
    report("plants", rows, title=f"5 s closed loop (PBC + smo-paper), best of {repeats} "
                                 "interleaved runs, loop time (startup excluded)",
           columns=["plant", "s", "ratio", "against", "target", "met", "realtime"])


if __name__ == "__main__":
    numbers = [a for a in sys.argv[1:] if a.isdigit()]
    main(int(numbers[0]) if numbers else REPEATS, truth="--reduced-only" not in sys.argv)
