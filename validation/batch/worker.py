"""What runs inside a worker: one scenario in, its result and metrics out, never an
exception (`execute_run`); how a worker process starts (`worker_init`; its loop, which
also stores the run, is `validation.batch.store.writing.serve`); and what a worker
needs before it runs anything: the simulation code (models, plants, laws, the closed
loop, metrics) loaded and its kernels compiled — not the command line and not
matplotlib.  `warm_up` compiles or loads the kernels the runs need in the parent before
the workers are forked, so numba compiles (first use in a checkout) or loads (from its
cache) each kernel once, not once per worker."""
from __future__ import annotations

import ctypes
import functools
import signal
import sys
import time

import numpy as np

from ..run import loop, metrics, requirements  # noqa: F401 - loaded once, before the fork
from ..run.results import RunResult
from ..run.tracebacks import own_frames
from .interrupts import Interrupted

__all__ = ["OVER_MEMORY", "execute_run", "load_run_libraries", "failed_result",
           "keep_freed_memory", "worker_init", "warm_up", "kernel_groups", "describe"]

#: The memory limit this process runs under [MiB] (set by `worker_init`; None: none).
_memory_limit: int | None = None


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


def failed_result(scenario, exc: BaseException | str,
                  traceback: str = "") -> tuple[RunResult, dict]:
    """The "failed" result of ``scenario`` (a `Scenario` or its mapping) that raised
    ``exc`` (or ended as the message ``exc`` says), with the frames of its plug-ins' code
    where it raised (``traceback``, `RunResult.traceback`)."""
    from ..run.scenario import Scenario, scenario_to_mapping
    config = scenario_to_mapping(scenario) if isinstance(scenario, Scenario) else scenario
    message = exc if isinstance(exc, str) else describe(exc)
    return (RunResult(time=np.zeros(0), names=(), signals=np.zeros((0, 0)), status="failed",
                      message=message, config=config, traceback=traceback),
            {"status": "failed", "end_time": 0.0})


def describe(exc: BaseException) -> str:
    """One line saying what ``exc`` means for a run."""
    from ..run.config import short_repr, short_str
    if isinstance(exc, SystemExit):
        return f"the run called sys.exit({short_repr(exc.code)})"
    if isinstance(exc, KeyboardInterrupt):  # workers ignore SIGINT: raised by the code
        return "KeyboardInterrupt raised during the run (not a Ctrl-C)"
    return short_str(exc)


#: How the message of a run that reached its worker's memory limit begins.
OVER_MEMORY = "exceeded the memory limit of"


def _over_memory(message: str) -> str:
    """``message`` of a run that ran out of memory, saying which limit it exceeded."""
    if _memory_limit is None or "MemoryError" not in message:
        return message
    return f"{OVER_MEMORY} {_memory_limit} MiB ({message})"


def execute_run(scenario, *, float32: bool = True) -> tuple[RunResult, dict]:
    """Run one scenario (in a worker; a checked `Scenario`, or a mapping to check): the
    result, with signals as float32 (what the store keeps; half the bytes to send back;
    float64 if not ``float32``: for an in-memory store),
    and its metrics — with each requirement's robustness ``rho_<name>`` — computed
    from the float64 signals.  Whatever the run raises —
    including `SystemExit` and `KeyboardInterrupt` from a law — becomes a "failed"
    result carrying its message, so one bad run never stops a campaign; a run out of
    memory says which limit it exceeded."""
    from ..run.loop import run_scenario
    from ..run.metrics import all_metrics
    from ..run.requirements import requirement_metrics
    from ..run.scenario import Scenario, scenario_from_mapping
    keep_freed_memory()
    started = time.perf_counter()
    try:
        if not isinstance(scenario, Scenario):
            scenario = scenario_from_mapping(scenario)
        result = run_scenario(scenario)
        # A diverged run's last samples may be huge: their squares overflow to inf and
        # beyond float32 they are stored as inf, as they should; no warning to print.
        with np.errstate(over="ignore", invalid="ignore"):
            metrics = all_metrics(result)
            metrics |= requirement_metrics(result, metrics)
            if float32:
                result.signals = result.signals.astype(np.float32)
    except Interrupted:  # a Ctrl-C to this process (a serial runner): not the run's
        raise
    except (Exception, SystemExit, KeyboardInterrupt) as exc:  # noqa: BLE001 - the run's failure
        where, frames = own_frames(exc, _plugin_modules(scenario))
        return failed_result(scenario, _over_memory(
            f"{describe(exc)}, {time.perf_counter() - started:.3g} s after the run started"
            f" ({where})"), frames)
    if result.status == "failed":
        result.message = _over_memory(result.message)
    return result, metrics


def _plugin_modules(scenario) -> list[str]:
    """The modules of the plug-ins ``scenario`` (a `Scenario` or its mapping) names."""
    from ..run.scenario import Scenario, scenario_to_mapping
    from .fingerprint import plugin_kinds
    mapping = scenario_to_mapping(scenario) if isinstance(scenario, Scenario) else scenario
    return [kind.partition(":")[0] for kind in plugin_kinds(mapping)]


