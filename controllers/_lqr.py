"""Gain-scheduled LQR tracking controller on the linearised reduced model: the standard
realisable vibration suppressor to compare the paper's PBC (eq. 14–20) against, on any
arm.

    τ = τ_ff(θ_d, θ̇_d, θ̈_d) − K(θ̂) (x − x_d),    x_d = [θ_d, q_d, θ̇_d, 0]

with τ_ff the arm's inverse dynamics of the reference (`rigid_inverse_dynamics`, at the
operating point [θ_d, q_d]) and K(θ) the discrete-time LQR gain of the reduced model
linearised about the arm at rest at θ, interpolated multilinearly in the angles the
linearisation depends on.  q_d = 0 on a horizontal arm (the paper's); in gravity q_d is
the links' static deflection at θ_d, the pose the arm rests in there.  Like the PBC it
uses the flexible states q, q̇; unlike eq. (20) it asks only for the N joint torques, so
nothing is left unrealised.
"""
from __future__ import annotations

import math
import numbers

import numpy as np
from numba import njit

from reduced_model import ArmModel
from reduced_model.dynamics import unpack_model, unpack_workspace

from ._baselines import rigid_inverse_dynamics
from ._compiled import CONTROLLER_SIGNATURE, CompiledLaw
from ._gains import control_period
from ._gains import gain_vector as _weights
from ._pbc import _static_deflection

#: The most grid points on one scheduled angle: one per degree.
MAX_GRID_POINTS = 360
#: The most designs of one schedule (the product of its grid counts).  Each is one
#: Riccati design (16 ms measured on the paper's arm, 2+2 modes), so the largest
#: schedule designs in ~6 s there.
MAX_DESIGNS = 360
#: The default grid on one scheduled angle (15°); on more, as many points per angle as
#: keep a schedule near `DEFAULT_DESIGNS` designs (12 × 12 on two angles, 5³ on three,
#: 4⁴ on four), so that any arm designs in seconds.
DEFAULT_GRID_POINTS = 24
DEFAULT_DESIGNS = 150
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


def _grid_counts(grid_points, angles: int) -> tuple[int, ...]:
    """The grid count of each of ``angles`` scheduled angles (`GainScheduledLQR`)."""
    if grid_points is None:
        each = max(4, min(DEFAULT_GRID_POINTS, int(DEFAULT_DESIGNS ** (1.0 / max(angles, 1))
                                                   + 1e-9)))
        return (each,) * angles
    values = list(grid_points) if isinstance(grid_points, (list, tuple)) else [grid_points]
    if len(values) == 1:
        values = values * angles
    bad = next((v for v in values if isinstance(v, bool) or not isinstance(v, numbers.Integral)
                or not 4 <= v <= MAX_GRID_POINTS), None)
    if bad is not None or (angles and len(values) != angles):
        raise ValueError(f"grid_points must be an integer in 4..{MAX_GRID_POINTS} (or one per "
                         f"scheduled angle, {angles}), got {grid_points!r}")
    if math.prod(values) > MAX_DESIGNS:
        raise ValueError(f"grid_points: {' x '.join(map(str, values))} = "
                         f"{math.prod(values)} designs, more than {MAX_DESIGNS}")
    return tuple(int(v) for v in values)


