"""Clamped-mass Euler–Bernoulli eigenfunctions of one link (the φ_ij of the paper's eq. 1),
and the weighted projection of a deflection onto them.

Each link is a uniform beam clamped at its hub and loaded at its tip by a mass M_L and a
rotary inertia J_L (De Luca & Siciliano 1991).  With λ = βL, β⁴ = ω²ρ/EI, μ = M_L/(ρL),
η = J_L/(ρL³), the tip conditions EI φ''(L) = J_L ω² φ'(L) and EI φ'''(L) = −M_L ω² φ(L)
give the frequency equation (derived by expanding the 2×2 boundary determinant)

    1 + cos λ cosh λ + μλ (cos λ sinh λ − sin λ cosh λ)
      − ηλ³ (cos λ sinh λ + sin λ cosh λ) + μηλ⁴ (1 − cos λ cosh λ) = 0,

solved here after division by cosh λ, which keeps it bounded by a polynomial in λ and
non-zero at λ = 0 (no spurious root there).
"""
from __future__ import annotations

import functools

import numpy as np

__all__ = ["LinkModes", "clamped_mass_roots", "weighted_projector", "gauss_legendre", "projection",
           "block_diagonal"]

_SCAN_STEP = 2e-3  # in λ; roots are ≈ π apart, so two roots are never within one step


def _frequency_function(lam, mu: float, eta: float):
    """Frequency equation divided by cosh λ (scalar or array λ)."""
    c, s = np.cos(lam), np.sin(lam)
    th, sech = np.tanh(lam), 1.0 / np.cosh(lam)
    return (
        sech
        + c
        + mu * lam * (c * th - s)
        - eta * lam**3 * (c * th + s)
        + mu * eta * lam**4 * (sech - c)
    )


def clamped_mass_roots(n: int, mu: float, eta: float) -> np.ndarray:
    """First ``n`` positive roots λ_k of the clamped-mass frequency equation.

    Scans λ on a fine grid in windows of length π, brackets every sign change with
    Brent's method, and also inspects every local minimum of |f| that does not change
    sign (two roots closer than one grid step would otherwise be missed).  Roots are
    de-duplicated; the scan continues until ``n`` roots are found.
    """
    if not 1 <= n <= 12:
        raise ValueError(f"number of modes must be in 1..12, got {n}")
    from scipy.optimize import brentq, minimize_scalar  # 0.2 s to import: when needed
    f = lambda x: float(_frequency_function(x, mu, eta))  # noqa: E731
    roots: list[float] = []
    lo = 1e-6
    while len(roots) < n:
        hi = lo + np.pi
        grid = np.arange(lo, hi + _SCAN_STEP, _SCAN_STEP)
        vals = _frequency_function(grid, mu, eta)
        for i in range(len(grid) - 1):
            if vals[i] == 0.0:
                roots.append(grid[i])
            elif vals[i] * vals[i + 1] < 0.0:
                roots.append(brentq(f, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15))
        absv = np.abs(vals)
        for i in range(1, len(grid) - 1):
            if absv[i] < absv[i - 1] and absv[i] <= absv[i + 1] and vals[i - 1] * vals[i + 1] > 0:
                sgn = np.sign(vals[i])
                res = minimize_scalar(
                    lambda x: sgn * f(x), bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                    options={"xatol": 1e-14},
                )
                if res.fun < 0.0:  # the function dips through zero twice inside the bracket
                    roots.append(brentq(f, grid[i - 1], res.x, xtol=1e-15, rtol=1e-15))
                    roots.append(brentq(f, res.x, grid[i + 1], xtol=1e-15, rtol=1e-15))
        lo = grid[-1]
        roots = sorted(set(np.round(roots, 12)))
    return np.asarray(roots[:n], dtype=float)


