"""The Vinnicombe ν-gap δν(P1, P2) and the generalised stability margin b(P, C): how far
apart two plant models are as far as feedback can tell, and how much of that distance a
loop tolerates (Vinnicombe, *Frequency domain uncertainty and the graph topology*, IEEE
TAC 38(9), 1993; Vinnicombe, *Uncertainty and Feedback*, 2001).

The certificate they give: if δν(P1, P2) < b(P1, C), the controller C that stabilises P1
stabilises P2 too (and b(P2, C) ≥ arcsin b(P1, C) − arcsin δν).

Definitions (continuous time on s = jω, discrete time on z = e^{jθ}, θ = ωTs ∈ [0, π]):

- G = [N; M] is the normalised right coprime factorisation of P = N M⁻¹ (stable, and
  G(jω)ᴴ G(jω) = I): an orthonormal basis of the graph of P, i.e. of the column space of
  [P; I].  It comes from the stabilising solution of the LQ Riccati equation of (A, B)
  with Q = CᵀC, S = CᵀD, R = I + DᵀD (`control.care`, `control.dare`: SLICOT's
  solver, else scipy's — each fails on some well-posed case the other solves, e.g. the
  ZOH double integrator at z = 1); F is the LQ gain and G = (A + BF, BH, [C + DF; F],
  [DH; H]) with H = R^{-1/2} (continuous) or (R + BᵀXB)^{-1/2} (discrete).
- The chordal distance κ(ω) = ‖(I + P2P2ᴴ)^{-1/2} (P2 − P1) (I + P1ᴴP1)^{-1/2}‖ is the
  sine of the largest angle between the two graphs: σ_max(G1 − G2 (G2ᴴ G1)).
- δν(P1, P2) = sup_ω κ(ω) if det(G2ᴴ G1) ≠ 0 on the whole axis and its winding number
  about the origin is 0; else 1 (Vinnicombe 2001, Definition 3.1).  The winding number
  condition is what makes δν a metric for feedback: without it, a stable 0.5/(s + 1) and
  an unstable 0.5/(s − 1) would be 0.8 apart while C = 0 stabilises the first with margin
  0.89 and not the second (a test).
- b(P, C) = 1/‖[P; I](I + CP)⁻¹[C, I]‖∞ if C stabilises P (negative feedback u = −C y,
  like `control.feedback` and MATLAB's ``ncfmargin``), else 0.

Poles on the stability boundary (rigid-body modes: s = 0, z = 1; undamped modes).  A
mode on or beyond the boundary that no input reaches or no output sees (PBH test on the
eigenvectors, or the Schur basis of a repeated eigenvalue; relative weight < 1e-9) is
removed first by an ordered real Schur form: it
is no pole of P, and it would leave the Riccati equation below without a stabilising
solution (the FE arm's undamped axial modes are such at θ2 = 0; SLICOT's staircase
``tb01pd``, behind `control.minreal`, removed none of them there, or 70 of 72 states
with another tolerance).  A hidden stable mode needs no removal: it drops out of the
factors.  The normalised coprime factors move every pole of P on the
axis into the open left half plane (z: into the unit disc) — the LQ gain F stabilises
them — and a pole of P becomes a zero of M: the graph is continuous through it.  So no
point of the axis is excluded or indented: κ and det(G2ᴴ G1) are evaluated at ω = 0
(z = 1) itself and through every resonance, and the winding number is counted on the
plain axis, 0 ≤ ω ≤ ∞ (the negative half is its mirror image for real systems, so the
winding number is the phase change over [0, ∞] divided by π).

The frequency grid.  A fixed grid underestimates sup κ near lightly damped modes (the
unsafe direction), so the grid holds: ω = 0 and ∞ (θ = 0 and π); ``points_per_decade``
log-spaced points from 1/100 of the slowest to 100× the fastest pole of P1, P2 and their
factors; every pole's damped frequency and natural frequency, and points at ω_d(1 ± kζ),
k = ½, 1, 2, 4, around each lightly damped one.  Every local maximum of κ on the grid is
then refined by a bounded scalar maximisation between its neighbours.  The winding
number is counted on the same grid, with midpoints inserted wherever the phase of
det(G2ᴴ G1) steps by more than π/4.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg
import scipy.optimize

__all__ = ["nu_gap", "stability_margin", "gap_detail", "margin_detail", "GapDetail",
           "MarginDetail", "FactorisationError", "as_statespace"]

#: Default grid density (the ν-gap changes by < 1e-3 when it is doubled: a test).
POINTS_PER_DECADE = 60
#: κ values below this are round-off: their local maxima are not refined.
_NOISE_FLOOR = 1e-9
#: Phase step of det(G2ᴴ G1) above which the winding count inserts a midpoint.
_MAX_PHASE_STEP = np.pi / 4
#: A winding number is an integer: the phase change over [0, ∞] must be this close to kπ.
_WINDING_SLACK = 0.1
#: A mode is on the stability boundary if its damping ratio is below this.
_BOUNDARY = 1e-6
#: A mode is hidden if an input (output) reaches it with less than this relative weight.
_HIDDEN = 1e-9
#: Eigenvalues this close (relative) are one cluster (a repeated eigenvalue).
_CLUSTER = 1e-8
#: An eigenvalue recomputed after a Schur reordering is the same one within this.
_MATCH = 1e-6
#: The coprime factors must be inner to this (G*G = I on the axis; κ is then accurate to
#: about as much); the better of two Riccati solvers is kept.
_INNER_TOLERANCE = 1e-3


class FactorisationError(ArithmeticError):
    """No normalised coprime factorisation could be computed to `_INNER_TOLERANCE`: the
    Riccati solvers fail on modes on the stability boundary that an input or output
    barely reaches (measured: the undamped FE arm of Table 1 seen through two outputs)."""


@dataclass(frozen=True)
class GapDetail:
    """The ν-gap with what it was computed from.

    ``value`` is δν; ``peak`` the supremum of the chordal distance and ``frequency`` where
    it is [rad/s; for a discrete system with unspecified period, rad/sample];
    ``winding`` the winding number of det(G2ᴴ G1) (0: the condition holds; None: the
    determinant vanishes on the axis); ``omega``, ``kappa`` the grid (refined points
    included) and κ on it.
    """

    value: float
    peak: float
    frequency: float
    winding: int | None
    omega: np.ndarray
    kappa: np.ndarray


@dataclass(frozen=True)
class MarginDetail:
    """b(P, C) with ``stable`` (does C stabilise P), the worst ``frequency`` and the grid
    of σ_max of the four-block closed loop (``omega``, ``gain``)."""

    value: float
    stable: bool
    frequency: float
    omega: np.ndarray
    gain: np.ndarray


# --- systems ----------------------------------------------------------------------------
def as_statespace(system, name: str = "system") -> control.StateSpace:
    """A python-control `StateSpace` of ``system`` (a StateSpace, a TransferFunction, or
    a matrix taken as a static gain)."""
    if isinstance(system, control.StateSpace):
        return system
    if isinstance(system, control.LTI):
        return control.ss(system)
    D = np.atleast_2d(np.asarray(system, dtype=float))
    if D.ndim != 2 or not np.all(np.isfinite(D)):
        raise ValueError(f"{name} must be a python-control system or a finite gain matrix")
    p, m = D.shape
    return control.ss(np.zeros((0, 0)), np.zeros((0, m)), np.zeros((p, 0)), D)


def _common_time(systems, names) -> tuple[bool, float | None]:
    """(discrete?, sampling period or None) shared by ``systems`` (a static gain fits
    either); ValueError if one is continuous and another discrete, or the periods differ."""
    discrete, period = None, None
    for sys_, name in zip(systems, names):
        if sys_.nstates == 0 and sys_.dt is None:
            continue
        d = bool(control.isdtime(sys_, strict=True))
        if discrete is not None and d != discrete:
            raise ValueError(f"{', '.join(names)} must all be continuous or all discrete")
        discrete = d
        if d and sys_.dt is not True:
            if period is not None and not math.isclose(period, sys_.dt, rel_tol=1e-12):
                raise ValueError(f"{', '.join(names)} have different sampling periods "
                                 f"({period} and {sys_.dt})")
            period = float(sys_.dt)
    return bool(discrete), period


def _balanced(sys_: control.StateSpace) -> control.StateSpace:
    """The same transfer function with the system matrix [[A, B], [C, 0]] balanced by a
    diagonal similarity of the states (SLICOT's ``tb01id``, here through
    `scipy.linalg.matrix_balance` of [[A, b], [c, 0]], b and c the row and column 1-norms
    of B and C): a mechanical model in (q, q̇) coordinates has ω² ~ 1e10 next to 1 in A,
    which defeats eigenvector tests, Schur reordering and the Riccati solvers; balanced,
    each mode reads [[0, ω], [−ω, −2ζω]].  B and C take part because the hidden-mode test
    weighs each mode against ‖B‖ and ‖C‖: balancing A alone can leave C's entries many
    decades apart, and a mode that the output sees then looks unobservable next to the
    largest (a test)."""
    if not sys_.nstates:
        return sys_
    A, B, C = (np.asarray(x, float) for x in (sys_.A, sys_.B, sys_.C))
    n = A.shape[0]
    system = np.zeros((n + 1, n + 1))
    system[:n, :n], system[:n, n], system[n, :n] = A, np.abs(B).sum(1), np.abs(C).sum(0)
    _, T = scipy.linalg.matrix_balance(system, permute=False)
    scale = np.diag(T)[:n] / T[n, n]  # the inputs and outputs keep their units
    return control.ss(A * (scale[None, :] / scale[:, None]), B / scale[:, None],
                      C * scale[None, :], sys_.D, sys_.dt)


def _prepared(sys_: control.StateSpace, discrete: bool) -> control.StateSpace:
    """Balanced, without hidden modes on the stability boundary."""
    return _without_hidden_boundary_modes(_balanced(sys_), discrete)


def _without_hidden_boundary_modes(sys_: control.StateSpace,
                                   discrete: bool) -> control.StateSpace:
    """``sys_`` without its uncontrollable or unobservable modes on or beyond the stability
    boundary (module docstring): the only hidden modes that matter — they would count as
    poles of P and leave the Riccati equation of the coprime factors without a stabilising
    solution — while a hidden stable mode drops out of the factors by itself."""
    for dual in (False, True):  # uncontrollable modes, then unobservable ones (dual system)
        A, B, C = ((sys_.A.T, sys_.C.T, sys_.B.T) if dual else (sys_.A, sys_.B, sys_.C))
        drop = _unreachable_boundary_eigenvalues(np.asarray(A, float), np.asarray(B, float),
                                                 discrete)
        if not drop.size:
            continue
        T, Q, k = scipy.linalg.schur(A, output="real", sort=lambda re, im: not _member(
            complex(re, im), drop))
        A1, B1, C1 = T[:k, :k], Q[:, :k].T @ B, C @ Q[:, :k]
        if dual:
            A1, B1, C1 = A1.T, C1.T, B1.T
        sys_ = control.ss(A1, B1, C1, sys_.D, sys_.dt)
    return sys_


def _member(z: complex, values: np.ndarray) -> bool:
    """Whether ``z`` is one of ``values`` (as recomputed after a Schur reordering)."""
    return bool(np.any(np.abs(values - z) <= _MATCH * max(1.0, abs(z))))


def _unreachable_boundary_eigenvalues(A, B, discrete: bool) -> np.ndarray:
    """Eigenvalues of A on or beyond the stability boundary that B does not reach (PBH):
    a simple one by its left eigenvector, a repeated one (a rigid body's Jordan block) by
    the orthonormal basis of its left invariant subspace from an ordered Schur form."""
    if not A.shape[0]:
        return np.zeros(0, complex)
    lam, left = scipy.linalg.eig(A, left=True, right=False)
    s = np.log(lam.astype(complex) + 1e-300) if discrete else lam  # per-sample s = ln z
    boundary = s.real >= -_BOUNDARY * np.abs(s)
    b_norm = max(np.linalg.norm(B), 1e-300)
    drop, seen = [], np.zeros(len(lam), bool)
    for i in np.flatnonzero(boundary):
        if seen[i]:
            continue
        cluster = np.abs(lam - lam[i]) <= _CLUSTER * max(1.0, abs(lam[i]))
        seen |= cluster
        if cluster.sum() == 1:
            reach = np.linalg.norm(left[:, i].conj() @ B) / np.linalg.norm(left[:, i])
        else:
            values = lam[cluster]
            T, Q, k = scipy.linalg.schur(A, output="real", sort=lambda re, im: not _member(
                complex(re, im), values))
            reach = np.linalg.norm(Q[:, k:].T @ B)
        if reach <= _HIDDEN * b_norm:
            drop.extend(lam[cluster])
    return np.array(drop, complex)


class _Realisation:
    """(A, B, C, D) of a stable system, evaluated fast at many frequencies through the
    complex Schur form of A."""

    def __init__(self, A, B, C, D, discrete: bool) -> None:
        self.discrete = discrete
        self.matrices = (A, B, C, D)
        self.D = np.asarray(D, dtype=complex)
        if A.shape[0]:
            T, Z = scipy.linalg.schur(np.asarray(A, dtype=complex), output="complex")
            self.T, self.B, self.C = T, Z.conj().T @ B, C @ Z
        else:
            self.T = np.zeros((0, 0), complex)
            self.B, self.C = np.zeros((0, B.shape[1]), complex), np.zeros((C.shape[0], 0), complex)
        self.poles = np.diag(self.T).copy()

    def __call__(self, w: np.ndarray) -> np.ndarray:
        """Frequency response at ``w`` (rad/s, or rad/sample if discrete; inf allowed in
        continuous time): array (len(w), p, m)."""
        w = np.atleast_1d(np.asarray(w, dtype=float))
        out = np.broadcast_to(self.D, (len(w), *self.D.shape)).copy()
        n = self.T.shape[0]
        finite = np.isfinite(w)
        if not n or not finite.any():
            return out
        s = np.exp(1j * w[finite]) if self.discrete else 1j * w[finite]
        # Back substitution of (sI − T) X = B for every s at once (T upper triangular).
        X = np.empty((len(s), n, self.B.shape[1]), complex)
        for i in range(n - 1, -1, -1):
            rhs = self.B[i] + np.einsum("j,fjk->fk", self.T[i, i + 1:], X[:, i + 1:])
            X[:, i] = rhs / (s - self.T[i, i])[:, None]
        out[finite] += np.einsum("pj,fjm->fpm", self.C, X)
        return out


def _graph_symbol(P: control.StateSpace, discrete: bool) -> _Realisation:
    """The normalised right coprime factors G = [N; M] of a minimal P (module docstring)."""
    A, B, C, D = (np.asarray(x, dtype=float) for x in (P.A, P.B, P.C, P.D))
    p, m = D.shape
    R = np.eye(m) + D.T @ D
    if A.shape[0] == 0:
        H = _inverse_sqrt(R)
        return _Realisation(A, np.zeros((0, m)), np.zeros((p + m, 0)), np.vstack([D @ H, H]),
                            discrete)
    errors, best = [], None
    for method in ("slycot", "scipy"):  # each fails on some well-posed cases the other solves
        try:
            with warnings.catch_warnings():  # SLICOT warns of an inaccurate solution
                warnings.simplefilter("error")
                X, poles, gain = (control.dare if discrete else control.care)(
                    A, B, C.T @ C, R, S=C.T @ D, method=method)
        except (ValueError, np.linalg.LinAlgError, ArithmeticError, ImportError,
                Warning) as exc:
            errors.append(f"{method}: {' '.join(str(exc).split())}")
            continue
        stable = np.all(np.abs(poles) < 1.0) if discrete else np.all(np.real(poles) < 0.0)
        if not stable:
            errors.append(f"{method}: the solution does not stabilise")
            continue
        H = _inverse_sqrt(R + B.T @ X @ B if discrete else R)
        F = -np.asarray(gain)
        G = _Realisation(A + B @ F, B @ H, np.vstack([C + D @ F, F]), np.vstack([D @ H, H]),
                         discrete)
        error = _inner_error(G, discrete)
        if best is None or error < best[0]:
            best = (error, G)
        if error > _INNER_TOLERANCE:
            errors.append(f"{method}: factors not normalised (|G*G - I| = {error:.1g})")
    if best is None or best[0] > _INNER_TOLERANCE:
        raise FactorisationError(f"no normalised coprime factorisation ({'; '.join(errors)})")
    return best[1]


def _inner_error(G: "_Realisation", discrete: bool) -> float:
    """max |G*G − I| at 0, 1 and the magnitudes of G's poles (an inaccurate Riccati
    solution shows as factors that are not inner)."""
    probe = np.abs(G.poles)
    w = np.concatenate([[0.0, 1.0], probe[probe > 0]])
    g = G(np.minimum(w, math.pi) if discrete else w)
    gram = np.conj(np.swapaxes(g, 1, 2)) @ g
    return float(np.abs(gram - np.eye(g.shape[2])).max())


def _inverse_sqrt(W: np.ndarray) -> np.ndarray:
    vals, vecs = np.linalg.eigh((W + W.T) / 2)
    return (vecs / np.sqrt(vals)) @ vecs.T


# --- the frequency grid -------------------------------------------------------------------
def _grid(poles: np.ndarray, discrete: bool, points_per_decade: int) -> np.ndarray:
    """ω (rad/s) or θ (rad/sample) grid of the module docstring, sorted, with 0 and the
    end of the axis (∞, or π)."""
    poles = poles[np.isfinite(poles)]
    if discrete:  # continuous-time equivalents (per sample) of the poles
        nz = poles[np.abs(poles) > 1e-300]
        poles = np.log(nz.astype(complex))
    mag = np.abs(poles)
    nonzero = mag[mag > 1e-12 * max(1.0, mag.max(initial=0.0))]
    top = math.pi if discrete else None
    if nonzero.size:
        lo, hi = nonzero.min() / 100.0, nonzero.max() * 100.0
    else:
        lo, hi = (1e-6, math.pi) if discrete else (1e-3, 1e3)
    if top is not None:
        hi = min(hi, top)
        lo = min(lo, top / 10.0)
    decades = max(math.log10(hi / lo), 1.0)
    points = [0.0, *np.logspace(math.log10(lo), math.log10(hi), int(decades * points_per_decade) + 1)]
    for lam in poles:
        wn, wd = abs(lam), abs(lam.imag)
        zeta = -lam.real / wn if wn > 0 else 1.0
        points += [wn, wd]
        if wd > 0 and zeta < 0.1:
            width = max(zeta, 1e-6) * wn
            for k in (0.5, 1.0, 2.0, 4.0):
                points += [wd - k * width, wd + k * width]
    w = np.array(points)
    w = np.unique(w[(w >= 0) & (w <= (top if top is not None else np.inf))])
    return np.append(w, top if top is not None else np.inf) if w[-1] != top else w


def _refine_peaks(f, w: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Maximise the scalar function ``f`` of frequency between the neighbours of every
    local maximum of ``values`` on ``w``; returns the grid and values with the refined
    points added (sorted)."""
    extra_w, extra_v = [], []
    n = len(w)
    for i in range(n):
        left = values[i - 1] if i > 0 else -np.inf
        right = values[i + 1] if i < n - 1 else -np.inf
        if values[i] < _NOISE_FLOOR or values[i] < left or values[i] < right:
            continue
        a, b = w[max(i - 1, 0)], w[min(i + 1, n - 1)]
        if not np.isfinite(b):
            b = max(10.0 * a, 1.0)
        if b <= a:
            continue
        if a > 0:
            # Search on u = ln(ω/a): resonances are narrow in relative terms, and Brent's
            # bounded search stops at √eps·|u| + xatol/3, which for u = ln ω would be a
            # relative 5e-8 in ω — too coarse next to an undamped pole (a test).
            res = scipy.optimize.minimize_scalar(
                lambda u: -f(a * math.exp(u)), bounds=(0.0, math.log(b / a)),
                method="bounded", options={"xatol": 1e-10})
            x = a * math.exp(res.x)
        else:
            res = scipy.optimize.minimize_scalar(lambda u: -f(u), bounds=(a, b),
                                                 method="bounded", options={"xatol": 1e-12 * b})
            x = res.x
        extra_w.append(x)
        extra_v.append(-res.fun)
    if not extra_w:
        return w, values
    w_all = np.concatenate([w, extra_w])
    v_all = np.concatenate([values, extra_v])
    order = np.argsort(w_all, kind="stable")
    return w_all[order], v_all[order]


