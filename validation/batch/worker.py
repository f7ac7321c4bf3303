"""What runs inside a worker: one scenario in, its result and metrics out, never an
exception (`execute_run`); and what a worker process needs before it runs anything: the
simulation code (models, plants, laws, the closed loop, metrics) loaded and its kernels
compiled — not the command line and not matplotlib.  `warm_up` compiles or loads the
kernels the runs need in the parent before the workers are forked, so numba compiles
(first use in a checkout) or loads (from its cache) each kernel once, not once per
worker."""
from __future__ import annotations

import ctypes
import functools
import signal
import sys

import numpy as np

from ..run import loop, metrics, requirements  # noqa: F401 - loaded once, before the fork
from ..run.results import RunResult

__all__ = ["execute_run", "failed_result", "keep_freed_memory", "worker_init", "warm_up",
           "kernel_groups", "compile_kernels"]


@functools.cache
def keep_freed_memory() -> None:
    """Have the C allocator keep freed blocks of up to 32 MiB for reuse (glibc; elsewhere
    nothing changes).  A run allocates its recording and copies of it (2.5 MB each for a
    5 s run); by default glibc maps such blocks fresh and unmaps them when freed, so
    every run pays its page faults again: ~3 ms of a 5 s reduced run's ~7 ms overhead
    (measured by timing `execute_run` over 48 runs).  Freed memory up to 128 MiB is kept
    (not trimmed): a worker's resident size stays at its largest run's."""
    if not sys.platform.startswith("linux"):
        return
    mallopt = getattr(ctypes.CDLL(None), "mallopt", None)  # the allocator of this process
    if mallopt is not None:  # glibc (musl has none)
        mallopt(-1, 128 << 20)  # M_TRIM_THRESHOLD
        mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD (glibc's largest on 64-bit)


def failed_result(scenario, exc: BaseException) -> tuple[RunResult, dict]:
    """The "failed" result of ``scenario`` (a `Scenario` or its mapping) that raised ``exc``."""
    from ..run.scenario import Scenario, scenario_to_mapping
    config = scenario_to_mapping(scenario) if isinstance(scenario, Scenario) else scenario
    text = str(exc).strip().splitlines()
    message = f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")
    return (RunResult(time=np.zeros(0), names=(), signals=np.zeros((0, 0)), status="failed",
                      message=message, config=config),
            {"status": "failed", "end_time": 0.0})


def execute_run(scenario) -> tuple[RunResult, dict]:
    """Run one scenario (in a worker; a checked `Scenario`, or a mapping to check): the
    result, with signals as float32 (what the store keeps; half the bytes to send back),
    and its metrics — with each requirement's robustness ``rho_<name>`` — computed from
    the float64 signals.  An unexpected exception becomes
    a "failed" result carrying its message, so one bad run never stops a campaign."""
    from ..run.loop import run_scenario
    from ..run.metrics import all_metrics
    from ..run.requirements import requirement_metrics
    from ..run.scenario import Scenario, scenario_from_mapping
    keep_freed_memory()
    try:
        if not isinstance(scenario, Scenario):
            scenario = scenario_from_mapping(scenario)
        result = run_scenario(scenario)
        metrics = all_metrics(result)
        metrics |= requirement_metrics(result, metrics)
    except Exception as exc:  # noqa: BLE001 - reported as the run's failure
        return failed_result(scenario, exc)
    result.signals = result.signals.astype(np.float32)
    return result, metrics


def worker_init() -> None:
    # The parent decides what a Ctrl-C means (stop, keep what finished, end the workers).
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def kernel_groups(scenarios) -> list[tuple[str, object]]:
    """The compiled code the runs of ``scenarios`` use, as (label, callable that compiles
    or loads it) in the order a run needs them: the arm model's kernels, each distinct
    law, the sample loop, the FE plant's readout.  Each piece is compiled once per
    checkout (numba's cache) and loaded in well under a second afterwards."""
    from controllers import compiled_form
    from reduced_model import ReducedPlant

    from ..run import _sample
    from ..run.laws import build_controller, build_observer, nominal_model

    def model_kernels():
        plant = ReducedPlant()
        plant.reset()
        plant.step([0.0, 0.0], plant.h)
        plant.truth_vector()

    groups, seen = [("arm model (M, C, RK4, kinematics)", model_kernels)], set()
    for s in scenarios:
        model = nominal_model(s.nominal_params, s.model.modes_per_link)
        for role, spec, build in (("controller", s.controller, build_controller),
                                  ("observer", s.observer, build_observer)):
            key = (role, spec.kind)
            if spec.kind == "none" or key in seen:
                continue
            seen.add(key)
            groups.append((f"{role} {spec.kind}", lambda b=build, s=s, m=model, r=role:
                           compiled_form(b(s, m), r, s.Ts)))
    groups.append(("sample loop", _sample.compile_sample_laws))
    plants = {s.plant.kind for s in scenarios}
    if "reduced" in plants:
        groups.append(("reduced-plant loop", _sample.compile_run_reduced))
    if "exudyn" in plants:
        def fe_readout():
            from plant_exudyn import ExudynPlant
            ExudynPlant().reset().values  # noqa: B018 - the readout compiles on first use
        groups.append(("FE plant readout", fe_readout))
    return groups


def compile_kernels(scenarios, *, report=None) -> float:
    """Compile or load every kernel the runs of ``scenarios`` use (`kernel_groups`),
    telling ``report`` (a callable taking a line) about each group that took more than
    half a second; returns the seconds spent."""
    import time
    total = 0.0
    for label, build in kernel_groups(scenarios):
        t0 = time.perf_counter()
        build()
        spent = time.perf_counter() - t0
        total += spent
        if report is not None and spent > 0.5:
            report(f"compiled {label} in {spent:.1f} s (once per checkout)")
    return total


def warm_up(scenarios=None) -> None:
    """Compile or load every kernel the runs of ``scenarios`` use (default: the PBC with
    the paper's SMO on both plants), here in the parent before the workers fork."""
    from ..run.scenario import scenario_from_mapping
    if scenarios is None:
        scenarios = [scenario_from_mapping({"plant": {"kind": plant},
                                            "observer": {"kind": "smo-paper"}})
                     for plant in ("reduced", "exudyn")]
    compile_kernels(scenarios)
