"""Metrics of a run: pure functions of a `RunResult` and its stored scenario.

Conventions: metrics "after the transient" use the samples at t ≥ the scenario's
``transient`` (default 2 s, or half of a run shorter than 4 s, so that the start-up is
excluded), recorded with them as ``transient_s`` (the window is [transient_s, end_time]);
RMS and max are per joint / per state; angles in rad, lengths in m, torques in N m.

Two metrics need a definition the paper does not give (vibration has its own module,
`validation.run.vibration`):

- **Estimation against the measurement**: for each estimated state the error RMS
  (``est_rms_*``) is set next to the RMS of the raw measurement's own error
  (``noise_rms_*``: y − x, noise and sensor error, for measured states) and the signal's
  RMS (``signal_rms_*``); ``est_to_noise_*`` > 1 means the estimate is worse than the raw
  measurement, ``est_to_signal_*`` ≥ 1 means no better than x̂ ≡ 0.  ``est_worse`` lists
  the states worse than their measurement.
- **Convergence** of an estimate: the earliest time from which the error's RMS over every
  full ``CONVERGENCE_WINDOW`` (0.1 s) stays within the state's tolerance
  (`convergence_tolerances`), the largest of
  (a) its **noise floor** × ``CONVERGENCE_NOISE_FACTOR`` (1.5): the RMS of the raw
      measurement's own error y − x after the transient for a measured state, the
      scenario's noise standard deviation of its sensor group (encoder, modal, rate) for
      one the observer does not measure — no estimator can be asked to beat its input in
      every 0.1 s window, and an estimate as noisy as 0.5σ must count as converged;
  (b) the **paper's bound** where the paper states one (Fig. 7): 0.02 rad on the joint
      angles, 2e-3 rad/s of tip-slope rate on the flexible rates (per mode, ÷ |φ'(L)|);
  (c) where it states none (modal positions, joint rates), ``CONVERGENCE_FRACTION``
      (10 %) of the state's own RMS after the transient — scale-free "near zero".
  So x̂ ≡ 0 fails (its error is the signal: above 0.02 rad on the angles, above 10 % of
  the RMS elsewhere), a constant 0.1 rad angle bias fails (> 0.02 rad) and so does a
  5 mm modal bias (≫ the 1e-5 m floor and 10 % of the modal RMS) — while the measurement
  noise alone never keeps a state from converging.  A state whose RMS is below its
  tolerance cannot show convergence at all (x̂ ≡ 0 meets it too): ``est_worse_zero``
  names the states whose estimate is worse than x̂ ≡ 0 (error RMS ≥ the state's RMS).
"""
from __future__ import annotations

import math

import numpy as np

from reduced_model import ArmParameters

from .reductions import after as _after
from .reductions import as_float as _f64
from .reductions import peak as _max
from .reductions import per_joint
from .reductions import rms as _rms
from .results import RunResult
from .vibration import vibration, vibration_cutoff

__all__ = ["tracking", "tip_error", "deflection", "estimation", "torque", "growth_rate",
           "residual", "convergence_time", "convergence_tolerances", "all_metrics",
           "CONVERGENCE_FRACTION", "CONVERGENCE_WINDOW", "CONVERGENCE_NOISE_FACTOR",
           "PAPER_ANGLE_BOUND", "PAPER_SLOPE_RATE_BOUND", "GROWTH_WINDOW", "GROWTH_FLOOR"]

