"""The reduced model of any arm description against independent references: a Lagrangian
assembled here from positions by quadrature (mass matrix, Christoffel forces, gravity), the
Euler–Bernoulli frequency equation of a link on a free hub with a tip mass, the cantilever's
sag in gravity, and energy conservation in free motion in gravity."""
import numpy as np
import pytest
from numpy.polynomial.legendre import leggauss
from scipy.optimize import brentq

from reduced_model import ArmModel, ArmParameters, ReducedPlant, named_arm

ARMS = ["default", "single-link", "rigid-flexible", "three-link", "vertical-two-link"]


# --- an independent Lagrangian: positions of mass points by quadrature ------------------------
def _centreline(modes, q, s, exact):
    """Points of a link's centreline at arc lengths ``s`` in its root frame: the paper's
    s + i w(s), or the inextensible curve ∫ e^{i atan w'} (Gauss–Legendre per point)."""
    if not exact:
        return s + 1j * (modes.phi(s).T @ q)
    t, w = leggauss(48)
    out = np.empty(len(s), dtype=complex)
    for k, sk in enumerate(s):
        x = 0.5 * sk * (t + 1)
        out[k] = 0.5 * sk * w @ np.exp(1j * np.arctan(modes.dphi(x).T @ q))
    return out


def _points(model, Q):
    """(positions, masses, rotor angles, rotor inertias) of every mass point of the arm."""
    p, N = model.params, model.n_joints
    t, w = leggauss(64)
    pos, mass, angles, inertias = [], [], [], []
    root, alpha, c = 0j, 0.0, N
    for i, (link, modes) in enumerate(zip(p.links, model.mode_shapes)):
        q = Q[c:c + modes.n]
        alpha = alpha + Q[i]
        s = 0.5 * link.length * (t + 1)
        end = np.array([link.length])
        if modes.n:
            centre = _centreline(modes, q, s, model.exact)
            tip = _centreline(modes, q, end, model.exact)[0]
            slope = modes.dphi(end)[:, 0] @ q
            slope = np.arctan(slope) if model.exact else slope
        else:
            centre, tip, slope = s + 0j, link.length + 0j, 0.0
        frame = np.exp(1j * alpha)
        pos += list(root + frame * centre)
        mass += list(link.mass_per_length * 0.5 * link.length * w)
        angles.append(alpha)
        inertias.append(link.hub_inertia)
        root = root + frame * tip
        alpha = alpha + slope
        pos.append(root)
        mass.append(p.tip_point_mass(i))
        angles.append(alpha)
        inertias.append(p.rotor_inertias()[2 * i + 1])
        c += modes.n
    return np.array(pos), np.array(mass), np.array(angles), np.array(inertias)


def _jacobians(model, Q, step=1e-6):
    columns = []
    for k in range(len(Q)):
        e = np.zeros(len(Q))
        e[k] = step
        (pp, _, ap, _), (pm, _, am, _) = _points(model, Q + e), _points(model, Q - e)
        columns.append(((pp - pm) / (2 * step), (ap - am) / (2 * step)))
    return np.array([c[0] for c in columns]).T, np.array([c[1] for c in columns]).T


def _mass_matrix(model, Q):
    """M = Σ m Re(∂pᴴ ∂p) + Σ J ∂a ∂aᵀ (central differences of the positions, ~1e-10)."""
    Jp, Ja = _jacobians(model, Q)
    _, m, _, J = _points(model, Q)
    return ((Jp.conj().T * m) @ Jp).real + (Ja.T * J) @ Ja


def _gravity_force(model, Q, step=1e-6):
    """∂V/∂Q of V = −Σ m g·p (central differences)."""
    g = complex(*model.params.gravity)
    V = lambda Q: -np.sum(_points(model, Q)[1] * (np.conj(g) * _points(model, Q)[0]).real)  # noqa
    return np.array([(V(Q + step * e) - V(Q - step * e)) / (2 * step) for e in np.eye(len(Q))])


def _state(model, seed, deflection):
    rng = np.random.default_rng(seed)
    Q = rng.normal(size=model.n) * 0.5
    Q[model.n_joints:] *= deflection
    return Q, rng.normal(size=model.n)


