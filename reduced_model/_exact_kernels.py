"""Compiled dynamics of the reduced model with exact inextensible kinematics: M(Q),
C(Q, Q̇), h = C Q̇, the exact bending forces, and the tip kinematics.

The same formulation as the paper's model (`reduced_model._kernels`), on a larger basis:
in each link's root frame a point at arc length s is

    ρ(s) = s + i w(s) + Σ_h g_h r_h(s),   g_h = g(p(s_h)),  p = w',

(`reduced_model._inextensible`), a combination of the fixed functions b = [1, s, φ_k,
r_h] with coefficients a(Q).  The link-1 tip slope turns link 2's root frame by
β1 = atan p1(L1) (not p1(L1)); the stator turns with it, hub 2 by α = θ1 + θ2 + β1, the
payload by α + atan p2(L2).  Velocity Jacobians are again combinations of b (rows of A),
so with the constant Gram matrices G of b

    M = Σ_links Re(conj(A) G Aᵀ) + Σ_rotors J a aᵀ,
    C = Σ_links Re(conj(A) G Ȧᵀ) + Σ_rotors J a ȧᵀ,    h = C Q̇,

where Ȧ is the time derivative of A (in the rotating frame, the frame's turning
included) and a the rotors' angular-velocity rows.  Positions are integrable, so C is the
Christoffel matrix (Ṁ − 2C skew) and the model conserves its energy without damping.

Elastic forces: the bending energy ½ EI ∫ κ² of the exact curvature κ = p'/(1 + p²),
written as the linear ½ qᵀ K q plus a correction of fourth order in q, and the
Kelvin–Voigt damping d ∫ κ̇ ∂κ/∂q as D q̇ plus its correction; both integrals by the
nodes' Gauss quadrature.

`ModelData.exact` and `Workspace.exact` point to the constants and the scratch
(`reduced_model._exact_data`); `reduced_model._kernels` calls the kernels here where
N > 0, so every compiled user of the model (plant, laws, loop) gets the model it was
given.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._exact_data import unpack_exact, unpack_exact_workspace

__all__ = ["exact_mass_bias_into", "exact_coriolis_matrix_into", "exact_elastic_into",
           "exact_tips_into", "exact_tip_jacobian_into"]


# --- the coefficients -----------------------------------------------------------------------
@njit(cache=True, inline="always")
def _slope(dphi, Q, Qd, c, k):
    """p and ṗ of the field with slopes ``dphi[:, k]`` of the coordinates from ``c``."""
    p = 0.0
    pd = 0.0
    for j in range(dphi.shape[0]):
        p += dphi[j, k] * Q[c + j]
        pd += dphi[j, k] * Qd[c + j]
    return p, pd


@njit(cache=True, inline="always")
def _nodes(dphi, Q, Qd, c, x):
    """g(p), g'(p), g''(p) and ṗ at a link's nodes into ``x`` (module docstring of
    `reduced_model._inextensible`: e^{iβ} = (1 + i p)/√(1 + p²))."""
    for k in range(dphi.shape[1]):
        p, pd = _slope(dphi, Q, Qd, c, k)
        u = 1.0 / (1.0 + p * p)
        e = (1.0 + 1j * p) * np.sqrt(u)
        x.g[k] = e - 1.0 - 1j * p
        x.g1[k] = 1j * (e * u - 1.0)
        x.g2[k] = -e * (1.0 + 2j * p) * u * u
        x.pd[k] = pd


@njit(cache=True, inline="always")
def _fill(e, Q, Qd, x, rates):
    """A1, A2, v1, v2 and the rotor rows (module docstring) into ``x``; with ``rates``
    also Ȧ1, Ȧ2 and the rotor rows' rates."""
    n1, n2, N = e.n1, e.n2, e.N
    n = 2 + n1 + n2
    A1, A2, Ad1, Ad2, v1, v2, a2 = x.A1, x.A2, x.Ad1, x.Ad2, x.v1, x.v2, x.a2
    A1[:, :] = 0j
    A2[:, :] = 0j
    if rates:
        Ad1[:, :] = 0j
        Ad2[:, :] = 0j
    th1d = Qd[0]
    r0 = 1 + n1  # first r_h column of link 1

    # ---- link 1 (its root frame): a = [1, i q_1, g]; rows θ1 → i a, q_1k → ∂a/∂q_1k.
    _nodes(e.dphi1, Q, Qd, 2, x)
    A1[0, 0] = 1j
    v1[0] = -th1d * th1d
    for k in range(n1):
        q, qd = Q[2 + k], Qd[2 + k]
        A1[0, 1 + k] = -q
        A1[1 + k, 1 + k] = 1j
        v1[1 + k] = -1j * th1d * th1d * q - 2.0 * th1d * qd
    for h in range(N):
        g, g1, g2, pd = x.g[h], x.g1[h], x.g2[h], x.pd[h]
        A1[0, r0 + h] = 1j * g
        v1[r0 + h] = -th1d * th1d * g + 2j * th1d * g1 * pd + g2 * pd * pd
        for k in range(n1):
            A1[1 + k, r0 + h] = g1 * e.dphi1[k, h]
    if rates:  # Ȧ in the turning frame: i θ̇1 A + d/dt of the coefficients
        Ad1[0, 0] = -th1d
        for k in range(n1):
            Ad1[0, 1 + k] = -1j * th1d * Q[2 + k] - Qd[2 + k]
            Ad1[1 + k, 1 + k] = -th1d
        for h in range(N):
            g, g1, g2, pd = x.g[h], x.g1[h], x.g2[h], x.pd[h]
            Ad1[0, r0 + h] = -th1d * g + 1j * g1 * pd
            for k in range(n1):
                Ad1[1 + k, r0 + h] = (1j * th1d * g1 + g2 * pd) * e.dphi1[k, h]

    # ---- link-1 tip: rows · b(L1), b(L1) = [L1, φ_1(L1), w_h].
    u1e = v1[0] * e.L1
    for r in range(1 + n1):
        t = A1[r, 0] * e.L1
        td = Ad1[r, 0] * e.L1 if rates else 0j
        for k in range(n1):
            t += A1[r, 1 + k] * e.phi1_tip[k]
            if rates:
                td += Ad1[r, 1 + k] * e.phi1_tip[k]
        for h in range(N):
            t += A1[r, r0 + h] * e.w1[h]
            if rates:
                td += Ad1[r, r0 + h] * e.w1[h]
        x.t[r] = t
        x.td[r] = td
    for k in range(n1):
        u1e += v1[1 + k] * e.phi1_tip[k]
    for h in range(N):
        u1e += v1[r0 + h] * e.w1[h]
    p1e, p1ed = 0.0, 0.0
    for k in range(n1):
        p1e += e.dphi1_tip[k] * Q[2 + k]
        p1ed += e.dphi1_tip[k] * Qd[2 + k]
    b1 = 1.0 / (1.0 + p1e * p1e)  # β1' = d atan p / dp
    b1d = -2.0 * p1e * b1 * b1  # β1''
    gamma = Q[1] + np.arctan(p1e)  # link 2's frame relative to link 1's
    eg = np.cos(gamma) - 1j * np.sin(gamma)
    alphad = th1d + Qd[1] + b1 * p1ed
    alpha_vp = b1d * p1ed * p1ed

    # ---- link 2 (its root frame): a = [0, 1, i q_2, g]; rows j ∈ {θ1, θ2, q_1*} →
    # da_j (i a) + (link-1 tip row j) e_0, q_2k → ∂a/∂q_2k.
    _nodes(e.dphi2, Q, Qd, 2 + n1, x)
    s0 = 2 + n2  # first r_h column of link 2
    a2[0] = 0j
    a2[1] = 1j
    for k in range(n2):
        a2[2 + k] = -Q[2 + n1 + k]
    for h in range(N):
        a2[s0 + h] = 1j * x.g[h]
    for j in range(2 + n1):
        da = 1.0 if j < 2 else b1 * e.dphi1_tip[j - 2]
        for b in range(1, s0 + N):
            A2[j, b] = da * a2[b]
        if j != 1:
            A2[j, 0] = eg * x.t[0 if j == 0 else j - 1]
    for k in range(n2):
        A2[2 + n1 + k, 2 + k] = 1j
        for h in range(N):
            A2[2 + n1 + k, s0 + h] = x.g1[h] * e.dphi2[k, h]
    # v2 = (i α̈ − α̇²) a + 2 i α̇ ȧ + ä (in i a terms), plus the link-1 tip's acceleration.
    v2[0] = eg * u1e
    v2[1] = 1j * alpha_vp - alphad * alphad
    for k in range(n2):
        q, qd = Q[2 + n1 + k], Qd[2 + n1 + k]
        v2[2 + k] = (1j * alpha_vp - alphad * alphad) * 1j * q - 2.0 * alphad * qd
    for h in range(N):
        g, g1, g2, pd = x.g[h], x.g1[h], x.g2[h], x.pd[h]
        v2[s0 + h] = (1j * alpha_vp - alphad * alphad) * g + 2j * alphad * g1 * pd \
            + g2 * pd * pd
    if rates:
        for j in range(2 + n1):
            da = 1.0 if j < 2 else b1 * e.dphi1_tip[j - 2]
            dda = 0.0 if j < 2 else b1d * p1ed * e.dphi1_tip[j - 2]
            c = 1j * alphad * da + dda
            Ad2[j, 1] = c * 1j
            for k in range(n2):  # da (i ȧ) on the φ_2 columns: i · i q̇ = −q̇
                Ad2[j, 2 + k] = -c * Q[2 + n1 + k] - da * Qd[2 + n1 + k]
            for h in range(N):
                Ad2[j, s0 + h] = c * 1j * x.g[h] + da * 1j * x.g1[h] * x.pd[h]
            if j != 1:
                Ad2[j, 0] = eg * x.td[0 if j == 0 else j - 1]
        for k in range(n2):
            row = 2 + n1 + k
            Ad2[row, 2 + k] = -alphad
            for h in range(N):
                Ad2[row, s0 + h] = (1j * alphad * x.g1[h] + x.g2[h] * x.pd[h]) * e.dphi2[k, h]

    # ---- rotors: hub 1 (θ1), stator (θ1 + β1), hub 2 (α), payload (α + β2).
    p2e, p2ed = 0.0, 0.0
    for k in range(n2):
        p2e += e.dphi2_tip[k] * Q[2 + n1 + k]
        p2ed += e.dphi2_tip[k] * Qd[2 + n1 + k]
    b2 = 1.0 / (1.0 + p2e * p2e)
    b2d = -2.0 * p2e * b2 * b2
    ax, axd = x.ax, x.axd
    ax[:, :] = 0.0
    axd[:, :] = 0.0
    ax[:, 0] = 1.0
    ax[2:, 1] = 1.0
    for k in range(n1):
        for r in range(1, 4):
            ax[r, 2 + k] = b1 * e.dphi1_tip[k]
            axd[r, 2 + k] = b1d * p1ed * e.dphi1_tip[k]
    for k in range(n2):
        ax[3, 2 + n1 + k] = b2 * e.dphi2_tip[k]
        axd[3, 2 + n1 + k] = b2d * p2ed * e.dphi2_tip[k]
    x.vp[0] = 0.0
    x.vp[1] = alpha_vp
    x.vp[2] = alpha_vp
    x.vp[3] = alpha_vp + b2d * p2ed * p2ed
    return n


