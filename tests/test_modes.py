"""Clamped-mass mode shapes against published numbers and an independent beam FE model."""
import numpy as np
import pytest
import scipy.linalg

from reduced_model import LinkModes
from reduced_model.shapes import clamped_mass_roots, gauss_legendre

# De Luca & Siciliano (1991) example: ρ = 0.2 kg/m, EI = 1 N m², L = 0.5 m, Jh2 = 0.1 kg m²,
# mh2 = 1 kg, Mp = 0.1 kg, Jp = 0.0005 kg m².
RHO, EI, L = 0.2, 1.0, 0.5
TIP1 = (1.0 + RHO * L + 0.1, 0.1 + RHO * L**3 / 3 + 0.0005 + 0.1 * L**2)  # M_L1, J_L1
TIP2 = (0.1, 0.0005)


def dls_link(tip, n=2):
    return LinkModes(L=L, rho=RHO, EI=EI, tip_mass=tip[0], tip_inertia=tip[1], n=n)


def test_de_luca_siciliano_clamped_frequencies():
    f1, f2 = dls_link(TIP1).frequencies_hz, dls_link(TIP2).frequencies_hz
    # Published with 3 decimals: allow half a unit of the last digit.
    np.testing.assert_allclose(f1, [0.480, 1.797], atol=5e-4)
    np.testing.assert_allclose(f2, [2.178, 15.915], atol=5e-4)


@pytest.mark.parametrize("tip, phi_ref, dphi_ref", [
    (TIP1, [0.186, 0.215], [0.657, -0.560]),
    (TIP2, [0.883, -0.069], [2.641, -10.853]),
])
def test_de_luca_siciliano_tip_values(tip, phi_ref, dphi_ref):
    phi, dphi = dls_link(tip).tip_values
    for j in range(2):
        # The sign of a whole mode is a convention: compare (φ, φ') up to one common sign.
        s = np.sign(dphi[j] * dphi_ref[j])
        # Published with 3 decimals: half a unit of the last digit.
        assert s * phi[j] == pytest.approx(phi_ref[j], abs=5e-4)
        assert s * dphi[j] == pytest.approx(dphi_ref[j], abs=5e-4)


def hermite_beam_frequencies(*, L, rho, EI, tip_mass, tip_inertia, n_el=20, n=4):
    """Independent reference: clamped Euler–Bernoulli beam, cubic Hermite elements with
    consistent mass and DOFs (w, h·w') for conditioning; tip mass/inertia on the last node."""
    h = L / n_el
    k = EI / h**3 * np.array([[12, 6, -12, 6], [6, 4, -6, 2], [-12, -6, 12, -6], [6, 2, -6, 4.0]])
    m = rho * h / 420 * np.array([[156, 22, 54, -13], [22, 4, 13, -3], [54, 13, 156, -22],
                                  [-13, -3, -22, 4.0]])
    ndof = 2 * (n_el + 1)
    K, M = np.zeros((ndof, ndof)), np.zeros((ndof, ndof))
    for e in range(n_el):
        s = slice(2 * e, 2 * e + 4)
        K[s, s] += k
        M[s, s] += m
    M[-2, -2] += tip_mass
    M[-1, -1] += tip_inertia / h**2
    w2 = scipy.linalg.eigh(K[2:, 2:], M[2:, 2:], eigvals_only=True, subset_by_index=[0, n - 1])
    return np.sqrt(w2) / (2 * np.pi)


# Tip loads from none to extreme (μ = M/ρL, η = J/ρL³ up to 10⁴), including Table 1's.
TIP_CASES = [(0.0, 0.0), (0.1, 0.0005), (2.2, 1.1), (0.0, 5.0), (50.0, 0.0), (5e3, 1.0), (1.0, 1e3)]