@pytest.mark.parametrize("kinematics", ["linear", "exact"])
@pytest.mark.parametrize("name", ARMS)
def test_mass_matrix_and_gravity_are_the_lagrangian_ones(name, kinematics):
    """M(Q) and ∂V/∂Q of every example arm (rigid and flexible links, 1–3 links) equal the
    ones of an independent Lagrangian assembled from positions of mass points (64-point
    Gauss quadrature per link, central differences of step 1e-6: ~1e-10 relative).  The
    exact kinematics' remainder is interpolated through 4 + 2 × modes nodes: at modal
    amplitudes of 1–2 % of a link's length it is then within 1e-6 (relative)."""
    arm = named_arm(name)
    if not any(arm.gravity):
        arm = arm.replace(gravity=[3.0, -9.81])  # gravity in every direction of the plane
    model = ArmModel(arm, kinematics=kinematics)
    Q, _ = _state(model, 3, 0.01)
    M, M_ref = model.mass_matrix(Q), _mass_matrix(model, Q)
    g, g_ref = model.gravity_force(Q), _gravity_force(model, Q)
    tol = 1e-8 if kinematics == "linear" else 1e-6
    assert np.abs(M - M_ref).max() < tol * np.abs(M_ref).max()
    assert np.abs(g - g_ref).max() < tol * np.abs(g_ref).max()


@pytest.mark.parametrize("kinematics", ["linear", "exact"])
@pytest.mark.parametrize("name", ["three-link", "rigid-flexible"])
def test_velocity_forces_are_the_christoffel_ones_of_the_mass_matrix(name, kinematics):
    """h = C(Q, Q̇) Q̇ equals Σ (∂M_ij/∂Q_k − ½ ∂M_jk/∂Q_i) Q̇_j Q̇_k from central
    differences (step 1e-5: ~1e-8 relative) of the model's own M; C is the matrix the PBC
    uses (the same h)."""
    model = ArmModel(named_arm(name), kinematics=kinematics)
    Q, Qd = _state(model, 5, 0.02)
    n, step = model.n, 1e-5
    dM = np.array([(model.mass_matrix(Q + step * e) - model.mass_matrix(Q - step * e))
                   / (2 * step) for e in np.eye(n)])  # dM[k] = ∂M/∂Q_k
    h_ref = np.einsum("kij,j,k->i", dM, Qd, Qd) - 0.5 * np.einsum("ijk,j,k->i", dM, Qd, Qd)
    h = model.coriolis_matrix(Q, Qd) @ Qd
    assert np.abs(h - h_ref).max() < 1e-6 * np.abs(h_ref).max()
    M0 = model.mass_matrix(Q)
    free = model.acceleration(Q, Qd, np.zeros(model.n_joints))
    forces = model.elastic_force(Q, Qd) + model.gravity_force(Q)
    assert np.allclose(M0 @ free, -(h + forces), rtol=0, atol=1e-9 * np.abs(h).max())


# --- a single flexible link on a free hub: the Euler–Bernoulli frequency equation ---------------
def _hub_link_determinant(omega, L, rho, EI, J_hub, M_tip, J_tip):
    """det of the boundary conditions of Y = A sin βx + B cos βx + C sinh βx + D cosh βx,
    β⁴ = ρω²/EI, on a pinned hub of inertia J_hub: Y(0) = 0, EI Y''(0) = −J_hub ω² Y'(0);
    at the tip, EI Y'''(L) = −M ω² Y(L) and EI Y''(L) = J_tip ω² Y'(L) (from the variation
    of T = ½∫ρẏ² + ½J_hub ẏ'(0)² + ½M ẏ(L)² + ½J_tip ẏ'(L)², V = ½∫EI y''²)."""
    b = (rho * omega**2 / EI) ** 0.25
    s, c, sh, ch = np.sin(b * L), np.cos(b * L), np.sinh(b * L), np.cosh(b * L)
    w2 = omega**2
    rows = [
        [0.0, 1.0, 0.0, 1.0],
        [J_hub * w2 * b, -EI * b**2, J_hub * w2 * b, EI * b**2],
        [-EI * b**3 * c + M_tip * w2 * s, EI * b**3 * s + M_tip * w2 * c,
         EI * b**3 * ch + M_tip * w2 * sh, EI * b**3 * sh + M_tip * w2 * ch],
        [-EI * b**2 * s - J_tip * w2 * b * c, -EI * b**2 * c + J_tip * w2 * b * s,
         EI * b**2 * sh - J_tip * w2 * b * ch, EI * b**2 * ch - J_tip * w2 * b * sh],
    ]
    return np.linalg.det(np.array(rows) / np.abs(np.array(rows)).max(axis=1, keepdims=True))