@njit(cache=True, inline="always")
def _gram_rows(G, A, GA, first, last):
    """GA[r] = G A[r] for rows first..last−1 (G symmetric: rows of G, contiguous)."""
    nb = G.shape[0]
    for r in range(first, last):
        for b in range(nb):
            acc = 0j
            for c in range(nb):
                acc += G[b, c] * A[r, c]
            GA[r, b] = acc


@njit(cache=True, inline="always")
def _products(e, x, all_rows):
    """G A, row by row: link 1's rows, link 2's rows θ2 and q_2*, and with ``all_rows``
    link 2's rows θ1 and q_1* too.  Those are da_j (i a) + t_j e_0, so they come from
    row θ2 (da = 1, no root term), G (i a), and G's first column; da_j is hub 2's
    angular-velocity row (``x.ax[2]``)."""
    n1, n2 = e.n1, e.n2
    G2, GA2 = e.G2, x.GA2
    _gram_rows(e.G1, x.A1, x.GA1, 0, 1 + n1)
    _gram_rows(G2, x.A2, GA2, 1, 2)
    _gram_rows(G2, x.A2, GA2, 2 + n1, 2 + n1 + n2)
    if all_rows:
        for j in range(2 + n1):
            if j != 1:
                da, root = x.ax[2, j], x.A2[j, 0]
                for b in range(G2.shape[0]):
                    GA2[j, b] = da * GA2[1, b] + root * G2[b, 0]


