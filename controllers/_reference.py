"""Reference trajectories: the paper's eq. (37) and a smooth rest-to-rest move.

A reference is called with the time and returns the desired joint angles, rates and
accelerations (each shape (2,)); the desired flexible coordinates are zero (the paper's
q_d = 0, eq. 4).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PaperReference", "QuinticMove"]


@dataclass(frozen=True)
class PaperReference:
    """θ1d = a1 sin(ω1 t), θ2d = a2 sin(ω2 t): eq. (37) with a = 2 rad, ω = (0.1π, 0.2π) rad/s."""

    amplitude: tuple[float, float] = (2.0, 2.0)
    omega: tuple[float, float] = (0.1 * np.pi, 0.2 * np.pi)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # Scalar math: six numpy ufuncs on 2-element arrays cost 4 µs, this 1.5 µs, and the
        # closed loop evaluates the reference at every sample.
        (a1, a2), (w1, w2) = self.amplitude, self.omega
        s1, c1, s2, c2 = math.sin(w1 * t), math.cos(w1 * t), math.sin(w2 * t), math.cos(w2 * t)
        return (np.array((a1 * s1, a2 * s2)), np.array((a1 * w1 * c1, a2 * w2 * c2)),
                np.array((-a1 * w1 * w1 * s1, -a2 * w2 * w2 * s2)))


@dataclass(frozen=True)
class QuinticMove:
    """Rest-to-rest move from ``start`` to ``goal`` [rad] in ``duration`` [s] with zero
    velocity and acceleration at both ends (quintic blend 10τ³ − 15τ⁴ + 6τ⁵), then hold."""

    start: tuple[float, float] = (0.0, 0.0)
    goal: tuple[float, float] = (1.0, -1.0)
    duration: float = 4.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"reference.duration must be > 0, got {self.duration!r}")

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        T = self.duration
        tau = min(max(t / T, 0.0), 1.0)
        s = tau**3 * (10 - 15 * tau + 6 * tau**2)
        ds = 30 * tau**2 * (1 - tau) ** 2 / T if 0 < t < T else 0.0
        dds = 60 * tau * (1 - tau) * (1 - 2 * tau) / T**2 if 0 < t < T else 0.0
        d = np.asarray(self.goal, float) - np.asarray(self.start, float)
        return np.asarray(self.start, float) + s * d, ds * d, dds * d

