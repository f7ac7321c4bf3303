"""The closed loop, written once for both plants (DESIGN.md: the data flow of one run).

At every control instant t_k = k·Ts:  y_k (+ noise, delay) → observer → x̂_k →
controller(t_k, x̂_k or x_k, ref) → saturation → τ_k (+ disturbances) held over
[t_k, t_{k+1}) by the plant.  Divergence and solver failures end the run as a result.
"""
from __future__ import annotations

import math
import time as _time
from collections import deque
from dataclasses import dataclass

import numpy as np

from controllers import PaperReference, QuinticMove
from plant_exudyn import ExudynPlant
from reduced_model import ArmModel, PlantFailure, ReducedPlant, SensorConfig
from reduced_model._plant_interface import TRUTH_EXTRAS

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
    """The reference, evaluated once per sample: the loop and the controller both ask
    for ref(t_k)."""

    def __init__(self, reference) -> None:
        self.reference, self._t, self._value = reference, None, None

    def __call__(self, t: float):
        if t != self._t:
            self._t, self._value = t, self.reference(t)
        return self._value


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


class _Disturbances:
    """Values of the scenario's disturbances at t, per target (τ1, τ2, Fx, Fy)."""

    _TARGETS = {"tau1": 0, "tau2": 1, "tip_x": 2, "tip_y": 3}

    def __init__(self, specs, Ts: float, rng: np.random.Generator) -> None:
        self.specs, self.rng = specs, rng
        self.noise_state = np.zeros(len(specs))
        self.decay = np.array([np.exp(-2 * np.pi * d.bandwidth * Ts) for d in specs])
        self.value = np.zeros(4)

    def __call__(self, t: float) -> np.ndarray:
        """Edges are half-open, [start, start + duration), decided to 1 ns: k·Ts and a
        sum like 0.2 + 0.1 differ in their last bit."""
        v = self.value
        v[:] = 0.0
        for i, d in enumerate(self.specs):
            if t < d.start - 1e-9:
                continue
            if d.kind == "step":
                x = d.amplitude
            elif d.kind == "pulse":
                x = d.amplitude if t < d.start + d.duration - 1e-9 else 0.0
            elif d.kind == "sine":
                x = d.amplitude * np.sin(2 * np.pi * d.frequency * (t - d.start))
            else:  # first-order low-passed white noise with standard deviation = amplitude
                a = self.decay[i]
                self.noise_state[i] = a * self.noise_state[i] + np.sqrt(1 - a * a) \
                    * d.amplitude * self.rng.standard_normal()
                x = self.noise_state[i]
            v[self._TARGETS[d.target]] += x
        return v


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
    """Run the closed loop of ``scenario`` on ``plant``; never raises for divergence or
    a plant solver failure — those end the run with the corresponding status."""
    s = scenario
    model = model or nominal_model(s.nominal_params, s.model.modes_per_link)
    ref = _SampledReference(reference or make_reference(s.reference))
    n, Ts = model.n, s.Ts
    N = int(round(s.duration / Ts))
    seeds = np.random.SeedSequence(s.seed).spawn(2)
    noise_rng, dist = np.random.default_rng(seeds[0]), _Disturbances(
        s.disturbances, Ts, np.random.default_rng(seeds[1]))
    lengths = (s.true_params.L1, s.true_params.L2)

    # Initial state: at rest at θ_d(0), or moving with the reference ("reference").
    x0 = np.zeros(2 * n)
    theta_d0, dtheta_d0, _ = ref(0.0)
    x0[:2] = theta_d0
    if s.initial_state == "reference":
        x0[n:n + 2] = dtheta_d0
    y = plant.reset(_to_plant_state(x0, plant, model))
    names_y = y.names
    std = np.array([s.sensors.rate_noise if m.endswith("_dot") else
                    s.sensors.encoder_noise if m.startswith("theta") else
                    s.sensors.modal_noise if m.startswith("q") else 0.0 for m in names_y])
    noisy = bool(np.any(std > 0))
    delayed = deque(maxlen=s.sensors.delay + 1)

    if observer is not None:
        missing = [m for m in observer.measured if m not in names_y]
        if missing:
            raise ValueError(f"the observer needs {missing} but the plant measures {names_y}")
        obs_index = np.array([names_y.index(m) for m in observer.measured])
        observer.reset(x0 + s.initial_estimate_error())
    use_estimate = s.uses_estimate
    residual = getattr(controller, "residual", None)  # the PBC's unrealisable forces
    names, sl = _signal_layout(model, names_y, observer is not None,
                               0 if residual is None else len(residual))
    rows = np.full((N, len(names)), np.nan)
    limit = s.torque_limit
    last_tau = np.zeros(2)
    status, message, k_done = "ok", "", N
    t_plant = t_ctrl = t_obs = 0.0
    wall0 = _time.perf_counter()
    first_sample = 0.0
    truth = plant.truth_vector()  # [x, *TRUTH_EXTRAS]: one copy per sample
    s_truth, s_state, s_ref, s_ref_rate, s_tip_ref = (
        slice(sl["truth"].start, sl["tips"].stop), sl["truth"], sl["ref"], sl["ref_rate"],
        sl["tip_ref"])
    s_xhat, s_y, s_cmd, s_tau = sl["xhat"], sl["y"], sl["tau_cmd"], sl["tau"]
    s_res, s_dist = sl["residual"], sl["dist"]
    no_disturbance = np.zeros(4)
    bounds = _Bounds(n, s.divergence, lengths)
    tau_shapes = ((2,), (n,))  # joint torques, or the idealised law's n generalised forces

    for k in range(N):
        t = k * Ts
        row = rows[k]
        row[s_truth] = truth
        reason = bounds.violated(truth)
        if reason:
            row[:] = np.nan
            status, message, k_done = "diverged", f"{reason} at t = {t:.4g} s", k
            break
        theta_d, dtheta_d, _ = ref(t)
        row[s_ref] = theta_d
        row[s_ref_rate] = dtheta_d
        row[s_tip_ref] = _rigid_tip(theta_d, lengths)

        y_k = y.values + std * noise_rng.standard_normal(std.shape) if noisy else y.values
        if not math.isfinite(y_k.sum()):
            status, message, k_done = "diverged", f"measurement not finite at t = {t:.4g} s", k
            break
        delayed.append(y_k)
        y_used = delayed[0]
        row[s_y] = y_used

        a = b = _time.perf_counter()
        calling = observer
        try:  # a law (a plug-in above all) may raise: the run fails, the campaign goes on
            if observer is not None:
                x_hat = observer.update(t, y_used[obs_index], last_tau, Ts)
                row[s_xhat] = x_hat
            b = _time.perf_counter()
            calling = controller
            tau = np.asarray(controller(t, x_hat if use_estimate else row[s_state], ref),
                             dtype=float)
            if tau.shape not in tau_shapes:
                raise ValueError(f"returned torques of shape {tau.shape}, expected (2,)")
        except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
            label = getattr(calling, "name", type(calling).__name__)
            status, message, k_done = "failed", (f"{label} raised {type(exc).__name__}: "
                                                 f"{_one_line(exc)} at t = {t:.4g} s"), k
            break
        c = _time.perf_counter()
        t_obs += b - a
        t_ctrl += c - b
        if not math.isfinite(tau.sum()):
            status, message, k_done = "diverged", f"controller output not finite at t = {t:.4g} s", k
            break
        row[s_cmd] = tau[:2]
        if limit > 0:
            tau = tau.copy()
            np.clip(tau[:2], -limit, limit, out=tau[:2])
        row[s_tau] = tau[:2]
        if residual is not None:
            row[s_res] = controller.residual  # read each sample: a law may rebind it
        last_tau = tau
        if s.disturbances:
            d = dist(t)
            row[s_dist] = d
            tau = tau.copy()
            tau[:2] += d[:2]
            force = d[2:] if d[2] or d[3] else None
        else:
            row[s_dist] = no_disturbance
            force = None
        try:
            y = plant.step(tau, Ts, tip_force=force)
        except PlantFailure as exc:
            status, message, k_done = "failed", str(exc), k + 1
            break
        truth = plant.truth_vector()
        t_plant += _time.perf_counter() - c
        if k == 0:  # the first sample pays for loading or compiling the kernels
            first_sample = _time.perf_counter() - wall0
    else:
        reason = bounds.violated(truth)
        if reason:
            status, message = "diverged", f"{reason} at t = {N * Ts:.4g} s"

    wall = _time.perf_counter() - wall0
    simulated = k_done * Ts
    rows = rows[:k_done]
    steady = wall - first_sample
    return RunResult(
        time=np.arange(k_done) * Ts, names=names, signals=np.ascontiguousarray(rows.T),
        status=status, message=message, end_time=simulated, config=scenario_to_mapping(s),
        timings={"wall_s": wall, "startup_s": first_sample, "plant_s": t_plant,
                 "controller_s": t_ctrl, "observer_s": t_obs,
                 "loop_s": wall - t_plant - t_ctrl - t_obs,
                 # simulated time per wall second, without the first sample (kernel
                 # loading or compilation is not simulation speed)
                 "realtime_factor": (simulated - Ts) / steady if steady > 0 else float("nan")})


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else "(no message)"


