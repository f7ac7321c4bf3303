"""Cost of the exact inextensible kinematics against the paper's linear kinematics, side
by side in one process: kernel calls, a 20 s plant run, and 20 s closed loops (PBC + sign
SMO, compiled) with the laws and the plant on each model.

Targets (issue 45: "at the reduced plant's speed"): the reduced plant's own targets
(`bench_reduced_model.py`) met by the exact kinematics with 2+2 modes — rhs inside a
jitted loop ≤ 2 µs, a 20 s ReducedPlant run stepped from Python ≤ 0.1 s — and a 20 s
closed loop on the exact model ≤ 2 × the linear one's.  The closed loops' times are
this process's CPU time (`time.process_time`): on a shared machine wall time also counts
the others' work; the kernels and plant runs are timed as `bench_reduced_model.py` does.
"""
from __future__ import annotations

import time

import numpy as np

from _report import report, target
from bench_reduced_model import (_loop_coriolis, _loop_mass, _loop_rhs, in_jit_us,
                                 kernel_inputs, plant_run_seconds)
from reduced_model import ArmModel
from validation.run.loop import run_scenario
from validation.run.scenario import scenario_from_mapping

KINEMATICS = ("linear", "exact")


def closed_loop_seconds(kinematics: str, repeat=3) -> float:
    """Best CPU time of 20 s of the paper's loop (PBC + sign SMO, from the reference),
    plant and laws on the same kinematics (the compiled sample)."""
    s = scenario_from_mapping({"duration": 20.0, "initial_state": "reference",
                               "observer": {"kind": "smo-paper"},
                               "plant": {"kinematics": kinematics},
                               "model": {"kinematics": kinematics}})
    run_scenario(s)  # compile
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        result = run_scenario(s)
        best = min(best, time.process_time() - t0)
        assert result.status == "ok", result.message
    return best


def main():
    rows = []
    for modes in [(2, 2), (4, 4)]:
        label = f"{modes[0]}+{modes[1]}"
        for kinematics in KINEMATICS:
            model = ArmModel(modes_per_link=modes, kinematics=kinematics)
            Q, Qd, x, tau, xd, M, C, d, ws = kernel_inputs(model)
            row = {"modes": label, "kinematics": kinematics,
                   "mass_us": in_jit_us(_loop_mass, d, Q, M, ws, n=20_000),
                   "coriolis_us": in_jit_us(_loop_coriolis, d, Q, Qd, C, ws, n=20_000),
                   "rhs_us": in_jit_us(_loop_rhs, d, x, tau, xd, ws, n=20_000)}
            if modes == (2, 2):
                row |= target(row["rhs_us"], "<=", 2.0)
            rows.append(row)
    report("exact_kinematics_calls", rows,
           title="Kernels, linear vs exact kinematics (µs per call in a jitted loop, best of 5)",
           columns=["modes", "kinematics", "mass_us", "coriolis_us", "rhs_us", "target", "met"])

    runs = []
    for kinematics in KINEMATICS:
        seconds = plant_run_seconds(kinematics=kinematics)
        runs.append({"what": "20 s ReducedPlant run, step() from Python", "modes": "2+2",
                     "kinematics": kinematics, "seconds": seconds}
                    | target(seconds, "<=", 0.1))
    for kinematics in KINEMATICS:
        runs.append({"what": "20 s ReducedPlant run, step() from Python", "modes": "4+4",
                     "kinematics": kinematics,
                     "seconds": plant_run_seconds((4, 4), kinematics=kinematics)})
    loops = {k: closed_loop_seconds(k) for k in KINEMATICS}
    for kinematics, seconds in loops.items():
        row = {"what": "20 s closed loop PBC + SMO (compiled), plant and laws", "modes": "2+2",
               "kinematics": kinematics, "seconds": seconds}
        if kinematics == "exact":
            row |= target(seconds / loops["linear"], "<=", 2.0) | {
                "what": row["what"] + f" ({seconds / loops['linear']:.2f} x linear)"}
        runs.append(row)
    report("exact_kinematics_runs", runs, title="Runs, linear vs exact kinematics (best of repeats)",
           columns=["what", "modes", "kinematics", "seconds", "target", "met"])


if __name__ == "__main__":
    main()