class LinkModes:
    """The first ``n`` clamped-mass mode shapes of one link, mass-normalised.

    Normalisation (De Luca–Siciliano): ∫ρφ_j² dx + M_L φ_j(L)² + J_L φ_j'(L)² = ρL
    (the link mass), so modal coordinates carry units of length.  Sign convention:
    φ_j''(0) > 0, i.e. each mode leaves the clamp bending towards +y.

    Parameters
    ----------
    L, rho, EI : float
        The link's length [m], mass per length [kg/m] and flexural rigidity [N m²].
    tip_mass, tip_inertia : float
        The load at its tip [kg, kg m²] (the next hub, or the payload).
    n : int
        How many modes, 0..4 (0: a rigid link, no modes).

    Attributes
    ----------
    lam : ndarray (n,)
        Dimensionless roots λ_j = β_j L.
    omega : ndarray (n,)
        Clamped-mass natural frequencies [rad/s].
    """

    def __init__(self, *, L: float, rho: float, EI: float, tip_mass: float,
                 tip_inertia: float, n: int) -> None:
        self.L, self.rho, self.EI = float(L), float(rho), float(EI)
        self.tip_mass, self.tip_inertia = float(tip_mass), float(tip_inertia)
        self.n = int(n)
        mu = self.tip_mass / (self.rho * self.L)
        eta = self.tip_inertia / (self.rho * self.L**3)
        self.lam = clamped_mass_roots(self.n, mu, eta) if self.n else np.zeros(0)
        self.beta = self.lam / self.L
        self.omega = self.beta**2 * np.sqrt(self.EI / self.rho)
        self._coef = np.empty((self.n, 2))  # (A, B) of A(sin−sinh) + B(cos−cosh)
        for j, lam in enumerate(self.lam):
            c, s, ch, sh = np.cos(lam), np.sin(lam), np.cosh(lam), np.sinh(lam)
            row_moment = (-(s + sh) - eta * lam**3 * (c - ch), -(c + ch) + eta * lam**3 * (s + sh))
            row_shear = (-(c + ch) + mu * lam * (s - sh), (s - sh) + mu * lam * (c - ch))
            row = max(row_moment, row_shear, key=lambda r: np.hypot(*r))
            self._coef[j] = (row[1] / ch, -row[0] / ch)
        self._normalise(mu, eta)
        end = np.array([self.L])
        self._tip = (self.evaluate(end)[:, 0], self.evaluate(end, 1)[:, 0])

    def _normalise(self, mu: float, eta: float) -> None:
        x, w = gauss_legendre(0.0, self.L)
        phi = self.evaluate(x)
        tip = self.evaluate(np.array([self.L]))[:, 0]
        slope = self.evaluate(np.array([self.L]), 1)[:, 0]
        norm2 = self.rho * (phi**2) @ w + self.tip_mass * tip**2 + self.tip_inertia * slope**2
        scale = np.sqrt(self.rho * self.L / norm2)
        curvature_at_root = self.evaluate(np.array([0.0]), 2)[:, 0]
        self._coef *= (scale * np.sign(curvature_at_root))[:, None]

    def evaluate(self, x, derivative: int = 0) -> np.ndarray:
        """d^k φ_j/dx^k at points ``x`` for all modes: array (n, len(x)).  k = 0..4."""
        if derivative not in (0, 1, 2, 3, 4):
            raise ValueError(f"derivative must be 0..4, got {derivative}")
        x = np.atleast_1d(np.asarray(x, dtype=float))
        bx = self.beta[:, None] * x[None, :]
        s, c, sh, ch = np.sin(bx), np.cos(bx), np.sinh(bx), np.cosh(bx)
        # k-th derivatives of sin and cos cycle with period 4; sinh/cosh with period 2.
        trig = [(s, c), (c, -s), (-s, -c), (-c, s)][derivative % 4]
        hyp = (sh, ch) if derivative % 2 == 0 else (ch, sh)
        a, b = self._coef[:, 0:1], self._coef[:, 1:2]
        out = a * (trig[0] - hyp[0]) + b * (trig[1] - hyp[1])
        return out * self.beta[:, None] ** derivative

    def phi(self, x) -> np.ndarray:
        """φ_j(x), shape (n, len(x))."""
        return self.evaluate(x, 0)

    def dphi(self, x) -> np.ndarray:
        """φ_j'(x), shape (n, len(x))."""
        return self.evaluate(x, 1)

    def ddphi(self, x) -> np.ndarray:
        """φ_j''(x), shape (n, len(x))."""
        return self.evaluate(x, 2)

    def shape(self, j: int, derivative: int = 0):
        """The callable x ↦ d^k φ_j/dx^k (x scalar or array) of mode ``j`` (0-based)."""
        if not 0 <= j < self.n:
            raise ValueError(f"mode index must be in 0..{self.n - 1}, got {j}")
        return lambda x: self.evaluate(x, derivative)[j].reshape(np.shape(x))

    @property
    def tip_values(self) -> tuple[np.ndarray, np.ndarray]:
        """(φ_j(L), φ_j'(L)) for all modes (computed once; do not modify)."""
        return self._tip

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self.omega / (2.0 * np.pi)


