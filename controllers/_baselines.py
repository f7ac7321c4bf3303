"""Baseline controllers to compare the PBC against: joint PD (with the rigid arm's
feedforward) and rigid-body computed torque, on any arm.  They use only the joint part of
the state and ignore the flexible coordinates.

Both rest on the rigid arm's inverse dynamics (`rigid_inverse_dynamics`): the model's
own M, C and gravity at q = q̇ = 0, from its compiled kernels.

Fair comparison: both are tuned to the joint error dynamics of the PBC's default gains
(`controllers.arm_gains`: Λ and K_v per joint, M_jj the inertia about joint j of the arm
straight and at rest).  The PBC's joint rows are τ = τ_ff − (M_θθ Λ + K_v) ė − K_v Λ e,
i.e. a PD with K_d = M_jj Λ_j + K_v,j and K_p = K_v,j Λ_j (poles at Λ_j and
K_v,j/M_jj), and for computed torque (unit-inertia error dynamics) K_p = Λ K_v/M and
K_d = Λ + K_v/M; each gain is rounded to 0.1 (to one significant figure below 1).  On
the paper's arm (Λ = 3, K_v = (10, 5), M_jj = 2.694, 1.067 kg m²) that is K_p = (30,
15), K_d = (18.1, 8.2) for the PD and K_p = (11.1, 14.1), K_d = (6.7, 7.7) for computed
torque.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from reduced_model import ArmModel
from reduced_model.dynamics import mass_bias_into, unpack_model, unpack_workspace

from ._compiled import CONTROLLER_SIGNATURE, CompiledLaw
from ._gains import arm_gains, control_period, gain_vector

__all__ = ["JointPD", "RigidComputedTorque", "baseline_gains", "rigid_inverse_dynamics"]


def _tenth(value: float) -> float:
    """Rounded to 0.1 (one significant figure below 1, so that no gain rounds to 0)."""
    return round(value, 1) if value >= 1.0 else float(f"{value:.0e}")


def baseline_gains(model: ArmModel, Ts: float, law: str) -> tuple[np.ndarray, np.ndarray]:
    """Default (K_p, K_d) of the joint PD (``law="pd"``) or of computed torque
    (``"ct"``) on ``model`` at ``Ts``: the PBC's joint error dynamics (module docstring).

    Parameters
    ----------
    model : ArmModel
        The law's nominal model.
    Ts : float
        The control period [s].
    law : {"pd", "ct"}
        Which law's gains.

    Returns
    -------
    (ndarray, ndarray)
        K_p and K_d, one per joint ([N m/rad], [N m s/rad] for the PD; [1/s²], [1/s]
        for computed torque).
    """
    rule = arm_gains(model, Ts)
    lam, kv, m = rule.lambda_joint, rule.kv_joint, rule.inertia
    if law == "pd":
        kp, kd = kv * lam, m * lam + kv
    else:
        kp, kd = lam * kv / m, lam + kv / m
    return (np.array([_tenth(g) for g in kp]), np.array([_tenth(g) for g in kd]))


def _flag(name: str, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return bool(value)


def _without_gravity(model: ArmModel) -> ArmModel:
    """``model`` with gravity switched off: what a law without gravity compensation
    believes."""
    if not any(model.params.gravity):
        return model
    return ArmModel(model.params.replace(gravity=(0.0, 0.0)), model.modes_per_link,
                    model.kinematics)


@njit(cache=True, forceinline=True)
def rigid_inverse_dynamics(d, ws, theta, dtheta, ddtheta, Qs, tau):
    """τ = M_θθ θ̈ + C_θθ θ̇ + g_θ of the arm at Q = [θ, q₀], Q̇ = [θ̇, 0] into
    ``tau[:N]``, from the model's kernels (paper's kinematics: at rest both kinematics
    have the same M and gravity).  ``Qs`` is scratch (2n) whose entries N…n−1 hold q₀:
    0 for the rigid arm (the model at q = q̇ = 0), the static deflection for the arm at
    rest in gravity (the LQR's operating point)."""
    N, n = d.links, d.n
    Q, Qd = Qs[:n], Qs[n:]
    for i in range(N):
        Q[i] = theta[i]
        Qd[i] = dtheta[i]
    for i in range(N, n):
        Qd[i] = 0.0
    mass_bias_into(d, Q, Qd, ws.M, ws.f, ws, False)
    for i in range(N):
        acc = ws.f[i]
        for j in range(N):
            acc += ws.M[i, j] * ddtheta[j]
        tau[i] = acc


class _JointLaw:
    """What the PD and computed torque share: gains, the model they believe and running
    their kernel from Python on their own buffers."""

    _kernel = None
    _law = ""

    def _setup(self, model, Ts, kp, kd, gravity, ints) -> None:
        self.model, self.Ts = model, control_period(Ts)
        N = model.n_joints
        default_kp, default_kd = baseline_gains(model, self.Ts, self._law)
        self.kp = gain_vector("kp", default_kp if kp is None else kp, N)
        self.kd = gain_vector("kd", default_kd if kd is None else kd, N)
        self.gravity_compensation = _flag("gravity_compensation", gravity)
        self._believed = model if self.gravity_compensation else _without_gravity(model)
        self._ints = np.array(ints, dtype=np.int64)
        self._reals = np.concatenate([self.kp, self.kd])
        self._state = np.zeros(3 * model.n_joints + 2 * model.n)
        self._work = self._believed.new_workspace()
        self._ref = np.zeros(3 * N)
        self._tau = np.zeros(N)
        self._residual = np.zeros(0)

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        N = self.model.n_joints
        theta_d, dtheta_d, ddtheta_d = ref(t)
        self._ref[:N], self._ref[N:2 * N], self._ref[2 * N:] = theta_d, dtheta_d, ddtheta_d
        self._kernel(t, np.ascontiguousarray(x, dtype=float), self._ref, self._ints,
                     self._reals, self._state, *self._believed.packed, *self._work, self._tau,
                     self._residual)
        return self._tau.copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): the gains, the model it believes."""
        return CompiledLaw.of(self._kernel, CONTROLLER_SIGNATURE, self._believed,
                              ints=self._ints, reals=self._reals, state=self._state)


class JointPD(_JointLaw):
    """τ = τ_ff + K_p (θ_d − θ) + K_d (θ̇_d − θ̇).

    Parameters
    ----------
    model : ArmModel
        The nominal model (for the feedforward).
    Ts : float
        The control period [s] (the law is continuous: it is recorded, not used).
    kp, kd : one number, or one per joint
        Joint gains [N m/rad], [N m s/rad]; default: the PBC's joint error dynamics
        (`baseline_gains`; (30, 15) and (18.1, 8.2) on the paper's arm).
    feedforward : bool
        τ_ff includes M_θθ(θ_d) θ̈_d + C_θθ(θ_d, θ̇_d) θ̇_d of the rigid arm (the model at
        q = q̇ = 0) if true (default).
    gravity_compensation : bool
        τ_ff includes the rigid arm's gravity torque g_θ(θ_d) (default true; false: the
        joints settle off their reference by the static moment over K_p).
    """

    name = "pd"
    _law = "pd"

    def __init__(self, model: ArmModel, *, Ts: float, kp=None, kd=None,
                 feedforward: bool = True, gravity_compensation: bool = True) -> None:
        feedforward = _flag("feedforward", feedforward)
        self.feedforward = feedforward
        self._kernel = pd_kernel
        self._setup(model, Ts, kp, kd, gravity_compensation, [int(feedforward)])


@njit(cache=True)
def pd_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`JointPD` compiled: ints = [feedforward], reals = [K_p, K_d], state = scratch
    (3N + 2n)."""
    d = unpack_model(mi, mr)
    ws = unpack_workspace(mi, wc, wr)
    N, n = d.links, d.n
    zero, Qs, ff = state[:2 * N], state[2 * N:2 * N + 2 * n], state[2 * N + 2 * n:]
    for i in range(2 * n):
        Qs[i] = 0.0
    if ints[0] == 1:  # the whole rigid inverse dynamics of the reference
        rigid_inverse_dynamics(d, ws, ref[:N], ref[N:2 * N], ref[2 * N:3 * N], Qs, ff)
    elif d.gx != 0.0 or d.gy != 0.0:  # its gravity torque only
        for i in range(2 * N):
            zero[i] = 0.0
        rigid_inverse_dynamics(d, ws, ref[:N], zero[:N], zero[N:], Qs, ff)
    else:
        for i in range(N):
            ff[i] = 0.0
    for i in range(N):
        tau[i] = reals[i] * (ref[i] - x[i]) + reals[N + i] * (ref[N + i] - x[n + i]) + ff[i]
    return N


