"""Reference trajectories: the paper's eq. (37) and a smooth rest-to-rest move.

A reference is called with the time and returns the desired joint angles, rates and
accelerations (each shape (2,)); the desired flexible coordinates are zero (the paper's
q_d = 0, eq. 4).  Each formula is written once, in `reference_into`, which compiled
loops call directly and the Python objects call too.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numba import njit

__all__ = ["PaperReference", "QuinticMove", "ReferenceKind", "reference_into"]


class ReferenceKind(IntEnum):
    """The reference formulas of `reference_into`."""

    PAPER = 0  # eq. (37): spec = [a1, a2, ω1, ω2]
    QUINTIC = 1  # rest to rest: spec = [T, start1, start2, goal1, goal2]


@njit(cache=True)
def reference_into(kind, spec, t, out):
    """θ_d, θ̇_d, θ̈_d at ``t`` into out[0:2], out[2:4], out[4:6] for the reference
    ``kind`` (`ReferenceKind`) with parameters ``spec``."""
    if kind == ReferenceKind.PAPER:  # eq. (37)
        a1, a2, w1, w2 = spec[0], spec[1], spec[2], spec[3]
        s1, c1, s2, c2 = math.sin(w1 * t), math.cos(w1 * t), math.sin(w2 * t), math.cos(w2 * t)
        out[0], out[1] = a1 * s1, a2 * s2
        out[2], out[3] = a1 * w1 * c1, a2 * w2 * c2
        out[4], out[5] = -a1 * w1 * w1 * s1, -a2 * w2 * w2 * s2
        return
    T = spec[0]  # quintic blend 10τ³ − 15τ⁴ + 6τ⁵, then hold
    tau = min(max(t / T, 0.0), 1.0)
    s = tau * tau * tau * (10 - 15 * tau + 6 * tau * tau)
    ds = 30 * tau * tau * (1 - tau) * (1 - tau) / T if 0 < t < T else 0.0
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / (T * T) if 0 < t < T else 0.0
    for j in range(2):
        d = spec[3 + j] - spec[1 + j]
        out[j] = spec[1 + j] + s * d
        out[2 + j] = ds * d
        out[4 + j] = dds * d


class _Reference:
    """A reference evaluated by `reference_into`; subclasses give ``kind`` and ``spec``."""

    kind: ReferenceKind

    spec: np.ndarray  # the parameters `reference_into` reads (read-only by convention)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        out = np.empty(6)
        reference_into(int(self.kind), self.spec, float(t), out)
        return out[0:2], out[2:4], out[4:6]


@dataclass(frozen=True)
class PaperReference(_Reference):
    """θ1d = a1 sin(ω1 t), θ2d = a2 sin(ω2 t): eq. (37) with a = 2 rad, ω = (0.1π, 0.2π) rad/s.

    Parameters
    ----------
    amplitude : (float, float)
        a1, a2 [rad] (default 2, 2).
    omega : (float, float)
        ω1, ω2 [rad/s] (default 0.1π, 0.2π).

    Examples
    --------
    >>> from controllers import PaperReference
    >>> theta_d, dtheta_d, ddtheta_d = PaperReference()(2.5)
    >>> theta_d.round(4), dtheta_d.round(4)  # 2 sin(π/4), 2 sin(π/2); 0.2π·2 cos(π/4), 0
    (array([1.4142, 2.    ]), array([0.4443, 0.    ]))
    """

    amplitude: tuple[float, float] = (2.0, 2.0)
    omega: tuple[float, float] = (0.1 * np.pi, 0.2 * np.pi)
    kind = ReferenceKind.PAPER

    @functools.cached_property
    def spec(self) -> np.ndarray:
        return np.array([*self.amplitude, *self.omega], dtype=float)


@dataclass(frozen=True)
class QuinticMove(_Reference):
    """Rest-to-rest move from ``start`` to ``goal`` [rad] in ``duration`` [s] with zero
    velocity and acceleration at both ends (quintic blend 10τ³ − 15τ⁴ + 6τ⁵), then hold.

    Parameters
    ----------
    start, goal : (float, float)
        Joint angles [rad] at the start and the end (defaults (0, 0) and (1, −1)).
    duration : float
        Time of the move [s] (default 4); the reference holds ``goal`` after it.

    Examples
    --------
    >>> from controllers import QuinticMove
    >>> move = QuinticMove(goal=(1.0, -1.0), duration=4.0)
    >>> move(2.0)[0], move(2.0)[1]  # half-way, at the largest speed 15/8 · 1 rad / 4 s
    (array([ 0.5, -0.5]), array([ 0.46875, -0.46875]))
    >>> move(9.0)[0]
    array([ 1., -1.])
    """

    start: tuple[float, float] = (0.0, 0.0)
    goal: tuple[float, float] = (1.0, -1.0)
    duration: float = 4.0
    kind = ReferenceKind.QUINTIC

    def __post_init__(self) -> None:
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"reference.duration must be > 0, got {self.duration!r}")

    @functools.cached_property
    def spec(self) -> np.ndarray:
        return np.array([self.duration, *self.start, *self.goal], dtype=float)