#: Convergence, states the paper gives no number for: windowed error RMS within this
#: fraction of the state's RMS.
CONVERGENCE_FRACTION = 0.1
#: Convergence: the noise floor counts this many times the measurement's error RMS.  A
#: 0.1 s window of white noise has an RMS within ±7 % (1σ) of the noise's, so over the
#: ~200 windows of a 20 s run an estimate exactly as noisy as its input still crosses
#: 1.2×; 1.5 leaves an estimate at the floor converged and one at 2× the floor not.
CONVERGENCE_NOISE_FACTOR = 1.5
#: The paper's bounds (Fig. 7): estimation errors within 0.02 rad, flexible-mode
#: (tip-slope rate) errors at 2e-3 rad/s.
PAPER_ANGLE_BOUND = 0.02
PAPER_SLOPE_RATE_BOUND = 2e-3
#: Window [s] of `growth_rate`: 0.1 s holds ≥ 10 periods of anything a 1-10 ms loop can
#: make unstable; ten of them in the second half of a 2 s run.
GROWTH_WINDOW = 0.1
#: `growth_rate`'s floor: fast motion below 1e-3 of the torques' RMS is not a motion of the
#: loop (the default arm's PBC at 2.6 ms, stable: 1e-6; at 2.76 ms, growing: 1.4, the
#: torque's RMS ~1 N m).
GROWTH_FLOOR = 1e-3
#: Length [s] of the sliding window of the convergence test (100 samples at 1 kHz: noise
#: averages out, a real excursion of a few periods of the 34 Hz mode does not).
CONVERGENCE_WINDOW = 0.1



def tracking(result: RunResult, transient: float) -> dict[str, float]:
    """Tracking: the angle error after ``transient``, and the rate error with its ratio to
    the reference's peak rate (the phase portrait's distance from the reference's own
    orbit).

    Parameters
    ----------
    result : RunResult
        The run.
    transient : float
        Start of the window measured [s].

    Returns
    -------
    track_rms_i : float
        RMS of θ_i − θ_i,d after the transient [rad], joint i = 1 … N.
    track_max_i : float
        Max |θ_i − θ_i,d| after the transient [rad].
    rate_err_max_i : float
        Max |θ̇_i − θ̇_i,d| after the transient [rad/s].
    rate_err_rel : float
        The larger of rate_err_max_i ÷ the reference's peak rate of joint i [ratio].
    """
    window = _after(result, transient)
    err = (_f64(result, per_joint(result, "theta{}"))
           - _f64(result, per_joint(result, "theta{}_ref")))
    rate_ref = _f64(result, per_joint(result, "theta{}_dot_ref"))[:, window]
    rate_err = _f64(result, per_joint(result, "theta{}_dot"))[:, window] - rate_ref
    err = err[:, window]
    rms, mx, rmx = _rms(err), _max(err), _max(rate_err)
    peak = _max(rate_ref)
    joints = range(err.shape[0])
    out = {f"track_rms_{i + 1}": float(rms[i]) for i in joints}
    out |= {f"track_max_{i + 1}": float(mx[i]) for i in joints}
    out |= {f"rate_err_max_{i + 1}": float(rmx[i]) for i in joints}
    with np.errstate(divide="ignore", invalid="ignore"):
        out["rate_err_rel"] = float(np.max(rmx / peak)) if np.all(peak > 0) else math.nan
    return out


def tip_error(result: RunResult, transient: float) -> dict[str, float]:
    """Cartesian distance between the payload and the rigid arm's tip at θ_d.

    Parameters
    ----------
    result : RunResult
        The run.
    transient : float
        Start of the window measured [s].

    Returns
    -------
    tip_err_rms : float
        Its RMS after the transient [m].
    tip_err_max : float
        Its max after the transient [m].
    """
    window = _after(result, transient)
    tip = per_joint(result, "tip{}")[-1]  # the last link's tip: the payload
    d = np.hypot(result[f"{tip}_x"].astype(float) - result["tip_ref_x"],
                 result[f"{tip}_y"].astype(float) - result["tip_ref_y"])[window]
    return {"tip_err_rms": float(_rms(d)), "tip_err_max": float(_max(d))}


def deflection(result: RunResult, transient: float) -> dict[str, float]:
    """Tip deflections: max over the whole run and after ``transient``, RMS after it.

    Parameters
    ----------
    result : RunResult
        The run.
    transient : float
        Start of the window measured [s].

    Returns
    -------
    defl_max_i : float
        Max |tip deflection| of link i over the whole run [m].
    defl_late_max_i : float
        Max |tip deflection| of link i after the transient [m].
    defl_rms_i : float
        RMS tip deflection of link i after the transient [m].
    """
    w = _f64(result, per_joint(result, "tip_defl{}"))
    late = _after(result, transient)
    out = {}
    for i in range(w.shape[0]):
        out[f"defl_max_{i + 1}"] = float(_max(w[i]))
        out[f"defl_late_max_{i + 1}"] = float(_max(w[i, late]))
        out[f"defl_rms_{i + 1}"] = float(_rms(w[i, late]))
    return out