def hub_link_frequencies(arm, count):
    """The first ``count`` non-zero natural frequencies [Hz] of a single link on a free hub
    (roots of `_hub_link_determinant`, bracketed on a fine grid)."""
    link, payload = arm.links[0], arm.payload
    args = (link.length, link.mass_per_length, link.bending_stiffness, link.hub_inertia,
            payload.mass, payload.inertia)
    grid = np.linspace(0.5, 2 * np.pi * 2000.0, 400_001)
    values = np.array([_hub_link_determinant(w, *args) for w in grid])
    roots = [brentq(_hub_link_determinant, grid[i], grid[i + 1], args=args, xtol=1e-12)
             for i in np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))[:count]]
    return np.array(roots) / (2 * np.pi)


def test_a_single_link_on_a_free_hub_has_the_euler_bernoulli_frequencies():
    """The reduced model of the single flexible link (hub inertia, tip mass and inertia)
    converges to the roots of the frequency equation: with 4 assumed modes its first two
    free frequencies are within 0.1 % (measured: bench/..., errors per mode count in the
    README of the docs' theory page)."""
    arm = named_arm("single-link")
    exact = hub_link_frequencies(arm, 2)
    errors = {}
    for modes in (1, 2, 3, 4):
        f = ArmModel(arm, (modes,)).natural_frequencies(joints="free")
        errors[modes] = np.abs(f[:2] - exact[:len(f[:2])]) / exact[:len(f[:2])]
    assert np.all(errors[4] < 1e-3), errors
    assert errors[1][0] > errors[4][0]  # it converges with the modes: 1 mode is coarser


# --- gravity: the cantilever's sag, the holding torque, energy ---------------------------------
def _sag(model, arm, theta=0.0):
    """The static deflection of the arm held at ``theta`` (joints locked): the modal
    coordinates where the elastic force balances gravity (Newton on the exact forces)."""
    N, n = model.n_joints, model.n
    Q = np.zeros(n)
    Q[:N] = theta
    for _ in range(30):
        r = (model.elastic_force(Q, np.zeros(n)) + model.gravity_force(Q))[N:]
        K = np.column_stack([((model.elastic_force(Q + 1e-7 * e, np.zeros(n))
                               + model.gravity_force(Q + 1e-7 * e))
                              - (model.elastic_force(Q - 1e-7 * e, np.zeros(n))
                                 + model.gravity_force(Q - 1e-7 * e)))[N:] / 2e-7
                             for e in np.eye(n)[N:]])
        dq = np.linalg.solve(K, -r)
        Q[N:] += dq
        if np.abs(dq).max() < 1e-14:
            break
    return Q


@pytest.mark.parametrize("modes", [2, 3, 4])
def test_a_link_held_horizontal_sags_as_the_cantilever(modes):
    """A single flexible link held horizontal in a vertical plane sags to ρgL⁴/(8EI) +
    M_p g L³/(3EI) (Euler–Bernoulli cantilever) within 0.5 % with 2 modes or more, and
    the torque that holds it is the static moment ρgL²/2 + M_p g L to 1e-6 (exactly, with
    the paper's kinematics: the point x + i w keeps its lever x)."""
    arm = named_arm("vertical-single-link")
    link, Mp, g = arm.links[0], arm.payload.mass, -arm.gravity[1]
    model = ArmModel(arm, (modes,))
    Q = _sag(model, arm)
    sag = model.tip_deflection(Q)[0]
    L, rho, EI = link.length, link.mass_per_length, link.bending_stiffness
    cantilever = -(rho * g * L**4 / (8 * EI) + Mp * g * L**3 / (3 * EI))
    assert abs(sag / cantilever - 1) < 5e-3
    moment = rho * g * L**2 / 2 + Mp * g * L
    held = model.gravity_force(Q)[0]
    assert abs(held / moment - 1) < 1e-6


def test_free_motion_in_gravity_conserves_energy():
    """With no damping and no friction, the vertical two-link arm swinging freely from
    rest 0.3 rad above horizontal keeps T + V (elastic and gravity) to 1e-6 of its range
    over 5 s (RK4 at 0.1 ms; the model's M, C and ∂V/∂Q are consistent)."""
    arm = named_arm("vertical-two-link").replace(bending_damping1=0.0, bending_damping2=0.0)
    plant = ReducedPlant(arm, step=1e-4, Ts=1e-3)
    model = plant.model
    x0 = np.zeros(2 * model.n)
    x0[:2] = [0.3, -0.2]
    plant.reset(x0)
    energy = []
    for _ in range(5000):
        plant.advance(np.zeros(2))
        Q, Qd = plant.state[:model.n], plant.state[model.n:]
        energy.append(model.kinetic_energy(Q, Qd) + model.potential_energy(Q))
    energy = np.array(energy)
    swing = np.ptp([model.potential_energy(plant.state[:model.n])]) + energy[0] - energy.min()
    assert np.ptp(energy) < 1e-6 * max(abs(energy).max(), swing)
