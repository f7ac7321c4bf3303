"""Compiled hot paths of the reduced model: M(Q), C(Q, Q̇), rhs of the paper's eq. (2)–(3).

Formulation (equivalent to De Luca & Siciliano's closed form, organised for speed):
every material point of link i is written in complex planar notation as

    z_i(x) = Σ_β A_iβ(Q) b_β(x),    b(x) = [1, x, φ_i1(x), …, φ_in(x)]

(link 1 never needs the constant 1), linear in a basis of functions of the arc length x.
Its velocity Jacobian ∂z_i/∂Q_j is again a combination of the basis, with coefficients
A_i[j, β] (filled below), so

    M(Q)   = Σ_i Re( conj(A_i) G_i A_iᵀ ) + Σ_rotors J a aᵀ,
    C(Q,Q̇) = Σ_i Re( conj(A_i) G_i Ȧ_iᵀ ),

where G_i = ∫ρ b bᵀ dx + (tip point mass) b(L) b(L)ᵀ is a constant Gram matrix computed
once and Ȧ the time derivative of A.  Because z is a true position (integrable), this C is
the Christoffel-symbol matrix: Ṁ = C + Cᵀ, so Ṁ − 2C = Cᵀ − C is skew-symmetric exactly.
Rotors (hub 1, stator, hub 2, payload) turn by angles linear in Q, so they add J a aᵀ to M
and nothing to C.

Kinematics (θ2 is measured from the link-1 tip tangent):
    z_1(x) = e^{iθ1} (x + i w1(x)),
    z_2(x) = z_1(L1) + e^{iα} (x + i w2(x)),   α = θ1 + θ2 + w1'(L1).

Coordinates: Q = [θ1, θ2, q_11..q_1n1, q_21..q_2n2].  Link 1 depends only on θ1 and q_1,
so its coefficient rows are stored compactly (local row r ↔ global row ``rows1[r]``).

Two evaluations of the same formulas.  `coriolis_matrix_into` forms the dense A, Ȧ and C
(the controller needs the matrix).  The rhs needs only M and the vector h = C Q̇, and
`mass_bias_into` evaluates them with the structure of A written out: link 1's rows are
e^{iθ1}·[i, −q_1] (θ1) and e^{iθ1}·i e_k (q_1k); link 2's rows are c_j e_0 + a_j ζ for
j ∈ {θ1, θ2, q_1*}, with c_j = ∂z_1(L1)/∂Q_j, ζ = e^{iα}[0, i, −q_2], and i e^{iα} e_k
for q_2k.  The unit phases cancel in every product, which leaves O(nb²) work.  The tests
check one evaluation against the other (h = C Q̇) and M against point-mass quadrature.

Calling convention.  Inner kernels take a `ModelData` and a `Workspace` (namedtuples of
arrays) and never allocate; other compiled code (controllers, observers) calls them
directly.  From Python, numba checks a namedtuple argument field by field (~5 µs per
call here), so every model and workspace is also kept *packed* in two flat buffers, and
the ``*_packed`` entry points take only those buffers and `unpack_*` them into views
inside compiled code.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ._exact_data import ExactRef, ExactScratch, exact_reals, exact_workspace_sizes
from ._exact_pointers import (exact_coriolis_matrix_into, exact_elastic_into,
                              exact_mass_bias_into, exact_tips_into, load_exact_kernels)
from ._cholesky import cholesky_solve_inplace
from ._views import matrix_view

__all__ = [
    "ModelData", "Workspace", "pack_model", "unpack_model", "new_workspace", "unpack_workspace",
    "mass_matrix_into", "coriolis_matrix_into", "mass_bias_into", "bias_forces_into",
    "acceleration_into",
    "rhs_into", "rk4_advance", "rk4_advance_packed", "tip_kinematics_packed",
]


class ModelData(NamedTuple):
    """Configuration-independent constants of one `ArmModel` (read-only in kernels)."""

    n1: int
    n2: int
    rows1: np.ndarray  # (1+n1,) global rows of link 1's coefficients: θ1, q_1*
    rows2: np.ndarray  # (n,) global rows of link 2's coefficients: all
    L1: float
    gram1: np.ndarray  # (1+n1, 1+n1) basis [x, φ_1*]
    gram2: np.ndarray  # (2+n2, 2+n2) basis [1, x, φ_2*]
    phi1_tip: np.ndarray  # (n1,) φ_1j(L1)
    dphi1_tip: np.ndarray  # (n1,) φ_1j'(L1)
    phi2_tip: np.ndarray  # (n2,) φ_2j(L2)
    L2: float
    M_rotors: np.ndarray  # (n, n) Σ J a aᵀ of hub 1, stator, hub 2, payload (constant)
    K: np.ndarray  # (n, n) stiffness
    D: np.ndarray  # (n, n) Kelvin–Voigt damping
    exact: object  # `ExactRef`: the exact inextensible kinematics (N = 0: the paper's)


class Workspace(NamedTuple):
    """Scratch arrays so that no kernel allocates; one per user (not thread-safe)."""

    A1: np.ndarray  # complex (1+n1, 1+n1)
    Ad1: np.ndarray
    A2: np.ndarray  # complex (n, 2+n2)
    Ad2: np.ndarray
    c_hat: np.ndarray  # complex (n,) link-1 tip velocity Jacobian in link 2's frame
    v: np.ndarray  # complex (2+max(n1,n2),) basis coefficients
    Gv: np.ndarray  # complex (2+max(n1,n2),) G v
    M: np.ndarray  # (n, n)
    f: np.ndarray  # (n,)
    k1: np.ndarray  # (2n,) RK4 stages and trial state
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray
    xt: np.ndarray
    exact: object  # `ExactScratch`: the exact kinematics' scratch


# --- packing -------------------------------------------------------------------------
def pack_model(*, n1, n2, L1, L2, gram1, gram2, phi1_tip, dphi1_tip, phi2_tip, M_rotors,
               K, D, exact=None) -> tuple[np.ndarray, np.ndarray]:
    """(ints, reals) buffers holding a model, in the order `unpack_model` reads them
    (``exact``: the parts of `ExactData` by name, or None for the paper's kinematics)."""
    n = 2 + n1 + n2
    rows1 = [0, *range(2, 2 + n1)]
    if exact is not None:
        load_exact_kernels()
        exact = {"L": [L1, L2], "phi1_tip": phi1_tip, "dphi1_tip": dphi1_tip,
                 "phi2_tip": phi2_tip, **exact}
    exact_ints, exact_parts = exact_reals(exact, n1, n2)
    ints = np.array([n1, n2, *rows1, *range(n), *exact_ints], dtype=np.int64)
    parts = [[L1, L2], gram1, gram2, phi1_tip, dphi1_tip, phi2_tip, M_rotors, K, D]
    shapes = [(2,), (1 + n1, 1 + n1), (2 + n2, 2 + n2), (n1,), (n1,), (n2,), (n, n), (n, n),
              (n, n)]
    for part, shape in zip(parts, shapes):
        if np.shape(part) != shape:
            raise ValueError(f"model part has shape {np.shape(part)}, expected {shape}")
    reals = np.concatenate([np.ravel(np.asarray(p, dtype=float)) for p in parts]
                           + exact_parts)
    return ints, reals


@njit(cache=True, inline="always")
def unpack_model(ints, reals):
    """`ModelData` of views into the packed buffers (no copy)."""
    n1, n2 = ints[0], ints[1]
    n, nb1, nb2 = 2 + n1 + n2, 1 + n1, 2 + n2
    o = 2
    gram1 = matrix_view(reals, o, nb1, nb1)
    o += nb1 * nb1
    gram2 = matrix_view(reals, o, nb2, nb2)
    o += nb2 * nb2
    phi1_tip = reals[o:o + n1]
    o += n1
    dphi1_tip = reals[o:o + n1]
    o += n1
    phi2_tip = reals[o:o + n2]
    o += n2
    M_rotors = matrix_view(reals, o, n, n)
    o += n * n
    K = matrix_view(reals, o, n, n)
    o += n * n
    D = matrix_view(reals, o, n, n)
    exact = ExactRef(ints[2 + nb1 + n], n1, n2, reals, o + n * n)
    return ModelData(n1, n2, ints[2:2 + nb1], ints[2 + nb1:2 + nb1 + n], reals[0], gram1, gram2,
                     phi1_tip, dphi1_tip, phi2_tip, reals[1], M_rotors, K, D, exact)


def new_workspace(ints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(complex, real) scratch buffers for the model described by ``ints``."""
    n1, n2 = int(ints[0]), int(ints[1])
    n, nb1, nb2 = 2 + n1 + n2, 1 + n1, 2 + n2
    nb = max(nb1, nb2)
    exact_complex, exact_real = exact_workspace_sizes(n1, n2, int(ints[2 + nb1 + n]))
    return (np.zeros(2 * nb1 * nb1 + 2 * n * nb2 + n + 2 * nb + exact_complex, np.complex128),
            np.zeros(n * n + n + 5 * 2 * n + exact_real))


@njit(cache=True, inline="always")
def unpack_workspace(ints, wc, wr):
    """`Workspace` of views into the buffers made by `new_workspace`."""
    n1, n2 = ints[0], ints[1]
    n, nb1, nb2 = 2 + n1 + n2, 1 + n1, 2 + n2
    nb = max(nb1, nb2)
    o = 0
    A1 = matrix_view(wc, o, nb1, nb1)
    o += nb1 * nb1
    Ad1 = matrix_view(wc, o, nb1, nb1)
    o += nb1 * nb1
    A2 = matrix_view(wc, o, n, nb2)
    o += n * nb2
    Ad2 = matrix_view(wc, o, n, nb2)
    o += n * nb2
    c_hat = wc[o:o + n]
    o += n
    v = wc[o:o + nb]
    Gv = wc[o + nb:o + 2 * nb]
    M = matrix_view(wr, 0, n, n)
    exact = ExactScratch(wc, o + 2 * nb, wr, n * n + 11 * n)
    o = n * n
    f = wr[o:o + n]
    o += n
    m = 2 * n
    return Workspace(A1, Ad1, A2, Ad2, c_hat, v, Gv, M, f, wr[o:o + m], wr[o + m:o + 2 * m],
                     wr[o + 2 * m:o + 3 * m], wr[o + 3 * m:o + 4 * m], wr[o + 4 * m:o + 5 * m],
                     exact)


# --- kinematic coefficients ------------------------------------------------------------
# The dense path (`mass_matrix_into`, `coriolis_matrix_into` and their helpers) is inlined
# into its callers, as `mass_bias_into` is: calls that are not inlined pass the model and
# workspace namedtuples field by field, which more than doubled the cost of forming C
# (~680 instead of ~290 ns per call, `bench/bench_reduced_model.py`).
@njit(cache=True, inline="always")
def _fill_coefficients(d, Q, Qd, ws):
    """A_i[row, β] = coefficient of b_β in ∂z_i/∂Q_row, and its time derivative Ȧ_i."""
    n1, n2 = d.n1, d.n2
    A1, Ad1, A2, Ad2 = ws.A1, ws.Ad1, ws.A2, ws.Ad2
    A1[:, :] = 0.0
    Ad1[:, :] = 0.0
    A2[:, :] = 0.0
    Ad2[:, :] = 0.0
    th1, th1d = Q[0], Qd[0]
    w1e = 0.0
    w1ed = 0.0
    s1e = 0.0
    s1ed = 0.0
    for k in range(n1):
        w1e += d.phi1_tip[k] * Q[2 + k]
        w1ed += d.phi1_tip[k] * Qd[2 + k]
        s1e += d.dphi1_tip[k] * Q[2 + k]
        s1ed += d.dphi1_tip[k] * Qd[2 + k]
    alpha = th1 + Q[1] + s1e
    alphad = th1d + Qd[1] + s1ed
    E1 = np.cos(th1) + 1j * np.sin(th1)
    Ea = np.cos(alpha) + 1j * np.sin(alpha)

    # Link 1, z1 = E1 (x + i w1); local rows [θ1, q_1*], columns [x, φ_1*].
    A1[0, 0] = 1j * E1
    Ad1[0, 0] = -th1d * E1
    for k in range(n1):
        q, qd = Q[2 + k], Qd[2 + k]
        A1[0, 1 + k] = -E1 * q
        Ad1[0, 1 + k] = -(1j * th1d * q + qd) * E1
        A1[1 + k, 1 + k] = 1j * E1
        Ad1[1 + k, 1 + k] = -th1d * E1

    # Link 2, z2 = z1e + Ea (x + i w2), z1e = E1 (L1 + i w1e); columns [1, x, φ_2*].
    z1e = E1 * (d.L1 + 1j * w1e)
    z1ed = 1j * th1d * z1e + 1j * E1 * w1ed
    A2[0, 0] = 1j * z1e
    Ad2[0, 0] = 1j * z1ed
    for k in range(n1):
        A2[2 + k, 0] = 1j * E1 * d.phi1_tip[k]
        Ad2[2 + k, 0] = -th1d * E1 * d.phi1_tip[k]
    for j in range(2 + n1):  # a_j = ∂α/∂Q_j: 1, 1, φ_1k'(L1)
        aj = 1.0 if j < 2 else d.dphi1_tip[j - 2]
        A2[j, 1] = 1j * aj * Ea
        Ad2[j, 1] = -aj * alphad * Ea
        for k in range(n2):
            q, qd = Q[2 + n1 + k], Qd[2 + n1 + k]
            A2[j, 2 + k] = -aj * Ea * q
            Ad2[j, 2 + k] = -aj * (1j * alphad * q + qd) * Ea
    for k in range(n2):
        j = 2 + n1 + k
        A2[j, 2 + k] = 1j * Ea
        Ad2[j, 2 + k] = -alphad * Ea


@njit(cache=True, inline="always")
def _add_gram(A, G, B, rows, out, gb):
    """out[rows[i], rows[j]] += Re(conj(A) G Bᵀ)[i, j] for real symmetric G.
    ``gb``: complex scratch (nb,)."""
    m, nb = A.shape
    for j in range(m):
        for beta in range(nb):
            acc = 0.0 + 0.0j
            for gamma in range(nb):
                acc += G[beta, gamma] * B[j, gamma]
            gb[beta] = acc
        for i in range(m):
            s = 0.0
            for beta in range(nb):
                a = A[i, beta]
                s += a.real * gb[beta].real + a.imag * gb[beta].imag
            out[rows[i], rows[j]] += s


@njit(cache=True, inline="always")
def mass_matrix_into(d, Q, M, ws):
    """M(Q) into ``M`` (n, n)."""
    mass_bias_into(d, Q, Q, M, ws.f, ws, False)


@njit(cache=True, inline="always")
def coriolis_matrix_into(d, Q, Qd, C, ws):
    """Christoffel-form C(Q, Q̇) into ``C`` (n, n)."""
    if d.exact.N > 0:
        exact_coriolis_matrix_into(d.exact, ws.exact, Q, Qd, C)
        return
    _fill_coefficients(d, Q, Qd, ws)
    C[:, :] = 0.0
    _add_gram(ws.A1, d.gram1, ws.Ad1, d.rows1, C, ws.Gv)
    _add_gram(ws.A2, d.gram2, ws.Ad2, d.rows2, C, ws.Gv)


@njit(cache=True, inline="always")
def mass_bias_into(d, Q, Qd, M, h, ws, with_bias=True):
    """M(Q) into ``M`` and, ``with_bias``, h = C(Q, Q̇) Q̇ into ``h`` (structured
    evaluation, see module doc).

    Everything is expressed in link 2's frame (link 1's in its own), where the phases
    e^{iθ1}, e^{iα} drop out.  v is the basis-coefficient vector of the velocity-product
    accelerations Σ_j Ȧ_j Q̇_j of each link, and h_i = Re(conj(A_i) G v).
    """
    if d.exact.N > 0:
        exact_mass_bias_into(d.exact, ws.exact, Q, Qd, M, h, with_bias)
        return
    n1, n2 = d.n1, d.n2
    n = 2 + n1 + n2
    G1, G2, v, Gv, c_hat = d.gram1, d.gram2, ws.v, ws.Gv, ws.c_hat
    th1d = Qd[0]
    w1e = 0.0
    w1ed = 0.0
    s1e = 0.0
    s1ed = 0.0
    for k in range(n1):
        w1e += d.phi1_tip[k] * Q[2 + k]
        w1ed += d.phi1_tip[k] * Qd[2 + k]
        s1e += d.dphi1_tip[k] * Q[2 + k]
        s1ed += d.dphi1_tip[k] * Qd[2 + k]
    alphad = th1d + Qd[1] + s1ed

    for i in range(n):
        h[i] = 0.0
        for j in range(n):
            M[i, j] = d.M_rotors[i, j]

    # ---- link 1: rows θ1 → [i, −q_1], q_1k → i e_k; basis [x, φ_1*].
    M[0, 0] += G1[0, 0]
    for k in range(n1):
        M[0, 2 + k] += G1[0, 1 + k]
        for l in range(n1):
            M[2 + k, 2 + l] += G1[1 + k, 1 + l]
            M[0, 0] += Q[2 + k] * G1[1 + k, 1 + l] * Q[2 + l]
    if with_bias:
        v[0] = -th1d * th1d
        for k in range(n1):
            v[1 + k] = -1j * th1d * th1d * Q[2 + k] - 2.0 * th1d * Qd[2 + k]
        for b in range(1 + n1):
            acc = 0.0 + 0.0j
            for g in range(1 + n1):
                acc += G1[b, g] * v[g]
            Gv[b] = acc
        h[0] += Gv[0].imag
        for k in range(n1):
            h[0] -= Q[2 + k] * Gv[1 + k].real
            h[2 + k] += Gv[1 + k].imag

    # ---- link 2: rows j ∈ {θ1, θ2, q_1*} → c_j e_0 + a_j [0, i, −q_2]; q_2k → i e_k;
    # basis [1, x, φ_2*]; c_j (c_hat) is the link-1 tip Jacobian in link 2's frame.
    gamma = Q[1] + s1e
    eg = np.cos(gamma) - 1j * np.sin(gamma)  # e^{-iγ}: link-1 frame → link-2 frame
    c_hat[0] = 1j * eg * (d.L1 + 1j * w1e)
    c_hat[1] = 0.0
    for k in range(n1):
        c_hat[2 + k] = 1j * eg * d.phi1_tip[k]
    g0 = 1j * G2[0, 1]  # (G ζ')_0 with ζ' = [0, i, −q_2]
    Z = G2[1, 1]  # ζ'ᴴ G ζ'
    for k in range(n2):
        g0 -= G2[0, 2 + k] * Q[2 + n1 + k]
        for l in range(n2):
            M[2 + n1 + k, 2 + n1 + l] += G2[2 + k, 2 + l]
            Z += Q[2 + n1 + k] * G2[2 + k, 2 + l] * Q[2 + n1 + l]
    m_bar = G2[0, 0]
    for i in range(2 + n1):
        ai = 1.0 if i < 2 else d.dphi1_tip[i - 2]
        ci = c_hat[i]
        ri = ci.real * g0.real + ci.imag * g0.imag  # Re(conj(c_i) g0)
        for j in range(i, 2 + n1):
            aj = 1.0 if j < 2 else d.dphi1_tip[j - 2]
            cj = c_hat[j]
            rj = cj.real * g0.real + cj.imag * g0.imag
            M[i, j] += m_bar * (ci.real * cj.real + ci.imag * cj.imag) + aj * ri + ai * rj \
                + ai * aj * Z
        for k in range(n2):
            M[i, 2 + n1 + k] += ci.imag * G2[0, 2 + k] + ai * G2[1, 2 + k]
    for i in range(n):
        for j in range(i):
            M[i, j] = M[j, i]

    if not with_bias:
        return
    # velocity-product accelerations: link-1 tip (centripetal + Coriolis) and link 2.
    v[0] = eg * (-th1d * th1d * (d.L1 + 1j * w1e) - 2.0 * th1d * w1ed)
    v[1] = -alphad * alphad
    for k in range(n2):
        v[2 + k] = -1j * alphad * alphad * Q[2 + n1 + k] - 2.0 * alphad * Qd[2 + n1 + k]
    for b in range(2 + n2):
        acc = 0.0 + 0.0j
        for g in range(2 + n2):
            acc += G2[b, g] * v[g]
        Gv[b] = acc
    zeta_gv = Gv[1].imag  # Re(ζ'ᴴ G v)
    for k in range(n2):
        zeta_gv -= Q[2 + n1 + k] * Gv[2 + k].real
        h[2 + n1 + k] += Gv[2 + k].imag
    for i in range(2 + n1):
        ai = 1.0 if i < 2 else d.dphi1_tip[i - 2]
        ci = c_hat[i]
        h[i] += ci.real * Gv[0].real + ci.imag * Gv[0].imag + ai * zeta_gv


@njit(cache=True, inline="always")
def bias_forces_into(d, Q, Qd, h, ws):
    """h = C(Q,Q̇) Q̇ + D Q̇ + K Q into ``h``, and M(Q) into ws.M."""
    mass_bias_into(d, Q, Qd, ws.M, h, ws)
    n = h.shape[0]
    for i in range(2, n):  # K and D vanish on the joint rows/columns
        s = 0.0
        for j in range(2, n):
            s += d.K[i, j] * Q[j] + d.D[i, j] * Qd[j]
        h[i] += s
    if d.exact.N > 0:
        exact_elastic_into(d.exact, Q, Qd, h, True)


@njit(cache=True, inline="always")
def acceleration_into(d, Q, Qd, tau, Qdd, ws):
    """Q̈ = M⁻¹(B τ − C Q̇ − D Q̇ − K Q) into ``Qdd``, B = [I2; 0].  ``tau`` holds the two
    joint torques, or n generalised forces (the paper's idealised, unrealisable input)."""
    f = ws.f
    bias_forces_into(d, Q, Qd, f, ws)
    n = f.shape[0]
    for i in range(n):
        Qdd[i] = (tau[i] if i < tau.shape[0] else 0.0) - f[i]
    if not cholesky_solve_inplace(ws.M, Qdd):
        Qdd[:] = np.nan


@njit(cache=True, inline="always")
def rhs_into(d, x, tau, xdot, ws):
    """ẋ for the state x = [Q, Q̇] (length 2n) into ``xdot``."""
    n = x.shape[0] // 2
    for i in range(n):
        xdot[i] = x[n + i]
    acceleration_into(d, x[:n], x[n:], tau, xdot[n:], ws)


@njit(cache=True, inline="always")
def rk4_advance(d, x, tau, h, nsteps, ws):
    """Advance ``x`` in place by ``nsteps`` classical RK4 steps of size ``h`` with ``tau``
    held constant (zero-order hold).

    The four stages run in one loop, so the (inlined) right-hand side appears once in the
    compiled code: a quarter of the machine code to compile, the same arithmetic in the
    same order as the textbook form x += h/6 (k1 + 2 k2 + 2 k3 + k4)."""
    m = x.shape[0]
    k, acc, xt = ws.k1, ws.k2, ws.xt
    for _ in range(nsteps):
        for i in range(m):
            xt[i] = x[i]
            acc[i] = 0.0
        for stage in range(4):
            rhs_into(d, xt, tau, k, ws)
            weight = 2.0 if stage == 1 or stage == 2 else 1.0
            step = h if stage == 2 else 0.5 * h  # where the next stage is evaluated
            for i in range(m):
                acc[i] += weight * k[i]
                xt[i] = x[i] + step * k[i]
        for i in range(m):
            x[i] += h / 6.0 * acc[i]


@njit(cache=True)
def rk4_advance_packed(ints, reals, wc, wr, x, tau, h, nsteps):
    """`rk4_advance` on packed buffers (the fast entry point from Python)."""
    rk4_advance(unpack_model(ints, reals), x, tau, h, nsteps, unpack_workspace(ints, wc, wr))


@njit(cache=True)
def tip_kinematics_packed(ints, reals, Q, out):
    """Planar kinematics with deflection: ``out`` = [x1, y1, x2, y2, w1(L1), w2(L2)],
    the link-1 tip, the payload, and both tip deflections in their root frames."""
    d = unpack_model(ints, reals)
    if d.exact.N > 0:
        exact_tips_into(d.exact, Q, out)
        return
    n1, n2 = d.n1, d.n2
    w1e = 0.0
    s1e = 0.0
    for k in range(n1):
        w1e += d.phi1_tip[k] * Q[2 + k]
        s1e += d.dphi1_tip[k] * Q[2 + k]
    w2e = 0.0
    for k in range(n2):
        w2e += d.phi2_tip[k] * Q[2 + n1 + k]
    c1, s1 = np.cos(Q[0]), np.sin(Q[0])
    alpha = Q[0] + Q[1] + s1e
    ca, sa = np.cos(alpha), np.sin(alpha)
    out[0] = c1 * d.L1 - s1 * w1e
    out[1] = s1 * d.L1 + c1 * w1e
    out[2] = out[0] + ca * d.L2 - sa * w2e
    out[3] = out[1] + sa * d.L2 + ca * w2e
    out[4] = w1e
    out[5] = w2e