def convergence_time(time: np.ndarray, error: np.ndarray, tolerance: float,
                     window: float = CONVERGENCE_WINDOW) -> float:
    """Earliest t from which the RMS of ``error`` over every full ``window`` [t', t' +
    window], t' ≥ t, is ≤ ``tolerance``; NaN if it never settles, or settles only in the
    last ten windows of the run (a dip at the end is not convergence).  Only full windows
    count: a window of a few samples would judge noise by a handful of draws."""
    if time.size < 2:
        return math.nan
    k = min(max(1, int(round(window / (time[1] - time[0])))), time.size)
    sq = np.concatenate([[0.0], np.cumsum(np.square(error))])
    windowed = np.sqrt((sq[k:] - sq[:-k]) / k)  # [i] covers samples i .. i + k - 1
    outside = np.flatnonzero(~(windowed <= tolerance))
    if outside.size == 0:
        return float(time[0])
    first_good = outside[-1] + 1
    if time.size - (first_good + k) < 10 * k:
        return math.nan
    return float(time[first_good])


def convergence_tolerances(states, signal_rms: dict, noise_floor: dict,
                           model=None) -> dict[str, float]:
    """The convergence tolerance of each estimated state (module docstring): the largest
    of its noise floor × `CONVERGENCE_NOISE_FACTOR`, the paper's bound for its group
    (angles; flexible rates through the mode's tip slope |φ'(L)|, given ``model``) and,
    where the paper states no number, `CONVERGENCE_FRACTION` × its RMS."""
    slopes = {}
    if model is not None:
        names = model.coordinate_names[model.n_joints:]
        dphi = np.concatenate([m.tip_values[1] for m in model.mode_shapes])
        slopes = {f"{c}_dot": abs(float(d)) for c, d in zip(names, dphi)}
    out = {}
    for s in states:
        floor = CONVERGENCE_NOISE_FACTOR * noise_floor[s]
        if s.startswith("theta") and not s.endswith("_dot"):
            paper = PAPER_ANGLE_BOUND
        elif s in slopes and slopes[s] > 0:
            paper = PAPER_SLOPE_RATE_BOUND / slopes[s]
        else:
            paper = CONVERGENCE_FRACTION * signal_rms[s]
        out[s] = max(floor, paper)
    return out


def _sensor_sigma(config: dict, state: str) -> float:
    """The scenario's noise standard deviation of the sensor group reading ``state``."""
    sensors = config.get("sensors", {})
    key = ("rate_noise" if state.endswith("_dot") else
           "encoder_noise" if state.startswith("theta") else "modal_noise")
    return float(sensors.get(key, 0.0))