class RigidComputedTorque(_JointLaw):
    """Rigid-body computed torque: flexibility ignored.

    τ = M_θθ(θ) (θ̈_d + K_d (θ̇_d − θ̇) + K_p (θ_d − θ)) + C_θθ(θ, θ̇) θ̇ + g_θ(θ), with M, C
    and g of the model at q = q̇ = 0 (the rigid arm with the same masses:
    `rigid_inverse_dynamics`).

    Parameters
    ----------
    model : ArmModel
        The nominal model (its rigid part).
    Ts : float
        The control period [s] (the law is continuous: it is recorded, not used).
    kp, kd : one number, or one per joint
        K_p [1/s²] and K_d [1/s]; default: the PBC's joint error poles
        (`baseline_gains`; (11.1, 14.1) and (6.7, 7.7) on the paper's arm).
    gravity_compensation : bool
        Include the gravity torque g_θ(θ) (default true; false: the joints settle off
        their reference by the static moment over M_θθ K_p).
    """

    name = "ct"
    _law = "ct"

    def __init__(self, model: ArmModel, *, Ts: float, kp=None, kd=None,
                 gravity_compensation: bool = True) -> None:
        self._kernel = ct_kernel
        self._setup(model, Ts, kp, kd, gravity_compensation, [])


@njit(cache=True)
def ct_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`RigidComputedTorque` compiled: reals = [K_p, K_d], state = scratch (3N + 2n)."""
    d = unpack_model(mi, mr)
    ws = unpack_workspace(mi, wc, wr)
    N, n = d.links, d.n
    accel, Qs = state[:N], state[3 * N:3 * N + 2 * n]
    for i in range(2 * n):
        Qs[i] = 0.0
    for i in range(N):
        accel[i] = ref[2 * N + i] + reals[N + i] * (ref[N + i] - x[n + i]) \
            + reals[i] * (ref[i] - x[i])
    rigid_inverse_dynamics(d, ws, x[:N], x[n:n + N], accel, Qs, tau)
    return N
