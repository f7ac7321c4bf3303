"""Gain-scheduled LQR tracking controller on the linearised reduced model: the standard
realisable vibration suppressor to compare the paper's PBC (eq. 14–20) against.

    τ = τ_ff(θ_d, θ̇_d, θ̈_d) − K(θ̂2) (x − x_d),    x_d = [θ_d, 0, θ̇_d, 0]

with τ_ff the rigid arm's inverse dynamics of the reference (`RigidArm`)
and K(θ2) the discrete-time LQR gain of the reduced model linearised about rest at
Q = (0, θ2, 0, …, 0), interpolated linearly in θ2 between grid points.  Like the PBC it
uses the flexible states q, q̇ (the paper's q_d = 0); unlike eq. (20) it asks only for
the two joint torques, so nothing is left unrealised.
"""
from __future__ import annotations

import math
import numbers

import numpy as np
from numba import njit

from reduced_model import ArmModel

from ._baselines import RigidArm, rigid_torque
from ._compiled import CONTROLLER_SIGNATURE, CompiledLaw
from ._gains import control_period
from ._gains import gain_vector as _weights

#: The most θ2 grid points: one per degree.  Each is one Riccati design (16 ms measured),
#: so the largest schedule designs in ~6 s; the default 24 already interpolates the gains.
MAX_GRID_POINTS = 360
#: The slowest closed-loop decay rate [1/s] a design may have: a pole with a time constant
#: beyond 10⁵ s (28 h, longer than any run: 5e6 samples at 1 kHz is 1.4 h) stabilises
#: nothing in practice.  It keeps the verdict off round-off: an undamped mode the cost
#: does not see sits on the unit circle, where the computed |z| is 1 ± 1e-9 (7e-10 inside
#: on one machine, outside on another: Table 1, 4+4 modes, q_q = q_q_dot = 0, a rate of
#: ±7e-7 1/s at Ts = 1 ms), 14× below this.  The weakest design the tests use clears it
#: 5.5×: Table 1, 2+2 modes, no flexible or rate weights (5.5e-5 1/s, a mode that rings
#: for hours); the default weights give ≥ 6.9e-4 (Table 1) and 0.12 1/s (default arm).
MIN_DECAY_RATE = 1e-5

__all__ = ["GainScheduledLQR"]