@njit(cache=True, inline="always")
def _re_dot(A, r, B, s, nb):
    """Re(Σ_c conj(A[r, c]) B[s, c]) (rows indexed, not sliced: a row view per call
    costs its reference counting)."""
    acc = 0.0
    for c in range(nb):
        acc += A[r, c].real * B[s, c].real + A[r, c].imag * B[s, c].imag
    return acc


@njit(cache=True, inline="always")
def _re_dot_vector(A, r, v, nb):
    """Re(Σ_c conj(A[r, c]) v[c])."""
    acc = 0.0
    for c in range(nb):
        acc += A[r, c].real * v[c].real + A[r, c].imag * v[c].imag
    return acc


@njit(cache=True)
def exact_mass_bias_into(ref, scratch, Q, Qd, M, h, with_bias):
    """M(Q) into ``M`` and, ``with_bias``, h = C(Q, Q̇) Q̇ into ``h`` (``ref``,
    ``scratch``: `ModelData.exact`, `Workspace.exact`)."""
    e, x = unpack_exact(ref), unpack_exact_workspace(ref, scratch)
    n1 = e.n1
    n = _fill(e, Q, Qd, x, False)
    for i in range(n):
        h[i] = 0.0
        for j in range(n):
            M[i, j] = 0.0
    _products(e, x, False)
    nb1, nb2 = x.A1.shape[1], x.A2.shape[1]
    for r in range(1 + n1):
        i = 0 if r == 0 else 1 + r
        if with_bias:  # h = Re(conj(A) G v) = Re(conj(G A) v), G real symmetric
            h[i] += _re_dot_vector(x.GA1, r, x.v1, nb1)
        for s in range(r, 1 + n1):
            j = 0 if s == 0 else 1 + s
            M[i, j] += _re_dot(x.A1, r, x.GA1, s, nb1)
    # Link 2.  Rows i, j of θ1, θ2, q_1* are da (i a) + t e_0 with G (i a) = y (row θ2)
    # and G e_0 = g0: their products are da_i da_j Re(aᴴ y) + da_i Re(t_j aᴴ g0)
    # + da_j Re(conj(t_i) y_0) + G_00 Re(conj(t_i) t_j), from four sums.
    G2, A2, GA2, a, y = e.G2, x.A2, x.GA2, x.a2, x.GA2[1]
    Z, ag0, vy, vg0 = 0.0, 0j, 0.0, 0j
    for c in range(nb2):
        Z += a[c].real * y[c].real + a[c].imag * y[c].imag
        ag0 += a[c].conjugate() * G2[c, 0]
        vy += y[c].real * x.v2[c].real + y[c].imag * x.v2[c].imag
        vg0 += G2[c, 0] * x.v2[c]
    big = 2 + n1
    for i in range(big):
        da_i, t_i = x.ax[2, i], A2[i, 0].conjugate()
        if with_bias:
            h[i] += da_i * vy + (t_i * vg0).real
        for j in range(i, big):
            da_j, t_j = x.ax[2, j], A2[j, 0]
            M[i, j] += da_i * da_j * Z + da_i * (t_j * ag0).real + da_j * (t_i * y[0]).real \
                + G2[0, 0] * (t_i * t_j).real
        for j in range(big, n):  # rows q_2*: da_i Re(aᴴ G A_j) + Re(conj(t_i) (G A_j)_0)
            M[i, j] += da_i * _re_dot_vector(GA2, j, a, nb2) + (t_i * GA2[j, 0]).real
    for i in range(big, n):
        for j in range(i, n):
            M[i, j] += _re_dot(A2, i, GA2, j, nb2)
        if with_bias:
            h[i] += _re_dot_vector(GA2, i, x.v2, nb2)
    for r in range(4):
        J = e.inertia[r]
        for i in range(n):
            a = J * x.ax[r, i]
            if a != 0.0:
                if with_bias:
                    h[i] += a * x.vp[r]
                for j in range(i, n):
                    M[i, j] += a * x.ax[r, j]
    for i in range(n):
        for j in range(i):
            M[i, j] = M[j, i]


