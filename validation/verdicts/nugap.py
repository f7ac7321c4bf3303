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

Poles on the stability boundary (rigid-body modes, undamped modes) and the normalised
coprime factors: `validation.verdicts.graphs`.

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
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg
import scipy.optimize

from .graphs import (FactorisationError, Realisation, as_statespace, common_time,
                     graph_symbol, prepared)

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
    discrete, period = common_time((P1, P2), ("P1", "P2"))
    P1, P2 = prepared(P1, discrete), prepared(P2, discrete)
    G1, G2 = graph_symbol(P1, discrete), graph_symbol(P2, discrete)
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
    >>> from validation import nu_gap
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
    discrete, period = common_time((P, C), ("P", "C"))
    P, C = prepared(P, discrete), prepared(C, discrete)
    A, B, Cm, D = _four_block(P, C)
    poles = np.linalg.eigvals(A) if A.shape[0] else np.zeros(0)
    stable = bool(np.all(np.abs(poles) < 1.0)) if discrete else bool(np.all(poles.real < 0))
    scale = 1.0 / period if period else 1.0
    if not stable:
        return MarginDetail(0.0, False, math.nan, np.zeros(0), np.zeros(0))
    H = Realisation(A, B, Cm, D, discrete)
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
    >>> from validation import stability_margin
    >>> round(stability_margin(control.tf(4, [1, -0.001]), 1.0), 4)
    0.7069
    """
    return margin_detail(P, C, points_per_decade=points_per_decade).value
