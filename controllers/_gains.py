"""Diagonal gains given as one number or one per coordinate, validated once."""
from __future__ import annotations

import numpy as np

__all__ = ["gain_vector", "joint_flex_gains", "control_period"]


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


def joint_flex_gains(name: str, joint, flex, n_flex: int) -> np.ndarray:
    """[2 joint gains, ``n_flex`` flexible gains]: ``joint`` one or two numbers, ``flex``
    one or ``n_flex``."""
    return np.concatenate([gain_vector(name, joint, 2), gain_vector(name, flex, n_flex)])