@njit(cache=True)
def exact_coriolis_matrix_into(ref, scratch, Q, Qd, C):
    """The Christoffel-form C(Q, Q̇) into ``C`` (n, n)."""
    e, x = unpack_exact(ref), unpack_exact_workspace(ref, scratch)
    n1 = e.n1
    n = _fill(e, Q, Qd, x, True)
    _products(e, x, True)
    nb1, nb2 = x.A1.shape[1], x.A2.shape[1]
    C[:, :] = 0.0
    for r in range(1 + n1):
        i = 0 if r == 0 else 1 + r
        for s in range(1 + n1):
            j = 0 if s == 0 else 1 + s
            C[i, j] += _re_dot(x.GA1, r, x.Ad1, s, nb1)
    for i in range(n):
        for j in range(n):
            C[i, j] += _re_dot(x.GA2, i, x.Ad2, j, nb2)
    for r in range(4):
        for i in range(n):
            a = e.inertia[r] * x.ax[r, i]
            for j in range(n):
                C[i, j] += a * x.axd[r, j]


@njit(cache=True)
def exact_elastic_into(ref, Q, Qd, f, with_damping):
    """Add the exact bending forces beyond K Q (and, ``with_damping``, beyond D Q̇) to
    ``f``: ∂/∂q of ½ EI ∫ (κ² − w''²) and d ∫ (κ̇ ∂κ/∂q − ẇ'' φ'')."""
    e = unpack_exact(ref)
    for link in range(2):
        dphi = e.dphi1 if link == 0 else e.dphi2
        ddphi = e.ddphi1 if link == 0 else e.ddphi2
        w = e.w1 if link == 0 else e.w2
        c = 2 if link == 0 else 2 + e.n1
        EI, damping = e.EI[link], e.damping[link]
        for h in range(e.N):
            p, pd = _slope(dphi, Q, Qd, c, h)
            pp, ppd = _slope(ddphi, Q, Qd, c, h)
            u = 1.0 / (1.0 + p * p)
            along_dd = EI * pp * (u * u - 1.0)  # coefficient of φ'' (elastic)
            along_d = -2.0 * EI * pp * pp * p * u * u * u  # coefficient of φ'
            if with_damping:
                dk_dp = -2.0 * p * pp * u * u  # ∂κ/∂p; ∂κ/∂p' = u
                kd = ppd * u + dk_dp * pd  # κ̇
                along_dd += damping * (kd * u - ppd)
                along_d += damping * kd * dk_dp
            for k in range(dphi.shape[0]):
                f[c + k] += w[h] * (along_dd * ddphi[k, h] + along_d * dphi[k, h])