# --- the ν-gap ---------------------------------------------------------------------------------
def gap_detail(P1, P2, *, points_per_decade: int = POINTS_PER_DECADE) -> GapDetail:
    """The ν-gap of ``P1`` and ``P2`` with its grid, peak and winding number (`GapDetail`);
    see `nu_gap`."""
    P1, P2 = as_statespace(P1, "P1"), as_statespace(P2, "P2")
    if (P1.noutputs, P1.ninputs) != (P2.noutputs, P2.ninputs):
        raise ValueError(f"P1 and P2 must have the same inputs and outputs: "
                         f"{P1.ninputs}→{P1.noutputs} vs {P2.ninputs}→{P2.noutputs}")
    discrete, period = _common_time((P1, P2), ("P1", "P2"))
    P1, P2 = _prepared(P1, discrete), _prepared(P2, discrete)
    G1, G2 = _graph_symbol(P1, discrete), _graph_symbol(P2, discrete)
    poles = np.concatenate([np.linalg.eigvals(P.A) if P.nstates else [] for P in (P1, P2)]
                           + [G1.poles, G2.poles]).astype(complex)
    w = _grid(poles, discrete, points_per_decade)

    def kappa_and_det(x):
        g1, g2 = G1(x), G2(x)
        inner = np.conj(np.swapaxes(g2, 1, 2)) @ g1
        k = np.linalg.svd(g1 - g2 @ inner, compute_uv=False)[:, 0]
        return np.minimum(k, 1.0), np.linalg.det(inner)

    kappa, det = kappa_and_det(w)
    w, kappa = _refine_peaks(lambda x: float(kappa_and_det(np.array([x]))[0][0]), w, kappa)
    winding = _winding(lambda x: kappa_and_det(x)[1], w)
    peak_at = int(np.argmax(kappa))
    scale = 1.0 / period if period else 1.0
    value = float(kappa[peak_at]) if winding == 0 else 1.0
    return GapDetail(value, float(kappa[peak_at]), float(w[peak_at] * scale), winding,
                     w * scale, kappa)


