"""The closed loop, written once for both plants (DESIGN.md: the data flow of one run).

At every control instant t_k = k·Ts:  y_k (+ noise, delay) → observer → x̂_k →
controller(t_k, x̂_k or x_k, ref) → saturation → τ_k (+ disturbances) held over
[t_k, t_{k+1}) by the plant.  Divergence and solver failures end the run as a result.

What happens at a sample is the compiled kernels of `validation.run._sample`, on every
path: laws with a compiled form run through it (`controllers._compiled`), others as the
Python objects they are; a plant that can step itself in compiled code (the reduced
plant) with compiled laws runs the whole loop in one compiled call, any other plant is
stepped from Python.  Every path computes the same numbers (tested).
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np

from controllers import ObserverFailure, PaperReference, QuinticMove, compiled_form
from controllers._compiled import no_observer
from reduced_model import ArmModel, PlantFailure, ReducedPlant, SensorConfig
from reduced_model._plant_interface import TRUTH_EXTRAS

from ._sample import (DisturbanceKind, DisturbanceTarget, Group, SampleStatus,
                      check_bounds, compile_run_reduced, compile_sample_laws, noise_stream,
                      post_sample, pre_sample, signal_layout, status_message)
from .laws import build_controller, build_observer, nominal_model
from .results import RunResult
from .scenario import Scenario, check_scenario, scenario_to_mapping

__all__ = ["Setup", "build", "simulate", "run_scenario", "make_reference"]


@dataclass
class Setup:
    """The objects of one run, built from a scenario."""

    model: ArmModel
    plant: object
    controller: object
    observer: object | None
    reference: object


class _SampledReference:
    """The reference as the laws see it: at the current sample, the values the sample
    kernel computed (so every path uses the same numbers); at any other time, the
    reference object itself."""

    def __init__(self, reference, values: np.ndarray) -> None:
        self.reference, self.values, self.t = reference, values, None

    def __call__(self, t: float):
        if t == self.t:
            v = self.values
            return v[0:2].copy(), v[2:4].copy(), v[4:6].copy()
        return self.reference(t)


def make_reference(spec):
    if spec.kind == "paper":
        return PaperReference(amplitude=spec.amplitude, omega=spec.omega)
    return QuinticMove(start=spec.start, goal=spec.goal, duration=spec.move_time)


def build(scenario: Scenario) -> Setup:
    """Plant from ``true_params``, controller and observer from ``nominal_params``."""
    check_scenario(scenario)
    s = scenario
    model = nominal_model(s.nominal_params, s.model.modes_per_link)
    sens = s.sensors
    sensor_config = SensorConfig(
        encoder_resolution=sens.encoder_resolution,
        strain_gauges=(sens.gauges_link1, sens.gauges_link2) if sens.modal == "gauges" else None,
        strain_quantity=sens.strain_quantity or "curvature", modal=sens.modal != "none",
        rates=sens.rates, tip_position=sens.tip_position)
    if s.plant.kind == "reduced":
        own = s.true_params == s.nominal_params and s.plant.modes_per_link == s.model.modes_per_link
        plant = ReducedPlant(s.true_params, modes_per_link=s.plant.modes_per_link,
                             step=s.plant.step, modal_basis=None if own else model.mode_shapes,
                             sensors=sensor_config)
    else:
        from plant_exudyn import ExudynPlant  # Exudyn is loaded by the runs that use it
        plant = ExudynPlant(s.true_params, s.plant.mesh, step=s.plant.step,
                            modal_basis=model.mode_shapes, sensors=sensor_config,
                            spectral_radius=s.plant.spectral_radius,
                            newton_tolerance=s.plant.newton_tolerance)
    controller, observer = build_controller(s, model), build_observer(s, model)
    return Setup(model, plant, controller, observer, make_reference(s.reference))


def run_scenario(scenario: Scenario) -> RunResult:
    """Build the objects of ``scenario`` and simulate it."""
    setup = build(scenario)
    return simulate(setup.plant, setup.controller, setup.observer, scenario,
                    reference=setup.reference, model=setup.model)


class _Run:
    """The buffers of one run that every path shares (allocated once, no per-sample
    allocation)."""

    def __init__(self, s: Scenario, model: ArmModel, reference, measured: tuple[str, ...],
                 observer, residual_names: tuple[str, ...]) -> None:
        n, Ts = model.n, s.Ts
        self.n, self.N = n, int(round(s.duration / Ts))
        seeds = np.random.SeedSequence(s.seed).spawn(2)
        self.std = np.array([s.sensors.rate_noise if m.endswith("_dot") else
                             s.sensors.encoder_noise if m.startswith("theta") else
                             s.sensors.modal_noise if m.startswith("q") else 0.0
                             for m in measured])
        self.noise = (noise_stream(np.random.default_rng(seeds[0]), (self.N, len(measured)))
                      if np.any(self.std > 0) else np.zeros((0, len(measured))))
        self.dspec = _disturbance_spec(s.disturbances, Ts)
        self.dstate = np.zeros(len(s.disturbances))
        self.dnoise = noise_stream(np.random.default_rng(seeds[1]),
                                   _noise_draws(self.dspec, self.N, Ts))
        self.counts = np.array([0, 2], dtype=np.int64)  # noise draws used, torques applied
        self.dbuf = np.zeros((s.sensors.delay + 1, len(measured)))
        self.refkind, self.refspec = int(reference.kind), reference.spec
        self.bounds = np.array([s.divergence.max_angle, s.divergence.max_rate,
                                s.divergence.max_deflection * s.true_params.L1,
                                s.divergence.max_deflection * s.true_params.L2])
        self.lengths = np.array([s.true_params.L1, s.true_params.L2])
        self.names, self.off = signal_layout(model.state_names, TRUTH_EXTRAS, measured,
                                             observer is not None, residual_names)
        self.rows = np.full((self.N, len(self.names)), np.nan)
        self.obs_idx = (np.array([measured.index(m) for m in observer.measured], dtype=np.int64)
                        if observer is not None else np.zeros(0, dtype=np.int64))
        self.info = np.zeros(1)
        self.ref = np.zeros(6)
        self.yv, self.y_used = np.zeros(len(measured)), np.zeros(len(measured))
        self.y_obs = np.zeros(len(self.obs_idx))
        self.x_hat = np.zeros(2 * n)
        self.tau, self.tau_plant, self.last_tau = np.zeros(2 * n), np.zeros(2 * n), np.zeros(2 * n)
        self.force = np.zeros(2)


def simulate(plant, controller, observer, scenario: Scenario, *, reference=None,
             model: ArmModel | None = None) -> RunResult:
    """Run the closed loop of ``scenario`` on ``plant``; never raises for divergence, a
    plant solver failure or a law that raises — those end the run with their status.

    Parameters
    ----------
    plant : Plant
        Any object with the Plant interface (`reduced_model._plant_interface`).
    controller, observer
        The laws (`controllers._interface`); ``observer`` may be None.
    scenario : Scenario
        Timing, reference, sensors, disturbances, saturation, bounds, seed.
    reference : optional
        Must be the scenario's own reference if given (kept for symmetry with `build`).
    model : ArmModel, optional
        The nominal model the laws were built on (default: the scenario's).

    Returns
    -------
    RunResult
        Named signals at every sample, status, message, timings, and ``timings["paths"]``:
        which parts ran compiled.
    """
    s = scenario
    model = model or nominal_model(s.nominal_params, s.model.modes_per_link)
    if reference is not None and reference != make_reference(s.reference):
        raise ValueError("reference must be the scenario's own (see scenario.reference)")
    n, Ts = model.n, s.Ts
    reference = make_reference(s.reference)
    # Initial state: at rest at θ_d(0), or moving with the reference ("reference").
    x0 = np.zeros(2 * n)
    theta_d0, dtheta_d0, _ = reference(0.0)
    x0[:2] = theta_d0
    if s.initial_state == "reference":
        x0[n:n + 2] = dtheta_d0
    y = plant.reset(_to_plant_state(x0, plant, model))
    if observer is not None:
        missing = [m for m in observer.measured if m not in y.names]
        if missing:
            raise ValueError(f"the observer needs {missing} but the plant measures {y.names}")
        observer.reset(x0 + s.initial_estimate_error())
    residual = getattr(controller, "residual", None)  # the PBC's unrealisable forces
    residual_names = () if residual is None else (
        model.coordinate_names[2:] if len(residual) == n - 2 else
        tuple(str(i + 1) for i in range(len(residual))))
    r = _Run(s, model, reference, y.names, observer, residual_names)
    laws = _compiled_laws(controller, observer, model, Ts)
    stepping = getattr(plant, "compiled_stepping", None)
    payload_force = any(d.target in ("tip_x", "tip_y") for d in s.disturbances)
    plant_form = stepping() if laws is not None and stepping is not None and not payload_force \
        else None
    paths = {"loop": "compiled" if plant_form is not None else "python",
             "controller": "compiled" if laws is not None else "python",
             "observer": ("none" if observer is None else
                          "compiled" if laws is not None else "python")}
    wall0 = _time.perf_counter()
    if plant_form is not None:
        status, message, k_done, timings = _compiled_loop(plant_form, r, s, model, laws,
                                                          observer is not None)
    else:
        status, message, k_done, timings = _python_loop(plant, controller, observer, s,
                                                        reference, y, r, laws,
                                                        residual is not None)
    wall = _time.perf_counter() - wall0
    simulated = k_done * Ts
    steady = wall - timings.pop("first")
    if k_done < r.N:
        r.rows[k_done:] = np.nan
    return RunResult(
        time=np.arange(k_done) * Ts, names=r.names,
        signals=np.ascontiguousarray(r.rows[:k_done].T), status=status, message=message,
        end_time=simulated, config=scenario_to_mapping(s),
        timings={"wall_s": wall, "startup_s": wall - steady, **timings,
                 "loop_s": wall - sum(timings.values()),
                 "compiled_loop": plant_form is not None, "paths": paths,
                 # simulated time per wall second, without the first sample (kernel
                 # loading or compilation is not simulation speed)
                 "realtime_factor": (simulated - Ts) / steady if steady > 0 else math.nan})


def _compiled_laws(controller, observer, model: ArmModel, Ts: float):
    """The arguments of the laws for `sample_laws` (controller, then observer, each a
    `CompiledLaw` without its failure text) and the observer's failure text, or None if
    either law has no compiled form (both then run as Python objects)."""
    c = compiled_form(controller, "controller", Ts)
    o = no_observer(model) if observer is None else compiled_form(observer, "observer", Ts)
    if c is None or o is None:
        return None
    label = getattr(observer, "name", type(observer).__name__)
    return (*c[:-1], *o[:-1]), (f"{label}: {o.failure}" if o.failure else "")


def _compiled_loop(plant_form: dict, r: _Run, s: Scenario, model: ArmModel, laws,
                   has_observer: bool):
    """The whole loop in one compiled call (`run_reduced`)."""
    args, failure = laws
    states = model.state_names
    measured_idx = np.array([states.index(m.removeprefix("y_"))
                             for m in r.names if m.startswith("y_")], dtype=np.int64)
    k_done, code = compile_run_reduced()(
        r.N, s.Ts, plant_form["h"], plant_form["nsteps"](s.Ts), plant_form["x"],
        *plant_form["model"], plant_form["basis"], measured_idx, r.std, r.noise, r.dbuf,
        r.refkind, r.refspec, r.bounds, r.n, r.lengths, r.rows, r.off, r.info,
        s.torque_limit, r.dspec, r.dstate, r.dnoise, r.obs_idx, has_observer,
        s.uses_estimate, *args)
    message = status_message(code, r.info[0], s.divergence, min(k_done, r.N) * s.Ts, failure)
    status = "ok" if code == SampleStatus.OK else "diverged"
    return status, message, k_done, {"first": 0.0}  # one call: no split into plant and laws


def _python_loop(plant, controller, observer, s: Scenario, reference, y, r: _Run, laws,
                 has_residual: bool):
    """The loop stepping the plant from Python: per sample one compiled call
    (`sample_laws`) with compiled laws, or `pre_sample`, the Python laws, `post_sample`;
    returns (status, message, samples done, timings)."""
    n, N, Ts = r.n, r.N, s.Ts
    use_estimate = s.uses_estimate
    ref = _SampledReference(reference, r.ref)
    off = r.off
    s_xhat = slice(off[Group.XHAT], off[Group.Y])
    s_res = slice(off[Group.RESIDUAL], off[Group.DIST])
    sample = compile_sample_laws() if laws is not None else None
    args, failure = laws if laws is not None else ((), "")
    has_observer = observer is not None
    t_plant = t_laws = first = 0.0
    status, message, k_done = "ok", "", N
    truth = plant.truth_vector()  # [x, *TRUTH_EXTRAS]: one copy per sample
    wall0 = _time.perf_counter()
    for k in range(N):
        t = k * Ts
        row = r.rows[k]
        r.yv[:] = y.values
        a = _time.perf_counter()
        if sample is not None:
            code = sample(t, k, Ts, truth, r.yv, r.std, r.noise, r.dbuf, r.refkind, r.refspec,
                          r.bounds, n, r.lengths, row, off, r.y_used, r.ref, r.info,
                          s.torque_limit, r.dspec, r.dstate, r.dnoise, r.counts, r.last_tau,
                          r.x_hat, r.y_obs, r.obs_idx, has_observer, use_estimate, r.tau,
                          r.tau_plant, r.force, *args)
            if code != SampleStatus.OK:
                status, k_done = "diverged", k
                message = status_message(code, r.info[0], s.divergence, t, failure)
                break
        else:
            code = pre_sample(t, k, truth, r.yv, r.std, r.noise, r.dbuf, r.refkind, r.refspec,
                              r.bounds, n, r.lengths, row, off, r.y_used, r.ref, r.info)
            ref.t = t
            if code != SampleStatus.OK:
                status, message, k_done = ("diverged",
                                           status_message(code, r.info[0], s.divergence, t), k)
                break
            calling = observer
            try:  # a plug-in may raise: the run fails, the campaign goes on
                x_hat = r.x_hat
                if observer is not None:
                    x_hat = np.asarray(observer.update(t, r.y_used[r.obs_idx],
                                                       r.last_tau[:r.counts[1]], Ts), dtype=float)
                    row[s_xhat] = x_hat
                calling = controller
                out = np.asarray(controller(t, x_hat if use_estimate else row[:2 * n], ref),
                                 dtype=float)
                if out.shape not in ((2,), (n,)):
                    raise ValueError(f"returned torques of shape {out.shape}, expected (2,)")
            except ObserverFailure as exc:
                label = getattr(calling, "name", type(calling).__name__)
                status, k_done = "diverged", k
                message = status_message(SampleStatus.OBSERVER_FAILED, 0.0, s.divergence, t,
                                         f"{label}: {exc}")
                break
            except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
                label = getattr(calling, "name", type(calling).__name__)
                status, message, k_done = "failed", (f"{label} raised {type(exc).__name__}: "
                                                     f"{_one_line(exc)} at t = {t:.4g} s"), k
                break
            n_tau = out.shape[0]
            r.tau[:n_tau] = out
            if has_residual:
                row[s_res] = controller.residual  # read each sample: a law may rebind it
            code = post_sample(t, r.tau, n_tau, s.torque_limit, r.dspec, r.dstate, r.dnoise,
                               r.counts, row, off, r.tau_plant, r.force)
            if code != SampleStatus.OK:
                status, message, k_done = ("diverged",
                                           status_message(code, r.info[0], s.divergence, t), k)
                break
            r.last_tau[:n_tau] = r.tau[:n_tau]
        b = _time.perf_counter()
        t_laws += b - a
        try:
            force = r.force if r.force[0] or r.force[1] else None
            y = plant.step(r.tau_plant[:r.counts[1]], Ts, tip_force=force)
        except PlantFailure as exc:
            status, message, k_done = "failed", str(exc), k + 1
            break
        truth = plant.truth_vector()
        t_plant += _time.perf_counter() - b
        if k == 0:  # the first sample pays for loading or compiling the kernels
            first = _time.perf_counter() - wall0
    else:
        code = check_bounds(truth, n, r.bounds, r.info)
        if code != SampleStatus.OK:
            status, message = "diverged", status_message(code, r.info[0], s.divergence, N * Ts)
    return status, message, k_done, {"plant_s": t_plant, "laws_s": t_laws, "first": first}


def _disturbance_spec(specs, Ts: float) -> np.ndarray:
    """The scenario's disturbances as rows [kind, target, amplitude, start, duration,
    frequency, decay] for the sample kernel (`DisturbanceKind`, `DisturbanceTarget`);
    decay = exp(−2π·bandwidth·Ts) of the low-passed noise."""
    out = np.zeros((len(specs), 7))
    for i, d in enumerate(specs):
        out[i] = (DisturbanceKind[d.kind.upper()], DisturbanceTarget[d.target.upper()],
                  d.amplitude, d.start, d.duration or 0.0, d.frequency or 0.0,
                  np.exp(-2 * np.pi * d.bandwidth * Ts) if d.bandwidth else 0.0)
    return out


def _noise_draws(dspec: np.ndarray, n_samples: int, Ts: float) -> int:
    """How many draws the noise disturbances take over the run: one per noise row at
    every sample from its start (`post_sample`'s test, t ≥ start − 1e-9)."""
    t = np.arange(n_samples) * Ts
    return int(sum(np.count_nonzero(t >= row[3] - 1e-9) for row in dspec
                   if row[0] == DisturbanceKind.NOISE))


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else "(no message)"


def _to_plant_state(x0: np.ndarray, plant, model: ArmModel) -> np.ndarray:
    """The initial state in the plant's own coordinates: same joints, no deflection."""
    out = np.zeros(plant.state_size)
    half, n = plant.state_size // 2, model.n
    out[:2], out[half:half + 2] = x0[:2], x0[n:n + 2]
    return out
