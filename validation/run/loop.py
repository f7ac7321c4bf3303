"""The closed loop, written once for both plants (README, *The closed loop*).

At every control instant t_k = k·Ts:  y_k (+ noise, delay) → observer → x̂_k →
controller(t_k, x̂_k or x_k, ref) → saturation → τ_k (+ disturbances) held over
[t_k, t_{k+1}) by the plant.  Divergence and solver failures end the run as a result.

What happens at a sample is the compiled kernels of `validation.run.sample`, on every
path: laws with a compiled form run through it (`controllers._compiled`), others as the
Python objects they are; a plant that can step itself in compiled code (the reduced
plant) with compiled laws runs the whole loop in one compiled call, any other plant is
stepped from Python.  Every path computes the same numbers (tested).
"""
from __future__ import annotations

import functools
import math
import time as _time
from dataclasses import dataclass

import numpy as np

from controllers import ObserverFailure, PaperReference, QuinticMove, absent, compiled_form
from reduced_model import ArmModel, PlantFailure, SensorConfig, truth_extras

from .config import short_repr, short_str
from .sample import (DisturbanceKind, Group, SampleStatus, check_bounds, context,
                      disturbance_target, law_fields, noise_stream, plant_fields, post_sample,
                      pre_sample, run_compiled, sample_laws, signal_layout, status_message)
from .laws import build_controller, build_observer, name_of, nominal_model
from .results import RunResult
from .scenario import Scenario, check_scenario, scenario_to_mapping
from .threads import one_thread
from .tracebacks import own_frames

__all__ = ["Setup", "build", "simulate", "run_scenario", "make_reference",
           "measurement_noise"]


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
            N = len(v) // 3
            return v[0:N].copy(), v[N:2 * N].copy(), v[2 * N:].copy()
        return self.reference(t)


@functools.lru_cache(maxsize=128)  # one object per reference: a run asks three times
def make_reference(spec):
    """The reference object of a `ReferenceSpec` (eq. 37, or a quintic move)."""
    if spec.kind == "paper":
        return PaperReference(amplitude=spec.amplitude, omega=spec.omega)
    return QuinticMove(start=spec.start, goal=spec.goal, duration=spec.move_time)


@one_thread
def build(scenario: Scenario) -> Setup:
    """The objects of a run: the plant from ``true_params``, the controller and observer
    from ``nominal_params``.

    Parameters
    ----------
    scenario : Scenario
        The run, checked again here.

    Returns
    -------
    Setup
        The laws' model, the plant, the controller, the observer (None if the scenario
        has none) and the reference.
    """
    check_scenario(scenario)
    s = scenario
    model = nominal_model(s.nominal_params, s.model.modes_per_link, s.model.kinematics)
    sens = s.sensors
    sensor_config = SensorConfig(
        encoder_resolution=sens.encoder_resolution,
        strain_gauges=(sens.gauges_link1, sens.gauges_link2) if sens.modal == "gauges" else None,
        strain_quantity=sens.strain_quantity or "curvature", modal=sens.modal != "none",
        rates=sens.rates, tip_position=sens.tip_position)
    plant = s.plant.build(s.true_params, model, sensor_config, s.Ts)
    controller, observer = build_controller(s, model), build_observer(s, model)
    return Setup(model, plant, controller, observer, make_reference(s.reference))


def run_scenario(scenario: Scenario) -> RunResult:
    """Build the objects of ``scenario`` (`build`) and simulate it (`simulate`).

    Parameters
    ----------
    scenario : Scenario
        The run.

    Returns
    -------
    RunResult
        Its named signals, status (``ok``, ``diverged`` or ``failed``) and resolved
        scenario; where a law raised, the frames of its own code (``traceback``).

    Examples
    --------
    >>> from validation import all_metrics, run_scenario, scenario_from_mapping
    >>> result = run_scenario(scenario_from_mapping({"duration": 0.5}))
    >>> result.status, result.time.size, result["theta1"].shape
    ('ok', 500, (500,))
    >>> metrics = all_metrics(result)
    >>> metrics["transient_s"], metrics["end_time"]  # the window measured [s]
    (0.25, 0.5)
    >>> 0 < metrics["track_max_1"] < 0.2  # the largest |θ1 − θ1d| in it [rad]
    True
    """
    setup = build(scenario)
    return simulate(setup.plant, setup.controller, setup.observer, scenario,
                    reference=setup.reference, model=setup.model)


