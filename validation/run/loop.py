"""The closed loop, written once for both plants (DESIGN.md: the data flow of one run).

At every control instant t_k = k·Ts:  y_k (+ noise, delay) → observer → x̂_k →
controller(t_k, x̂_k or x_k, ref) → saturation → τ_k (+ disturbances) held over
[t_k, t_{k+1}) by the plant.  Divergence and solver failures end the run as a result.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np

from controllers import PaperReference, QuinticMove
from plant_exudyn import ExudynPlant
from reduced_model import ArmModel, PlantFailure, ReducedPlant, SensorConfig
from reduced_model._plant_interface import TRUTH_EXTRAS

from ._sample import OFFSETS, check_bounds, laws, pack_laws, post_sample, pre_sample, run_reduced
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
        strain_quantity=sens.strain_quantity, modal=sens.modal != "none", rates=sens.rates,
        tip_position=sens.tip_position)
    if s.plant.kind == "reduced":
        own = s.true_params == s.nominal_params and s.plant.modes_per_link == s.model.modes_per_link
        plant = ReducedPlant(s.true_params, modes_per_link=s.plant.modes_per_link,
                             step=s.plant.step, modal_basis=None if own else model.mode_shapes,
                             sensors=sensor_config)
    else:
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


def _signal_layout(model: ArmModel, measured: tuple[str, ...], has_observer: bool,
                   n_residual: int):
    states = model.state_names
    groups = {  # "truth" then "tips" is exactly a plant's truth_vector
        "truth": states,
        "tips": TRUTH_EXTRAS,
        "ref": ("theta1_ref", "theta2_ref"),
        "ref_rate": ("theta1_dot_ref", "theta2_dot_ref"),
        "tip_ref": ("tip_ref_x", "tip_ref_y"),
        "xhat": tuple(f"xhat_{s}" for s in states) if has_observer else (),
        "y": tuple(f"y_{m}" for m in measured),
        "tau_cmd": ("tau1_cmd", "tau2_cmd"),
        "tau": ("tau1", "tau2"),
        "residual": (tuple(f"residual_{c}" for c in model.coordinate_names[2:])
                     if n_residual == model.n - 2 else
                     tuple(f"residual_{i + 1}" for i in range(n_residual))),
        "dist": ("dist_tau1", "dist_tau2", "dist_tip_x", "dist_tip_y"),
    }
    names, slices, start = [], {}, 0
    for key, group in groups.items():
        slices[key] = slice(start, start + len(group))
        names += group
        start += len(group)
    return tuple(names), slices


def simulate(plant, controller, observer, scenario: Scenario, *, reference=None,
             model: ArmModel | None = None) -> RunResult:
    """Run the closed loop of ``scenario`` on ``plant``; never raises for divergence, a
    plant solver failure or a law that raises — those end the run with their status.

    Every sample is the compiled `validation._sample` kernels: `pre_sample`, the laws,
    `post_sample`.  Built-in laws run compiled (`pack_laws`); a plug-in runs as the
    Python object it is.  A plant that offers compiled stepping (the reduced plant) with
    built-in laws runs the whole loop in one compiled call; otherwise this loop steps
    the plant from Python.  Every path computes the same numbers (tested)."""
    s = scenario
    model = model or nominal_model(s.nominal_params, s.model.modes_per_link)
    spec_reference = make_reference(s.reference)
    if reference is not None and reference != spec_reference:
        raise ValueError("reference must be the scenario's own (see scenario.reference)")
    n, Ts = model.n, s.Ts
    N = int(round(s.duration / Ts))
    seeds = np.random.SeedSequence(s.seed).spawn(2)
    noise_rng, dist_rng = np.random.default_rng(seeds[0]), np.random.default_rng(seeds[1])
    refkind, refspec = _reference_spec(s.reference)
    ref_values = np.zeros(6)
    ref = _SampledReference(spec_reference, ref_values)

    # Initial state: at rest at θ_d(0), or moving with the reference ("reference").
    x0 = np.zeros(2 * n)
    theta_d0, dtheta_d0, _ = spec_reference(0.0)
    x0[:2] = theta_d0
    if s.initial_state == "reference":
        x0[n:n + 2] = dtheta_d0
    y = plant.reset(_to_plant_state(x0, plant, model))
    names_y = y.names
    std = np.array([s.sensors.rate_noise if m.endswith("_dot") else
                    s.sensors.encoder_noise if m.startswith("theta") else
                    s.sensors.modal_noise if m.startswith("q") else 0.0 for m in names_y])
    obs_index = np.zeros(0, dtype=np.int64)
    if observer is not None:
        missing = [m for m in observer.measured if m not in names_y]
        if missing:
            raise ValueError(f"the observer needs {missing} but the plant measures {names_y}")
        obs_index = np.array([names_y.index(m) for m in observer.measured], dtype=np.int64)
        observer.reset(x0 + s.initial_estimate_error())
    residual = getattr(controller, "residual", None)  # the PBC's unrealisable forces
    names, sl = _signal_layout(model, names_y, observer is not None,
                               0 if residual is None else len(residual))
    off = np.array([sl[k].start for k in OFFSETS], dtype=np.int64)
    rows = np.full((N, len(names)), np.nan)
    k_ = dict(std=std, noisy=bool(np.any(std > 0)),
              dbuf=np.zeros((s.sensors.delay + 1, len(names_y))), rng=noise_rng,
              refkind=refkind, refspec=refspec, n=n, off=off,
              bounds=np.array([s.divergence.max_angle, s.divergence.max_rate,
                               s.divergence.max_deflection * s.true_params.L1,
                               s.divergence.max_deflection * s.true_params.L2]),
              lengths=np.array([s.true_params.L1, s.true_params.L2]))
    dspec, dstate = _disturbance_spec(s.disturbances, Ts), np.zeros(len(s.disturbances))
    packed = pack_laws(controller, observer, Ts)
    info = np.zeros(1)
    wall0 = _time.perf_counter()
    stepping = getattr(plant, "compiled_stepping", None)
    fast = stepping(dspec) if packed is not None and stepping is not None else None
    if fast is not None:
        states = model.state_names
        k_done, code = run_reduced(
            N, Ts, fast["h"], fast["nsteps"](Ts), fast["x"], *fast["model"], fast["basis"],
            np.array([states.index(m) for m in names_y], dtype=np.int64),
            k_["std"], k_["noisy"], k_["dbuf"], noise_rng, refkind, refspec, k_["bounds"], n,
            k_["lengths"], rows, off, s.torque_limit, dspec, dstate, dist_rng, *packed,
            obs_index, s.uses_estimate, info)
        timings = {"first": 0.0}  # one compiled call: no split into plant and laws
        message = _reason(code, info[0], s.divergence, (k_done if k_done < N else N) * Ts)
        status = "ok" if code == 0 else "diverged"
        if k_done < N:
            rows[k_done] = np.nan
    else:
        status, message, k_done, timings = _python_loop(
            plant, controller, observer, s, model, y, ref, ref_values, rows, k_, dspec,
            dstate, dist_rng, obs_index, residual, packed, sl, info, N)
    wall = _time.perf_counter() - wall0
    simulated = k_done * Ts
    steady = wall - timings.pop("first")
    return RunResult(
        time=np.arange(k_done) * Ts, names=names, signals=np.ascontiguousarray(rows[:k_done].T),
        status=status, message=message, end_time=simulated, config=scenario_to_mapping(s),
        timings={"wall_s": wall, "startup_s": wall - steady, **timings,
                 "loop_s": wall - sum(timings.values()),
                 "compiled_loop": fast is not None,
                 # simulated time per wall second, without the first sample (kernel
                 # loading or compilation is not simulation speed)
                 "realtime_factor": (simulated - Ts) / steady if steady > 0 else math.nan})


def _python_loop(plant, controller, observer, s, model, y, ref, ref_values, rows, k_, dspec,
                 dstate, dist_rng, obs_index, residual, packed, sl, info, N):
    """The loop stepping the plant from Python, one sample kernel call on each side of
    the laws; returns (status, message, samples done, timings)."""
    n, Ts, limit = model.n, s.Ts, s.torque_limit
    use_estimate = s.uses_estimate
    yv = np.zeros(len(y.values))
    y_used = np.zeros(len(y.values))
    y_obs = np.zeros(len(obs_index))
    x_hat = np.zeros(2 * n)
    tau = np.zeros(2 * n)
    tau_plant = np.zeros(2 * n)
    force = np.zeros(2)
    last_tau = np.zeros(2)
    s_state, s_res, s_y = sl["truth"], sl["residual"], sl["y"]
    t_plant = t_ctrl = t_obs = first = 0.0
    status, message, k_done = "ok", "", N
    truth = plant.truth_vector()  # [x, *TRUTH_EXTRAS]: one copy per sample
    wall0 = _time.perf_counter()
    for k in range(N):
        t = k * Ts
        row = rows[k]
        yv[:] = y.values
        code = pre_sample(t, truth, yv, k_["std"], k_["noisy"], k_["dbuf"], k, k_["rng"],
                          k_["refkind"], k_["refspec"], k_["bounds"], n, k_["lengths"], row,
                          k_["off"], y_used, ref_values, info)
        ref.t = t
        if code:
            status, message, k_done = "diverged", _reason(code, info[0], s.divergence, t), k
            break
        a = b = _time.perf_counter()
        if packed is not None:
            code, n_tau = laws(t, Ts, y_obs, obs_index, last_tau, row[s_state], use_estimate,
                               ref_values, row, k_["off"], *packed, x_hat, tau)
            b = _time.perf_counter()
        else:
            calling = observer
            try:  # a plug-in may raise: the run fails, the campaign goes on
                if observer is not None:
                    x_hat = np.asarray(observer.update(t, row[s_y][obs_index], last_tau, Ts),
                                       dtype=float)
                    row[sl["xhat"]] = x_hat
                b = _time.perf_counter()
                calling = controller
                out = np.asarray(controller(t, x_hat if use_estimate else row[s_state], ref),
                                 dtype=float)
                if out.shape not in ((2,), (n,)):
                    raise ValueError(f"returned torques of shape {out.shape}, expected (2,)")
            except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
                label = getattr(calling, "name", type(calling).__name__)
                status, message, k_done = "failed", (f"{label} raised {type(exc).__name__}: "
                                                     f"{_one_line(exc)} at t = {t:.4g} s"), k
                break
            n_tau = out.shape[0]
            tau[:n_tau] = out
            if residual is not None:
                row[s_res] = controller.residual  # read each sample: a law may rebind it
        c = _time.perf_counter()
        t_obs += b - a
        t_ctrl += c - b
        code = post_sample(t, tau, n_tau, limit, dspec, dstate, dist_rng, row, k_["off"],
                           tau_plant, force)
        if code:
            status, message, k_done = "diverged", _reason(code, info[0], s.divergence, t), k
            break
        last_tau = tau[:n_tau].copy()
        try:
            y = plant.step(tau_plant[:n_tau], Ts,
                           tip_force=force if force[0] or force[1] else None)
        except PlantFailure as exc:
            status, message, k_done = "failed", str(exc), k + 1
            break
        truth = plant.truth_vector()
        t_plant += _time.perf_counter() - c
        if k == 0:  # the first sample pays for loading or compiling the kernels
            first = _time.perf_counter() - wall0
    else:
        code = check_bounds(truth, n, k_["bounds"], info)
        if code:
            status, message = "diverged", _reason(code, info[0], s.divergence, N * Ts)
    return status, message, k_done, {"plant_s": t_plant, "controller_s": t_ctrl,
                                     "observer_s": t_obs, "first": first}


def _reason(code: int, value: float, spec, t: float) -> str:
    """The message of a status code of the sample kernels (`validation._sample`)."""
    if code == 0:
        return ""
    text = {1: "state not finite", 2: f"|θ| = {value:.3g} rad exceeds {spec.max_angle:g} rad",
            3: f"|θ̇| = {value:.3g} rad/s exceeds {spec.max_rate:g} rad/s",
            4: f"tip deflection of link 1 = {value:.3g} m exceeds {spec.max_deflection:g} x "
               "its length",
            5: f"tip deflection of link 2 = {value:.3g} m exceeds {spec.max_deflection:g} x "
               "its length",
            6: "measurement not finite", 7: "controller output not finite"}[code]
    return f"{text} at t = {t:.4g} s"


def _reference_spec(spec) -> tuple[int, np.ndarray]:
    """(kind, parameters) of the scenario's reference for the sample kernel."""
    values = [*spec.amplitude, *spec.omega, spec.move_time, *spec.start, *spec.goal]
    return (0 if spec.kind == "paper" else 1), np.array(values, dtype=float)


_DISTURBANCE_KINDS = {"step": 0, "pulse": 1, "sine": 2, "noise": 3}
_TARGETS = {"tau1": 0, "tau2": 1, "tip_x": 2, "tip_y": 3}


def _disturbance_spec(specs, Ts: float) -> np.ndarray:
    """The scenario's disturbances as rows [kind, target, amplitude, start, duration,
    frequency, decay] for the sample kernel; decay = exp(−2π·bandwidth·Ts) of the
    low-passed noise."""
    out = np.zeros((len(specs), 7))
    for i, d in enumerate(specs):
        out[i] = (_DISTURBANCE_KINDS[d.kind], _TARGETS[d.target], d.amplitude, d.start,
                  d.duration, d.frequency, np.exp(-2 * np.pi * d.bandwidth * Ts))
    return out


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else "(no message)"


def _to_plant_state(x0: np.ndarray, plant, model: ArmModel) -> np.ndarray:
    """The initial state in the plant's own coordinates: same joints, no deflection."""
    out = np.zeros(plant.state_size)
    half, n = plant.state_size // 2, model.n
    out[:2], out[half:half + 2] = x0[:2], x0[n:n + 2]
    return out