def worker_init(parent: int, memory_mib: int | None) -> None:
    """Prepare a worker process forked by ``parent``: it ignores Ctrl-C (the parent
    decides what a Ctrl-C means: stop, keep what finished, end the workers), dies with
    its parent, and runs under a memory limit of ``memory_mib`` MiB (None: none)."""
    global _memory_limit
    from ..run.processes import (contain_checks, die_with_parent, lead_process_group,
                                 release_signals)
    from .limits import limit_memory
    lead_process_group()  # killed with what a plug-in starts (`executor`)
    contain_checks(None)  # a run's faults are contained by this process already
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    release_signals()  # held while it was started (`executor`)
    die_with_parent(parent)
    if memory_mib is not None:
        limit_memory(memory_mib)
        _memory_limit = memory_mib


def kernel_groups(scenarios) -> list[tuple[str, object]]:
    """The compiled code the runs of ``scenarios`` use, as (label, callable that compiles
    or loads it) in the order a run needs them: the reduced plant's kernel of each
    kinematics and joints a run steps, each distinct built-in law on each kinematics of
    its model, the closed loop on each built-in plant (the sample kernels, the FE plant's
    readout).  Each piece is compiled once per checkout (numba's cache) and loaded in well
    under a second afterwards.  A plug-in's own code and an FMU plant (whose import or
    instantiation may exit, crash or hang) are left to their runs; what a plug-in run
    uses of the project — the built-in laws beside it, the reduced model's kernels a
    plug-in plant built on `ReducedPlant` steps with — is compiled here, so a run's time
    limit counts simulation, not compilation."""
    from controllers import compiled_form
    from reduced_model import ReducedPlant

    from ..run.laws import build_controller, build_observer, nominal_model

    def plant_kernel(s, kinematics):
        plant = ReducedPlant(s.true_params, kinematics=kinematics, Ts=s.Ts,
                             step=getattr(s.plant, "step", s.Ts))
        plant.reset()
        plant.advance(np.zeros(plant.n_joints))

    groups, seen = [], set()
    for s in scenarios:
        plugin_plant = ":" in s.plant.kind
        kinematics = (getattr(s.plant, "kinematics", "linear"),) if s.plant.kind == "reduced" \
            else (("linear", s.model.kinematics) if plugin_plant else ())
        for kin in kinematics:
            key = ("plant", kin, any(j != type(j)() for j in s.true_params.joints))
            if key not in seen:
                seen.add(key)
                groups.append((f"reduced plant ({_kinematics_label(kin)}"
                               f"{', joints' if key[2] else ''})",
                               lambda s=s, k=kin: plant_kernel(s, k)))
        model = nominal_model(s.nominal_params, s.model.modes_per_link, s.model.kinematics)
        for role, spec, build in (("controller", s.controller, build_controller),
                                  ("observer", s.observer, build_observer)):
            key = (role, spec.kind, s.model.kinematics)
            if spec.kind == "none" or ":" in spec.kind or key in seen:
                continue
            seen.add(key)
            label = f"{role} {spec.kind}" + (f" ({_kinematics_label(s.model.kinematics)})"
                                            if s.model.kinematics != "linear" else "")
            groups.append((label, lambda b=build, s=s, m=model, r=role: compiled_form(b(s, m), r)))
    examples = {}
    for s in scenarios:  # a user's FMU is a user's code too: it runs in its runs only
        if ":" not in s.controller.kind + s.observer.kind + s.plant.kind and \
                s.plant.kind != "fmu":
            examples.setdefault(s.plant.kind, s)
    for plant, example in sorted(examples.items()):
        groups.append((f"closed loop on the {plant} plant", lambda e=example: _short_run(e)))
    return groups


def _kinematics_label(kinematics: str) -> str:
    return "exact kinematics" if kinematics == "exact" else "the paper's kinematics"


def _short_run(scenario) -> None:
    """Two samples of ``scenario`` (compiles what its loop needs)."""
    from ..run.loop import run_scenario
    from ..run.scenario import scenario_from_mapping, scenario_to_mapping
    data = scenario_to_mapping(scenario)
    data.update(duration=(scenario.sensors.delay + 2) * scenario.Ts, transient=0.0,
                requirement=[])  # what is compiled needs no requirement (nor fits them)
    run_scenario(scenario_from_mapping(data))


def load_run_libraries() -> None:
    """Import the libraries every run needs that a command's start leaves out
    (scipy.signal: the vibration metrics' high-pass; scipy.optimize: the mode shapes),
    before any worker runs under its memory limit: imported lazily by a run that has
    used most of the limit, an extension module fails to map ("ImportError: ... failed
    to map segment") — the run would fail for the wrong reason and the import stay half
    done for the runs after it."""
    import scipy.optimize  # noqa: F401
    import scipy.signal  # noqa: F401


def warm_up(scenarios=None) -> None:
    """Compile or load, silently, every kernel the runs of ``scenarios`` use (default: the
    PBC with the paper's SMO on both plants), and `load_run_libraries`, e.g. in a process
    before it forks workers (`validation.batch.compiling` does it with progress)."""
    load_run_libraries()
    if scenarios is None:
        _warm_up_default()
        return
    for _, build in kernel_groups(scenarios):
        build()


@functools.cache  # once per process: every runner it starts forks from the same state
def _warm_up_default() -> None:
    from ..run.scenario import PLANT_KINDS, scenario_from_mapping
    warm_up([scenario_from_mapping({"plant": {"kind": kind}, "observer": {"kind": "smo-paper"}})
             for kind in PLANT_KINDS])
