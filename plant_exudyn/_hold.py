"""The exact zero-order hold on Exudyn's generalised-α step.

A load that jumps at a step boundary enters Exudyn's generalised-α step (Arnold and
Brüls's Algorithm 1) through the accelerations the last step ended with: the predictor
uses the algorithmic acceleration a_n and the true acceleration q̈_n, both computed under
the *old* load, so the new load is blended in over the step and the velocity takes an
error h(1 − γ)·Δq̈ per jump.  With one jump per control period the global error is then
first order in the step (replaying a 3 s closed loop at steps Ts, Ts/2, Ts/4, Ts/8
against Ts/64: 5.4e-4, 2.6e-4, 1.3e-4, 6.0e-5 rad), whatever ρ∞ (Newmark's trapezoid
too).  A motor's torque steps: over [t_k, t_k+1) it is the new torque from the start.

`ExactHold` restarts the step from accelerations consistent with the new load: both
q̈_n and a_n move by Δq̈ = W Δf, the constrained response of the arm's accelerations to the
load change Δf (W = M⁻¹ − M⁻¹Cᵀ(C M⁻¹ Cᵀ)⁻¹C M⁻¹, M the mass matrix, C the constraint
Jacobian).  Exudyn lets Python set q_n, q̇_n and q̈_n but not a_n; the step uses a_n only
in its predictor (q += h²(½ − β) a_n, q̇ += h(1 − γ) a_n) and in a' = (α_f q̈_n − α_m a_n)
/ (1 − α_m), so moving q_n by h²(½ − β)Δq̈, q̇_n by h(1 − γ)Δq̈ and q̈_n by
(α_f − α_m)/α_f Δq̈ gives the step exactly what a_n + Δq̈, q̈_n + Δq̈ would (α_f > 0, i.e.
ρ∞ > 0).  The same replay is then second order (5.0e-6, 1.3e-6, 3.3e-7, 7.8e-8 rad).

What it needs per jump, without asking Exudyn for matrices (a dense Jacobian read costs
~75 µs): M is constant in absolute nodal coordinates (ANCF cable, geometrically exact 2D
beam and rigid 2D bodies), and so is C except where a rigid marker sits on an ANCF slope
node: its rotation is atan2(s_y, s_x), whose gradient (−s_y, s_x)/|s|² follows the
slope.  Those entries of C (clamps) and of the load matrix (a torque on such a marker)
are rescaled from the current slope.  A rigid link's body (`_bodies`) has its node at
its centre of mass and its joints at points along it: the entries of C (and of the load
matrix) in its rotation's column are K + A cos φ + B sin φ of its angle φ (K alone for a
torque, A and B alone for a joint or a force away from the node), read from Exudyn at φ,
φ + π/2 and φ + π and set from the current angle.
Everything else is read once from Exudyn.  The compiled update costs ~2 µs; with the
state read and written back, ~10 µs per period.

A stuck friction joint (`_drives`: a stiff bristle spring-damper about its last sticking
position) is, for the hold, what it stands for: a constraint D Δq̈ = 0 on its relative
coordinate.  A load jump then changes the holding torque by the constraint's multiplier
μ = (D W Dᵀ)⁻¹ D W Δf at once, and the arm's accelerations by W Δf − W Dᵀ μ.  The hold
moves the bristle's sticking position by −μ/k, so the bristle carries the new holding
torque from the step's start instead of finding it through a transient of its own (which
overshoots a torque step: the break-loose below breakaway the exact stick never makes).
A joint whose new holding torque would exceed its breakaway level is left free (it slips
in that step, as the reduced plant's joint does); the others are solved for again.
"""
from __future__ import annotations

import exudyn as exu
import numpy as np

from ._hold_kernels import new_hold_data, response_into, restart

__all__ = ["ExactHold", "slope_gradient_entries", "rotation_entries", "scaled"]

_TOL = 1e-9  # relative: what counts as a non-zero entry of C or of a load vector


def scaled(value, x: float):
    """A load parameter's value per unit input (a vector or a number) times ``x``, as
    Exudyn takes it."""
    return x * value if isinstance(value, float) else [x * v for v in value]


