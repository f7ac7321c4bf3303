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

import math

import numpy as np
from numba import njit

from reduced_model import ArmModel

from ._compiled import CONTROLLER_SIGNATURE, CompiledLaw
from ._gains import control_period, gain_vector

__all__ = ["JointPD", "RigidComputedTorque", "RigidArm", "rigid_torque"]


class RigidArm:
    """The rigid arm of a model (q = q̇ = 0) for fast inverse dynamics.

    Every rigid planar two-link arm has M_θθ(θ2) = [[a + 2c, d + c], [d + c, d]] with
    c = b_c cos θ2 − b_s sin θ2 and C_θθ θ̇ from the Christoffel symbols of that M.  The
    four constants are read off the model's own M at θ2 = 0 and π/2 and checked against
    its M and C at random states (to 1e-9 relative, else RuntimeError), so this is the
    model's rigid part, evaluated in ~1 µs by `rigid_torque` instead of ~30 µs through
    the general M and C.

    Parameters
    ----------
    model : ArmModel
        The model whose rigid part is taken (any modes per link).

    Raises
    ------
    RuntimeError
        If the model's M and C are not those of a rigid planar two-link arm at q = 0
        (to 1e-9 relative).
    """

    def __init__(self, model: ArmModel) -> None:
        Q = np.zeros(model.n)
        m0 = model.mass_matrix(Q)[:2, :2]
        Q[1] = np.pi / 2
        m90 = model.mass_matrix(Q)[:2, :2]
        d = m0[1, 1]
        bc, bs = m0[0, 1] - d, d - m90[0, 1]
        #: (a, d, b_c, b_s)
        self.constants = np.array([m0[0, 0] - 2.0 * bc, d, bc, bs])
        rng = np.random.default_rng(0)
        for _ in range(3):
            th, dth, ddth = rng.uniform(-3, 3, 2), rng.uniform(-2, 2, 2), rng.uniform(-2, 2, 2)
            Q, Qd = np.zeros(model.n), np.zeros(model.n)
            Q[:2], Qd[:2] = th, dth
            want = model.mass_matrix(Q)[:2, :2] @ ddth + model.coriolis_matrix(Q, Qd)[:2, :2] @ dth
            got = self.torque(th, dth, ddth)
            if not np.allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max()):
                raise RuntimeError(f"the model's rigid part is not a planar two-link arm: "
                                   f"{got} vs {want}")

    def torque(self, theta, dtheta, ddtheta) -> np.ndarray:
        """M_θθ(θ) θ̈ + C_θθ(θ, θ̇) θ̇ of the rigid arm."""
        out = np.empty(2)
        rigid_torque(self.constants, np.asarray(theta, float), np.asarray(dtheta, float),
                     np.asarray(ddtheta, float), out)
        return out


@njit(cache=True)
def rigid_torque(ff, th, dth, ddth, tau):
    """M_θθ(θ2) θ̈ + C_θθ(θ2, θ̇) θ̇ of a rigid planar two-link arm, constants (a, d, b_c, b_s)."""
    a, d, bc, bs = ff[0], ff[1], ff[2], ff[3]
    c2, s2 = math.cos(th[1]), math.sin(th[1])
    c = bc * c2 - bs * s2  # the θ2-dependent inertia term
    dc = -(bc * s2 + bs * c2)  # ∂c/∂θ2
    tau[0] = (a + 2.0 * c) * ddth[0] + (d + c) * ddth[1] \
        + dc * (2.0 * dth[0] * dth[1] + dth[1] * dth[1])
    tau[1] = (d + c) * ddth[0] + d * ddth[1] - dc * dth[0] * dth[0]


