"""The paper's passivity-based controller, eq. (14)–(20), on the reduced model.

    e = Q − Q_d,  s = ė + Λ e,  v = Q̇_d − Λ e                       (4), (5), (14)
    τ = M(Q) v̇ + C(Q, Q̇) v + K Q + D Q̇ − K_v s                    (20)

with Q_d = [θ_d, 0] (the paper's q_d = 0), K Q in place of the paper's g(Q) (horizontal
plane) and the model's Kelvin–Voigt D Q̇ — on a model with exact kinematics, its exact
bending and damping forces.  Eq. (20) asks for n generalised forces; the
arm has two actuators.  Two laws, two names:

- `PassivityBasedController` (``"pbc"``) applies rows 0–1 of eq. (20) — what two motors
  can do — and reports rows 2… (forces on the flexible coordinates no actuator can
  produce) as the *unrealisable residual*.  K and D have no joint rows and K_v, Λ are
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
from reduced_model._exact_pointers import exact_elastic_into
from reduced_model._kernels import (coriolis_matrix_into, mass_matrix_into, unpack_model,
                                    unpack_workspace)
from reduced_model._views import matrix_view

from ._compiled import CONTROLLER_SIGNATURE, CompiledLaw
from ._gains import control_period, gain_vector

__all__ = ["PassivityBasedController", "IdealisedPBC"]


class PassivityBasedController:
    """Eq. (20), rows 0–1 applied (the realisable law), with diagonal Λ and K_v.

    Parameters
    ----------
    model : ArmModel
        The nominal model (its M, Christoffel C, K, D).
    Ts : float
        The control period [s] (the law is continuous: it is recorded, not used).
    lambda_joint, lambda_flex : gains of Λ [1/s] on θ (one or two numbers) and on q (one
        number, or one per mode).
    kv_joint : gains of K_v on θ [N m s/rad].

    Defaults (Λ = 3, 3 | 1; K_v = 10, 5), chosen on the paper's scenario from rest: the
    joint error dynamics of the rigid arm at θ2 = 0 have poles at Λ = 3 and
    K_v/M_jj = 3.7, 4.7 rad/s.  Larger joint gains (Λ = 5, K_v = 20, 10) bend link 1 by
    10 cm at the start (the reference starts at 0.6/1.3 rad/s while the arm is at rest)
    and track worse after 2 s; Λ_f > 0 couples into the joint rows through M_θq v̇_q.
    """

    name = "pbc"
    _rows = 2  # rows of eq. (20) applied

    def __init__(self, model: ArmModel, *, Ts: float, lambda_joint=(3.0, 3.0),
                 lambda_flex=1.0, kv_joint=(10.0, 5.0)) -> None:
        self._setup(model, Ts, lambda_joint, lambda_flex, kv_joint, 0.0, False)
        #: Unrealisable flexible-coordinate forces of the last call (rows 2… of eq. 20).
        self.residual = np.zeros(model.n - 2)

    def _setup(self, model, Ts, lambda_joint, lambda_flex, kv_joint, kv_flex, damping) -> None:
        self.model, self.Ts = model, control_period(Ts)
        n = model.n
        self.lam = np.concatenate([gain_vector("lambda_joint", lambda_joint, 2),
                                   gain_vector("lambda_flex", lambda_flex, n - 2)])
        self.kv = np.concatenate([gain_vector("kv_joint", kv_joint, 2),
                                  gain_vector("kv_flex", kv_flex, n - 2)])
        self.compensate_damping = bool(damping)
        self._work = model.new_workspace()[0]
        self._M, self._C = np.zeros((n, n)), np.zeros((n, n))
        self._scratch = np.zeros(4 * n)
        self._tau = np.zeros(n)

    def _eq20(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        theta_d, dtheta_d, ddtheta_d = ref(t)
        ints, reals = self.model.packed
        wc, wr = self._work
        _pbc_torque(ints, reals, wc, wr, self._M, self._C, self._scratch, x, theta_d,
                    dtheta_d, ddtheta_d, self.lam, self.kv, self.compensate_damping, self._tau)
        return self._tau

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        tau = self._eq20(t, x, ref)
        self.residual[:] = tau[2:]
        return tau[:2].copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): this law's kernel and gains."""
        return self._compiled(rows=2)

    def _compiled(self, rows: int) -> CompiledLaw:
        n = self.model.n
        return CompiledLaw.of(pbc_kernel, CONTROLLER_SIGNATURE, self.model,
                              ints=[rows, int(self.compensate_damping)],
                              reals=np.concatenate([self.lam, self.kv]),
                              state=np.zeros(2 * n * n + 5 * n))


