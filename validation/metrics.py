"""Metrics of a run: pure functions of a `RunResult` (no simulation state).

Conventions: tracking metrics use the samples at t ≥ ``transient`` (the scenario's
``transient``, default 2 s, so that the start-up from rest is excluded); RMS and max are
per joint / per state; angles in rad, lengths in m, torques in N m.
"""
from __future__ import annotations

import math

import numpy as np

from .results import RunResult

__all__ = ["tracking", "tip_error", "deflection", "estimation", "torque", "residual",
           "convergence_time", "all_metrics", "CONVERGENCE_TOLERANCE"]

#: |x̂ − x| below which an estimate counts as converged, per kind of state.  Angles: the
#: paper's 0.02 rad; modal positions: 2e-3 m (≈ 2 % of the largest deflections); rates:
#: 0.1 rad/s and 0.05 m/s, ten times the default sign observer's chattering bands
#: (±5e-3, ±2e-3) and above the position-only variant's reconstruction error.
CONVERGENCE_TOLERANCE = {"theta": 0.02, "q": 2e-3, "theta_dot": 0.1, "q_dot": 0.05}


def _after(result: RunResult, start: float) -> np.ndarray:
    return result.time >= start - 1e-12


def _rms(x: np.ndarray, axis=-1) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=axis)) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def _max(x: np.ndarray, axis=-1) -> np.ndarray:
    return np.max(np.abs(x), axis=axis) if x.shape[-1] else np.full(x.shape[:-1], np.nan)


def tracking(result: RunResult, transient: float) -> dict[str, float]:
    """RMS and max |θ_i − θ_i,d| after ``transient``."""
    window = _after(result, transient)
    err = result.select(["theta1", "theta2"]) - result.select(["theta1_ref", "theta2_ref"])
    err = err[:, window]
    rms, mx = _rms(err), _max(err)
    return {f"track_rms_{i + 1}": float(rms[i]) for i in range(2)} | \
        {f"track_max_{i + 1}": float(mx[i]) for i in range(2)}


def tip_error(result: RunResult, transient: float) -> dict[str, float]:
    """Cartesian distance between the payload and the rigid arm's tip at θ_d."""
    window = _after(result, transient)
    d = np.hypot(result["tip2_x"] - result["tip_ref_x"], result["tip2_y"] - result["tip_ref_y"])
    d = d[window]
    return {"tip_err_rms": float(_rms(d)), "tip_err_max": float(_max(d))}


def deflection(result: RunResult, transient: float, motion_end: float | None) -> dict[str, float]:
    """Tip deflections: max over the whole run, RMS after ``transient``, and the residual
    vibration (RMS after ``motion_end``, for references that come to rest; NaN else)."""
    w = result.select(["tip_defl1", "tip_defl2"])
    out = {}
    for i in range(2):
        out[f"defl_max_{i + 1}"] = float(_max(w[i]))
        out[f"defl_rms_{i + 1}"] = float(_rms(w[i, _after(result, transient)]))
        out[f"residual_vib_{i + 1}"] = (float(_rms(w[i, _after(result, motion_end)]))
                                        if motion_end is not None else math.nan)
    return out


def convergence_time(time: np.ndarray, error: np.ndarray, tolerance: float) -> float:
    """Earliest t after which |error| stays ≤ ``tolerance`` (NaN if it never settles)."""
    outside = np.flatnonzero(np.abs(error) > tolerance)
    if outside.size == 0:
        return float(time[0]) if time.size else math.nan
    last = outside[-1]
    return float(time[last + 1]) if last + 1 < time.size else math.nan


def _kind(state: str) -> str:
    base = state.removesuffix("_dot")
    return ("theta" if base.startswith("theta") else "q") + ("_dot" if state.endswith("_dot") else "")


def estimation(result: RunResult, transient: float,
               tolerance: dict[str, float] | None = None) -> dict[str, float]:
    """Per state: RMS and max |x̂ − x| after ``transient``, and the convergence time
    (|x̂ − x| ≤ tolerance from then on; tolerances per kind of state in
    `CONVERGENCE_TOLERANCE`).  Empty if the run had no observer."""
    tol = CONVERGENCE_TOLERANCE | (tolerance or {})
    states = [n.removeprefix("xhat_") for n in result.names_with("xhat_")]
    if not states:
        return {}
    err = result.select([f"xhat_{s}" for s in states]) - result.select(states)
    window = _after(result, transient)
    out = {}
    for i, s in enumerate(states):
        out[f"est_rms_{s}"] = float(_rms(err[i, window]))
        out[f"est_max_{s}"] = float(_max(err[i, window]))
        out[f"est_conv_{s}"] = convergence_time(result.time, err[i], tol[_kind(s)])
    return out


def torque(result: RunResult) -> dict[str, float]:
    """Applied joint torques: RMS, max, and total variation Σ|Δτ| per second (chattering)."""
    out = {}
    span = max(result.time[-1] - result.time[0], 1e-12) if result.time.size > 1 else math.nan
    for i in (1, 2):
        tau = result[f"tau{i}"]
        out[f"tau_rms_{i}"] = float(_rms(tau))
        out[f"tau_max_{i}"] = float(_max(tau))
        out[f"tau_tv_{i}"] = float(np.abs(np.diff(tau)).sum() / span) if tau.size > 1 else math.nan
    return out


def residual(result: RunResult) -> dict[str, float]:
    """RMS of the PBC's unrealisable flexible-coordinate forces, per coordinate."""
    return {f"residual_rms_{n.removeprefix('residual_')}": float(_rms(result[n]))
            for n in result.names_with("residual_")}


def all_metrics(result: RunResult) -> dict[str, float]:
    """Every metric of a run, using its stored scenario (transient, reference end)."""
    config = result.config
    transient = float(config.get("transient", 2.0))
    ref = config.get("reference", {})
    motion_end = float(ref["move_time"]) if ref.get("kind") == "quintic" else None
    if result.time.size == 0:
        return {"status": result.status, "end_time": result.end_time}
    return ({"status": result.status, "end_time": result.end_time}
            | tracking(result, transient) | tip_error(result, transient)
            | deflection(result, transient, motion_end) | estimation(result, transient)
            | torque(result) | residual(result)
            | {"wall_s": result.timings.get("wall_s", math.nan),
               "realtime_factor": result.timings.get("realtime_factor", math.nan)})
