"""The paper's passivity-based controller, eq. (14)–(20), on the reduced model of any arm.

    e = Q − Q_d,  s = ė + Λ e,  v = Q̇_d − Λ e                       (4), (5), (14)
    τ = M(Q) v̇ + C(Q, Q̇) v + g(Q) + D Q̇ − K_v s                   (20)

with the paper's g(Q) = ∂V/∂Q the force of the whole potential: the elastic K Q (on a
model with exact kinematics, its exact bending forces) and, for an arm in gravity, the
gravitational ∂V_g/∂Q — the energy shaping of the PBC with the arm's own potential —,
and the model's Kelvin–Voigt D Q̇.  Q_d = [θ_d, q_d]: the paper's q_d = 0 on a horizontal
arm; in gravity q_d is the links' static deflection at θ_d (K q_d = −∂V_g/∂q at
[θ_d, q_d], three fixed-point steps from 0), the desired pose of an arm that sags, with
q̇_d = q̈_d = 0.  Eq. (20) asks for n generalised forces; the arm has N actuators.  Two
laws, two names:

- `PassivityBasedController` (``"pbc"``) applies the joint rows of eq. (20) — what the
  motors can do — and reports the others (forces on the flexible coordinates no actuator
  can produce) as the *unrealisable residual*.  K and D have no joint rows and K_v, Λ are
  diagonal, so the flexible gain K_v,f and the damping compensation cannot change the
  applied torque: this law does not take them.  Λ_f still matters (it enters the joint
  rows through M_θq v̇_q and C_θq v_q).
- `IdealisedPBC` (``"pbc-idealised"``) applies all n rows: the paper's idealisation, which
  only the reduced plant can take (generalised forces on the modal coordinates).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from reduced_model import ArmModel
from reduced_model.dynamics import (coriolis_matrix_into, mass_bias_into, mass_matrix_into,
                                    matrix_view, unpack_model, unpack_workspace)
from reduced_model.dynamics.exact import exact_elastic

from ._compiled import CONTROLLER_SIGNATURE, CompiledLaw
from ._gains import arm_gains, control_period, gain_vector

__all__ = ["PassivityBasedController", "IdealisedPBC"]


class PassivityBasedController:
    """Eq. (20), the joint rows applied (the realisable law), with diagonal Λ and K_v.

    Parameters
    ----------
    model : ArmModel
        The nominal model (its M, Christoffel C, K, D and gravity).
    Ts : float
        The control period [s] (the law is continuous: it is recorded, not used).
    lambda_joint, lambda_flex : gains of Λ [1/s] on θ (one number, or one per joint) and on
        q (one number, or one per mode); default: the arm's rule (`controllers.arm_gains`).
    kv_joint : gains of K_v on θ [N m s/rad]; default: the arm's rule.
    gravity_compensation : bool
        Include gravity in g(Q) and the static deflection in q_d (default true; false:
        the law of a horizontal arm, whose joints then settle off their reference by the
        static moment over K_v Λ).

    The rule's gains on the paper's arm are the paper's (Λ = 3, 3 | 1; K_v = 10, 5),
    chosen on its scenario from rest: the joint error dynamics of the rigid arm at
    θ2 = 0 have poles at Λ = 3 and K_v/M_jj = 3.7, 4.7 rad/s.  Larger joint gains (Λ = 5,
    K_v = 20, 10) bend link 1 by 10 cm at the start (the reference starts at 0.6/1.3 rad/s
    while the arm is at rest) and track worse after 2 s; Λ_f > 0 couples into the joint
    rows through M_θq v̇_q.
    """

    name = "pbc"

    def __init__(self, model: ArmModel, *, Ts: float, lambda_joint=None, lambda_flex=None,
                 kv_joint=None, gravity_compensation: bool = True) -> None:
        self._setup(model, Ts, lambda_joint, lambda_flex, kv_joint, 0.0, False,
                    gravity_compensation)
        #: Unrealisable flexible-coordinate forces of the last call (rows N… of eq. 20).
        self.residual = self._residual

    def _setup(self, model, Ts, lambda_joint, lambda_flex, kv_joint, kv_flex, damping,
               gravity) -> None:
        self.model, self.Ts = model, control_period(Ts)
        n, N = model.n, model.n_joints
        if not isinstance(gravity, (bool, np.bool_)):
            raise ValueError(f"gravity_compensation must be true or false, got {gravity!r}")
        rule = arm_gains(model, self.Ts)
        self.lam = np.concatenate([
            gain_vector("lambda_joint", rule.lambda_joint if lambda_joint is None
                        else lambda_joint, N),
            gain_vector("lambda_flex", rule.lambda_flex if lambda_flex is None
                        else lambda_flex, n - N)])
        self.kv = np.concatenate([
            gain_vector("kv_joint", rule.kv_joint if kv_joint is None else kv_joint, N),
            gain_vector("kv_flex", kv_flex, n - N)])
        self.compensate_damping = bool(damping)
        self.gravity_compensation = bool(gravity) and any(model.params.gravity)
        self._kernel = pbc_kernel_exact if model.exact else pbc_kernel
        self._ints = np.array([self._rows(), int(self.compensate_damping),
                               int(self.gravity_compensation)], dtype=np.int64)
        stiffness = np.zeros(0)
        if self.gravity_compensation and n > N:  # K_ff's Cholesky factor, for q_d
            stiffness = np.ravel(np.linalg.cholesky(model.stiffness_matrix()[N:, N:]))
        self._reals = np.concatenate([self.lam, self.kv, stiffness])
        self._state = np.zeros(2 * n * n + 5 * n + (2 * n if self.gravity_compensation else 0))
        self._work = model.new_workspace()
        self._ref = np.zeros(3 * N)
        self._tau = np.zeros(n)
        self._residual = np.zeros(n - self._rows())

    def _rows(self) -> int:
        return self.model.n_joints

    def _eq20(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        """Eq. (20)'s applied rows (the kernel's own computation), the rest into
        ``residual``."""
        N = self.model.n_joints
        theta_d, dtheta_d, ddtheta_d = ref(t)
        self._ref[:N], self._ref[N:2 * N], self._ref[2 * N:] = theta_d, dtheta_d, ddtheta_d
        rows = self._kernel(t, np.ascontiguousarray(x, dtype=float), self._ref, self._ints,
                            self._reals, self._state, *self.model.packed, *self._work,
                            self._tau, self._residual)
        return self._tau[:rows].copy()

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        return self._eq20(t, x, ref)

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): this law's kernel and gains."""
        return CompiledLaw.of(self._kernel, CONTROLLER_SIGNATURE, self.model, ints=self._ints,
                              reals=self._reals, state=self._state)