def slope_gradient_entries(matrix: np.ndarray, slopes: np.ndarray, s0: np.ndarray):
    """The entries of ``matrix`` (rows: constraint equations or load vectors, columns:
    ODE2 coordinates) on the slope coordinates ``slopes`` (k, 2) of ANCF nodes, as
    (row, node, coefficient): the entry pair equals coefficient × (−s_y, s_x)/|s|² at the
    slope ``s0`` (k, 2) they were read at.  Raises ValueError if a pair is not of that form
    (a constraint this hold does not know)."""
    out = []
    scale = np.abs(matrix).max(initial=0.0)
    for k, (ix, iy) in enumerate(slopes):
        sx, sy = s0[k]
        g = np.array([-sy, sx]) / (sx * sx + sy * sy)
        for row in np.flatnonzero(np.abs(matrix[:, [ix, iy]]).max(axis=1) > _TOL * scale):
            pair = matrix[row, [ix, iy]]
            coefficient = pair @ g / (g @ g)
            if np.abs(pair - coefficient * g).max() > 1e-9 * np.abs(pair).max():
                raise ValueError(f"row {row} acts on ANCF slope coordinates {ix}, {iy} other "
                                 "than through the node's rotation: not supported")
            out.append((row, k, coefficient))
    return out


def rotation_entries(matrix: np.ndarray, quarter: np.ndarray, half: np.ndarray, columns,
                     angles):
    """The entries of ``matrix`` (rows: constraint equations or load vectors, columns:
    ODE2 coordinates) in the rotation ``columns`` of rigid bodies at ``angles``
    ((reference, angle) [rad]) that turn with them, as (row, column, K, A, B, reference)
    with entry = K + A cos φ + B sin φ at the angle φ = reference + displacement, from
    ``matrix``, ``quarter`` and ``half`` (the same read with every one of those bodies
    turned by π/2 and by π).  Raises ValueError if another entry changed (a dependence
    on the rotation this hold does not know)."""
    others = np.ones(matrix.shape[1], dtype=bool)
    others[list(columns)] = False
    scale = max(np.abs(m).max(initial=0.0) for m in (matrix, quarter, half))
    changed = max(np.abs(matrix[:, others] - m[:, others]).max(initial=0.0)
                  for m in (quarter, half))
    if changed > _TOL * scale:
        raise ValueError("a constraint or load depends on a rigid body's rotation other "
                         "than through that rotation's column: not supported")
    out = []
    for col, (reference, angle) in zip(columns, angles):
        c, s = np.cos(angle), np.sin(angle)
        for row in range(matrix.shape[0]):
            e0, e90, e180 = matrix[row, col], quarter[row, col], half[row, col]
            K = 0.5 * (e0 + e180)
            a, b = e0 - K, e90 - K  # the sinusoid at φ and φ + π/2
            if max(abs(a), abs(b)) > _TOL * scale:
                out.append((row, col, K, a * c - b * s, a * s + b * c, reference))
    return np.array(out, dtype=float).reshape(-1, 6)