def estimation(result: RunResult, transient: float, model=None) -> dict[str, float]:
    """Estimation against the measurement, per estimated state (module docstring).
    Empty if the run had no observer.

    Parameters
    ----------
    result : RunResult
        The run.
    transient : float
        Start of the window measured [s].
    model : reduced_model.ArmModel, optional
        The laws' model: gives the flexible rates the paper's bound.

    Returns
    -------
    est_rms_<state> : float
        RMS of the estimation error after the transient [the state's unit].
    est_max_<state> : float
        Its max [the state's unit].
    signal_rms_<state> : float
        RMS of the state itself [the state's unit].
    est_to_signal_<state> : float
        est_rms ÷ signal_rms [ratio]; ≥ 1: no better than x̂ ≡ 0.
    noise_rms_<state> : float
        RMS of the raw measurement's own error, for a measured state [the state's unit].
    est_to_noise_<state> : float
        est_rms ÷ noise_rms [ratio]; > 1: worse than the measurement it is fed.
    est_tol_<state> : float
        Convergence tolerance (`convergence_tolerances`) [the state's unit].
    est_conv_<state> : float
        Convergence time, NaN if never [s].
    est_worse : str
        The states worse than their measurement, space-separated.
    est_worse_zero : str
        The states worse than x̂ ≡ 0, space-separated.
    """
    states = [n.removeprefix("xhat_") for n in result.names_with("xhat_")]
    if not states:
        return {}
    truth = _f64(result, states)
    err = _f64(result, [f"xhat_{s}" for s in states]) - truth
    window = _after(result, transient)
    out, worse, worse_zero, signal, floor = {}, [], [], {}, {}
    for i, s in enumerate(states):
        e = err[i, window]
        signal[s] = float(_rms(truth[i, window]))
        est = float(_rms(e))
        out[f"est_rms_{s}"] = est
        out[f"est_max_{s}"] = float(_max(e))
        out[f"signal_rms_{s}"] = signal[s]
        out[f"est_to_signal_{s}"] = est / signal[s] if signal[s] > 0 else math.nan
        if signal[s] > 0 and est >= signal[s]:
            worse_zero.append(s)
        floor[s] = _sensor_sigma(result.config, s)
        if f"y_{s}" in result:
            noise = float(_rms(result[f"y_{s}"][window].astype(float) - truth[i, window]))
            out[f"noise_rms_{s}"] = noise
            out[f"est_to_noise_{s}"] = est / noise if noise > 0 else math.nan
            floor[s] = noise
            if noise > 0 and est > noise:
                worse.append(s)
    tolerance = convergence_tolerances(states, signal, floor, model)
    for i, s in enumerate(states):
        out[f"est_tol_{s}"] = tolerance[s]
        out[f"est_conv_{s}"] = convergence_time(result.time, err[i], tolerance[s])
    out["est_worse"] = " ".join(worse)
    out["est_worse_zero"] = " ".join(worse_zero)
    return out


def tip_slope_rate_error(result: RunResult, transient: float, model) -> dict[str, float]:
    """The flexible-rate estimation error in the paper's unit, independent of how the
    modes are normalised.  Empty if the run had no observer.

    Parameters
    ----------
    result : RunResult
        The run.
    transient : float
        Start of the window measured [s].
    model : reduced_model.ArmModel
        The laws' model (its mode shapes' tip slopes φ'_ij(L_i)).

    Returns
    -------
    est_rms_slope_rate_i : float
        RMS after the transient of the error of link i's tip-slope rate
        Σ_j φ'_ij(L_i) q̇_ij [rad/s].
    """
    if "xhat_theta1" not in result:
        return {}
    window = _after(result, transient)
    names = model.coordinate_names[model.n_joints:]
    out, start = {}, 0
    for i, modes in enumerate(model.mode_shapes):
        if not modes.n:
            continue
        link = names[start:start + modes.n]
        start += modes.n
        dphi = modes.tip_values[1]
        err = dphi @ (_f64(result, [f"xhat_{c}_dot" for c in link])
                      - _f64(result, [f"{c}_dot" for c in link]))
        out[f"est_rms_slope_rate_{i + 1}"] = float(_rms(err[window]))
    return out


def torque(result: RunResult) -> dict[str, float]:
    """Applied joint torques over the whole run.

    Parameters
    ----------
    result : RunResult
        The run.

    Returns
    -------
    tau_rms_i : float
        RMS of the torque applied to joint i [N m].
    tau_max_i : float
        Its max magnitude [N m].
    tau_tv_i : float
        Its total variation Σ|Δτ| per second of run [N m/s]: chattering.
    """
    out = {}
    span = max(result.time[-1] - result.time[0], 1e-12) if result.time.size > 1 else math.nan
    for i, name in enumerate(per_joint(result, "tau{}"), start=1):
        tau = result[name].astype(float)
        out[f"tau_rms_{i}"] = float(_rms(tau))
        out[f"tau_max_{i}"] = float(_max(tau))
        out[f"tau_tv_{i}"] = float(np.abs(np.diff(tau)).sum() / span) if tau.size > 1 else math.nan
    return out