class IdealisedPBC(PassivityBasedController):
    """Eq. (20) with all n rows applied: the paper's idealisation (reduced plant only).

    K_v,f > 0 is needed: the law cancels the elastic force K q with a sampled (ZOH) force,
    which destabilises the 34 Hz mode without damping.  Nothing is unrealisable here, so
    there is no ``residual``.

    Parameters
    ----------
    model, Ts, lambda_joint, lambda_flex, kv_joint, gravity_compensation
        As `PassivityBasedController`: the nominal model, the control period [s], Λ and
        K_v on θ, gravity.
    kv_flex : float or sequence of float
        K_v on q [N s/m], one number or one per mode (default 5).
    compensate_damping : bool
        Include D Q̇ in the law (default true).
    """

    name = "pbc-idealised"
    #: It applies forces to every coordinate, not only the two joint torques.
    generalised_forces = True

    def __init__(self, model: ArmModel, *, Ts: float, lambda_joint=None, lambda_flex=None,
                 kv_joint=None, kv_flex=5.0, compensate_damping: bool = True,
                 gravity_compensation: bool = True) -> None:
        if not isinstance(compensate_damping, (bool, np.bool_)):
            raise ValueError(f"compensate_damping must be true or false, got {compensate_damping!r}")
        self._setup(model, Ts, lambda_joint, lambda_flex, kv_joint, kv_flex, compensate_damping,
                    gravity_compensation)

    def _rows(self) -> int:
        return self.model.n


@njit(cache=True, inline="always")
def _static_deflection(d, ws, theta_d, chol, q, Qs, exact):
    """The links' static deflection under gravity at the joint angles ``theta_d`` into
    ``q``: K_ff q = −∂V_g/∂q at [θ_d, q], three fixed-point steps from 0 (K_ff by its
    Cholesky factor ``chol``; gravity's stiffness is small against the links')."""
    N, n = d.links, d.n
    nf = n - N
    L = chol.reshape((nf, nf)) if nf else chol.reshape((0, 0))
    for i in range(n):
        Qs[i] = theta_d[i] if i < N else 0.0
    for _ in range(3):
        zero = Qs[n:2 * n]
        for i in range(n):
            zero[i] = 0.0
        mass_bias_into(d, Qs[:n], zero, ws.M, ws.f, ws, exact)
        for i in range(nf):  # forward and back substitution, −g_f as the right-hand side
            acc = -ws.f[N + i]
            for k in range(i):
                acc -= L[i, k] * q[k]
            q[i] = acc / L[i, i]
        for i in range(nf - 1, -1, -1):
            acc = q[i]
            for k in range(i + 1, nf):
                acc -= L[k, i] * q[k]
            q[i] = acc / L[i, i]
        for i in range(nf):
            Qs[N + i] = q[i]


