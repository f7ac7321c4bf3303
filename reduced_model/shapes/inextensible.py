"""Exact inextensible kinematics of one link, set up once (the compiled dynamics:
`reduced_model.dynamics.exact`; the derivation: the docs' theory page *Exact inextensible
kinematics*).

The modal field w(s) = Σ φ_k(s) q_k fixes the slope of the centreline, tan β(s) = w'(s)
= p(s), as the FE plant places its nodes; the centreline keeps its arc length, so in the
link's root frame (complex notation) its point at arc length s is

    ρ(s) = ∫₀ˢ e^{iβ} dσ = s + i w(s) + ∫₀ˢ g(p(σ)) dσ,
    g(p) = e^{i atan p} − 1 − i p = (1 + i p)/√(1 + p²) − 1 − i p = O(p²):

the paper's linear kinematics x + i w plus the foreshortening and the rest, exactly.  The
remainder's integrand is interpolated by a polynomial through its values at N
Gauss–Legendre nodes s_h, so ∫₀ˢ g = Σ_h g(p(s_h)) r_h(s) with r_h(s) = ∫₀ˢ ℓ_h, the
integrated Lagrange polynomials of the nodes (r_h(L) is the node's Gauss weight).  Every
material point is then a combination of fixed functions of s, [1, s, φ_k, r_h], with
coefficients that depend on the coordinates: their Gram matrix (mass-weighted, with the
tip's point mass) is computed once, exactly, like the linear model's.
"""
from __future__ import annotations

import functools

import numpy as np
from numpy.polynomial import legendre

from .modes import LinkModes, block_diagonal, gauss_legendre, weighted_projector

__all__ = ["InextensibleLink", "interpolation_nodes", "readout_matrix"]


def interpolation_nodes(modes_per_link: tuple[int, ...]) -> int:
    """Nodes N per flexible link for the remainder: 4 + 2 × the most modes of a link (8
    for 2+2 modes, 12 for 4+4).  On the issue's open-loop pulses (link-1 tip deflection 0.1 m)
    the joint angles are then within 3e-10 rad (2+2) and 4e-14 rad (4+4) of N = 24 and
    32 (tests/test_exact_kinematics.py checks N against 2N); the cost grows as N²."""
    return 4 + 2 * max(modes_per_link)


