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
are rescaled from the current slope; everything else is read once from Exudyn.  The
compiled update costs ~2 µs; with the state read and written back, ~10 µs per period.

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
from numba import njit, types
from numba.experimental import structref

__all__ = ["ExactHold", "HoldData", "slope_gradient_entries", "scaled"]

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
    sticks : list of tuple, optional
        The friction bristles kept stuck across a load jump (module docstring), each
        (base, moving, mode, position, stiffness, damping, level): the ODE2 indices of
        its base (−1: ground) and moving coordinate, the data indices of its friction
        mode (0: stuck) and last sticking position, its stiffness, damping and
        breakaway level.
    """

    def __init__(self, mbs, settings, step: float, loads, slope_nodes, sticks=()) -> None:
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
        solver.SetSystemJacobian(np.zeros((n + m, n + m)))
        solver.ComputeJacobianAE(mbs, 1.0, 0.0, 1.0, False)
        C = solver.GetSystemJacobian()[n:, :n]
        C = C[np.abs(C).max(axis=1) > 0.0]  # rows of unused algebraic coordinates are zero

        def rhs() -> np.ndarray:
            solver.ComputeODE2RHS(mbs)
            return solver.GetSystemResidual()[:n].copy()

        base = rhs()
        B = np.zeros((n, len(loads)))
        for j, parts in enumerate(loads):
            for load, parameter, value in parts:
                mbs.SetLoadParameter(load, parameter, scaled(value, 1.0))
            B[:, j] = rhs() - base
            for load, parameter, value in parts:
                mbs.SetLoadParameter(load, parameter, scaled(value, 0.0))

        sd, cfg = mbs.systemData, exu.ConfigurationType
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
        fixed = np.setdiff1d(np.arange(C.shape[0]), c_rows[:, 0].astype(int))
        k = np.abs(np.diag(mass)).max()
        minv = np.linalg.inv(mass + k * C[fixed].T @ C[fixed])
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
            minv, np.ascontiguousarray(C), _pattern(C, c_rows, slopes),
            np.ascontiguousarray(B.T), _pattern(B.T, b_rows, slopes), c_rows, b_rows,
            slopes, slope_ref, factors, np.empty(n), np.empty((m, n)),
            np.empty((m, m)), np.empty(m), np.empty(n), np.empty(len(loads)),
            np.ascontiguousarray(sticks[:, :4].astype(np.int64)),
            np.ascontiguousarray(sticks[:, 4:]), np.empty((len(sticks), n)))
        self._change = self.data.change  # the structure's own array: written in place
        self._sticking = len(sticks) > 0
        self._no_data = np.empty(0)
        self.sd = sd

    def apply(self, change) -> None:
        """Restart the next step with the accelerations of the loads changed by ``change``
        (one value per input): moves Exudyn's current q, q̇, q̈ (module docstring)."""
        sd, cur = self.sd, exu.ConfigurationType.Current
        q, v, a = (sd.GetODE2Coordinates(cur), sd.GetODE2Coordinates_t(cur),
                   sd.GetODE2Coordinates_tt(cur))
        self._change[:] = change
        if self._sticking:
            data = sd.GetDataCoordinates(cur)
            restart(self.data, q, v, a, data)
            sd.SetDataCoordinates(data, cur)
        else:
            restart(self.data, q, v, a, self._no_data)
        sd.SetODE2Coordinates(q, cur)
        sd.SetODE2Coordinates_t(v, cur)
        sd.SetODE2Coordinates_tt(a, cur)

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