@njit(cache=True, inline="always")
def _pbc_torque(ints, reals, wc, wr, M, C, scratch, x_hat, ref, lam, kv, with_damping, tau,
                gravity, chol, qs, exact):
    """Eq. (20)'s n forces into ``tau``, with M(Q) into ``M`` and the dense C(Q, Q̇) into
    ``C`` (``ref`` = [θ_d, θ̇_d, θ̈_d]); with ``gravity``, ∂V_g/∂Q and q_d (module
    docstring; ``qs``: scratch 2n).  C v is formed from C, not from the polar form of the
    structured C Q̇: that sums in another order, enough to move a 20 s truth-plant run's θ
    by 1e-10 rad."""
    d = unpack_model(ints, reals)
    ws = unpack_workspace(ints, wc, wr)
    n = x_hat.shape[0] // 2
    N = d.links
    Q = x_hat[:n]
    Qd = x_hat[n:]
    e, de, v, dv = scratch[:n], scratch[n:2 * n], scratch[2 * n:3 * n], scratch[3 * n:]
    if gravity:  # the desired flexible coordinates: the static deflection at θ_d
        _static_deflection(d, ws, ref[:N], chol, tau[N:], qs, exact)
    for j in range(n):
        qd_des = ref[j] if j < N else (tau[j] if gravity else 0.0)
        dqd_des = ref[N + j] if j < N else 0.0
        ddqd_des = ref[2 * N + j] if j < N else 0.0
        e[j] = Q[j] - qd_des
        de[j] = Qd[j] - dqd_des
        v[j] = dqd_des - lam[j] * e[j]  # eq. (14)
        dv[j] = ddqd_des - lam[j] * de[j]
    mass_matrix_into(d, Q, M, ws, exact)
    coriolis_matrix_into(d, Q, Qd, C, ws, exact)
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += M[i, j] * dv[j] + C[i, j] * v[j] + d.K[i, j] * Q[j]
            if with_damping:
                acc += d.D[i, j] * Qd[j]
        tau[i] = acc - kv[i] * (de[i] + lam[i] * e[i])  # eq. (20), s from eq. (5)
    if exact:  # exact kinematics: the bending forces beyond K Q (and D Q̇)
        exact_elastic(ints, reals, Q, Qd, tau, with_damping)
    if gravity:  # ∂V_g/∂Q at the state (at rest: M is formed again)
        zero = qs[n:]
        for j in range(n):
            zero[j] = 0.0
        mass_bias_into(d, Q, zero, ws.M, ws.f, ws, exact)
        for i in range(n):
            tau[i] += ws.f[i]


@njit(cache=True, inline="always")
def _pbc(x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual, exact):
    """Eq. (20) as a compiled controller (`controllers._compiled`): ints = [rows applied
    (N: realisable, n: idealised), damping compensated, gravity compensated], reals =
    [Λ, K_v, K_ff's Cholesky factor (with gravity)], state = scratch for M, C, eq. (20)'s
    n forces (and, with gravity, 2n more); rows beyond those applied go to
    ``residual``."""
    n = x.shape[0] // 2
    M = matrix_view(state, 0, n, n)
    C = matrix_view(state, n * n, n, n)
    scratch = state[2 * n * n:2 * n * n + 4 * n]
    full = state[2 * n * n + 4 * n:2 * n * n + 5 * n]
    _pbc_torque(mi, mr, wc, wr, M, C, scratch, x, ref, reals[:n], reals[n:2 * n], ints[1] == 1,
                full, ints[2] == 1, reals[2 * n:], state[2 * n * n + 5 * n:], exact)
    rows = ints[0]
    for i in range(rows):
        tau[i] = full[i]
    for i in range(rows, n):
        residual[i - rows] = full[i]
    return rows


@njit(cache=True)
def pbc_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`_pbc` on a model with the paper's kinematics."""
    return _pbc(x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual, False)


@njit(cache=True)
def pbc_kernel_exact(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`_pbc` on a model with exact kinematics."""
    return _pbc(x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual, True)