@functools.lru_cache(maxsize=8)
def _integrated_lagrange(nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes t_h and weights on [−1, 1], and the Legendre coefficients
    (column h) of ∫₋₁ᵗ ℓ_h: the integrated Lagrange basis of the nodes."""
    t, w = legendre.leggauss(nodes)
    lagrange = np.linalg.inv(legendre.legvander(t, nodes - 1))  # column h: ℓ_h's coefficients
    integrated = np.column_stack([legendre.legint(lagrange[:, h], lbnd=-1.0)
                                  for h in range(nodes)])
    return t, w, integrated


class InextensibleLink:
    """One link's exact kinematics: nodes, weights, the functions r_h and the Gram matrix.

    Parameters
    ----------
    modes : LinkModes
        The link's mode shapes (they define w and hence the slope p = w').
    nodes : int
        Interpolation nodes N (`interpolation_nodes`).

    Attributes
    ----------
    s, weights : ndarray (N,)
        The nodes on [0, L] and their Gauss weights (= r_h(L)).
    dphi, ddphi : ndarray (n, N)
        φ_k' and φ_k'' at the nodes.
    """

    def __init__(self, modes: LinkModes, nodes: int) -> None:
        self.modes = modes
        self.nodes = int(nodes)
        t, w, self._integrated = _integrated_lagrange(self.nodes)
        half = 0.5 * modes.L
        self.s = half * (t + 1.0)
        self.weights = half * w
        self.dphi = modes.dphi(self.s)
        self.ddphi = modes.ddphi(self.s)

    def r(self, x) -> np.ndarray:
        """r_h(x) = ∫₀ˣ ℓ_h(s) ds at points ``x`` [m]: array (N, len(x))."""
        half = 0.5 * self.modes.L
        t = np.atleast_1d(np.asarray(x, dtype=float)) / half - 1.0
        return half * legendre.legval(t, self._integrated).reshape(self.nodes, -1)

    def gram(self, tip_mass: float, *, with_constant: bool) -> np.ndarray:
        """∫ρ b bᵀ ds + m_tip b(L) b(L)ᵀ for the basis b = [1, s, φ_1…φ_n, r_1…r_N]
        (without the 1 unless ``with_constant``); exact for the polynomial r_h by the
        same 96-point quadrature as the linear model's Gram matrix."""
        m = self.modes
        x, w = gauss_legendre(0.0, m.L)
        end = np.array([m.L])
        basis = np.vstack([np.ones_like(x), x, m.phi(x), self.r(x)])
        tip = np.concatenate([[1.0, m.L], m.phi(end)[:, 0], self.r(end)[:, 0]])
        if not with_constant:
            basis, tip = basis[1:], tip[1:]
        return m.rho * (basis * w) @ basis.T + tip_mass * np.outer(tip, tip)

    # --- the field (sensors, initial checks: plain numpy) ---------------------------------
    def remainder(self, q) -> np.ndarray:
        """g(p(s_h)) at the nodes (complex, N) for modal coordinates ``q``."""
        p = self.dphi.T @ np.asarray(q, dtype=float)
        return (1.0 + 1j * p) / np.sqrt(1.0 + p * p) - 1.0 - 1j * p

    def transverse(self, x, q) -> np.ndarray:
        """The centreline's transverse position Im ρ(x) [m] in the root frame."""
        q = np.asarray(q, dtype=float)
        return self.modes.phi(x).T @ q + self.r(x).T @ self.remainder(q).imag

    def curvature(self, x, q) -> np.ndarray:
        """The centreline's curvature κ = β' = p'/(1 + p²) [1/m] at points ``x``."""
        q = np.asarray(q, dtype=float)
        p = self.modes.dphi(x).T @ q
        return self.modes.ddphi(x).T @ q / (1.0 + p * p)

    # --- the elastic energy ½ EI ∫ κ², beyond the linear ½ qᵀ K q ----------------------------
    def _strain(self, q):
        p = self.dphi.T @ q
        pp = self.ddphi.T @ q
        u = 1.0 / (1.0 + p * p)
        return p, pp, u

    def energy_correction(self, q, EI: float) -> float:
        """½ EI ∫ κ² − ½ EI ∫ w''²: the exact bending energy beyond the linear one [J]."""
        p, pp, u = self._strain(np.asarray(q, dtype=float))
        return 0.5 * EI * float(self.weights @ (pp * pp * (u * u - 1.0)))

    def stiffness_correction(self, q, EI: float) -> np.ndarray:
        """∂²/∂q² of `energy_correction` (n, n): the tangent stiffness beyond K."""
        p, pp, u = self._strain(np.asarray(q, dtype=float))
        f = u * u - 1.0
        df = -4.0 * p * u ** 3
        ddf = -4.0 * u ** 3 + 24.0 * p * p * u ** 4
        wt = self.weights
        a, b = self.ddphi, self.dphi
        return EI * ((a * (wt * f)) @ a.T + (a * (wt * pp * df)) @ b.T
                     + (b * (wt * pp * df)) @ a.T + (b * (wt * 0.5 * pp * pp * ddf)) @ b.T)

    def damping_correction(self, q, d: float) -> np.ndarray:
        """d ∫ [(∂κ/∂q)(∂κ/∂q)ᵀ − φ''φ''ᵀ] (n, n): the Kelvin–Voigt damping matrix about
        a state at rest at ``q`` beyond the linear D (zero at q = 0)."""
        p, pp, u = self._strain(np.asarray(q, dtype=float))
        dk = self.ddphi * u - self.dphi * (2.0 * p * pp * u * u)
        return d * ((dk * self.weights) @ dk.T - (self.ddphi * self.weights) @ self.ddphi.T)


def readout_matrix(links: tuple, basis) -> np.ndarray:
    """The map from an exact plant's deflection features to q in the mode shapes
    ``basis`` (`reduced_model.plant.readout`): per flexible link, features [q_own, Im g_h,
    sin β(L) − p(L)] give the transverse field y = Σ φ q + Σ r_h Im g_h and its tip slope
    dy/ds = sin β(L), projected on ``basis`` by the FE plant's weighted least squares
    (`weighted_projector`): the q an FE plant reports for the same centreline.
    Block-diagonal by link (a rigid link, None in ``links``, has none), (Σ basis modes,
    Σ features)."""
    blocks = []
    for link, b in zip(links, basis):
        if link is None:
            continue
        m = link.modes
        if abs(b.L - m.L) > 1e-12 * m.L:
            raise ValueError(f"modal basis: L = {b.L}, the plant's link has L = {m.L}")
        x, w = gauss_legendre(0.0, m.L)
        end = np.array([m.L])
        target_quad = np.hstack([m.phi(x).T, link.r(x).T, np.zeros((len(x), 1))])
        target_tip = np.vstack([np.concatenate([m.phi(end)[:, 0], link.r(end)[:, 0], [0.0]]),
                                np.concatenate([m.dphi(end)[:, 0], np.zeros(link.nodes), [1.0]])])
        blocks.append(weighted_projector(b, w_quad=w, basis_quad=b.phi(x).T,
                                         basis_tip=np.vstack(b.tip_values),
                                         target_quad=target_quad, target_tip=target_tip))
    return block_diagonal(blocks)
