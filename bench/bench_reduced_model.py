"""Speed of the reduced model: kernel calls, a 20 s plant run, cold start.

Targets (issue 2): rhs inside a jitted loop ≤ 2 µs; 20 s ReducedPlant run at Ts = 1 ms
stepped from Python ≤ 0.1 s warm; cold start (import + compile from a warm cache) ≤ 2 s.
"""
from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
from numba import njit

from _report import report, target
from reduced_model import ArmModel, ReducedPlant
from reduced_model import _kernels as kern


@njit
def _loop_mass(d, Q, M, ws, n):
    for _ in range(n):
        kern.mass_matrix_into(d, Q, M, ws)


@njit
def _loop_coriolis(d, Q, Qd, C, ws, n):
    for _ in range(n):
        kern.coriolis_matrix_into(d, Q, Qd, C, ws)


@njit
def _loop_rhs(d, x, tau, xd, ws, n):
    for _ in range(n):
        kern.rhs_into(d, x, tau, xd, ws)


def per_call_us(fn, *args, repeat=5):
    """Best-of-``repeat`` µs per call; each repeat calls ``fn`` until ≥ 0.1 s has passed."""
    fn(*args)
    best = np.inf
    for _ in range(repeat):
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < 0.1:
            fn(*args)
            n += 1
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def in_jit_us(loop, *args, n=200_000, repeat=5):
    loop(*args, 10)
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        loop(*args, n)
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def plant_run_seconds(modes=(2, 2), repeat=5, kinematics="linear"):
    plant = ReducedPlant(modes_per_link=modes, kinematics=kinematics)
    tau = np.array([0.5, -0.2])
    plant.reset()
    plant.step(tau, 1e-3)  # JIT warm-up
    best = np.inf
    for _ in range(repeat):
        plant.reset()
        t0 = time.perf_counter()
        for _ in range(20_000):
            plant.step(tau, 1e-3)
        best = min(best, time.perf_counter() - t0)
    return best


COLD = ("import time; t0 = time.perf_counter(); import numpy as np; "
        "from reduced_model import ReducedPlant; p = ReducedPlant(); p.reset(); "
        "p.step(np.zeros(2), 1e-3); print(time.perf_counter() - t0)")


def cold_start_seconds(repeat=3):
    subprocess.run([sys.executable, "-c", COLD], check=True, capture_output=True)  # fill cache
    return min(float(subprocess.run([sys.executable, "-c", COLD], check=True,
                                    capture_output=True, text=True).stdout)
               for _ in range(repeat))


def kernel_inputs(model):
    """A state of ``model`` (slightly bent, moving) and the buffers its kernels fill:
    (Q, Qd, x, tau, xd, M, C, data, workspace)."""
    n = model.n
    rng = np.random.default_rng(0)
    Q = np.concatenate([[0.3, 0.7], rng.normal(0, 0.01, n - 2)])
    Qd = rng.normal(0, 1, n)
    x, tau, xd = np.concatenate([Q, Qd]), np.array([0.1, 0.2]), np.empty(2 * n)
    return Q, Qd, x, tau, xd, np.empty((n, n)), np.empty((n, n)), model.data, \
        model.new_workspace()[1]


def main():
    rows = []
    for modes in [(2, 2), (4, 4)]:
        model = ArmModel(modes_per_link=modes)
        Q, Qd, x, tau, xd, M, C, d, ws = kernel_inputs(model)
        label = f"{modes[0]}+{modes[1]}"
        rows += [
            {"what": "mass_matrix", "modes": label,
             "python_us": per_call_us(model.mass_matrix, Q),
             "jit_loop_us": in_jit_us(_loop_mass, d, Q, M, ws)},
            {"what": "coriolis_matrix", "modes": label,
             "python_us": per_call_us(model.coriolis_matrix, Q, Qd),
             "jit_loop_us": in_jit_us(_loop_coriolis, d, Q, Qd, C, ws)},
            {"what": "rhs", "modes": label, "python_us": per_call_us(model.rhs, x, tau),
             "jit_loop_us": in_jit_us(_loop_rhs, d, x, tau, xd, ws)},
        ]
    for r in rows:
        if r["what"] == "rhs":
            r |= target(r["jit_loop_us"], "<=", 2.0)
    report("reduced_model_calls", rows, title="Reduced model kernels (µs per call, best of 5)",
           columns=["what", "modes", "python_us", "jit_loop_us", "target", "met"])
    plant = plant_run_seconds()
    cold = cold_start_seconds()
    runs = [{"what": "20 s ReducedPlant run, Ts = h = 1 ms, step() from Python",
             "modes": "2+2", "seconds": plant} | target(plant, "<=", 0.1),
            {"what": "20 s ReducedPlant run, Ts = h = 1 ms, step() from Python",
             "modes": "4+4", "seconds": plant_run_seconds((4, 4))},
            {"what": "cold start: import + first step, warm numba cache",
             "modes": "2+2", "seconds": cold} | target(cold, "<=", 2.0)]
    report("reduced_model_runs", runs, title="Reduced plant runs (best of repeats)",
           columns=["what", "modes", "seconds", "target", "met"])


if __name__ == "__main__":
    main()