class _Run:
    """The buffers of one run, shared by every path and held by its `SampleContext`
    (allocated once: no allocation per sample)."""

    def __init__(self, s: Scenario, model: ArmModel, reference, measured: tuple[str, ...],
                 observer, residual_names: tuple[str, ...], laws, plant_form,
                 y_idx: np.ndarray) -> None:
        n, Ts, joints = model.n, s.Ts, model.n_joints
        extras = truth_extras(joints)
        self.n, self.N, self.joints = n, int(round(s.duration / Ts)), joints
        seeds = np.random.SeedSequence(s.seed).spawn(2)
        self.std = measurement_noise(s.sensors, measured)
        noise = (noise_stream(np.random.default_rng(seeds[0]), (self.N, len(measured)))
                 if np.any(self.std > 0) else np.zeros((0, len(measured))))
        dspec = _disturbance_spec(s.disturbances, Ts, joints)
        dnoise = noise_stream(np.random.default_rng(seeds[1]), _noise_draws(dspec, self.N, Ts))
        self.names, self.off = signal_layout(model.state_names, extras, measured,
                                             observer is not None, residual_names, joints)
        self.rows = np.full((self.N, len(self.names)), np.nan)
        self.obs_idx = (np.array([measured.index(m) for m in observer.measured], dtype=np.int64)
                        if observer is not None else np.zeros(0, dtype=np.int64))
        self.info, self.ref = np.zeros(2), np.zeros(3 * joints)
        lengths = np.array([link.length for link in s.true_params.links])
        self.bounds = np.array([s.divergence.max_angle, s.divergence.max_rate,
                                *(s.divergence.max_deflection * lengths)])
        self.truth = np.zeros(2 * n + len(extras))
        self.yv, self.y_used = np.zeros(len(measured)), np.zeros(len(measured))
        self.x_hat = np.zeros(2 * n)
        self.tau, self.tau_plant, self.last_tau = np.zeros(2 * n), np.zeros(2 * n), np.zeros(2 * n)
        self.force = np.zeros(2)
        self.traceback = ""  # a law's own frames where it raised (`own_frames`)
        self.counts = np.array([0, joints], dtype=np.int64)  # noise draws, torques applied
        (controller, observer_law), self.failure = laws
        self.context = context(
            n=n, joints=joints, Ts=Ts, refkind=int(reference.kind), refspec=reference.spec,
            bounds=self.bounds, lengths=lengths,
            info=self.info, truth=self.truth, y_idx=y_idx, yv=self.yv, std=self.std,
            noise=noise, dbuf=np.zeros((s.sensors.delay + 1, len(measured))),
            y_used=self.y_used, ref=self.ref, off=self.off, limit=float(s.torque_limit),
            dspec=dspec, dstate=np.zeros(len(s.disturbances)), dnoise=dnoise,
            counts=self.counts, has_observer=observer is not None,
            use_estimate=s.uses_estimate, obs_idx=self.obs_idx,
            y_obs=np.zeros(len(self.obs_idx)), x_hat=self.x_hat, tau=self.tau,
            tau_plant=self.tau_plant, force=self.force, last_tau=self.last_tau,
            **law_fields("c", "controller", controller),
            **law_fields("o", "observer", observer_law),
            **plant_fields(plant_form, len(plant_form.state) if plant_form else 0))


