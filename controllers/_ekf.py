"""Discrete-time extended Kalman filter on the nominal nonlinear reduced model: the
standard observer to compare the paper's sliding-mode observer (eq. 21–36) against.

    predict:  x̂⁻ = F(x̂, τ),  P⁻ = Φ P Φᵀ + Q_d,   Φ = ∂F/∂x at (x̂, τ)
    correct:  K = P⁻Hᵀ(H P⁻Hᵀ + R)⁻¹,  x̂ = x̂⁻ + K (y − H x̂⁻),
              P = (I − K H) P⁻ (I − K H)ᵀ + K R Kᵀ                    (Joseph form)

F is the reduced model's eq. (2) advanced over one control period by classical RK4 with
τ held (sub-steps of at most 1 ms, exactly like the SMO's model part), H selects the
measured states (the whole state, as the paper's SMO assumes, or the positions only).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from reduced_model import ArmModel
from reduced_model.dynamics import (cholesky_factor_inplace, cholesky_solve_factored,
                                    matrix_view, unpack_model)
from reduced_model.dynamics.entries import advance_exact, advance_linear

from ._compiled import OBSERVER_SIGNATURE, CompiledLaw
from ._gains import control_period, gain_vector
from ._interface import ObserverFailure

__all__ = ["ExtendedKalmanFilter", "PositionEKF"]

_MAX_SUBSTEP = 1e-3
#: Relative forward-difference step of the Jacobian, ≈ √(round-off of the RK4 map / |F''|):
#: the map's round-off is ~1e-13 on the Table 1 arm (cond M ≈ 1e4), so √ε = 1.5e-8 would
#: leave 1e-5 errors in Φ there; 3e-7 balances round-off and truncation (both ~1e-6).
_FD_STEP = 3e-7
#: What it means when the update fails (H P⁻ Hᵀ + R not positive definite).
COVARIANCE_FAILURE = "the covariance update failed (H P Hᵀ + R is not positive definite)"


class ExtendedKalmanFilter:
    """``"ekf"``: EKF on the nominal reduced model measuring the whole state [Q, Q̇]
    (like ``smo-paper``); `PositionEKF` (``"ekf-pos"``) measures Q only (like
    ``smo-pos``).  `measured` lists the names in the order of ``y``.

    Parameters
    ----------
    model : ArmModel
        The nominal model providing F (any modes per link).
    Ts : float
        The control period [s]: the prediction's horizon and Q_d's.
    sigma_theta, sigma_q, sigma_theta_dot, sigma_q_dot : float (or one per coordinate)
        Measurement-noise standard deviations [rad, m, rad/s, m/s], > 0 (R is their
        squares on the diagonal).  Defaults 1e-4, 1e-5, 1e-3, 1e-3: the shipped
        campaigns' sensor noise.  `PositionEKF` has no rate sigmas.
    accel_noise_theta, accel_noise_q : float (or one per coordinate)
        Process noise: how far the filter distrusts the model's accelerations, as the
        √intensity s of continuous white acceleration noise on each joint
        [rad/s²/√Hz] and modal coordinate [m/s²/√Hz], >= 0.  Discretised per (position,
        rate) pair as Q_d = s² [[Ts³/3, Ts²/2], [Ts²/2, Ts]] (exact for a double
        integrator; the coupling through Φ within one period changes it by O(ω·Ts)).
        Defaults 0.03 and 0.03, measured on the paper's reference with the campaigns'
        noise (error RMS / measurement-noise RMS after 1 s): exact model 0.1–0.3 on
        positions and 0.65–0.71 on rates; payload mismatch (true Mp = 0.3 kg, nominal
        0.1 kg) ≤ 0.83 everywhere.  s = 3e-3 filters rates better on the exact model
        (0.2–0.4) but lets the mismatch through (q21 error 4.5× the noise); s = 0.3
        passes the rate measurements through (0.99).
    p0_theta, p0_q, p0_theta_dot, p0_q_dot : float (or one per coordinate)
        Initial estimate-error standard deviations [rad, m, rad/s, m/s], >= 0: P(0) is
        their squares on the diagonal.  Defaults 0.1, 5e-3, 0.3, 0.05 — the shipped
        campaigns' initial observer error.

    Notes
    -----
    Jacobian.  Φ = ∂F/∂x is computed in compiled code by forward differences of the
    RK4 map itself (the same sub-steps as the prediction), one column per state with
    step 3e-7·max(1, |x_j|): 2n RK4 maps per update (θ1 is cyclic in a horizontal arm,
    so its column is e_1 exactly; the test's independent central differences check that
    column too).  Φ is accurate to 1e-7 on the default arm and 1.5e-6 on the Table 1 arm (measured against
    Richardson-extrapolated central differences; the Table 1 mass matrix has condition
    ≈ 1e4, so the map's round-off is ~1e-13 and a √ε step would leave 1e-5 errors).
    Differentiating the discrete map rather than the continuous rhs keeps Φ consistent
    with the prediction at any Ts; central differences would double the cost for
    accuracy the covariance does not need.

    No allocation; the RK4 kernel is called, not inlined, so this module compiles in
    seconds instead of minutes.
    """

    name = "ekf"

    def __init__(self, model: ArmModel, *, Ts: float, sigma_theta=1e-4, sigma_q=1e-5,
                 sigma_theta_dot=1e-3, sigma_q_dot=1e-3, accel_noise_theta=0.03,
                 accel_noise_q=0.03, p0_theta=0.1, p0_q=5e-3, p0_theta_dot=0.3,
                 p0_q_dot=0.05) -> None:
        N, nf = model.n_joints, model.n - model.n_joints
        sigma = [gain_vector("sigma_theta", sigma_theta, N, positive=True),
                 gain_vector("sigma_q", sigma_q, nf, positive=True),
                 gain_vector("sigma_theta_dot", sigma_theta_dot, N, positive=True),
                 gain_vector("sigma_q_dot", sigma_q_dot, nf, positive=True)]
        self._setup(model, Ts, sigma, accel_noise_theta, accel_noise_q,
                    (p0_theta, p0_q, p0_theta_dot, p0_q_dot))

    def _setup(self, model, Ts, sigma, accel_noise_theta, accel_noise_q, p0) -> None:
        self.model, self.Ts = model, control_period(Ts)
        nsub = max(1, math.ceil(self.Ts / _MAX_SUBSTEP - 1e-9))  # RK4 sub-steps
        n, nj = model.n, model.n_joints
        nf = n - nj
        sigma = np.concatenate(sigma)
        accel = np.concatenate([gain_vector("accel_noise_theta", accel_noise_theta, nj),
                                gain_vector("accel_noise_q", accel_noise_q, nf)])
        self._p0 = np.concatenate([
            gain_vector(name, value, nj if "theta" in name else nf)
            for name, value in zip(("p0_theta", "p0_q", "p0_theta_dot", "p0_q_dot"), p0)])
        self._m = m = len(sigma)  # y = the first m states
        N = 2 * n
        Qd = np.zeros((N, N))
        s2, T = accel ** 2, self.Ts
        for i in range(n):  # white-noise acceleration on coordinate i, over one period
            Qd[i, i] = s2[i] * T ** 3 / 3.0
            Qd[i, n + i] = Qd[n + i, i] = s2[i] * T ** 2 / 2.0
            Qd[n + i, n + i] = s2[i] * T
        self._kernel = ekf_kernel_exact if model.exact else ekf_kernel
        self._ints = np.array([m, nsub, 1], dtype=np.int64)  # [.., fresh]
        self._reals = np.concatenate([sigma[:m] ** 2, Qd.ravel(), [self.Ts]])
        # state: x̂, P, then scratch: x⁻, perturbed x, Φ, two N×N products, K (N×m),
        # S (m×m), innovation (m,)
        self._state = np.zeros(N + N * N + 2 * N + 3 * N * N + N * m + m * m + m)
        self._x = self._state[:N]
        self._P = self._state[N:N + N * N].reshape(N, N)
        self._P[:] = np.diag(self._p0 ** 2)
        self._work = model.new_workspace()
        self._x_hat = np.zeros(N)

    @property
    def measured(self) -> tuple[str, ...]:
        """Names of the measurement signals the filter needs, in the order of y."""
        return self.model.state_names[:self._m]

    @property
    def covariance(self) -> np.ndarray:
        """The current error covariance P (a copy), (2n, 2n)."""
        return self._P.copy()

    def reset(self, x_hat0) -> np.ndarray:
        x0 = np.asarray(x_hat0, dtype=float)
        if x0.shape != self._x.shape:
            raise ValueError(f"x_hat0 must have shape {self._x.shape}, got {x0.shape}")
        self._x[:] = x0
        self._P[:] = np.diag(self._p0 ** 2)
        self._ints[2] = 1  # fresh: the next update only corrects
        return self._x.copy()

    def update(self, t: float, y: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Predict over the last period with the torque ``tau`` held (skipped on the first
        call after `reset`), then correct with ``y`` (in the order of `measured`)
        measured at ``t``.  Returns a copy of x̂; raises `ObserverFailure` if the
        covariance update failed (the closed loop then ends the run as diverged)."""
        y = np.ascontiguousarray(y, dtype=float)
        if y.shape != (self._m,):
            raise ValueError(f"y must have shape ({self._m},) (measured), got {y.shape}")
        failed = self._kernel(t, y, np.ascontiguousarray(tau, dtype=float), self._ints,
                              self._reals, self._state, *self.model.packed, *self._work,
                              self._x_hat)
        if failed:
            self._x[:] = np.nan
            raise ObserverFailure(COVARIANCE_FAILURE)
        return self._x.copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`), its state (x̂, P) copied as it is
        now."""
        return CompiledLaw.of(self._kernel, OBSERVER_SIGNATURE, self.model, ints=self._ints,
                              reals=self._reals, state=self._state, failure=COVARIANCE_FAILURE)

    def jacobian(self, x, tau) -> np.ndarray:
        """Φ = ∂F/∂x of the prediction map F (RK4 over ``Ts``, ``tau`` held) at ``x``,
        computed by the same compiled routine `update` uses."""
        x = np.array(x, dtype=float)
        if x.shape != self._x.shape:
            raise ValueError(f"x must have shape {self._x.shape}, got {x.shape}")
        N = x.shape[0]
        Phi, xn, xp = np.zeros((N, N)), np.zeros(N), np.zeros(N)
        nsub = self._ints[1]
        (ekf_jacobian_exact if self.model.exact else ekf_jacobian)(
            *self.model.packed, *self.model.new_workspace(), x, np.asarray(tau, dtype=float),
            self.Ts / nsub, nsub, xn, xp, Phi)
        return Phi


class PositionEKF(ExtendedKalmanFilter):
    """``"ekf-pos"``: the EKF measuring the positions Q only (encoders and modal
    positions, like ``smo-pos``); options as `ExtendedKalmanFilter` without the rate
    sigmas.

    Parameters
    ----------
    model, Ts, sigma_theta, sigma_q, accel_noise_theta, accel_noise_q
        As `ExtendedKalmanFilter`: the nominal model, the control period [s], the
        position noise levels and the process noise.
    p0_theta, p0_q, p0_theta_dot, p0_q_dot
        As `ExtendedKalmanFilter`: the initial estimate-error standard deviations.
    """

    name = "ekf-pos"

    def __init__(self, model: ArmModel, *, Ts: float, sigma_theta=1e-4, sigma_q=1e-5,
                 accel_noise_theta=0.03, accel_noise_q=0.03, p0_theta=0.1, p0_q=5e-3,
                 p0_theta_dot=0.3, p0_q_dot=0.05) -> None:
        N = model.n_joints
        sigma = [gain_vector("sigma_theta", sigma_theta, N, positive=True),
                 gain_vector("sigma_q", sigma_q, model.n - N, positive=True)]
        self._setup(model, Ts, sigma, accel_noise_theta, accel_noise_q,
                    (p0_theta, p0_q, p0_theta_dot, p0_q_dot))


@njit(cache=True, inline="always")
def _advance(ints, reals, wc, wr, x, tau, h, nsub, exact):
    """The model's RK4 map, called, not inlined: the same machine code, and this module
    compiles in seconds instead of minutes."""
    if exact:
        advance_exact(ints, reals, wc, wr, x, tau, h, nsub)
    else:
        advance_linear(ints, reals, wc, wr, x, tau, h, nsub)


@njit(cache=True, inline="always")
def _jacobian(ints, reals, wc, wr, x, tau, h, nsub, xn, xp, Phi, exact):
    """F(x) into ``xn`` and Φ = ∂F/∂x (forward differences of the RK4 map) into ``Phi``."""
    N = x.shape[0]
    xn[:] = x
    _advance(ints, reals, wc, wr, xn, tau, h, nsub, exact)
    # In a horizontal arm θ1 is cyclic (the rhs does not depend on it): ∂F/∂θ1 = e_1
    # exactly, one map saved; gravity makes it a coordinate like the others.
    d = unpack_model(ints, reals)
    first = 1 if d.gx == 0.0 and d.gy == 0.0 else 0
    if first:
        for i in range(N):
            Phi[i, 0] = 0.0
        Phi[0, 0] = 1.0
    for j in range(first, N):
        xp[:] = x
        xp[j] = x[j] + _FD_STEP * max(1.0, abs(x[j]))
        step = xp[j] - x[j]  # the step actually taken (exactly representable)
        _advance(ints, reals, wc, wr, xp, tau, h, nsub, exact)
        for i in range(N):
            Phi[i, j] = (xp[i] - xn[i]) / step


@njit(cache=True)
def ekf_jacobian(ints, reals, wc, wr, x, tau, h, nsub, xn, xp, Phi):
    """`_jacobian` with the paper's kinematics (for `ExtendedKalmanFilter.jacobian`)."""
    _jacobian(ints, reals, wc, wr, x, tau, h, nsub, xn, xp, Phi, False)


@njit(cache=True)
def ekf_jacobian_exact(ints, reals, wc, wr, x, tau, h, nsub, xn, xp, Phi):
    """`_jacobian` with exact kinematics."""
    _jacobian(ints, reals, wc, wr, x, tau, h, nsub, xn, xp, Phi, True)


@njit(cache=True, inline="always")
def _ekf_update(ints, reals, wc, wr, x, P, tau, h, nsub, predict, y, r, Qd, xn, xp, Phi,
                T1, T2, Kg, S, nu, exact):
    """One EKF step in place on ``x`` and ``P``; False if H P Hᵀ + R is not positive
    definite (P no longer a covariance)."""
    N = x.shape[0]
    m = y.shape[0]
    if predict:
        _jacobian(ints, reals, wc, wr, x, tau, h, nsub, xn, xp, Phi, exact)
        # P⁻ = Φ P Φᵀ + Q_d, symmetrised against round-off.
        for i in range(N):
            for j in range(N):
                acc = 0.0
                for k in range(N):
                    acc += Phi[i, k] * P[k, j]
                T1[i, j] = acc
        for i in range(N):
            for j in range(i + 1):
                acc = 0.0
                for k in range(N):
                    acc += T1[i, k] * Phi[j, k]
                acc += Qd[i, j]
                P[i, j] = acc
                P[j, i] = acc
        x[:] = xn

    # S = H P Hᵀ + R with H = [I_m 0], factored in place (Cholesky).
    for i in range(m):
        for j in range(m):
            S[i, j] = P[i, j]
        S[i, i] += r[i]
    if not cholesky_factor_inplace(S):
        return False
    # K = P Hᵀ S⁻¹: row i of K solves S kᵢ = (H P)[:, i] = P[:m, i] (S symmetric).
    for i in range(N):
        for a in range(m):
            Kg[i, a] = P[a, i]
        cholesky_solve_factored(S, Kg[i])
    for a in range(m):
        nu[a] = y[a] - x[a]
    for i in range(N):
        acc = 0.0
        for a in range(m):
            acc += Kg[i, a] * nu[a]
        x[i] += acc
    # Joseph form: P = A P Aᵀ + K R Kᵀ with A = I − K H (A[:, j] = e_j − K[:, j], j < m).
    for i in range(N):  # T1 = A P
        for j in range(N):
            acc = P[i, j]
            for a in range(m):
                acc -= Kg[i, a] * P[a, j]
            T1[i, j] = acc
    for i in range(N):  # T2 = T1 Aᵀ + K R Kᵀ (lower triangle, then mirrored)
        for j in range(i + 1):
            acc = T1[i, j]
            for a in range(m):
                acc += Kg[j, a] * (r[a] * Kg[i, a] - T1[i, a])
            T2[i, j] = acc
    for i in range(N):
        for j in range(i + 1):
            P[i, j] = T2[i, j]
            P[j, i] = T2[i, j]
    return True


@njit(cache=True, inline="always")
def _ekf(y, tau, ints, reals, state, mi, mr, wc, wr, x_hat, exact):
    """The EKF compiled (`controllers._compiled`): ints = [m measured, RK4 sub-steps,
    fresh], reals = [R diagonal, Q_d, Ts], state = [x̂, P, scratch]; status 1 when the
    covariance update fails."""
    N = x_hat.shape[0]
    m, nsub = ints[0], ints[1]
    x = state[:N]
    nn = N * N
    P = matrix_view(state, N, N, N)
    b = N + nn  # the scratch: two vectors, three N x N, N x m, m x m, m
    s = b + 2 * N + 3 * nn
    ok = _ekf_update(mi, mr, wc, wr, x, P, tau, reals[m + nn] / nsub, nsub, ints[2] == 0, y, reals[:m],
                     matrix_view(reals, m, N, N), state[b:b + N], state[b + N:b + 2 * N],
                     matrix_view(state, b + 2 * N, N, N),
                     matrix_view(state, b + 2 * N + nn, N, N),
                     matrix_view(state, b + 2 * N + 2 * nn, N, N),
                     matrix_view(state, s, N, m), matrix_view(state, s + N * m, m, m),
                     state[s + N * m + m * m:s + N * m + m * m + m], exact)
    ints[2] = 0  # no longer fresh: later calls predict
    for i in range(N):
        x_hat[i] = x[i] if ok else np.nan
    return 0 if ok else 1


@njit(cache=True)
def ekf_kernel(t, y, tau, ints, reals, state, mi, mr, wc, wr, x_hat):
    """`_ekf` on a model with the paper's kinematics."""
    return _ekf(y, tau, ints, reals, state, mi, mr, wc, wr, x_hat, False)


@njit(cache=True)
def ekf_kernel_exact(t, y, tau, ints, reals, state, mi, mr, wc, wr, x_hat):
    """`_ekf` on a model with exact kinematics."""
    return _ekf(y, tau, ints, reals, state, mi, mr, wc, wr, x_hat, True)