def growth_rate(result: RunResult) -> dict[str, float]:
    """``growth_rate`` [1/s]: how fast the loop's fastest motion grows over the second half
    of the run — the slope of log RMS of the torques' second difference Δ²τ (what a
    sampled loop's instability at or near the Nyquist frequency drives first) per
    ``GROWTH_WINDOW`` window.  A stable loop's transient decays (< 0), a chattering one
    holds (≈ 0), an unstable one grows (the default arm's PBC at 2.76 ms: +4 1/s, long
    before it leaves the divergence bounds).  0 when the last window's Δ²τ is below
    ``GROWTH_FLOOR`` of the torques' RMS: a smooth torque's Δ²τ ≈ τ̈ Ts² (1e-8 N m at
    0.2 ms) varies with the reference, not with the loop's stability.

    Parameters
    ----------
    result : RunResult
        The run.

    Returns
    -------
    growth_rate : float
        Growth rate of the loop's fastest motion over the run's second half [1/s].
    """
    tau = _f64(result, per_joint(result, "tau{}"))
    if tau.shape[1] < 3:
        return {"growth_rate": math.nan}
    d2, t = np.diff(tau, 2, axis=1), result.time[2:]
    start = result.time[0] + 0.5 * (result.time[-1] - result.time[0])
    edges = np.arange(start, t[-1] + 1e-12, GROWTH_WINDOW)
    rms = np.array([_rms(d2[:, (t >= a) & (t < a + GROWTH_WINDOW)].ravel()) for a in edges[:-1]])
    if rms.size < 3 or not np.all(np.isfinite(rms)):
        return {"growth_rate": math.nan}
    if rms[-1] <= GROWTH_FLOOR * _rms(tau[:, result.time >= start].ravel()):
        return {"growth_rate": 0.0}  # no fast motion to speak of: a smooth torque
    return {"growth_rate": float(np.polyfit(edges[:-1], np.log(np.maximum(rms, 1e-300)),
                                            1)[0])}


def residual(result: RunResult) -> dict[str, float]:
    """The PBC's unrealisable flexible-coordinate forces (rows 2… of eq. 20).

    Parameters
    ----------
    result : RunResult
        The run.

    Returns
    -------
    residual_rms_<coordinate> : float
        RMS of the force on modal coordinate q_ij that no actuator produces [N].
    """
    return {f"residual_rms_{n.removeprefix('residual_')}": float(_rms(result[n].astype(float)))
            for n in result.names_with("residual_")}


def all_metrics(result: RunResult, transient: float | None = None) -> dict[str, float]:
    """Every metric of a run, using its stored scenario.

    Parameters
    ----------
    result : RunResult
        The run; its ``config`` is the resolved scenario (arm, model, transient).
    transient : float, optional
        The start of the window measured [s]; default the scenario's (the claims
        evaluate a family of them).

    Returns
    -------
    status : str
        "ok", "diverged" or "failed".
    end_time : float
        Simulated time reached [s].
    transient_s : float
        The scenario's transient: the window measured is [transient_s, end_time] [s].
    metrics : dict
        And the keys of `tracking`, `tip_error`, `deflection`, `vibration`,
        `vibration_decay`, `estimation`, `tip_slope_rate_error`, `torque`, `growth_rate`
        and `residual`.
    """
    from .laws import nominal_model
    config = result.config
    base = {"status": result.status, "end_time": result.end_time,
            "transient_s": float(config["transient"])}
    if result.time.size == 0:
        return base
    if transient is None:
        transient = float(config["transient"])
    true_params = ArmParameters.from_mapping(config["true_params"])
    model = nominal_model(ArmParameters.from_mapping(config["nominal_params"]),
                          config["model"]["modes_per_link"])
    return (base | tracking(result, transient) | tip_error(result, transient)
            | deflection(result, transient)
            | vibration(result, transient, vibration_cutoff(true_params))
            | estimation(result, transient, model) | tip_slope_rate_error(result, transient, model)
            | torque(result) | growth_rate(result) | residual(result))
