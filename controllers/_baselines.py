"""Baseline controllers to compare the PBC against: joint PD (with the rigid arm's
feedforward) and rigid-body computed torque.  They use only the joint part of the state
and ignore the flexible coordinates.

Fair comparison: both are tuned to the same joint error dynamics as the PBC's defaults
(Λ = 3, K_v = (10, 5)) on the rigid arm at θ2 = 0.  The PBC's joint rows are
τ = τ_ff − (M_θθ Λ + K_v) ė − K_v Λ e, i.e. a PD with K_d = M_jj Λ_j + K_v,j and
K_p = K_v,j Λ_j (poles at Λ_j and K_v,j/M_jj); with M_11 = 2.694, M_22 = 1.067 kg m²
(`ArmModel()` at Q = 0) that is K_p = (30, 15), K_d = (18.1, 8.2), and for computed
torque (unit-inertia error dynamics) K_p = Λ K_v/M = (11.1, 14.1), K_d = Λ + K_v/M =
(6.7, 7.7).  A test recomputes these from the model.
"""
from __future__ import annotations

import numpy as np

from reduced_model import ArmModel

from ._gains import gain_vector

__all__ = ["JointPD", "RigidComputedTorque", "rigid_inverse_dynamics"]


def rigid_inverse_dynamics(model: ArmModel, theta, dtheta, ddtheta) -> np.ndarray:
    """M_θθ(θ) θ̈ + C_θθ(θ, θ̇) θ̇ of the rigid arm: the model at q = q̇ = 0."""
    Q, Qd = np.zeros(model.n), np.zeros(model.n)
    Q[:2], Qd[:2] = theta, dtheta
    M = model.mass_matrix(Q)[:2, :2]
    C = model.coriolis_matrix(Q, Qd)[:2, :2]
    return M @ ddtheta + C @ dtheta


class JointPD:
    """τ = τ_ff + K_p (θ_d − θ) + K_d (θ̇_d − θ̇).

    Parameters
    ----------
    model : ArmModel
        The nominal model (for the feedforward).
    kp, kd : one or two numbers
        Joint gains [N m/rad], [N m s/rad].  Defaults (30, 15) and (18.1, 8.2): the PBC's
        joint error dynamics (module docstring).
    feedforward : bool
        τ_ff = M_θθ(θ_d) θ̈_d + C_θθ(θ_d, θ̇_d) θ̇_d of the rigid arm (the model at q = 0)
        if true (default), else 0.
    """

    name = "pd"

    def __init__(self, model: ArmModel, *, kp=(30.0, 15.0), kd=(18.1, 8.2),
                 feedforward: bool = True) -> None:
        if not isinstance(feedforward, (bool, np.bool_)):
            raise ValueError(f"feedforward must be true or false, got {feedforward!r}")
        self.model = model
        self.kp, self.kd = gain_vector("kp", kp, 2), gain_vector("kd", kd, 2)
        self.feedforward = bool(feedforward)

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        n = x.shape[0] // 2
        theta_d, dtheta_d, ddtheta_d = ref(t)
        tau = self.kp * (theta_d - x[:2]) + self.kd * (dtheta_d - x[n:n + 2])
        if self.feedforward:
            tau = tau + rigid_inverse_dynamics(self.model, theta_d, dtheta_d, ddtheta_d)
        return tau


class RigidComputedTorque:
    """Rigid-body computed torque: flexibility ignored.

    τ = M_θθ(θ) (θ̈_d + K_d (θ̇_d − θ̇) + K_p (θ_d − θ)) + C_θθ(θ, θ̇) θ̇, with M and C of the
    model at q = q̇ = 0 (the rigid arm with the same masses).  Defaults K_p = (11.1, 14.1),
    K_d = (6.7, 7.7) [1/s², 1/s]: the PBC's joint error poles (module docstring).
    """

    name = "ct"

    def __init__(self, model: ArmModel, *, kp=(11.1, 14.1), kd=(6.7, 7.7)) -> None:
        self.model = model
        self.kp, self.kd = gain_vector("kp", kp, 2), gain_vector("kd", kd, 2)

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        n = x.shape[0] // 2
        theta, dtheta = x[:2], x[n:n + 2]
        theta_d, dtheta_d, ddtheta_d = ref(t)
        accel = ddtheta_d + self.kd * (dtheta_d - dtheta) + self.kp * (theta_d - theta)
        return rigid_inverse_dynamics(self.model, theta, dtheta, accel)