def gauss_legendre(a: float, b: float, n: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes and weights on [a, b].

    96 nodes integrate the products of mode shapes used here (λ ≤ ~15, i.e. e^{2λx}
    growth) to round-off; checked against 192 nodes in the tests.
    """
    t, w = _legendre(n)
    half = 0.5 * (b - a)
    return a + half * (t + 1.0), half * w


@functools.lru_cache(maxsize=8)
def _legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights on [−1, 1] (2 ms to compute, asked for at every model build)."""
    t, w = np.polynomial.legendre.leggauss(n)
    t.setflags(write=False)
    w.setflags(write=False)
    return t, w


def weighted_projector(basis: LinkModes, *, w_quad, basis_quad, basis_tip, target_quad,
                       target_tip) -> np.ndarray:
    """Least-squares projector onto ``basis`` in the inner product the clamped-mass modes
    are orthonormal in, ⟨f, g⟩ = Σ ρ w_g f(x_g) g(x_g) + M_L f(L) g(L) + J_L f'(L) g'(L).

    ``basis_quad`` (n_quad, m) and ``basis_tip`` (2, m) are the basis functions at the
    quadrature points and their (value, slope) at the tip, as the caller represents them;
    ``target_quad`` (n_quad, k) and ``target_tip`` (2, k) the same for k functions to be
    projected.  Returns P (m, k): the coefficients of the best fit of target column j are
    P[:, j].  The Gram matrix uses the same quadrature, so a target in the span of the
    basis is recovered to round-off.
    """
    loads = np.array([basis.tip_mass, basis.tip_inertia])
    weighted = basis.rho * basis_quad.T * w_quad  # (m, n_quad)
    gram = weighted @ basis_quad + (basis_tip.T * loads) @ basis_tip
    rhs = weighted @ target_quad + (basis_tip.T * loads) @ target_tip
    return np.linalg.solve(gram, rhs)


@functools.lru_cache(maxsize=64)
def projection(own: tuple[LinkModes, ...], basis: tuple[LinkModes, ...]) -> np.ndarray:
    """Block matrix mapping modal coordinates of the mode shapes ``own`` to ``basis``'s
    (cached by the shapes' identity: the models of a sweep are shared, `cached_model`;
    callers must not modify it)."""
    if len(own) != len(basis):
        raise ValueError(f"modal_basis: {len(basis)} links, the plant has {len(own)}")
    blocks = []
    for link, (b, mine) in enumerate(zip(basis, own)):
        if abs(b.L - mine.L) > 1e-12 * mine.L:
            raise ValueError(f"modal_basis: link {link + 1} has L = {b.L}, the plant "
                             f"L = {mine.L}; the deflection cannot be projected")
        if (b.n == 0) != (mine.n == 0):
            raise ValueError(f"modal_basis: link {link + 1} is rigid in one model and "
                             "flexible in the other")
        if b.n == 0:
            blocks.append(np.zeros((0, 0)))
            continue
        x, w = gauss_legendre(0.0, mine.L)
        blocks.append(weighted_projector(
            b, w_quad=w, basis_quad=b.phi(x).T, basis_tip=np.vstack(b.tip_values),
            target_quad=mine.phi(x).T, target_tip=np.vstack(mine.tip_values)))
    return block_diagonal(blocks)


def block_diagonal(blocks) -> np.ndarray:
    """The block-diagonal matrix of ``blocks`` (any shapes, empty ones included)."""
    out = np.zeros((sum(p.shape[0] for p in blocks), sum(p.shape[1] for p in blocks)))
    r = c = 0
    for p in blocks:
        out[r:r + p.shape[0], c:c + p.shape[1]] = p
        r, c = r + p.shape[0], c + p.shape[1]
    return out