class IdealisedPBC(PassivityBasedController):
    """Eq. (20) with all n rows applied: the paper's idealisation (reduced plant only).

    K_v,f > 0 is needed: the law cancels the elastic force K q with a sampled (ZOH) force,
    which destabilises the 34 Hz mode without damping.  Nothing is unrealisable here, so
    there is no ``residual``.

    Parameters
    ----------
    model, Ts, lambda_joint, lambda_flex, kv_joint
        As `PassivityBasedController`: the nominal model, the control period [s], Λ and
        K_v on θ.
    kv_flex : float or sequence of float
        K_v on q [N s/m], one number or one per mode (default 5).
    compensate_damping : bool
        Include D Q̇ in the law (default true).
    """

    name = "pbc-idealised"
    #: It applies forces to every coordinate, not only the two joint torques.
    generalised_forces = True

    def __init__(self, model: ArmModel, *, Ts: float, lambda_joint=(3.0, 3.0),
                 lambda_flex=1.0, kv_joint=(10.0, 5.0), kv_flex=5.0,
                 compensate_damping: bool = True) -> None:
        if not isinstance(compensate_damping, (bool, np.bool_)):
            raise ValueError(f"compensate_damping must be true or false, got {compensate_damping!r}")
        self._setup(model, Ts, lambda_joint, lambda_flex, kv_joint, kv_flex, compensate_damping)

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        return self._eq20(t, x, ref).copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): all n rows applied."""
        return self._compiled(rows=self.model.n)


@njit(cache=True)
def _pbc_torque(ints, reals, wc, wr, M, C, scratch, x_hat, theta_d, dtheta_d, ddtheta_d,
                lam, kv, with_damping, tau):
    """Eq. (20)'s n forces into ``tau``, with M(Q) into ``M`` and the dense C(Q, Q̇) into
    ``C``.  C v without forming C (the polar form of the structured C Q̇) is faster but
    sums in another order: it moved a 20 s truth-plant run's θ by 1e-10 rad, a sign SMO's
    by 2e-8 rad.  Forming C keeps runs bit-identical to earlier revisions (README, Speed)."""
    d = unpack_model(ints, reals)
    ws = unpack_workspace(ints, wc, wr)
    n = x_hat.shape[0] // 2
    Q = x_hat[:n]
    Qd = x_hat[n:]
    e, de, v, dv = scratch[:n], scratch[n:2 * n], scratch[2 * n:3 * n], scratch[3 * n:]
    for j in range(n):
        qd_des = theta_d[j] if j < 2 else 0.0
        dqd_des = dtheta_d[j] if j < 2 else 0.0
        ddqd_des = ddtheta_d[j] if j < 2 else 0.0
        e[j] = Q[j] - qd_des
        de[j] = Qd[j] - dqd_des
        v[j] = dqd_des - lam[j] * e[j]  # eq. (14)
        dv[j] = ddqd_des - lam[j] * de[j]
    mass_matrix_into(d, Q, M, ws)
    coriolis_matrix_into(d, Q, Qd, C, ws)
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += M[i, j] * dv[j] + C[i, j] * v[j] + d.K[i, j] * Q[j]
            if with_damping:
                acc += d.D[i, j] * Qd[j]
        tau[i] = acc - kv[i] * (de[i] + lam[i] * e[i])  # eq. (20), s from eq. (5)
    if d.exact.N > 0:  # exact kinematics: the bending forces beyond K Q (and D Q̇)
        exact_elastic_into(d.exact, Q, Qd, tau, with_damping)


@njit(cache=True)
def pbc_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """Eq. (20) as a compiled controller (`controllers._compiled`): ints = [rows applied
    (2: realisable, n: idealised), damping compensated], reals = [Λ, K_v], state =
    scratch for M, C and eq. (20)'s n forces; rows beyond those applied go to
    ``residual``."""
    n = x.shape[0] // 2
    M = matrix_view(state, 0, n, n)
    C = matrix_view(state, n * n, n, n)
    scratch = state[2 * n * n:2 * n * n + 4 * n]
    full = state[2 * n * n + 4 * n:2 * n * n + 5 * n]
    _pbc_torque(mi, mr, wc, wr, M, C, scratch, x, ref[0:2], ref[2:4], ref[4:6],
                reals[:n], reals[n:2 * n], ints[1] == 1, full)
    rows = ints[0]
    for i in range(rows):
        tau[i] = full[i]
    for i in range(rows, n):
        residual[i - rows] = full[i]
    return rows