def _winding(det_at, w: np.ndarray) -> int | None:
    """Winding number about 0 of det(G2ᴴ G1) over the whole axis (module docstring), or
    None if it vanishes on the axis (|det| < 1e-13, or a phase jump that 40 bisections do
    not resolve: a zero crossed between two points)."""
    d = det_at(w)
    for _ in range(40):
        if np.any(np.abs(d) < 1e-13):
            return None
        steps = np.angle(d[1:] / d[:-1])
        wide = np.flatnonzero(np.abs(steps) > _MAX_PHASE_STEP)
        if not wide.size:
            turns = steps.sum() / np.pi
            k = round(turns)
            if abs(turns - k) > _WINDING_SLACK:
                raise ArithmeticError(f"the phase of det(G2* G1) changes by {turns:.3f}π over "
                                      "[0, ∞], not by a whole multiple of π")
            return int(k)
        a, b = w[wide], w[wide + 1]
        mid = np.where(np.isinf(b), 10.0 * np.maximum(a, 1.0),
                       np.where(a > 0, np.sqrt(a * np.where(np.isinf(b), 1.0, b)), b / 2))
        w = np.concatenate([w, mid])
        order = np.argsort(w)
        w = w[order]
        d = np.concatenate([d, det_at(mid)])[order]
    # The phase still jumps by more than π/4 between points 2⁻⁴⁰ apart: det(G2*G1) passes
    # through zero there (a jump of π), i.e. κ = 1 on the axis.
    return None


