"""Diagonal gains given as one number or one per coordinate, validated once, and the
rule that gives a law's default gains from the arm it is built on (`arm_gains`)."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["gain_vector", "joint_flex_gains", "control_period", "ArmGains", "arm_gains",
           "RIGID_BANDWIDTH", "SAMPLING_BANDWIDTH", "FLEX_POSITION_GAIN"]

#: The bandwidth [rad/s] the gains are scaled to on an arm of rigid links only.
RIGID_BANDWIDTH = 10.0
#: The flexible coordinates' share of the observers' position gain, L_P,q·ω² [m/s³]: a
#: mode of frequency ω deflects ∝ 1/ω² under the same joint motion, and the discrete
#: sliding band ±Ts·L_P,q must stay below that deflection, or the chatter it injects
#: into q̂ (through K q̂) biases the light joints' rate estimates.  8 m/s³ gives the
#: paper's L_P,q = 0.5 m/s on its arm (ω = 3.95 rad/s).
FLEX_POSITION_GAIN = 8.0
#: The largest bandwidth the rule takes, as a fraction of the sampling rate 1/Ts: well
#: inside what a 1 kHz loop samples (50 rad/s at 1 ms).
SAMPLING_BANDWIDTH = 0.05


class ArmGains(NamedTuple):
    """The default gains of an arm (`arm_gains`).

    Parameters
    ----------
    bandwidth : float
        ω [rad/s]: the first locked frequency, capped.
    inertia : ndarray
        M_ii: the arm's inertia about each joint, straight, at rest [kg m²].
    lambda_joint : ndarray
        Λ on θ [1/s].
    lambda_flex : float
        Λ on q [1/s].
    kv_joint : ndarray
        K_v on θ [N m s/rad].
    l_position_flex : float
        The observers' L_P on q [m/s].
    """

    bandwidth: float
    inertia: np.ndarray
    lambda_joint: np.ndarray
    lambda_flex: float
    kv_joint: np.ndarray
    l_position_flex: float


def _round(value: float) -> float:
    """One significant figure: a starting point, not an optimum."""
    return float(f"{value:.0e}")


def arm_gains(model, Ts: float) -> ArmGains:
    """The rule behind the laws' default gains, from the arm of ``model`` and ``Ts``.

    ω is the arm's first natural frequency with the joints locked [rad/s] (`RIGID_BANDWIDTH`
    for an arm of rigid links only), at most `SAMPLING_BANDWIDTH`/Ts; M_ii is the
    inertia about joint i of the arm straight and at rest (the diagonal of M(0)).  The
    PBC's joint error dynamics, (M_ii s + K_v,i)(s + Λ_i) = 0, get their poles at
    Λ = 0.75 ω and K_v,i/M_ii = 1.1 ω — just below and at the first flexible mode, so
    that the joints follow without driving it hard —, and Λ_f = 0.25 ω; the sliding-mode
    observers' position gain on q is L_P,q = `FLEX_POSITION_GAIN`/ω²; each gain is
    rounded to one significant figure.  On the paper's arm (ω = 3.95 rad/s, M_ii =
    2.69, 1.07 kg m²) that is the paper's Λ = 3, Λ_f = 1, K_v = (10, 5) and L_P,q = 0.5.

    Parameters
    ----------
    model : reduced_model.ArmModel
        The law's nominal model.
    Ts : float
        The control period [s].

    Returns
    -------
    ArmGains
    """
    locked = model.natural_frequencies(joints="locked")
    omega = 2 * math.pi * float(locked[0]) if locked.size else RIGID_BANDWIDTH
    omega = min(omega, SAMPLING_BANDWIDTH / Ts)
    inertia = np.diag(model.mass_matrix(np.zeros(model.n)))[:model.n_joints].copy()
    return ArmGains(omega, inertia, np.full(model.n_joints, _round(0.75 * omega)),
                    _round(0.25 * omega), np.array([_round(1.1 * omega * m) for m in inertia]),
                    _round(FLEX_POSITION_GAIN / omega ** 2))


def gain_vector(name: str, value, length: int, *, positive: bool = False) -> np.ndarray:
    """``value`` (one number, or ``length`` numbers) as an array of ``length`` gains, each
    finite and >= 0 (> 0 if ``positive``); ValueError starting with ``name`` otherwise."""
    try:
        g = np.atleast_1d(np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None
    if g.shape == (1,):
        g = np.repeat(g, length)
    if g.shape != (length,):
        raise ValueError(f"{name}: need 1 or {length} values, got {np.size(value)}")
    if not np.all(np.isfinite(g)) or np.any(g <= 0 if positive else g < 0):
        raise ValueError(f"{name} must be finite and {'> 0' if positive else '>= 0'}, "
                         f"got {g.tolist()}")
    return g


def control_period(Ts) -> float:
    """The control period ``Ts`` [s] a law is built for, checked: a finite number > 0."""
    if isinstance(Ts, bool) or not isinstance(Ts, (int, float, np.number)) or not (
            np.isfinite(Ts) and Ts > 0):
        raise ValueError(f"Ts must be a finite number of seconds > 0, got {Ts!r}")
    return float(Ts)


def joint_flex_gains(name: str, joint, flex, n_joints: int, n_flex: int) -> np.ndarray:
    """[``n_joints`` joint gains, ``n_flex`` flexible gains]: ``joint`` one number or one
    per joint, ``flex`` one or ``n_flex``."""
    return np.concatenate([gain_vector(name, joint, n_joints), gain_vector(name, flex, n_flex)])