@one_thread
def simulate(plant, controller, observer, scenario: Scenario, *, reference=None,
             model: ArmModel | None = None) -> RunResult:
    """Run the closed loop of ``scenario`` on ``plant``; never raises for divergence, a
    plant solver failure or a law that raises — those end the run with their status.

    Parameters
    ----------
    plant : Plant
        Any plant (`reduced_model.Plant`), built for the scenario's ``Ts``.
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
        Named signals at every sample, status, message, timings, ``timings["paths"]``:
        which parts ran compiled, and ``timings["observer_measured"]``: the measurements
        the observer was fed.
    """
    s = scenario
    model = model or nominal_model(s.nominal_params, s.model.modes_per_link,
                                   s.model.kinematics)
    if reference is not None and reference != make_reference(s.reference):
        raise ValueError("reference must be the scenario's own (see scenario.reference)")
    n, Ts, N = model.n, s.Ts, model.n_joints
    reference = make_reference(s.reference)
    x0 = initial_state(s, model)
    y = plant.reset(plant_state(x0, plant, model))
    if observer is not None:
        missing = [m for m in observer.measured if m not in y.names]
        if missing:
            raise ValueError(f"the observer needs {missing} but the plant measures {y.names}")
        observer.reset(x0 + s.initial_estimate_error())
    residual = getattr(controller, "residual", None)  # the PBC's unrealisable forces
    residual_names = () if residual is None else (
        model.coordinate_names[N:] if len(residual) == n - N else
        tuple(str(i + 1) for i in range(len(residual))))
    laws = _compiled_laws(controller, observer, model)
    payload_force = any(d.target in ("tip_x", "tip_y") for d in s.disturbances)
    direct = plant.measurement_index()  # the measurement's place in the truth, or None
    plant_form = (plant.compiled() if laws is not None and not payload_force
                  and direct is not None else None)
    y_idx = np.zeros(0, dtype=np.int64) if direct is None else direct
    r = _Run(s, model, reference, y.names, observer, residual_names,
             laws or _absent_laws(model), plant_form, y_idx)
    paths = {"loop": "compiled" if plant_form is not None else "python",
             "controller": "compiled" if laws is not None else "python",
             "observer": ("none" if observer is None else
                          "compiled" if laws is not None else "python")}
    wall0 = _time.perf_counter()
    if plant_form is not None:
        status, message, k_done, timings = _compiled_loop(r, s)
    else:
        status, message, k_done, timings = _python_loop(plant, controller, observer, s,
                                                        reference, r, laws is not None,
                                                        residual is not None, direct is None)
    wall = _time.perf_counter() - wall0
    simulated = k_done * Ts
    steady = wall - timings.pop("first")
    if k_done < r.N:
        r.rows[k_done:] = np.nan
    return RunResult(
        time=np.arange(k_done) * Ts, names=r.names,
        signals=np.ascontiguousarray(r.rows[:k_done].T), status=status, message=message,
        end_time=simulated, config=scenario_to_mapping(s), traceback=r.traceback,
        timings={"wall_s": wall, "startup_s": wall - steady, **timings,
                 "loop_s": wall - sum(timings.values()),
                 "compiled_loop": plant_form is not None, "paths": paths,
                 # what the observer was fed: read by reports without building it
                 "observer_measured": [] if observer is None else list(observer.measured),
                 # simulated time per wall second, without the first sample (kernel
                 # loading or compilation is not simulation speed)
                 "realtime_factor": (simulated - Ts) / steady if steady > 0 else math.nan})


def _compiled_laws(controller, observer, model: ArmModel):
    """The compiled forms of the laws (controller, observer) and what the observer's
    failure means ("name: reason"), or None if either law has none (both then run as
    the Python objects they are)."""
    c = compiled_form(controller, "controller")
    o = absent("observer", model) if observer is None else compiled_form(observer, "observer")
    if c is None or o is None:
        return None
    label = name_of(observer)
    return (c, o), (f"{label}: {o.failure}" if o.failure else "")


def _absent_laws(model: ArmModel):
    """The context's law slots when the laws run as Python objects (never called)."""
    return (absent("controller", model), absent("observer", model)), ""


def _compiled_loop(r: _Run, s: Scenario):
    """The whole loop in one compiled call (`run_compiled`)."""
    k_done, code = run_compiled(r.context, r.rows)
    message = status_message(code, r.info, s.divergence, min(k_done, r.N) * s.Ts, r.failure)
    status = "ok" if code == SampleStatus.OK else "diverged"
    return status, message, k_done, {"first": 0.0}  # one call: no split into plant and laws


