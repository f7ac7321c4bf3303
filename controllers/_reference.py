"""Reference trajectories: the paper's eq. (37) and a smooth rest-to-rest move.

A reference is called with the time and returns the desired joint angles, rates and
accelerations (each of shape (N,), one per joint); the desired flexible coordinates are zero (the paper's
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

    PAPER = 0  # eq. (37): spec = [a_1 … a_N, ω_1 … ω_N]
    QUINTIC = 1  # rest to rest: spec = [T, start_1 … start_N, goal_1 … goal_N]


@njit(cache=True)
def reference_into(kind, spec, t, out):
    """θ_d, θ̇_d, θ̈_d at ``t`` into out[0:N], out[N:2N], out[2N:3N] (N joints: ``out``
    holds 3N) for the reference ``kind`` (`ReferenceKind`) with parameters ``spec``."""
    N = out.shape[0] // 3
    if kind == ReferenceKind.PAPER:  # eq. (37)
        for j in range(N):
            a, w = spec[j], spec[N + j]
            s, c = math.sin(w * t), math.cos(w * t)
            out[j] = a * s
            out[N + j] = a * w * c
            out[2 * N + j] = -a * w * w * s
        return
    T = spec[0]  # quintic blend 10τ³ − 15τ⁴ + 6τ⁵, then hold
    tau = min(max(t / T, 0.0), 1.0)
    s = tau * tau * tau * (10 - 15 * tau + 6 * tau * tau)
    ds = 30 * tau * tau * (1 - tau) * (1 - tau) / T if 0 < t < T else 0.0
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / (T * T) if 0 < t < T else 0.0
    for j in range(N):
        d = spec[1 + N + j] - spec[1 + j]
        out[j] = spec[1 + j] + s * d
        out[N + j] = ds * d
        out[2 * N + j] = dds * d


class _Reference:
    """A reference evaluated by `reference_into`; subclasses give ``kind`` and ``spec``."""

    kind: ReferenceKind

    spec: np.ndarray  # the parameters `reference_into` reads (read-only by convention)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        N = self.joints
        out = np.empty(3 * N)
        reference_into(int(self.kind), self.spec, float(t), out)
        return out[0:N], out[N:2 * N], out[2 * N:]


@dataclass(frozen=True)
class PaperReference(_Reference):
    """θ_id = a_i sin(ω_i t): eq. (37) with a = 2 rad, ω = (0.1π, 0.2π) rad/s.

    Parameters
    ----------
    amplitude : tuple of float
        a_i [rad], one per joint (default 2, 2).
    omega : tuple of float
        ω_i [rad/s], one per joint (default 0.1π, 0.2π).

    Examples
    --------
    >>> from controllers import PaperReference
    >>> theta_d, dtheta_d, ddtheta_d = PaperReference()(2.5)
    >>> theta_d.round(4), dtheta_d.round(4)  # 2 sin(π/4), 2 sin(π/2); 0.2π·2 cos(π/4), 0
    (array([1.4142, 2.    ]), array([0.4443, 0.    ]))
    """

    amplitude: tuple[float, ...] = (2.0, 2.0)
    omega: tuple[float, ...] = (0.1 * np.pi, 0.2 * np.pi)
    kind = ReferenceKind.PAPER

    def __post_init__(self) -> None:
        if len(self.amplitude) != len(self.omega):
            raise ValueError(f"reference: {len(self.amplitude)} amplitudes for "
                             f"{len(self.omega)} frequencies")

    @property
    def joints(self) -> int:
        return len(self.amplitude)

    @functools.cached_property
    def spec(self) -> np.ndarray:
        return np.array([*self.amplitude, *self.omega], dtype=float)


@dataclass(frozen=True)
class QuinticMove(_Reference):
    """Rest-to-rest move from ``start`` to ``goal`` [rad] in ``duration`` [s] with zero
    velocity and acceleration at both ends (quintic blend 10τ³ − 15τ⁴ + 6τ⁵), then hold.

    Parameters
    ----------
    start, goal : tuple of float
        Joint angles [rad] at the start and the end, one per joint (defaults (0, 0) and
        (1, −1)).
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

    start: tuple[float, ...] = (0.0, 0.0)
    goal: tuple[float, ...] = (1.0, -1.0)
    duration: float = 4.0
    kind = ReferenceKind.QUINTIC

    def __post_init__(self) -> None:
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"reference.duration must be > 0, got {self.duration!r}")
        if len(self.start) != len(self.goal):
            raise ValueError(f"reference: {len(self.start)} start angles for "
                             f"{len(self.goal)} goals")

    @property
    def joints(self) -> int:
        return len(self.start)

    @functools.cached_property
    def spec(self) -> np.ndarray:
        return np.array([self.duration, *self.start, *self.goal], dtype=float)
