"""Diagonal gains given per joint and per flexible coordinate, validated once."""
from __future__ import annotations

import numpy as np

__all__ = ["gain_vector"]


def gain_vector(name: str, joint, flex=(), n_flex: int = 0) -> np.ndarray:
    """[2 joint gains, ``n_flex`` flexible gains] as one array.  ``joint`` is one number
    or two; ``flex`` one number or ``n_flex`` (nothing when ``n_flex`` is 0).  Gains
    must be finite and >= 0 (ValueError naming ``name`` otherwise)."""
    j = np.atleast_1d(np.asarray(joint, dtype=float))
    f = np.atleast_1d(np.asarray(flex, dtype=float))
    if j.shape == (1,):
        j = np.repeat(j, 2)
    if n_flex and f.shape == (1,):
        f = np.repeat(f, n_flex)
    if j.shape != (2,) or f.shape != (n_flex,):
        raise ValueError(f"{name}: need 1 or 2 joint gains and 1 or {n_flex} flexible gains")
    gains = np.concatenate([j, f])
    if not np.all(np.isfinite(gains)) or np.any(gains < 0):
        raise ValueError(f"{name} must be finite and >= 0, got {gains.tolist()}")
    return gains