def _to_plant_state(x0: np.ndarray, plant, model: ArmModel) -> np.ndarray:
    """The initial state in the plant's own coordinates: same joints, no deflection."""
    out = np.zeros(plant.state_size)
    half, n = plant.state_size // 2, model.n
    out[:2], out[half:half + 2] = x0[:2], x0[n:n + 2]
    return out


def _rigid_tip(theta: np.ndarray, lengths) -> tuple[float, float]:
    """Payload position of the rigid arm at joint angles ``theta``."""
    a1 = theta.item(0)
    a12 = a1 + theta.item(1)
    return (lengths[0] * math.cos(a1) + lengths[1] * math.cos(a12),
            lengths[0] * math.sin(a1) + lengths[1] * math.sin(a12))


class _Bounds:
    """The divergence test of a `truth_vector` with ``n`` coordinates; plain float
    comparisons, since it runs at every sample."""

    def __init__(self, n: int, spec, lengths) -> None:
        self.n, self.spec = n, spec
        self.max_deflection = (spec.max_deflection * lengths[0], spec.max_deflection * lengths[1])

    def violated(self, truth: np.ndarray) -> str:
        """Why the run must stop, or ""."""
        if not math.isfinite(truth.sum()):  # any NaN or inf makes the sum non-finite
            return "state not finite"
        n, spec = self.n, self.spec
        angle = max(abs(truth.item(0)), abs(truth.item(1)))
        if angle > spec.max_angle:
            return f"|θ| = {angle:.3g} rad exceeds {spec.max_angle:g} rad"
        rate = max(abs(truth.item(n)), abs(truth.item(n + 1)))
        if rate > spec.max_rate:
            return f"|θ̇| = {rate:.3g} rad/s exceeds {spec.max_rate:g} rad/s"
        for i in range(2):
            w = truth.item(2 * n + 4 + i)
            if abs(w) > self.max_deflection[i]:
                return (f"tip deflection of link {i + 1} = {w:.3g} m exceeds "
                        f"{spec.max_deflection:g} x its length")
        return ""