class ExactHold:
    """The zero-order hold of a set of loads on an Exudyn system, exact in the step
    (module docstring).

    Parameters
    ----------
    mbs : exudyn.MainSystem
        The assembled system, at a configuration where its loads are all zero.
    settings : exudyn.SimulationSettings
        The generalised-α settings the system is stepped with.
    step : float
        Its fixed integration step [s].
    loads : list of list of (load, parameter, value)
        One input per entry: the loads it sets, the load parameter and its value per unit
        input (e.g. τ2 = [(hub-2 torque, "loadVector", (0, 0, 1)), (link-1 tip torque,
        "loadVector", (0, 0, -1))]; a coordinate load: (load, "load", 1.0)).
    slope_nodes : list of int
        The ANCF nodes (``NodePoint2DSlope1``) that carry rigid markers (clamps, torques).
    rotation_nodes : list of int
        The rigid bodies' nodes whose joints or loads act away from the node (rigid
        links, module docstring).
    sticks : list of tuple, optional
        The friction bristles kept stuck across a load jump (module docstring), each
        (base, moving, mode, position, stiffness, damping, level): the ODE2 indices of
        its base (−1: ground) and moving coordinate, the data indices of its friction
        mode (0: stuck) and last sticking position, its stiffness, damping and
        breakaway level.
    """

    def __init__(self, mbs, settings, step: float, loads, slope_nodes, rotation_nodes=(),
                 sticks=()) -> None:
        ga = settings.timeIntegration.generalizedAlpha
        if ga.useNewmark or ga.spectralRadius <= 0.0:
            raise ValueError("the exact hold is written for generalised-alpha with a "
                             "spectral radius > 0 (alpha_f > 0)")
        solver = exu.MainSolverImplicitSecondOrder()  # its own: the plant's keeps its state
        if not solver.InitializeSolver(mbs, settings):
            raise RuntimeError(f"Exudyn could not initialise: {solver.GetErrorString()}")
        n, m = solver.GetODE2size(), solver.GetAEsize()
        solver.ComputeMassMatrix(mbs)
        mass = solver.GetSystemMassMatrix()[:n, :n]

        def jacobian() -> np.ndarray:
            solver.SetSystemJacobian(np.zeros((n + m, n + m)))
            solver.ComputeJacobianAE(mbs, 1.0, 0.0, 1.0, False)
            return solver.GetSystemJacobian()[n:, :n]

        def rhs() -> np.ndarray:
            solver.ComputeODE2RHS(mbs)
            return solver.GetSystemResidual()[:n].copy()

        def load_matrix() -> np.ndarray:
            base = rhs()
            B = np.zeros((n, len(loads)))
            for j, parts in enumerate(loads):
                for load, parameter, value in parts:
                    mbs.SetLoadParameter(load, parameter, scaled(value, 1.0))
                B[:, j] = rhs() - base
                for load, parameter, value in parts:
                    mbs.SetLoadParameter(load, parameter, scaled(value, 0.0))
            return B

        C = jacobian()
        B = load_matrix()
        sd, cfg = mbs.systemData, exu.ConfigurationType
        turns = [sd.GetNodeLTGODE2(k)[2] for k in rotation_nodes]
        if turns:  # the same at every rigid body turned by π/2 and π (module docstring)
            u = sd.GetODE2Coordinates(cfg.Current)
            turned = []
            for angle in (0.5 * np.pi, np.pi):
                at = u.copy()
                at[turns] += angle
                sd.SetODE2Coordinates(at, cfg.Current)
                turned.append((jacobian(), load_matrix()))
            sd.SetODE2Coordinates(u, cfg.Current)
            angles = [(r, r + u[col]) for r, col in zip(
                [mbs.GetNodeParameter(k, "referenceCoordinates")[2] for k in rotation_nodes],
                turns)]
            (C90, B90), (C180, B180) = turned
            used = np.abs(np.hstack([C, C90, C180])).max(axis=1) > 0.0
            C, C90, C180 = C[used], C90[used], C180[used]
            c_rot = rotation_entries(C, C90, C180, turns, angles)
            b_rot = rotation_entries(B.T, B90.T, B180.T, turns, angles)
        else:
            C = C[np.abs(C).max(axis=1) > 0.0]  # rows of unused algebraic coordinates are zero
            c_rot = b_rot = np.zeros((0, 6))
        slopes = np.array([sd.GetNodeLTGODE2(k)[2:4] for k in slope_nodes],
                          dtype=np.int64).reshape(-1, 2)
        slope_ref = np.array([mbs.GetNodeParameter(k, "referenceCoordinates")[2:4]
                              for k in slope_nodes], dtype=float).reshape(-1, 2)
        s0 = slope_ref + sd.GetODE2Coordinates(cfg.Current)[slopes] if len(slope_nodes) \
            else slope_ref
        c_rows = _entries(slope_gradient_entries(C, slopes, s0))
        b_rows = _entries(slope_gradient_entries(B.T, slopes, s0))
        # A body may have no mass in some direction (the stator: inertia without mass):
        # M + k C_fᵀC_f, with C_f the constraint rows that never change, has the same
        # constrained response (C_f Δq̈ = 0) and is invertible.
        fixed = np.setdiff1d(np.arange(C.shape[0]),
                             np.concatenate([c_rows[:, 0], c_rot[:, 0]]).astype(int))
        k = np.abs(np.diag(mass)).max()
        try:
            minv = np.linalg.inv(mass + k * C[fixed].T @ C[fixed])
        except np.linalg.LinAlgError:
            raise ValueError("the exact hold needs inertia on every rotation clamped to a "
                             "beam: a hub inertia of 0 on a flexible link leaves its "
                             "accelerations undetermined") from None
        minv = np.ascontiguousarray(0.5 * (minv + minv.T))  # symmetric: rows are columns
        h = step
        rho = ga.spectralRadius  # Exudyn's α_m, α_f, β, γ of ρ∞ (Arnold and Brüls)
        am, af = (2 * rho - 1) / (rho + 1), rho / (rho + 1)
        beta, gamma = 0.25 * (1 - am + af) ** 2, 0.5 - am + af
        #: What Δq̈ = 1 does to (q_n, q̇_n, q̈_n) (module docstring).
        factors = np.array([h * h * (0.5 - beta), h * (1 - gamma), (af - am) / af])
        m = C.shape[0]
        sticks = np.array(sticks, dtype=float).reshape(-1, 7)
        self.data = new_hold_data(
            minv, np.ascontiguousarray(C), _pattern(C, c_rows, slopes, c_rot),
            np.ascontiguousarray(B.T), _pattern(B.T, b_rows, slopes, b_rot), c_rows, b_rows,
            slopes, slope_ref, c_rot, b_rot, factors, np.empty(n), np.empty((m, n)),
            np.empty((m, m)), np.empty(m), np.empty(n), np.empty(len(loads)),
            np.ascontiguousarray(sticks[:, :4].astype(np.int64)),
            np.ascontiguousarray(sticks[:, 4:]), np.empty((len(sticks), n)))
        self._change = self.data.change  # the structure's own array: written in place
        self._sticking = len(sticks) > 0
        self._no_data = np.empty(0)
        self.sd = sd
        #: The configurations `apply` writes (start_of_step False, True).
        self._written = ((cfg.Current,), (cfg.Current, cfg.StartOfStep))

    def apply(self, change, *, start_of_step: bool = False) -> None:
        """Restart the next step with the accelerations of the loads changed by ``change``
        (one value per input): moves Exudyn's current q, q̇, q̈ (module docstring).
        ``start_of_step``: called from a pre-step function, where Exudyn has already taken
        the step's start (what it repeats a step from, what a friction switch goes back
        to) from the current state: moves that too."""
        sd, cur = self.sd, exu.ConfigurationType.Current
        q, v, a = (sd.GetODE2Coordinates(cur), sd.GetODE2Coordinates_t(cur),
                   sd.GetODE2Coordinates_tt(cur))
        self._change[:] = change
        data = sd.GetDataCoordinates(cur) if self._sticking else self._no_data
        restart(self.data, q, v, a, data)
        # as lists: Exudyn reads a list about twice as fast as an array (element by element)
        data, q, v, a = data.tolist(), q.tolist(), v.tolist(), a.tolist()
        for cfg in self._written[start_of_step]:
            if self._sticking:
                sd.SetDataCoordinates(data, cfg)
            sd.SetODE2Coordinates(q, cfg)
            sd.SetODE2Coordinates_t(v, cfg)
            sd.SetODE2Coordinates_tt(a, cfg)

    def response(self, q: np.ndarray, change) -> np.ndarray:
        """Δq̈ = W B(q) ``change``: the constrained acceleration response to a change of
        the loads at the configuration ``q`` (ODE2 displacements)."""
        self._change[:] = change
        out = np.empty(len(q))
        response_into(self.data, np.asarray(q, float), out)
        return out


def _entries(entries) -> np.ndarray:
    """(row, node, coefficient) as a (k, 3) float array for the compiled update."""
    return np.array(entries, dtype=float).reshape(-1, 3)


def _pattern(matrix: np.ndarray, slope_rows: np.ndarray, slopes: np.ndarray,
             rotation_rows: np.ndarray) -> np.ndarray:
    """The columns of each row's non-zero entries (the slope pair of a slope-dependent row
    and the column of a rotation-dependent entry included, whatever their value now),
    padded with −1: (rows, most entries)."""
    cols = [set(np.flatnonzero(row)) for row in matrix]
    for row, k, _ in slope_rows:
        cols[int(row)] |= set(slopes[int(k)])
    for row, col, *_ in rotation_rows:
        cols[int(row)].add(int(col))
    out = np.full((len(cols), max((len(c) for c in cols), default=0)), -1, dtype=np.int64)
    for i, c in enumerate(cols):
        out[i, :len(c)] = sorted(c)
    return out
