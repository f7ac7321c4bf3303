"""The Plant interface of DESIGN.md, shared by the reduced and the Exudyn plant.

A plant is anything with ``name``, ``reset(state0) -> Measurement``,
``step(tau, Ts) -> Measurement`` and ``truth() -> TrueState``.  The closed loop in
`validation` talks to plants only through this interface.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Measurement", "TrueState", "Plant", "PlantFailure", "check_sample_time"]


class PlantFailure(RuntimeError):
    """The plant's solver could not complete a step (the message says why)."""


class Measurement:
    """A named measurement vector at ``time`` [s] (radians, metres, SI).

    A plain slotted class rather than a frozen dataclass: plants create one per control
    period, and this is ~3× cheaper to construct.  Treat it as read-only.
    """

    __slots__ = ("time", "names", "values")

    def __init__(self, time: float, names: tuple[str, ...], values: np.ndarray) -> None:
        self.time = time
        self.names = names
        self.values = values

    def __repr__(self) -> str:
        pairs = ", ".join(f"{k}={v:.6g}" for k, v in zip(self.names, self.values))
        return f"Measurement(t={self.time:.6g}, {pairs})"

    def __getitem__(self, name: str) -> float:
        try:
            return float(self.values[self.names.index(name)])
        except ValueError:
            raise KeyError(f"no signal {name!r} in measurement {self.names}") from None


@dataclass(frozen=True)
class TrueState:
    """What the plant really does, in the reduced model's coordinates.

    Attributes
    ----------
    time : float
    theta, theta_dot : ndarray (2,)
        Joint angles [rad] and rates [rad/s]; θ2 relative to the link-1 tip tangent.
    q, q_dot : ndarray (n1 + n2,)
        Modal coordinates of the plant's assumed modes [m] and their rates.
    tip_positions : ndarray (2, 2)
        (x, y) [m] of the link-1 tip and the link-2 tip (payload).
    tip_deflections : ndarray (2,)
        w_i(L_i) [m] in each link's clamped root frame.
    projection_residual : ndarray (2,)
        Per link, RMS over the link of the deflection the modes cannot represent,
        divided by the RMS deflection (0 for the reduced plant, whose deflection is
        modal by construction).
    """

    time: float
    theta: np.ndarray
    theta_dot: np.ndarray
    q: np.ndarray
    q_dot: np.ndarray
    tip_positions: np.ndarray
    tip_deflections: np.ndarray
    projection_residual: np.ndarray

    @property
    def x(self) -> np.ndarray:
        """The reduced model's state vector [θ, q, θ̇, q̇]."""
        return np.concatenate([self.theta, self.q, self.theta_dot, self.q_dot])


@runtime_checkable
class Plant(Protocol):
    name: str

    def reset(self, state0=None) -> Measurement: ...

    def step(self, tau, Ts: float) -> Measurement: ...

    def truth(self) -> TrueState: ...


def check_sample_time(Ts: float, h: float) -> int:
    """Number of internal steps h in one control period Ts; ValueError unless Ts is a
    positive whole multiple of h (to 1e-9 relative)."""
    if not (np.isfinite(Ts) and Ts > 0.0):
        raise ValueError(f"Ts must be a positive number of seconds, got {Ts!r}")
    n = int(round(Ts / h))
    if n < 1 or abs(n * h - Ts) > 1e-9 * Ts:
        raise ValueError(f"Ts={Ts!r} s is not a whole multiple of the plant step {h!r} s")
    return n
