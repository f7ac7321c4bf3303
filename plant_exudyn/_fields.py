"""Deflection fields of the FE links in their clamped root frames, and their projection
onto the reduced model's mode shapes (the modal coordinates q of the paper's eq. 1).

Per link and node k, the *local degrees of freedom* are the transverse position y_k and
the transverse slope y'_k in the root frame (origin at the hub centre, x along the hub's
zero direction), as functions of the reference arc length s:

- ANCF cable: y'_k is the y component of the nodal slope vector ∂r/∂s; the field is the
  element's own cubic Hermite interpolation of (y, y').
- geometrically exact beam: y'_k = sin(β_k − ψ) from the nodal rotation β_k (exact for
  an inextensible, shear-rigid beam); the field is the element's linear interpolation of
  y, and its curvature the difference quotient of the nodal rotations.

The projection minimises ⟨w − Σ φ_j q_j, same⟩ with the inner product the modes are
orthonormal in, ⟨f, g⟩ = ∫ρ f g ds + M_L f(L) g(L) + J_L f'(L) g'(L), by Gauss
quadrature.  The φ_j used are the mode shapes *as the element interpolates them* (their
nodal values and slopes, filled in by the element's shape functions): an FE link can
only carry that interpolant, so a deflection built from the modes is recovered to
round-off, and the difference to the exact φ_j (O(h⁴) for ANCF) is not mistaken for
unmodelled deflection.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from reduced_model import LinkModes
from reduced_model.shapes import gauss_legendre, weighted_projector

from ._build import ArmSystem

__all__ = ["LinkField"]

_GAUSS_PER_ELEMENT = 6  # exact for the cubic field times the smooth mode shapes to ~1e-12


def _hermite(xi: np.ndarray, h: np.ndarray, derivative: int) -> np.ndarray:
    """Cubic Hermite shape functions for the dofs (y_a, y'_a, y_b, y'_b) of an element of
    length h at ξ = (s − s_a)/h, differentiated ``derivative`` times with respect to s:
    array (len(ξ), 4)."""
    if derivative == 0:
        dn = [1 - 3 * xi**2 + 2 * xi**3, xi - 2 * xi**2 + xi**3, 3 * xi**2 - 2 * xi**3,
              -xi**2 + xi**3]
    elif derivative == 1:
        dn = [-6 * xi + 6 * xi**2, 1 - 4 * xi + 3 * xi**2, 6 * xi - 6 * xi**2, -2 * xi + 3 * xi**2]
    elif derivative == 2:
        dn = [-6 + 12 * xi, -4 + 6 * xi, 6 - 12 * xi, -2 + 6 * xi]
    else:
        raise ValueError(f"derivative must be 0, 1 or 2, got {derivative}")
    scale = h ** (-derivative)
    return np.stack([dn[0] * scale, dn[1] * h * scale, dn[2] * scale, dn[3] * h * scale], axis=-1)


class LinkField:
    """Reads flexible link ``link`` of an `ArmSystem` in its root frame and projects it.

    Parameters
    ----------
    system : ArmSystem
    link : int
        The link, from 0 (root frame: its hub's).
    modes : LinkModes
        The mode shapes to project on (normally the reduced model's, same link).
    """

    def __init__(self, system: ArmSystem, link: int, modes: LinkModes) -> None:
        mbs = system.mbs
        nodes = system.links[link]
        self.element = system.element
        self.s = nodes.s
        self.L = float(nodes.s[-1])
        if abs(self.L - modes.L) > 1e-12 * self.L:
            raise ValueError(f"mode shapes are for L = {modes.L}, link {link + 1} has L = {self.L}")
        self.modes = modes
        self.n_nodes = len(nodes.nodes)
        coords = np.ascontiguousarray(nodes.coords, dtype=np.int64)
        ref = np.array([mbs.GetNodeParameter(n, "referenceCoordinates") for n in nodes.nodes],
                       dtype=float)
        # ANCF nodes: (x, y, x', y'); geometrically exact nodes: (x, y, β).
        self._idx, self._ref = coords, ref
        hub = system.hubs[link]
        self._hub_idx = np.array(mbs.systemData.GetNodeLTGODE2(hub), dtype=np.int64)
        self._hub_ref = np.array(mbs.GetNodeParameter(hub, "referenceCoordinates"), dtype=float)
        self._d = np.empty(2 * self.n_nodes)
        self._dd = np.empty(2 * self.n_nodes)

        # Quadrature points on every element, and the field's interpolation there.
        xs, ws = [], []
        for a, b in zip(self.s[:-1], self.s[1:]):
            x, w = gauss_legendre(a, b, _GAUSS_PER_ELEMENT)
            xs.append(x)
            ws.append(w)
        self.x_quad, self.w_quad = np.concatenate(xs), np.concatenate(ws)
        H = self.interpolation(self.x_quad)
        self.nodal_modes = np.vstack([modes.phi(self.s).T, modes.dphi(self.s).T])  # (2n, modes)
        phi_quad = H @ self.nodal_modes  # interpolated mode shapes (n_quad, n_modes)
        n = self.n_nodes
        # The tip value and slope of the local dofs are the last node's y and y'.
        tip_rows = np.zeros((2, 2 * n))
        tip_rows[0, n - 1] = tip_rows[1, 2 * n - 1] = 1.0
        self._projector = weighted_projector(
            modes, w_quad=self.w_quad, basis_quad=phi_quad, basis_tip=np.vstack(modes.tip_values),
            target_quad=H, target_tip=tip_rows)
        self._H_quad = H
        self._phi_quad_T = phi_quad
        self._rho_w = modes.rho * self.w_quad

    # --- interpolation --------------------------------------------------------------
    def interpolation(self, x, derivative: int = 0) -> np.ndarray:
        """Matrix (len(x), 2·n_nodes) mapping local dofs [y_0..y_n-1, y'_0..y'_n-1] to the
        ``derivative``-th s-derivative of the transverse deflection at points ``x``."""
        x = np.atleast_1d(np.asarray(x, dtype=float))
        if np.any(x < -1e-12) or np.any(x > self.L * (1 + 1e-12)):
            raise ValueError(f"points must lie on the link, 0 ≤ x ≤ {self.L}")
        n = self.n_nodes
        elem = np.clip(np.searchsorted(self.s, x, side="right") - 1, 0, n - 2)
        h = np.diff(self.s)[elem]
        xi = (x - self.s[elem]) / h
        out = np.zeros((len(x), 2 * n))
        rows = np.arange(len(x))
        if self.element == "ancf":
            N = _hermite(xi, h, derivative)
            for col, (node_offset, dof_offset) in enumerate([(0, 0), (0, n), (1, 0), (1, n)]):
                out[rows, dof_offset + elem + node_offset] = N[:, col]
        elif derivative == 0:
            out[rows, elem] = 1.0 - xi
            out[rows, elem + 1] = xi
        elif derivative == 1:
            out[rows, elem] = -1.0 / h
            out[rows, elem + 1] = 1.0 / h
        elif derivative == 2:  # curvature from nodal rotations: (β_{k+1} − β_k)/h
            out[rows, n + elem] = -1.0 / h
            out[rows, n + elem + 1] = 1.0 / h
        else:
            raise ValueError(f"derivative must be 0, 1 or 2, got {derivative}")
        return out

    # --- reading the state ------------------------------------------------------------
    def frame(self, u: np.ndarray) -> tuple[np.ndarray, float]:
        """Root-frame origin (2,) and angle ψ from the ODE2 displacement vector ``u``."""
        hub = self._hub_ref + u[self._hub_idx]
        return hub[:2], float(hub[2])

    def local_dofs(self, u: np.ndarray, v: np.ndarray | None = None):
        """Local dofs (2n,) from ODE2 displacements ``u``; with velocities ``v`` also their
        time derivatives (2n,).  The returned arrays are reused by the next call."""
        _local_dofs(u, u if v is None else v, self.element == "ancf", self._idx, self._ref,
                    self._hub_idx, self._hub_ref, self._d, self._dd)
        return self._d if v is None else (self._d, self._dd)

    # --- projection ------------------------------------------------------------------------
    def project(self, d: np.ndarray) -> np.ndarray:
        """Modal coordinates q (n_modes,) of the field with local dofs ``d``."""
        return self._projector @ d

    def residual(self, d: np.ndarray, q: np.ndarray) -> float:
        """Mass-weighted RMS over the link [m] of the deflection the modes do not
        represent (0 when the field is exactly modal): an absolute measure, which stays
        meaningful when the deflection itself is near zero."""
        r = self._H_quad @ d - self._phi_quad_T @ q
        return float(np.sqrt(self._rho_w @ (r * r) / self._rho_w.sum()))

    def compiled(self) -> tuple:
        """The arrays `link_readout` needs, in its argument order."""
        return (self._idx, self._ref, self._hub_idx, self._hub_ref, self._d, self._dd,
                np.ascontiguousarray(self._projector), np.ascontiguousarray(self._H_quad),
                np.ascontiguousarray(self._phi_quad_T), self._rho_w)

    def tip_deflection(self, d: np.ndarray) -> float:
        return float(d[self.n_nodes - 1])


@njit(cache=True)
def link_readout(u, v, ancf, idx, ref, hub_idx, hub_ref, d, dd, projector, H_quad, phi_T,
                 rho_w, q, qd):
    """One link, compiled: modal coordinates q and rates q̇ (into ``q``, ``qd``), and the
    tip deflection and the projection residual (`LinkField.residual`) it returns."""
    _local_dofs(u, v, ancf, idx, ref, hub_idx, hub_ref, d, dd)
    m = d.shape[0]
    for j in range(q.shape[0]):
        a = 0.0
        b = 0.0
        for k in range(m):
            a += projector[j, k] * d[k]
            b += projector[j, k] * dd[k]
        q[j] = a
        qd[j] = b
    num = 0.0
    den = 0.0
    for i in range(H_quad.shape[0]):
        w = 0.0
        for k in range(m):
            w += H_quad[i, k] * d[k]
        for j in range(q.shape[0]):
            w -= phi_T[i, j] * q[j]
        num += rho_w[i] * w * w
        den += rho_w[i]
    return d[m // 2 - 1], np.sqrt(num / den)


@njit(cache=True)
def _local_dofs(u, v, ancf, idx, ref, hub_idx, hub_ref, d, dd):
    """Transverse positions/slopes of a link's nodes in the root frame, and their rates.

    y = Rᵀ(ψ)(r − r0)·e_y; d/dt of Rᵀ(ψ) a is Rᵀ ȧ − ψ̇ J Rᵀ a, whose y component is
    (Rᵀ ȧ)_y − ψ̇ (Rᵀ a)_x.
    """
    n = idx.shape[0]
    x0 = hub_ref[0] + u[hub_idx[0]]
    y0 = hub_ref[1] + u[hub_idx[1]]
    psi = hub_ref[2] + u[hub_idx[2]]
    c, s = np.cos(psi), np.sin(psi)
    vx0, vy0, psid = v[hub_idx[0]], v[hub_idx[1]], v[hub_idx[2]]
    for k in range(n):
        px = ref[k, 0] + u[idx[k, 0]] - x0
        py = ref[k, 1] + u[idx[k, 1]] - y0
        d[k] = -s * px + c * py
        vx = v[idx[k, 0]] - vx0
        vy = v[idx[k, 1]] - vy0
        dd[k] = -s * vx + c * vy - psid * (c * px + s * py)
        if ancf:
            sx = ref[k, 2] + u[idx[k, 2]]
            sy = ref[k, 3] + u[idx[k, 3]]
            d[n + k] = -s * sx + c * sy
            dd[n + k] = -s * v[idx[k, 2]] + c * v[idx[k, 3]] - psid * (c * sx + s * sy)
        else:
            rel = ref[k, 2] + u[idx[k, 2]] - psi
            d[n + k] = np.sin(rel)
            dd[n + k] = np.cos(rel) * (v[idx[k, 2]] - psid)