@njit(cache=True, inline="always")
def _link_end(dphi, w, phi_tip, L, Q, c):
    """ρ(L) of a link, in its root frame."""
    z = L + 0j
    for k in range(phi_tip.shape[0]):
        z += 1j * phi_tip[k] * Q[c + k]
    for h in range(w.shape[0]):
        p, _ = _slope(dphi, Q, Q, c, h)
        z += w[h] * ((1.0 + 1j * p) / np.sqrt(1.0 + p * p) - 1.0 - 1j * p)
    return z


@njit(cache=True)
def exact_tips_into(ref, Q, out):
    """``out`` = [x1, y1, x2, y2, v1, v2]: the link-1 tip and the payload (base frame)
    and each link's tip displacement across its root frame (its transverse position)."""
    e = unpack_exact(ref)
    n1 = e.n1
    r1 = _link_end(e.dphi1, e.w1, e.phi1_tip, e.L1, Q, 2)
    r2 = _link_end(e.dphi2, e.w2, e.phi2_tip, e.L2, Q, 2 + n1)
    p1e = 0.0
    for k in range(n1):
        p1e += e.dphi1_tip[k] * Q[2 + k]
    alpha = Q[0] + Q[1] + np.arctan(p1e)
    z1 = (np.cos(Q[0]) + 1j * np.sin(Q[0])) * r1
    z2 = z1 + (np.cos(alpha) + 1j * np.sin(alpha)) * r2
    out[0], out[1], out[2], out[3] = z1.real, z1.imag, z2.real, z2.imag
    out[4], out[5] = r1.imag, r2.imag


@njit(cache=True)
def exact_tip_jacobian_into(ref, scratch, Q, J):
    """∂(payload position)/∂Q into ``J`` (2, n): link 2's rows at s = L2, b(L2) =
    [1, L2, φ_2(L2), w_h], turned into the base frame."""
    e, x = unpack_exact(ref), unpack_exact_workspace(ref, scratch)
    n1, n2 = e.n1, e.n2
    n = _fill(e, Q, Q, x, False)
    p1e = 0.0
    for k in range(n1):
        p1e += e.dphi1_tip[k] * Q[2 + k]
    alpha = Q[0] + Q[1] + np.arctan(p1e)
    ea = np.cos(alpha) + 1j * np.sin(alpha)
    s0 = 2 + n2
    for j in range(n):
        z = x.A2[j, 0] + x.A2[j, 1] * e.L2
        for k in range(n2):
            z += x.A2[j, 2 + k] * e.phi2_tip[k]
        for h in range(e.N):
            z += x.A2[j, s0 + h] * e.w2[h]
        z *= ea
        J[0, j] = z.real
        J[1, j] = z.imag