def _pattern(matrix: np.ndarray, slope_rows: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """The columns of each row's non-zero entries (the slope pair of a slope-dependent row
    included, whatever its value now), padded with −1: (rows, most entries)."""
    cols = [set(np.flatnonzero(row)) for row in matrix]
    for row, k, _ in slope_rows:
        cols[int(row)] |= set(slopes[int(k)])
    out = np.full((len(cols), max((len(c) for c in cols), default=0)), -1, dtype=np.int64)
    for i, c in enumerate(cols):
        out[i, :len(c)] = sorted(c)
    return out


# --- the compiled update ------------------------------------------------------------------------
_V, _M = types.Array(types.float64, 1, "C"), types.Array(types.float64, 2, "C")
_MI = types.Array(types.int64, 2, "C")
_FIELDS = (("minv", _M), ("C", _M), ("c_cols", _MI), ("Bt", _M), ("b_cols", _MI),
           ("c_rows", _M), ("b_rows", _M), ("slopes", _MI), ("slope_ref", _M),
           ("factors", _V), ("y", _V), ("G", _M), ("S", _M), ("z", _V), ("delta", _V),
           ("change", _V), ("sticks", _MI), ("stick_law", _M), ("stick_response", _M))


@structref.register
class _HoldDataType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class HoldData(structref.StructRefProxy):
    """What `restart` works with: M⁻¹, C and the load matrix with their patterns and
    slope-dependent entries, the step's factors, the friction bristles (`ExactHold`'s
    ``sticks``: indices, then stiffness, damping, level) and the work arrays (one
    structure passed by reference: 19 separate arrays cost ~5 µs a call to unbox)."""

    @property
    def change(self):
        return _change(self)


@njit(cache=True)
def _change(d):
    return d.change


structref.define_boxing(_HoldDataType, HoldData)
_HOLD = _HoldDataType(_FIELDS)


@njit(cache=True)
def new_hold_data(minv, C, c_cols, Bt, b_cols, c_rows, b_rows, slopes, slope_ref, factors,
                  y, G, S, z, delta, change, sticks, stick_law, stick_response):
    """A `HoldData` of these arrays (shared, not copied)."""
    d = structref.new(_HOLD)
    d.minv, d.C, d.c_cols, d.Bt, d.b_cols = minv, C, c_cols, Bt, b_cols
    d.c_rows, d.b_rows, d.slopes, d.slope_ref, d.factors = (c_rows, b_rows, slopes,
                                                            slope_ref, factors)
    d.y, d.G, d.S, d.z, d.delta, d.change = y, G, S, z, delta, change
    d.sticks, d.stick_law, d.stick_response = sticks, stick_law, stick_response
    return d


@njit(cache=True)
def _set_slope_entries(matrix, rows, slopes, slope_ref, q):
    """Each slope-dependent pair of ``matrix`` (row, node, coefficient) from the slope in
    ``q``: coefficient × (−s_y, s_x)/|s|²."""
    for e in range(rows.shape[0]):
        row, k, coef = int(rows[e, 0]), int(rows[e, 1]), rows[e, 2]
        ix, iy = slopes[k, 0], slopes[k, 1]
        sx, sy = slope_ref[k, 0] + q[ix], slope_ref[k, 1] + q[iy]
        s2 = sx * sx + sy * sy
        matrix[row, ix], matrix[row, iy] = -coef * sy / s2, coef * sx / s2


@njit(cache=True)
def _factor(d):
    """G = C M⁻¹ and S = C M⁻¹ Cᵀ = L Lᵀ (L in S's lower triangle), C as last set."""
    minv, C, c_cols, G, S = d.minv, d.C, d.c_cols, d.G, d.S
    n, m = minv.shape[0], C.shape[0]
    for r in range(m):  # row r of G: C's few entries of row r
        G[r, :] = 0.0
        for c in c_cols[r]:
            if c >= 0:
                w = C[r, c]
                for i in range(n):
                    G[r, i] += w * minv[c, i]
    for r in range(m):  # S = G Cᵀ (symmetric positive definite)
        for t in range(r + 1):
            acc = 0.0
            for c in c_cols[t]:
                if c >= 0:
                    acc += G[r, c] * C[t, c]
            S[r, t] = acc
    for r in range(m):
        for t in range(r + 1):
            acc = S[r, t]
            for k in range(t):
                acc -= S[r, k] * S[t, k]
            S[r, t] = np.sqrt(acc) if t == r else acc / S[t, t]


@njit(cache=True)
def _project(d, y, out):
    """``out`` = y − Gᵀ S⁻¹ C y: the constrained response to the load whose unconstrained
    response is y = M⁻¹ f (`_factor` done)."""
    C, c_cols, G, S, z = d.C, d.c_cols, d.G, d.S, d.z
    n, m = y.shape[0], C.shape[0]
    for r in range(m):  # z = C y, then S⁻¹ z
        acc = 0.0
        for c in c_cols[r]:
            if c >= 0:
                acc += C[r, c] * y[c]
        z[r] = acc
    for r in range(m):
        acc = z[r]
        for k in range(r):
            acc -= S[r, k] * z[k]
        z[r] = acc / S[r, r]
    for r in range(m - 1, -1, -1):
        acc = z[r]
        for k in range(r + 1, m):
            acc -= S[k, r] * z[k]
        z[r] = acc / S[r, r]
    for i in range(n):
        out[i] = y[i]
    for r in range(m):
        for i in range(n):
            out[i] -= G[r, i] * z[r]


@njit(cache=True)
def constrained_response(d, out):
    """``out`` = W B ``d.change`` (module docstring), C and B as last set."""
    minv, Bt, b_cols, change, y = d.minv, d.Bt, d.b_cols, d.change, d.y
    n = minv.shape[0]
    y[:] = 0.0  # y = M⁻¹ B change, from B's few non-zero entries (M⁻¹ symmetric)
    for j in range(Bt.shape[0]):
        if change[j] != 0.0:
            for c in b_cols[j]:
                if c >= 0:
                    w = Bt[j, c] * change[j]
                    for i in range(n):
                        y[i] += w * minv[c, i]
    _factor(d)
    _project(d, y, out)


@njit(cache=True)
def response_into(d, q, out):
    """``out`` = W B(q) ``d.change``: C's and B's slope-dependent entries set from ``q``,
    then `constrained_response`."""
    _set_slope_entries(d.C, d.c_rows, d.slopes, d.slope_ref, q)
    _set_slope_entries(d.Bt, d.b_rows, d.slopes, d.slope_ref, q)
    constrained_response(d, out)


@njit(cache=True)
def _relative(x, base, moving):
    """A bristle's relative coordinate in ``x`` (base −1: the ground)."""
    return x[moving] - (x[base] if base >= 0 else 0.0)


@njit(cache=True)
def hold_sticks(d, q, v, data, delta):
    """Keep the stuck bristles stuck across the load change whose free response is
    ``delta`` (module docstring): ``delta`` becomes the response with them as
    constraints, each one's sticking position in ``data`` moves by −μ/k; a bristle whose
    holding force would exceed its level is left free (the largest excess first)."""
    sticks, law, response, y = d.sticks, d.stick_law, d.stick_response, d.y
    minv = d.minv
    count, n = sticks.shape[0], minv.shape[0]
    stuck = np.zeros(count, np.bool_)
    force = np.zeros(count)
    for j in range(count):
        base, moving, mode, position = sticks[j, 0], sticks[j, 1], sticks[j, 2], sticks[j, 3]
        if data[mode] != 0.0:  # slipping
            continue
        stuck[j] = True
        force[j] = (law[j, 0] * (_relative(q, base, moving) - data[position])
                    + law[j, 1] * _relative(v, base, moving))
        for i in range(n):  # M⁻¹ Dⱼᵀ (M⁻¹ symmetric)
            y[i] = minv[moving, i] - (minv[base, i] if base >= 0 else 0.0)
        _project(d, y, response[j])
    while True:
        held = np.flatnonzero(stuck)
        k = held.shape[0]
        if k == 0:
            return
        A, rhs = np.empty((k, k)), np.empty(k)
        for r in range(k):
            base, moving = sticks[held[r], 0], sticks[held[r], 1]
            rhs[r] = _relative(delta, base, moving)
            for t in range(k):
                A[r, t] = _relative(response[held[t]], base, moving)
        mu = np.linalg.solve(A, rhs)
        worst, excess = -1, 1.0
        for r in range(k):
            ratio = abs(force[held[r]] + mu[r]) / law[held[r], 2]
            if ratio > excess:
                worst, excess = held[r], ratio
        if worst < 0:
            break
        stuck[worst] = False
    for r in range(k):
        j = held[r]
        for i in range(n):
            delta[i] -= mu[r] * response[j, i]
        data[sticks[j, 3]] -= mu[r] / law[j, 0]


@njit(cache=True)
def restart(d, q, v, a, data):
    """Move the step's start (q, q̇, q̈ and the bristles' sticking positions in ``data``;
    in place) as the loads changed by ``d.change`` demand: Δq̈ = W B(q) change, with the
    stuck bristles held (`hold_sticks`), then the shifts of `ExactHold` (module
    docstring)."""
    delta = d.delta
    response_into(d, q, delta)
    if d.sticks.shape[0] > 0:
        hold_sticks(d, q, v, data, delta)
    fq, fv, fa = d.factors[0], d.factors[1], d.factors[2]
    for i in range(q.shape[0]):
        q[i] += fq * delta[i]
        v[i] += fv * delta[i]
        a[i] += fa * delta[i]