def nu_gap(P1, P2, *, points_per_decade: int = POINTS_PER_DECADE) -> float:
    """Vinnicombe's ν-gap δν(P1, P2) ∈ [0, 1] between two linear plants.

    Parameters
    ----------
    P1, P2 : control.StateSpace or control.TransferFunction
        Both continuous, or both discrete with the same sampling period; the same numbers
        of inputs and outputs (SISO or MIMO).  Poles on the stability boundary (rigid-body
        modes at s = 0 or z = 1, undamped modes) are allowed (module docstring).
    points_per_decade : int
        Density of the log-spaced part of the frequency grid (peaks are refined anyway).

    Returns
    -------
    float
        sup_ω κ(P1(jω), P2(jω)) if the winding number condition holds, else 1.

    Examples
    --------
    >>> import control
    >>> round(nu_gap(control.tf(1, [1, -0.001]), control.tf(1, [1, 0.001])), 6)
    0.002
    """
    return gap_detail(P1, P2, points_per_decade=points_per_decade).value


# --- the stability margin -----------------------------------------------------------------------
def _four_block(P: control.StateSpace, C: control.StateSpace):
    """(A, B, C, D) of H = [P; I](I + CP)⁻¹[C, I], inputs (w1 at the plant output, w2 at
    the plant input), outputs (y, u), for u = w2 + C(w1 − y), y = P u."""
    A, B, Cp, Dp = (np.asarray(x, float) for x in (P.A, P.B, P.C, P.D))
    Ac, Bc, Cc, Dc = (np.asarray(x, float) for x in (C.A, C.B, C.C, C.D))
    p, m = Dp.shape
    E = np.eye(m) + Dc @ Dp
    if abs(np.linalg.det(E)) < 1e-12:
        raise ValueError("the loop is not well posed: I + D_C D_P is singular")
    Ei = np.linalg.inv(E)
    Lx, Lxi, L1, L2 = -Ei @ Dc @ Cp, Ei @ Cc, Ei @ Dc, Ei
    Cy = Cp + Dp @ Lx
    Acl = np.block([[A + B @ Lx, B @ Lxi], [-Bc @ Cy, Ac - Bc @ Dp @ Lxi]])
    Bcl = np.block([[B @ L1, B @ L2], [Bc @ (np.eye(p) - Dp @ L1), -Bc @ Dp @ L2]])
    Ccl = np.block([[Cy, Dp @ Lxi], [Lx, Lxi]])
    Dcl = np.block([[Dp @ L1, Dp @ L2], [L1, L2]])
    return Acl, Bcl, Ccl, Dcl


