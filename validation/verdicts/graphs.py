"""The graph of a plant: its normalised right coprime factorisation G = [N; M] (P = N M⁻¹,
G*G = I on the axis), what the ν-gap and the stability margin of
`validation.verdicts.nugap` are computed from.

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
"""
from __future__ import annotations

import math
import warnings

import control
import numpy as np
import scipy.linalg

__all__ = ["FactorisationError", "as_statespace", "common_time", "prepared", "graph_symbol",
           "inner_error", "Realisation"]

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


def common_time(systems, names) -> tuple[bool, float | None]:
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


def prepared(sys_: control.StateSpace, discrete: bool) -> control.StateSpace:
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


class Realisation:
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


def graph_symbol(P: control.StateSpace, discrete: bool) -> Realisation:
    """The normalised right coprime factors G = [N; M] of a minimal P (module docstring)."""
    A, B, C, D = (np.asarray(x, dtype=float) for x in (P.A, P.B, P.C, P.D))
    p, m = D.shape
    R = np.eye(m) + D.T @ D
    if A.shape[0] == 0:
        H = _inverse_sqrt(R)
        return Realisation(A, np.zeros((0, m)), np.zeros((p + m, 0)), np.vstack([D @ H, H]),
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
        G = Realisation(A + B @ F, B @ H, np.vstack([C + D @ F, F]), np.vstack([D @ H, H]),
                         discrete)
        error = inner_error(G, discrete)
        if best is None or error < best[0]:
            best = (error, G)
        if error > _INNER_TOLERANCE:
            errors.append(f"{method}: factors not normalised (|G*G - I| = {error:.1g})")
    if best is None or best[0] > _INNER_TOLERANCE:
        raise FactorisationError(f"no normalised coprime factorisation ({'; '.join(errors)})")
    return best[1]


def inner_error(G: "Realisation", discrete: bool) -> float:
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