class JointPD:
    """τ = τ_ff + K_p (θ_d − θ) + K_d (θ̇_d − θ̇).

    Parameters
    ----------
    model : ArmModel
        The nominal model (for the feedforward).
    Ts : float
        The control period [s] (the law is continuous: it is recorded, not used).
    kp, kd : one or two numbers
        Joint gains [N m/rad], [N m s/rad].  Defaults (30, 15) and (18.1, 8.2): the PBC's
        joint error dynamics (module docstring).
    feedforward : bool
        τ_ff = M_θθ(θ_d) θ̈_d + C_θθ(θ_d, θ̇_d) θ̇_d of the rigid arm (the model at q = 0)
        if true (default), else 0.
    """

    name = "pd"

    def __init__(self, model: ArmModel, *, Ts: float, kp=(30.0, 15.0), kd=(18.1, 8.2),
                 feedforward: bool = True) -> None:
        if not isinstance(feedforward, (bool, np.bool_)):
            raise ValueError(f"feedforward must be true or false, got {feedforward!r}")
        self.model, self.Ts = model, control_period(Ts)
        self.rigid = RigidArm(model) if feedforward else None
        self.kp, self.kd = gain_vector("kp", kp, 2), gain_vector("kd", kd, 2)

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        n = x.shape[0] // 2
        theta_d, dtheta_d, ddtheta_d = ref(t)
        tau = self.kp * (theta_d - x[:2]) + self.kd * (dtheta_d - x[n:n + 2])
        if self.rigid is not None:
            tau = tau + self.rigid.torque(theta_d, dtheta_d, ddtheta_d)
        return tau

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): gains and the rigid constants."""
        ff = self.rigid.constants if self.rigid is not None else np.zeros(4)
        return CompiledLaw.of(pd_kernel, CONTROLLER_SIGNATURE, self.model,
                              ints=[int(self.rigid is not None)],
                              reals=np.concatenate([self.kp, self.kd, ff]), state=np.zeros(2))


@njit(cache=True)
def pd_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`JointPD` compiled: ints = [feedforward], reals = [K_p, K_d, rigid constants]."""
    n = x.shape[0] // 2
    for i in range(2):
        tau[i] = reals[i] * (ref[i] - x[i]) + reals[2 + i] * (ref[2 + i] - x[n + i])
    if ints[0] == 1:
        rigid_torque(reals[4:8], ref[0:2], ref[2:4], ref[4:6], state)
        tau[0] += state[0]
        tau[1] += state[1]
    return 2


class RigidComputedTorque:
    """Rigid-body computed torque: flexibility ignored.

    τ = M_θθ(θ) (θ̈_d + K_d (θ̇_d − θ̇) + K_p (θ_d − θ)) + C_θθ(θ, θ̇) θ̇, with M and C of the
    model at q = q̇ = 0 (the rigid arm with the same masses).

    Parameters
    ----------
    model : ArmModel
        The nominal model (its rigid part: `RigidArm`).
    Ts : float
        The control period [s] (the law is continuous: it is recorded, not used).
    kp, kd : (float, float) or float
        K_p [1/s²] and K_d [1/s] per joint, or one number for both; defaults (11.1, 14.1)
        and (6.7, 7.7): the PBC's joint error poles (module docstring).
    """

    name = "ct"

    def __init__(self, model: ArmModel, *, Ts: float, kp=(11.1, 14.1), kd=(6.7, 7.7)) -> None:
        self.model, self.Ts = model, control_period(Ts)
        self.rigid = RigidArm(model)
        self.kp, self.kd = gain_vector("kp", kp, 2), gain_vector("kd", kd, 2)

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        n = x.shape[0] // 2
        theta, dtheta = x[:2], x[n:n + 2]
        theta_d, dtheta_d, ddtheta_d = ref(t)
        accel = ddtheta_d + self.kd * (dtheta_d - dtheta) + self.kp * (theta_d - theta)
        return self.rigid.torque(theta, dtheta, accel)

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): gains and the rigid constants."""
        return CompiledLaw.of(ct_kernel, CONTROLLER_SIGNATURE, self.model,
                              reals=np.concatenate([self.kp, self.kd, self.rigid.constants]),
                              state=np.zeros(2))


@njit(cache=True)
def ct_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`RigidComputedTorque` compiled: reals = [K_p, K_d, rigid constants]."""
    n = x.shape[0] // 2
    for i in range(2):
        state[i] = ref[4 + i] + reals[2 + i] * (ref[2 + i] - x[n + i]) + reals[i] * (ref[i] - x[i])
    rigid_torque(reals[4:8], x[0:2], x[n:n + 2], state, tau)
    return 2