def _python_loop(plant, controller, observer, s: Scenario, reference, r: _Run,
                 compiled_laws: bool, has_residual: bool, measure: bool):
    """The loop stepping the plant from Python: per sample the plant's truth (and, unless
    it is part of the truth, its measurement), then one compiled call (`sample_laws`)
    with compiled laws, or `pre_sample`, the Python laws, `post_sample`; returns (status,
    message, samples done, timings)."""
    n, N, Ts, ctx, rows = r.n, r.N, s.Ts, r.context, r.rows
    laws = None if compiled_laws else _PythonLaws(controller, observer, s, reference, r,
                                                  has_residual)
    t_laws = first = 0.0
    status, message, k_done = "ok", "", N
    # the payload force, when a disturbance acts there (else the plant is told none)
    force = r.force if any(d.target in ("tip_x", "tip_y") for d in s.disturbances) else None
    applied = {m: r.tau_plant[:m] for m in (r.joints, n)}  # by the torques applied
    sample = laws.sample if laws is not None else (lambda t, k, row: sample_laws(ctx, t, k, row))
    advance, truth_into, truth = plant.advance, plant.truth_into, r.truth
    truth_into(truth)
    wall0 = _time.perf_counter()
    for k in range(N):
        t = k * Ts
        row = rows[k]
        if measure:
            r.yv[:] = plant.measure().values
        a = _time.perf_counter()
        try:
            code = sample(t, k, row)
        except _LawRaised as exc:
            status, message, k_done = exc.status, exc.message, k
            break
        if code != SampleStatus.OK:
            status, k_done = "diverged", k
            message = status_message(code, r.info, s.divergence, t, r.failure)
            break
        t_laws += _time.perf_counter() - a
        try:
            advance(applied[r.counts[1]], tip_force=force)
        except PlantFailure as exc:
            status, message, k_done = "failed", str(exc), k + 1
            break
        truth_into(truth)
        if k == 0:  # the first sample pays for loading or compiling the kernels
            first = _time.perf_counter() - wall0
    else:
        code = check_bounds(r.truth, n, r.joints, r.bounds, r.info)
        if code != SampleStatus.OK:
            status, message = "diverged", status_message(code, r.info, s.divergence, N * Ts)
    plant_s = _time.perf_counter() - wall0 - t_laws  # the plant and the loop around it
    return status, message, k_done, {"plant_s": plant_s, "laws_s": t_laws, "first": first}


class _LawRaised(Exception):
    """A law raised: the run ends with ``status`` ("failed", or "diverged" for an
    observer that failed) and ``message``."""

    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status, self.message = status, message


class _PythonLaws:
    """The laws as the Python objects they are, between `pre_sample` and `post_sample`
    (every law without a compiled form, every plug-in)."""

    def __init__(self, controller, observer, s: Scenario, reference, r: _Run,
                 has_residual: bool) -> None:
        self.controller, self.observer, self.r = controller, observer, r
        self.n, self.use_estimate = r.n, s.uses_estimate
        self.divergence = s.divergence
        self.ref = _SampledReference(reference, r.ref)
        self.s_xhat = slice(r.off[Group.XHAT], r.off[Group.Y])
        self.s_res = slice(r.off[Group.RESIDUAL], r.off[Group.DIST]) if has_residual else None

    def sample(self, t: float, k: int, row: np.ndarray) -> int:
        r = self.r
        code = pre_sample(r.context, t, k, row)
        if code != SampleStatus.OK:
            return code
        self.ref.t = t
        calling = self.observer
        try:  # a plug-in may raise, or return what is no estimate or torque: the run fails
            x_hat = r.x_hat
            if self.observer is not None:
                x_hat = _real_array(self.observer.update(t, r.y_used[r.obs_idx],
                                                         r.last_tau[:r.counts[1]]),
                                    ((2 * self.n,),), "an estimate")
                row[self.s_xhat] = x_hat
            calling = self.controller
            out = _real_array(self.controller(t, x_hat if self.use_estimate else
                                              r.truth[:2 * self.n], self.ref),
                              ((r.joints,), (self.n,)), "torques")
            if self.s_res is not None:  # read each sample: it may be rebound
                row[self.s_res] = _real_array(self.controller.residual,
                                              ((self.s_res.stop - self.s_res.start,),),
                                              "a residual")
        except ObserverFailure as exc:
            label = name_of(calling)
            raise _LawRaised("diverged", status_message(
                SampleStatus.OBSERVER_FAILED, (0.0, 0.0), self.divergence, t,
                f"{label}: {exc}")) from None
        except _NotReal as exc:
            label = name_of(calling)
            raise _LawRaised("failed", f"{label} returned {exc} at t = {t:.4g} s") from None
        except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
            label = name_of(calling)
            where, r.traceback = own_frames(exc, [c.__module__ for c in type(calling).__mro__])
            raise _LawRaised("failed", f"{label} raised {short_str(exc)} at t = {t:.4g} s "
                                       f"({where})") from None
        r.tau[:out.shape[0]] = out
        return post_sample(r.context, t, out.shape[0], row)