@pytest.mark.parametrize("tip_mass, tip_inertia", TIP_CASES)
def test_roots_match_independent_fe_no_missed_or_duplicated(tip_mass, tip_inertia):
    params = dict(L=0.5, rho=1.0, EI=10.0, tip_mass=tip_mass, tip_inertia=tip_inertia)
    modes = LinkModes(**params, n=4)
    ref = hermite_beam_frequencies(**params)
    # The FE error falls as h⁴ and is < 7e-5 for all four modes at 20 elements (finer
    # meshes lose digits to round-off with tip loads 10⁴× the link's); a missed or
    # duplicated root would be off by O(1).
    np.testing.assert_allclose(modes.frequencies_hz, ref, rtol=1e-4)
    assert np.all(np.diff(modes.lam) > 0.1)


@pytest.mark.parametrize("tip_mass, tip_inertia", TIP_CASES)
def test_boundary_conditions_and_orthonormality(tip_mass, tip_inertia):
    rho, EI, Lk = 1.0, 10.0, 0.5
    md = LinkModes(L=Lk, rho=rho, EI=EI, tip_mass=tip_mass, tip_inertia=tip_inertia, n=4)
    xs = np.linspace(0.0, Lk, 201)
    np.testing.assert_allclose(md.phi([0.0])[:, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(md.dphi([0.0])[:, 0], 0.0, atol=1e-10)
    end = [Lk]
    w2 = md.omega**2
    # Tip moment and shear balance, relative to the largest moment/shear along the link:
    # round-off from cos−cosh cancellation, amplified up to ~1e7 by tip loads 10⁴× the
    # link's (the extreme cases here), stays below 1e-6.
    moment = EI * md.ddphi(end)[:, 0]
    inertia_moment = tip_inertia * w2 * md.dphi(end)[:, 0]
    scale_m = EI * np.abs(md.ddphi(xs)).max(axis=1) + np.abs(inertia_moment)
    assert np.all(np.abs(moment - inertia_moment) <= 1e-6 * scale_m)
    shear = EI * md.evaluate(end, 3)[:, 0]
    inertia_force = -tip_mass * w2 * md.phi(end)[:, 0]
    scale_s = EI * np.abs(md.evaluate(xs, 3)).max(axis=1) + np.abs(inertia_force)
    assert np.all(np.abs(shear - inertia_force) <= 1e-6 * scale_s)
    x, w = gauss_legendre(0.0, Lk)
    phi, curv = md.phi(x), md.ddphi(x)
    tip, slope = md.tip_values
    mass = rho * (phi * w) @ phi.T + tip_mass * np.outer(tip, tip) + tip_inertia * np.outer(slope, slope)
    # Normalised to the link mass ρL (De Luca–Siciliano), orthogonal otherwise, to the
    # round-off the tip loads amplify: measured 4e-13 (no tip load) to 3.2e-11 (Haswell
    # BLAS kernels) and 1.1e-10 (Sandybridge) at a tip inertia 10⁴× the link's; 1e-9 is
    # 9× the worst, and a mode not normalised or not orthogonal is off by O(0.1).
    np.testing.assert_allclose(mass, rho * Lk * np.eye(4), atol=1e-9)
    stiff = EI * (curv * w) @ curv.T
    np.testing.assert_allclose(stiff, np.diag(rho * Lk * w2), rtol=1e-9, atol=1e-9 * stiff.max())
    assert np.all(md.ddphi([0.0])[:, 0] > 0), "sign convention: phi''(0) > 0"


def test_quadrature_order_is_converged():
    md = LinkModes(L=0.5, rho=1.0, EI=10.0, tip_mass=0.1, tip_inertia=0.0005, n=4)
    (x1, w1), (x2, w2) = gauss_legendre(0.0, 0.5), gauss_legendre(0.0, 0.5, 192)
    g1 = (md.ddphi(x1) * w1) @ md.ddphi(x1).T
    g2 = (md.ddphi(x2) * w2) @ md.ddphi(x2).T
    # 96 nodes agree with 192 to round-off (the worst integrand is the 4th mode's curvature²).
    np.testing.assert_allclose(g1, g2, rtol=1e-12, atol=1e-12 * np.abs(g2).max())


def test_root_finder_rejects_bad_count():
    with pytest.raises(ValueError, match="number of modes"):
        clamped_mass_roots(0, 1.0, 1.0)
