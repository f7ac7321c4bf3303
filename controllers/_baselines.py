"""Baseline controllers to compare the PBC against: joint PD (optionally with the rigid
arm's feedforward) and rigid-body computed torque.  They use only the joint part of the
state estimate and ignore the flexible coordinates."""
from __future__ import annotations

import numpy as np

from reduced_model import ArmModel

from ._gains import gain_vector

__all__ = ["JointPD", "RigidComputedTorque"]


def rigid_inverse_dynamics(model: ArmModel, theta, dtheta, ddtheta) -> np.ndarray:
    """M_θθ(θ) θ̈ + C_θθ(θ, θ̇) θ̇ of the rigid arm: the model at q = q̇ = 0."""
    Q, Qd = np.zeros(model.n), np.zeros(model.n)
    Q[:2], Qd[:2] = theta, dtheta
    M = model.mass_matrix(Q)[:2, :2]
    C = model.coriolis_matrix(Q, Qd)[:2, :2]
    return M @ ddtheta + C @ dtheta


class JointPD:
    """τ = τ_ff + Kp (θd − θ̂) + Kd (θ̇d − θ̂̇).

    Parameters
    ----------
    kp, kd : (float, float)
        Joint gains [N m/rad], [N m s/rad].  Defaults (40, 20) and (8, 4): roughly a
        4–6 rad/s, well-damped loop on each joint of the Table 1 arm (joint inertias
        ≈ 2.7 and 1.1 kg m² at θ2 = 0).
    feedforward : ArmModel, optional
        If given, τ_ff = M_θθ(θd) θ̈d + C_θθ(θd, θ̇d) θ̇d of the rigid arm (the model
        with q = 0): the "PD with rigid feedforward" baseline.  Otherwise τ_ff = 0.
    """

    name = "pd"

    def __init__(self, kp=(40.0, 20.0), kd=(8.0, 4.0), feedforward: ArmModel | None = None):
        self.kp, self.kd = gain_vector("kp", kp), gain_vector("kd", kd)
        self.model = feedforward
        if feedforward is not None:
            self.name = "pd_ff"

    def __call__(self, t: float, x_hat: np.ndarray, ref) -> np.ndarray:
        n = x_hat.shape[0] // 2
        theta_d, dtheta_d, ddtheta_d = ref(t)
        tau = self.kp * (theta_d - x_hat[:2]) + self.kd * (dtheta_d - x_hat[n:n + 2])
        if self.model is not None:
            tau = tau + rigid_inverse_dynamics(self.model, theta_d, dtheta_d, ddtheta_d)
        return tau


class RigidComputedTorque:
    """Rigid-body computed torque: flexibility ignored.

    τ = M_θθ(θ̂) (θ̈_d + K_d (θ̇_d − θ̂̇) + K_p (θ_d − θ̂)) + C_θθ(θ̂, θ̂̇) θ̂̇, with M and C of
    the model at q = q̇ = 0 (the rigid arm with the same masses).  Defaults K_p = 16,
    K_d = 8 [1/s², 1/s]: a critically damped 4 rad/s error dynamics on each joint.
    """

    name = "ct"

    def __init__(self, model: ArmModel, kp=(16.0, 16.0), kd=(8.0, 8.0)) -> None:
        self.model = model
        self.kp, self.kd = gain_vector("kp", kp), gain_vector("kd", kd)

    def __call__(self, t: float, x_hat: np.ndarray, ref) -> np.ndarray:
        n = x_hat.shape[0] // 2
        theta, dtheta = x_hat[:2], x_hat[n:n + 2]
        theta_d, dtheta_d, ddtheta_d = ref(t)
        accel = ddtheta_d + self.kd * (dtheta_d - dtheta) + self.kp * (theta_d - theta)
        return rigid_inverse_dynamics(self.model, theta, dtheta, accel)