def margin_detail(P, C, *, points_per_decade: int = POINTS_PER_DECADE) -> MarginDetail:
    """b(P, C) with its stability verdict and grid (`MarginDetail`); see
    `stability_margin`."""
    P, C = as_statespace(P, "P"), as_statespace(C, "C")
    if (C.ninputs, C.noutputs) != (P.noutputs, P.ninputs):
        raise ValueError(f"C must map the {P.noutputs} outputs of P to its {P.ninputs} "
                         f"inputs, got {C.ninputs}→{C.noutputs}")
    discrete, period = _common_time((P, C), ("P", "C"))
    P, C = _prepared(P, discrete), _prepared(C, discrete)
    A, B, Cm, D = _four_block(P, C)
    poles = np.linalg.eigvals(A) if A.shape[0] else np.zeros(0)
    stable = bool(np.all(np.abs(poles) < 1.0)) if discrete else bool(np.all(poles.real < 0))
    scale = 1.0 / period if period else 1.0
    if not stable:
        return MarginDetail(0.0, False, math.nan, np.zeros(0), np.zeros(0))
    H = _Realisation(A, B, Cm, D, discrete)
    w = _grid(poles.astype(complex), discrete, points_per_decade)

    def gain(x):
        return np.linalg.svd(H(x), compute_uv=False)[:, 0]

    w, g = _refine_peaks(lambda x: float(gain(np.array([x]))[0]), w, gain(w))
    worst = int(np.argmax(g))
    return MarginDetail(float(1.0 / g[worst]), True, float(w[worst] * scale), w * scale, g)


def stability_margin(P, C, *, points_per_decade: int = POINTS_PER_DECADE) -> float:
    """The generalised stability margin b(P, C) ∈ [0, 1] of the loop u = −C y, y = P u.

    Parameters
    ----------
    P : control.StateSpace or control.TransferFunction
        The plant (continuous or discrete, SISO or MIMO).
    C : control.StateSpace, control.TransferFunction or array
        The controller, from the plant's outputs to its inputs (a matrix: a static gain,
        e.g. a state feedback when P's outputs are its states); negative feedback, as in
        `control.feedback(P, C)`.
    points_per_decade : int
        Density of the log-spaced part of the frequency grid.

    Returns
    -------
    float
        1/‖[P; I](I + CP)⁻¹[C, I]‖∞ if C stabilises P, else 0.  If δν(P, P2) < b(P, C),
        C also stabilises P2.

    Examples
    --------
    >>> import control
    >>> round(stability_margin(control.tf(4, [1, -0.001]), 1.0), 4)
    0.7069
    """
    return margin_detail(P, C, points_per_decade=points_per_decade).value