class GainScheduledLQR:
    """Discrete-time LQR on the reduced model linearised about rest, scheduled on the
    joint angles its linearisation depends on.

    Design.  The linearisation (A, B) = ``model.linearize(Q0, tau0)`` about the arm at
    rest at the joint angles θ depends on the relative angles θ2 … θN only on a
    horizontal arm (θ1 is cyclic: Q0 = (0, θ2, …, θN, 0, …, 0), τ0 = 0), and on θ1 too
    in gravity, where Q0 = (θ, q_s(θ)) with q_s the links' static deflection and τ0 the
    joint torques that hold the arm there (the gravity torque at Q0).  Each scheduled
    angle gets ``grid_points`` values evenly spaced over one period [−π, π) (K(−π) =
    K(π)); on the product grid the model is discretised exactly with a zero-order hold
    over ``Ts`` and K(θ) = (R + B_dᵀ P B_d)⁻¹ B_dᵀ P A_d with P from
    ``scipy.linalg.solve_discrete_are``; weights W = diag(q_theta, q_q, q_theta_dot,
    q_q_dot) on x − x_d, R = diag(r).  At run time K is interpolated multilinearly in the
    estimated scheduled angles (wrapped into the period): 2^d blends per entry for d
    angles.  A single horizontal link has no scheduled angle: one design at rest.

    Why discrete time.  The loop holds τ over each period, and the arm has a very fast
    "mobility" direction: (M⁻¹)₂₂ ≈ 91 kg⁻¹m⁻² on the default arm, ≈ 920 on the Table 1
    arm (no stator inertia), so a joint-2 rate gain K_d2 alone is sampled stably only
    while K_d2·Ts·(M⁻¹)₂₂ < 2.  A continuous-time (CARE) gain ignores the hold: with
    these weights it happens to survive sampling at 1 ms on 2+2 modes, but on the Table
    1 arm with 3+3 or 4+4 modes the sampled loop has poles at |z| = 6.6 and 13
    (measured).  The ZOH-discretised Riccati equation is exact for the sampled linear
    loop, so K(θ) stabilises it at the design ``Ts`` by construction (checked at every
    grid point: a slowest decay rate below `MIN_DECAY_RATE` raises ValueError).  Use
    the controller at the ``Ts`` it was designed for.

    Tuning (defaults; numbers on the paper's arm at θ2 = 0, Ts = 1 ms, 2+2 modes).  R =
    I and q_theta = 1600 [1/rad²]: on a rigid joint LQR would give K_p = √(q_theta/r) =
    40 N m/rad.  With the flexible coupling the slowest closed-loop poles (joint errors
    mixed with link 1's 0.63 Hz locked mode) are 3.2 rad/s (ζ 0.47) and 6.9 rad/s (ζ
    0.55) on both arms; the PBC defaults' linearised loop has 2.0, 3.0, 3.8 (ζ 0.4) and
    10.3 rad/s — the same bandwidth.  q_q = 100 [1/m²] and q_q_dot = 1 [s²/m²] on every
    modal coordinate add damping to the flexible modes (open → closed loop, rad/s and
    ζ): default arm 13.7/0.001 → 20.2/0.34, 38.1/0.004 → 38.9/0.04, 85.8/0.009 →
    84.0/0.78, 212/0.02 unchanged; with q_q = q_q_dot = 0 they are 18.4/0.31,
    38.4/0.02, 89.3/0.22 and the flexible rates after 2 s on the paper's reference are
    twice as large.  q_theta_dot = 0: joint-rate weights (tried: 100, 10) doubled the
    Table 1 arm's joint-2 tracking error and added no flexible damping.  Resulting K(0)
    on the default arm: θ gains ≈ (40, 37) N m/rad, θ̇ gains ≈ (13.5, 6.4) N m s/rad,
    plus q and q̇ terms.

    Sampled margins (Ts = 1 ms, the paper's arms).  The fast, joint-2 "mobility" loop
    has gain Ts·K_v·M⁻¹B (K_v the rate columns of K), spectral radius 0.14 on the
    default arm and 0.72 on the Table 1 arm (< 2 needed): there the design places that
    mode at z ≈ 0.30 (1200 rad/s) — its θ̇2 gain alone would give K_d2·Ts·(M⁻¹)₂₂ = 3.3,
    the q̇ gains cancel the excess.  Every pole of the sampled linearisation is inside
    the unit circle at every grid point on both arms, for every model order; with 2+2
    modes A − B K(θ2) is Hurwitz too (not with 4 modes on link 1 of the Table 1 arm,
    whose 327 Hz mode has ω·Ts = 2: there only the sampled loop is meaningful).  Two
    free modes have no joint motion at some θ2 (5.4 Hz near θ2 ≈ ±1.37, 33 Hz near
    ±π/2): joint torques cannot act on them there, so their decay rate drops to the
    structural damping, 0.11 1/s on the default arm and 0 on the Table 1 arm (no
    damping), where the interpolated gain leaves them at ±0.01 1/s (time constant ≥ 100
    s) between grid points; no realisable controller can do better there.  Model order
    matters on the Table 1 arm: with 4 modes on link 1 a joint-2 torque mostly twists
    the inertia-free link-1 tip, the q̇ weights make joint-2 action expensive and K_θ2
    drops from 21 (2+2) to 3 N m/rad — stable, but joint 2 then tracks the paper's
    reference to only 0.3 rad (q_q_dot = 0 restores 0.02 rad).

    Feedforward.  τ_ff = M_θθ θ̈_d + C_θθ θ̇_d + g_θ of the arm at [θ_d, q_d] at rest in
    its flexible coordinates (`rigid_inverse_dynamics`): the rigid arm's inverse
    dynamics on a horizontal arm, and in gravity exactly the torque that holds the
    operating point the design linearised about.

    Parameters
    ----------
    model : ArmModel
        The nominal model (any arm, any modes per link).
    Ts : float
        The control period [s]: the sample time of the design, > 0.
    q_theta : float or one per joint
        Weight on the joint-angle errors [1/rad²]; must be > 0 (θ1 is a pure integrator
        the cost must see).
    q_q : float or one per modal coordinate
        Weight on the modal coordinates' errors q − q_d [1/m²], >= 0.
    q_theta_dot : float or one per joint
        Weight on the joint-rate errors [s²/rad²], >= 0.
    q_q_dot : float or one per modal coordinate
        Weight on the modal rates q̇ [s²/m²], >= 0.
    r : float or one per joint
        Torque weight [1/(N m)²], > 0.
    grid_points : int, one per scheduled angle, or None
        Grid points over one period of each scheduled angle, 4..`MAX_GRID_POINTS`, at
        most `MAX_DESIGNS` designs in all; default (None) `DEFAULT_GRID_POINTS` on one
        angle, fewer on more (`DEFAULT_DESIGNS`).  Unused on a single horizontal link.
    """

    name = "lqr"

    def __init__(self, model: ArmModel, *, Ts: float, q_theta=1600.0, q_q=100.0,
                 q_theta_dot=0.0, q_q_dot=1.0, r=1.0, grid_points=None) -> None:
        n, N = model.n, model.n_joints
        self.model = model
        self.q_theta = _weights("q_theta", q_theta, N, positive=True)
        self.q_q = _weights("q_q", q_q, n - N)
        self.q_theta_dot = _weights("q_theta_dot", q_theta_dot, N)
        self.q_q_dot = _weights("q_q_dot", q_q_dot, n - N)
        self.r = _weights("r", r, N, positive=True)
        self.Ts = control_period(Ts)
        gravity = any(model.params.gravity)
        #: The joints (from 0) whose angles the gains are scheduled on.
        self.scheduled = tuple(range(0 if gravity else 1, N))
        counts = _grid_counts(grid_points, len(self.scheduled))
        axes = [-np.pi + 2.0 * np.pi * np.arange(G) / G for G in counts]
        # In gravity: K_ff's Cholesky factor, for the static deflection q_d (as the PBC).
        self._chol = (np.ravel(np.linalg.cholesky(model.stiffness_matrix()[N:, N:]))
                      if gravity and n > N else np.zeros(0))
        self._work = model.new_workspace()
        W = np.diag(np.concatenate([self.q_theta, self.q_q, self.q_theta_dot, self.q_q_dot]))
        R = np.diag(self.r)
        table = np.empty(tuple(G + 1 for G in counts) + (N, 2 * n))
        grid = np.zeros(counts + (N,))
        for cell in np.ndindex(*counts):
            grid[cell][list(self.scheduled)] = [axes[k][i] for k, i in enumerate(cell)]
            table[cell] = self._design(grid[cell], W, R)
        for k, G in enumerate(counts):  # periodic: the interpolation never wraps i + 1
            first, last = [slice(None)] * len(counts), [slice(None)] * len(counts)
            first[k], last[k] = 0, G
            table[tuple(last)] = table[tuple(first)]
        table.setflags(write=False)
        self._table = table
        #: The joint angles of each design, (designs, N), in the order of `gains`.
        self.grid = grid.reshape(-1, N)
        self._ints = np.array([len(counts), int(gravity), *self.scheduled, *counts],
                              dtype=np.int64)
        self._reals = np.concatenate([[G / (2.0 * np.pi) for G in counts], self._chol,
                                      table.ravel()])
        nf = n - N
        self._state = np.zeros(N * 2 * n + 2 * len(counts) + 2 * n + nf)
        self._ref = np.zeros(3 * N)
        self._tau = np.zeros(N)
        self._residual = np.zeros(0)

    # --- design ------------------------------------------------------------------
    def operating_point(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """(Q0, τ0): the arm at rest at the joint angles ``theta`` — in gravity with the
        links' static deflection and the joint torques that hold it there (what the
        controller computes at run time for θ_d), else (θ, 0) and no torque."""
        model = self.model
        n, N = model.n, model.n_joints
        Q0 = np.zeros(n)
        Q0[:N] = theta
        if not any(model.params.gravity):
            return Q0, np.zeros(N)
        _deflection_entry(*model.packed, *self._work, np.asarray(Q0[:N], dtype=float),
                          self._chol, Q0[N:], np.zeros(2 * n))
        tau0 = (model.gravity_force(Q0) + model.elastic_force(Q0, np.zeros(n)))[:N]
        return Q0, tau0

    def _design(self, theta: np.ndarray, W: np.ndarray, R: np.ndarray) -> np.ndarray:
        import scipy.linalg  # as in `_zoh`
        A, B = self.model.linearize(*self.operating_point(theta))
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
        where = ", ".join(f"theta{j + 1} = {theta[j]:.4g}" for j in self.scheduled) or "rest"
        # Undamped modes that the cost does not see make (A, W) undetectable.
        raise ValueError(f"q_q, q_q_dot: no stabilising LQR gain at {where} rad "
                         f"({reason}); undamped flexible modes need q_q or q_q_dot > 0")

    # --- run time ----------------------------------------------------------------
    @property
    def gains(self) -> np.ndarray:
        """Designed gains, (designs, N, 2n), at the joint angles of `grid` (read-only)."""
        inner = tuple(slice(0, G - 1) for G in self._table.shape[:-2])
        return self._table[inner].reshape(-1, *self._table.shape[-2:])

    def gain(self, theta) -> np.ndarray:
        """K(θ), (N, 2n): the grid gains interpolated multilinearly (periodic) in the
        scheduled angles of the joint angles ``theta`` (N); NaN if one is not finite."""
        N, n = self.model.n_joints, self.model.n
        K = np.empty((N, 2 * n))
        d = self._ints[0]
        x = np.zeros(2 * n)
        x[:N] = theta
        if not _interpolate_gain(self._reals[d + self._chol.size:], self._ints, self._reals[:d],
                                 x, K, np.zeros(2 * d)):
            K[:] = np.nan
        return K

    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray:
        N = self.model.n_joints
        theta_d, dtheta_d, ddtheta_d = ref(t)
        self._ref[:N], self._ref[N:2 * N], self._ref[2 * N:] = theta_d, dtheta_d, ddtheta_d
        lqr_kernel(t, np.ascontiguousarray(x, dtype=float), self._ref, self._ints, self._reals,
                   self._state, *self.model.packed, *self._work, self._tau, self._residual)
        return self._tau.copy()

    def compiled(self) -> CompiledLaw:
        """The compiled form (`controllers._compiled`): the gain table (designed at this
        law's own ``Ts``), the schedule and, in gravity, K_ff's factor."""
        return CompiledLaw.of(lqr_kernel, CONTROLLER_SIGNATURE, self.model, ints=self._ints,
                              reals=self._reals, state=self._state)


@njit(cache=True)
def _deflection_entry(mi, mr, wc, wr, theta, chol, q, Qs):
    """The static deflection at ``theta`` into ``q`` (`controllers._pbc`), from Python."""
    _static_deflection(unpack_model(mi, mr), unpack_workspace(mi, wc, wr), theta, chol, q, Qs,
                       False)


@njit(cache=True)
def _interpolate_gain(table, ints, scale, x, K, cell):
    """K = Σ over the 2^d corners of the grid cell holding the scheduled angles of ``x``
    of (Π per angle: 1 − f or f) × the corner's gain; False if an angle is not finite.
    ``ints`` = [d, gravity, scheduled joints (d), grid counts (d)], ``scale`` = counts/2π,
    ``cell`` scratch (2d).  With one angle: (1 − f) table[i] + f table[i + 1]."""
    d = ints[0]
    for k in range(d):
        theta = x[ints[2 + k]]
        if not np.isfinite(theta):
            return False
        G = ints[2 + d + k]
        u = (theta + np.pi) * scale[k]
        u -= G * math.floor(u / G)  # wrap into [0, G)
        i = int(u)
        if i >= G:  # u rounded up to G
            i = G - 1
        cell[k] = i
        cell[d + k] = u - i
    rows, cols = K.shape
    size = rows * cols
    for r in range(rows):
        for j in range(cols):
            K[r, j] = 0.0
    for corner in range(1 << d):
        w = 1.0
        row = 0
        for k in range(d):  # row-major over the (G + 1)-point axes
            up = (corner >> (d - 1 - k)) & 1
            f = cell[d + k]
            w *= f if up else 1.0 - f
            row = row * (ints[2 + d + k] + 1) + int(cell[k]) + up
        o = row * size
        for r in range(rows):
            for j in range(cols):
                K[r, j] += w * table[o + r * cols + j]
    return True


@njit(cache=True)
def lqr_kernel(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    """`GainScheduledLQR` compiled: ints = [d, gravity, scheduled joints (d), grid counts
    (d)], reals = [counts/2π (d), K_ff's Cholesky factor (gravity), gain table], state =
    K, then scratch."""
    d_model = unpack_model(mi, mr)
    N, n = d_model.links, d_model.n
    d = ints[0]
    chol = reals[d:d + (n - N) * (n - N) * ints[1]]
    table = reals[d + chol.shape[0]:]
    K = state[:N * 2 * n].reshape((N, 2 * n))
    o = N * 2 * n
    cell, Qs, q_d = state[o:o + 2 * d], state[o + 2 * d:o + 2 * d + 2 * n], \
        state[o + 2 * d + 2 * n:o + 2 * d + 2 * n + n - N]
    if not _interpolate_gain(table, ints, reals[:d], x, K, cell):
        for i in range(N):
            tau[i] = np.nan  # the loop ends the run as diverged
        return N
    ws = unpack_workspace(mi, wc, wr)
    for i in range(2 * n):
        Qs[i] = 0.0
    for i in range(n - N):
        q_d[i] = 0.0
    if ints[1] == 1:  # the operating point at θ_d: the links' static deflection
        _static_deflection(d_model, ws, ref[:N], chol, q_d, Qs, False)
    rigid_inverse_dynamics(d_model, ws, ref[:N], ref[N:2 * N], ref[2 * N:3 * N], Qs, tau)
    for j in range(2 * n):
        if j < N:
            err = x[j] - ref[j]
        elif j < n:
            err = x[j] - q_d[j - N]
        elif j < n + N:
            err = x[j] - ref[N + j - n]
        else:
            err = x[j]
        for r in range(N):
            tau[r] -= K[r, j] * err
    return N