class _NotReal(ValueError):
    """A law returned something other than the real array its contract names
    (`controllers._interface`); the message says what it returned."""


def _real_array(value, shapes: tuple, what: str) -> np.ndarray:
    """``value`` as a float array if it holds real numbers (integer or floating dtype)
    in one of ``shapes``, else `_NotReal` describing it: ``np.asarray(value, float)``
    would drop an imaginary part, parse strings and take booleans.  Non-finite values
    pass: they end the run as the sample kernel says (`SampleStatus`)."""
    expected = f"expected real numbers of shape {' or '.join(map(str, shapes))}"
    try:
        array = np.asarray(value)
    except (ValueError, TypeError):  # a ragged sequence, an object numpy refuses
        raise _NotReal(f"{what} {short_repr(value, 80)}: not an array; {expected}") from None
    if array.dtype.kind not in "iuf" or array.shape not in shapes:
        raise _NotReal(f"{what} {short_repr(value, 80)}: dtype {array.dtype}, shape "
                       f"{array.shape}; {expected}")
    return array.astype(float, copy=False)


def _disturbance_spec(specs, Ts: float, joints: int) -> np.ndarray:
    """The scenario's disturbances as rows [kind, target, amplitude, start, duration,
    frequency, decay] for the sample kernel (`DisturbanceKind`, `disturbance_target`);
    decay = exp(−2π·bandwidth·Ts) of the low-passed noise."""
    out = np.zeros((len(specs), 7))
    for i, d in enumerate(specs):
        out[i] = (DisturbanceKind[d.kind.upper()], disturbance_target(d.target, joints),
                  d.amplitude, d.start, d.duration or 0.0, d.frequency or 0.0,
                  np.exp(-2 * np.pi * d.bandwidth * Ts) if d.bandwidth else 0.0)
    return out


def _noise_draws(dspec: np.ndarray, n_samples: int, Ts: float) -> int:
    """How many draws the noise disturbances take over the run: one per noise row at
    every sample from its start (`post_sample`'s test, t ≥ start − 1e-9)."""
    t = np.arange(n_samples) * Ts
    return int(sum(np.count_nonzero(t >= row[3] - 1e-9) for row in dspec
                   if row[0] == DisturbanceKind.NOISE))


def measurement_noise(sensors, measured) -> np.ndarray:
    """The noise standard deviation of each of the ``measured`` readings with the
    scenario's ``sensors``: rates, angles [rad] and modal coordinates [m] each their own;
    the payload position is read without noise."""
    return np.array([sensors.rate_noise if m.endswith("_dot") else
                     sensors.encoder_noise if m.startswith("theta") else
                     sensors.modal_noise if m.startswith("q") else 0.0 for m in measured])


def initial_state(scenario: Scenario, model: ArmModel) -> np.ndarray:
    """x(0) of a run of ``scenario`` in ``model``'s coordinates: at rest at θ_d(0), or
    moving with the reference (initial_state = "reference"); no deflection."""
    n, N = model.n, model.n_joints
    x0 = np.zeros(2 * n)
    theta_d0, dtheta_d0, _ = make_reference(scenario.reference)(0.0)
    x0[:N] = theta_d0
    if scenario.initial_state == "reference":
        x0[n:n + N] = dtheta_d0
    return x0


def plant_state(x0: np.ndarray, plant, model: ArmModel) -> np.ndarray:
    """The initial state in the plant's own coordinates: same joints, no deflection."""
    out = np.zeros(plant.state_size)
    half, n, N = plant.state_size // 2, model.n, model.n_joints
    out[:N], out[half:half + N] = x0[:N], x0[n:n + N]
    return out