def _zoh(A: np.ndarray, B: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation (A_d, B_d) of ẋ = A x + B u over Ts."""
    import scipy.linalg  # 0.1 s to import: when a law is built, not on every command's start
    m, k = A.shape[0], B.shape[1]
    E = scipy.linalg.expm(np.block([[A, B], [np.zeros((k, m + k))]]) * Ts)
    return E[:m, :m], E[:m, m:]


class GainScheduledLQR:
    """Discrete-time LQR on the reduced model linearised about rest, scheduled on θ2.

    Design.  θ1 is cyclic, so the linearisation (A, B) = ``model.linearize(Q0)`` at
    Q0 = (0, θ2, 0, …, 0) depends on θ2 only.  On ``grid_points`` values of θ2 evenly
    spaced over one period [−π, π) (default 24, i.e. 25 points over [−π, π] with
    K(−π) = K(π)) the model is discretised exactly with a zero-order hold over ``Ts``
    and K(θ2) = (R + B_dᵀ P B_d)⁻¹ B_dᵀ P A_d with P from
    ``scipy.linalg.solve_discrete_are``; weights W = diag(q_theta, q_q, q_theta_dot,
    q_q_dot) on x − x_d, R = r I.  At run time K is interpolated linearly in the
    estimated θ2 (wrapped into the period): one floor and one blend per entry.

    Why discrete time.  The loop holds τ over each period, and the arm has a very fast
    "mobility" direction: (M⁻¹)₂₂ ≈ 91 kg⁻¹m⁻² on the default arm, ≈ 920 on
    `ArmParameters.table1` (no stator inertia), so a joint-2 rate gain K_d2 alone is
    sampled stably only while K_d2·Ts·(M⁻¹)₂₂ < 2.  A continuous-time (CARE) gain
    ignores the hold: with these weights it happens to survive sampling at 1 ms on 2+2
    modes, but on the Table 1 arm with 3+3 or 4+4 modes the sampled loop has poles at
    |z| = 6.6 and 13 (measured).  The ZOH-discretised Riccati equation is exact for
    the sampled linear loop, so K(θ2) stabilises it at the design ``Ts`` by
    construction (checked at every grid point: a slowest decay rate below
    `MIN_DECAY_RATE` raises ValueError).  Use the
    controller at the ``Ts`` it was designed for.

    Tuning (defaults; numbers at θ2 = 0, Ts = 1 ms, 2+2 modes).  R = I and q_theta =
    1600 [1/rad²]: on a rigid joint LQR would give K_p = √(q_theta/r) = 40 N m/rad.
    With the flexible coupling the slowest closed-loop poles (joint errors mixed with
    link 1's 0.63 Hz locked mode) are 3.2 rad/s (ζ 0.47) and 6.9 rad/s (ζ 0.55) on both
    arms; the PBC defaults' linearised loop has 2.0, 3.0, 3.8 (ζ 0.4) and 10.3 rad/s —
    the same bandwidth.  q_q = 100 [1/m²] and q_q_dot = 1 [s²/m²] on every modal
    coordinate add damping to the flexible modes (open → closed loop, rad/s and ζ):
    default arm 13.7/0.001 → 20.2/0.34, 38.1/0.004 → 38.9/0.04, 85.8/0.009 → 84.0/0.78,
    212/0.02 unchanged; with q_q = q_q_dot = 0 they are 18.4/0.31, 38.4/0.02, 89.3/0.22
    and the flexible rates after 2 s on the paper's reference are twice as large.
    q_theta_dot = 0: joint-rate weights (tried: 100, 10) doubled the Table 1 arm's
    joint-2 tracking error and added no flexible damping.
    Resulting K(0) on the default arm: θ gains ≈ (40, 37) N m/rad, θ̇ gains ≈ (13.5,
    6.4) N m s/rad, plus q and q̇ terms.

    Sampled margins (Ts = 1 ms).  The fast, joint-2 "mobility" loop has gain
    Ts·K_v·M⁻¹B (K_v the rate columns of K), spectral radius 0.14 on the default arm and
    0.72 on the Table 1 arm (< 2 needed): there the design places that mode at
    z ≈ 0.30 (1200 rad/s) — its θ̇2 gain alone would give K_d2·Ts·(M⁻¹)₂₂ = 3.3, the q̇
    gains cancel the excess.  Every pole of the sampled linearisation is inside the unit
    circle at every grid point on both arms, for every model order; with 2+2 modes
    A − B K(θ2) is Hurwitz too (not with 4 modes on link 1 of the Table 1 arm, whose
    327 Hz mode has ω·Ts = 2: there only the sampled loop is meaningful).  Two free
    modes have no joint motion at some θ2 (5.4 Hz near θ2 ≈ ±1.37, 33 Hz near ±π/2):
    joint torques cannot act on them there, so their decay rate drops to the structural
    damping, 0.11 1/s on the default arm and 0 on the Table 1 arm (no damping), where
    the interpolated gain leaves them at ±0.01 1/s (time constant ≥ 100 s) between grid
    points; no realisable controller can do better there.  Model order matters on the
    Table 1 arm: with 4 modes on link 1 a joint-2 torque mostly twists the inertia-free
    link-1 tip, the q̇ weights make joint-2 action expensive and K_θ2 drops from 21
    (2+2) to 3 N m/rad — stable, but joint 2 then tracks the paper's reference to only
    0.3 rad (q_q_dot = 0 restores 0.02 rad).

    Feedforward.  τ_ff is the rigid arm's inverse dynamics (`RigidArm`: M_θθ θ̈_d +
    C_θθ θ̇_d of the model at q = q̇ = 0, ~1 µs).

    Parameters
    ----------
    model : ArmModel
        The nominal model (any modes per link).
    Ts : float
        The control period [s]: the sample time of the design, > 0.
    q_theta : float or (float, float)
        Weight on the joint-angle errors [1/rad²]; must be > 0 (θ1 is a pure integrator
        the cost must see).
    q_q : float or n−2 floats
        Weight on the modal coordinates q [1/m²] (desired value 0), >= 0.
    q_theta_dot : float or (float, float)
        Weight on the joint-rate errors [s²/rad²], >= 0.
    q_q_dot : float or n−2 floats
        Weight on the modal rates q̇ [s²/m²], >= 0.
    r : float or (float, float)
        Torque weight [1/(N m)²], > 0.
    grid_points : int
        Number of θ2 grid points over one period, 4..`MAX_GRID_POINTS`.
    """

    name = "lqr"

    def __init__(self, model: ArmModel, *, Ts: float, q_theta=(1600.0, 1600.0), q_q=100.0,
                 q_theta_dot=0.0, q_q_dot=1.0, r=1.0, grid_points: int = 24) -> None:
        n = model.n
        self.model = model
        self.q_theta = _weights("q_theta", q_theta, 2, positive=True)
        self.q_q = _weights("q_q", q_q, n - 2)
        self.q_theta_dot = _weights("q_theta_dot", q_theta_dot, 2)
        self.q_q_dot = _weights("q_q_dot", q_q_dot, n - 2)
        self.r = _weights("r", r, 2, positive=True)
        if (isinstance(grid_points, bool) or not isinstance(grid_points, numbers.Integral)
                or not 4 <= grid_points <= MAX_GRID_POINTS):
            raise ValueError(f"grid_points must be an integer in 4..{MAX_GRID_POINTS}, "
                             f"got {grid_points!r}")
        self.Ts = control_period(Ts)
        N = int(grid_points)
        #: θ2 grid [rad]: N points over [−π, π); K(−π) = K(π).
        self.grid = -np.pi + 2.0 * np.pi * np.arange(N) / N
        W = np.diag(np.concatenate([self.q_theta, self.q_q, self.q_theta_dot, self.q_q_dot]))
        R = np.diag(self.r)
        table = np.empty((N + 1, 2, 2 * n))
        for k, theta2 in enumerate(self.grid):
            table[k] = self._design(theta2, W, R)
        table[N] = table[0]  # periodic: the interpolation never needs a modulo on i + 1
        table.setflags(write=False)
        self._table = table
        self._scale = N / (2.0 * np.pi)
        self._ff = RigidArm(model).constants
        self._K = np.zeros((2, 2 * n))
        self._tau = np.zeros(2)

    # --- design ------------------------------------------------------------------
    def _design(self, theta2: float, W: np.ndarray, R: np.ndarray) -> np.ndarray:
        import scipy.linalg  # as in `_zoh`
        Q0 = np.zeros(self.model.n)
        Q0[1] = theta2
        A, B = self.model.linearize(Q0)
        Ad, Bd = _zoh(A, B, self.Ts)
        try:
            P = scipy.linalg.solve_discrete_are(Ad, Bd, W, R)
            K = np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
            radius = np.abs(np.linalg.eigvals(Ad - Bd @ K)).max()
        except (ValueError, np.linalg.LinAlgError) as exc:
            reason = str(exc)
        else:
            rate = -math.log(radius) / self.Ts if radius > 0.0 else math.inf
            if rate >= MIN_DECAY_RATE:
                return K
            reason = (f"slowest closed-loop decay rate {rate:.3g} 1/s, below the "
                      f"{MIN_DECAY_RATE:g} 1/s a stabilising design needs")
        # Undamped modes that the cost does not see make (A, W) undetectable.
        raise ValueError(f"q_q, q_q_dot: no stabilising LQR gain at theta2 = {theta2:.4g} rad "
                         f"({reason}); undamped flexible modes need q_q or q_q_dot > 0")

    # --- run time ----------------------------------------------------------------
    @property
    def gains(self) -> np.ndarray:
        """Designed gains on the grid, (grid_points, 2, 2n) (read-only view)."""
        return self._table[:-1]

    def gain(self, theta2: float) -> np.ndarray:
        """K(θ2), (2, 2n): the grid gains interpolated linearly (periodic in θ2)."""
        K = np.empty((2, 2 * self.model.n))
        if not _interpolate_gain(self._table, self._scale, float(theta2), K):
            K[:] = np.nan
        return K

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        theta_d, dtheta_d, ddtheta_d = ref(t)
        _lqr_torque(self._table, self._scale, self._ff, self._K, x, theta_d, dtheta_d,
                    ddtheta_d, self._tau)
        return self._tau.copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): the gain table (designed at this
        law's own ``Ts``), the scheduling scale and the rigid feedforward constants."""
        return CompiledLaw.of(lqr_kernel, CONTROLLER_SIGNATURE, self.model,
                              ints=[self._table.shape[0]],
                              reals=np.concatenate([[self._scale], self._ff,
                                                    self._table.ravel()]),
                              state=np.zeros(self._K.size))


@njit(cache=True)
def _interpolate_gain(table, scale, theta2, K):
    """K = (1 − f) table[i] + f table[i + 1] for θ2 in cell i; False if θ2 is not finite."""
    if not np.isfinite(theta2):
        return False
    N = table.shape[0] - 1
    u = (theta2 + np.pi) * scale
    u -= N * math.floor(u / N)  # wrap into [0, N)
    i = int(u)
    if i >= N:  # u rounded up to N
        i = N - 1
    f = u - i
    for r in range(K.shape[0]):
        for j in range(K.shape[1]):
            K[r, j] = (1.0 - f) * table[i, r, j] + f * table[i + 1, r, j]
    return True


@njit(cache=True)
def _lqr_torque(table, scale, ff, K, x, theta_d, dtheta_d, ddtheta_d, tau):
    if not _interpolate_gain(table, scale, x[1], K):
        tau[:] = np.nan  # the loop ends the run as diverged
        return
    rigid_torque(ff, theta_d, dtheta_d, ddtheta_d, tau)
    n = x.shape[0] // 2
    for j in range(2 * n):
        if j < 2:
            err = x[j] - theta_d[j]
        elif n <= j < n + 2:
            err = x[j] - dtheta_d[j - n]
        else:
            err = x[j]
        tau[0] -= K[0, j] * err
        tau[1] -= K[1, j] * err


@njit(cache=True)
def lqr_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`GainScheduledLQR` compiled: ints = [grid rows + 1], reals = [scale, rigid
    constants, gain table], state = K."""
    N = x.shape[0]
    rows = ints[0]
    table = reals[5:5 + rows * 2 * N].reshape((rows, 2, N))
    _lqr_torque(table, reals[0], reals[1:5], state.reshape((2, N)), x, ref[0:2], ref[2:4],
                ref[4:6], tau)
    return 2
