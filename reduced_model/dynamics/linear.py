"""The paper's (linear) kinematics of an N-link arm, compiled: M(Q), h = C(Q, Q̇) Q̇ with
gravity, the Christoffel C(Q, Q̇), and the tips (De Luca & Siciliano's closed form,
organised for speed).

Every material point of link l is written in complex planar notation in its root frame,

    z_l(s) = z_l(0) + e^{iα_l} (s + i w_l(s)),    α_l = θ_1 + … + θ_l + Σ_{k<l} w_k'(L_k),

a combination of the basis b(s) = [1, s, φ_l1(s), …] (link 1's root never moves: its
basis has no 1).  Its velocity Jacobian ∂z_l/∂Q_j is again a combination of b, with
coefficients A_l[j, β], so with the constant Gram matrices G_l = ∫ρ b bᵀ + m_tip b(L) b(L)ᵀ

    M(Q)   = Σ_l Re(conj(A_l) G_l A_lᵀ) + Σ_rotors J a aᵀ,
    C(Q,Q̇) = Σ_l Re(conj(A_l) G_l Ȧ_lᵀ),

and, in a uniform gravity field g, ∂V/∂Q_j = −Σ_l Re(conj(g) e^{iα_l} A_l[j] G_l[:, 0]).
Because z is a true position, this C is the Christoffel matrix: Ṁ − 2C is skew.  Rotors
(hubs, stators, payload) turn by angles linear in Q: J a aᵀ is constant (``M_rotors``).

Two evaluations of the same formulas.  `linear_coriolis` forms the dense A, Ȧ (base
frame) and C (the controller needs the matrix).  `linear_mass_bias` needs only M and
h = C Q̇ (+ gravity), and writes the structure of A out in each link's frame: link l's
rows are c_j e_0 + a_j ζ for the coordinates upstream of it (c_j the root's velocity
Jacobian, a_j the frame's angular one, ζ = [0, i, −q_l]) and i e_k for its own modes, so
the unit phases cancel in every product: O(nb²) work per row pair.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .layout import link_data, unpack_model, unpack_workspace

__all__ = ["linear_mass_bias", "linear_coriolis", "linear_tips",
           "upstream_rows", "link_rows", "row_of"]


@njit(cache=True, forceinline=True)
def row_of(link, links, r):
    """The coordinate of local row ``r`` of link ``link``'s rows: the joints 0..link, then
    the modal coordinates of links 0..link (contiguous from ``links``)."""
    return r if r <= link else links + r - link - 1


@njit(cache=True, forceinline=True)
def upstream_rows(link, links, c):
    """How many rows move link ``link``'s frame: its joint and those before, and the modes
    of the links before it (its own modes start at coordinate ``c``)."""
    return link + 1 + c - links


@njit(cache=True, forceinline=True)
def link_rows(link, links, c, n_own):
    """Rows of link ``link``'s coefficients: `upstream_rows` and its own modes."""
    return link + 1 + c + n_own - links


@njit(cache=True, forceinline=True)
def _tip_sums(ld, Q, Qd):
    """w(L), ẇ(L), w'(L), ẇ'(L) of the link ``ld``."""
    we = 0.0
    wed = 0.0
    se = 0.0
    sed = 0.0
    for k in range(ld.n):
        we += ld.phi_tip[k] * Q[ld.c + k]
        wed += ld.phi_tip[k] * Qd[ld.c + k]
        se += ld.dphi_tip[k] * Q[ld.c + k]
        sed += ld.dphi_tip[k] * Qd[ld.c + k]
    return we, wed, se, sed


@njit(cache=True, forceinline=True)
def _gram_vector(G, v, Gv, nb):
    """Gv = G v (complex v, real symmetric G), the first ``nb`` entries."""
    for b in range(nb):
        acc = 0.0 + 0.0j
        for g in range(nb):
            acc += G[b, g] * v[g]
        Gv[b] = acc


@njit(cache=True, forceinline=True)
def linear_mass_bias(ints, reals, wc, wr, Q, Qd, M, h):
    """M(Q) into ``M`` and h = C(Q, Q̇) Q̇ + ∂V_gravity/∂Q into ``h``
    (module docstring: structured, link by link)."""
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N, n = d.links, d.n
    v, Gv, c_hat, arow = ws.v, ws.Gv, ws.c_hat, ws.arow
    gravity = d.gx != 0.0 or d.gy != 0.0
    for i in range(n):
        h[i] = 0.0
        c_hat[i] = 0.0
        arow[i] = 0.0
        for j in range(n):
            M[i, j] = d.M_rotors[i, j]

    # ---- link 0, its own frame: rows θ1 → [i, −q], q_k → i e_k; basis [s, φ*].
    prev = link_data(d, 0)
    G1, n1, c1 = prev.G, prev.n, prev.c
    th1d = Qd[0]
    M[0, 0] += G1[0, 0]
    for k in range(n1):
        M[0, c1 + k] += G1[0, 1 + k]
        for l in range(n1):
            M[c1 + k, c1 + l] += G1[1 + k, 1 + l]
            M[0, 0] += Q[c1 + k] * G1[1 + k, 1 + l] * Q[c1 + l]
    v[0] = -th1d * th1d
    for k in range(n1):
        v[1 + k] = -1j * th1d * th1d * Q[c1 + k] - 2.0 * th1d * Qd[c1 + k]
    _gram_vector(G1, v, Gv, 1 + n1)
    h[0] += Gv[0].imag
    for k in range(n1):
        h[0] -= Q[c1 + k] * Gv[1 + k].real
        h[c1 + k] += Gv[1 + k].imag
    g_hat = 0j  # gravity in the current link's frame
    if gravity:
        g_hat = (np.cos(Q[0]) - 1j * np.sin(Q[0])) * (d.gx + 1j * d.gy)
        mu = prev.moment  # ∂V/∂Q_j = −Re(conj(ĝ) A[j]·μ)
        s = 1j * mu[0]
        for k in range(n1):
            s -= Q[c1 + k] * mu[1 + k]
            h[c1 + k] -= (g_hat.conjugate() * (1j * mu[1 + k])).real
        h[0] -= (g_hat.conjugate() * s).real

    # ---- links 1…, each in its root frame: rows upstream → c_j e_0 + a_j [0, i, −q],
    # own q_k → i e_k; basis [1, s, φ*].
    alphad = th1d
    arow[0] = 1.0
    acc_root = 0j  # the root's velocity-product acceleration, in the current frame
    for link in range(1, N):
        cur = link_data(d, link)
        we, wed, se, sed = _tip_sums(prev, Q, Qd)
        gamma = Q[link] + se
        eg = np.cos(gamma) - 1j * np.sin(gamma)  # e^{-iγ}: previous frame → this frame
        up_prev = upstream_rows(link - 1, N, prev.c)
        for r in range(up_prev):  # c: the previous link's tip, in this frame
            j = row_of(link - 1, N, r)
            c_hat[j] = eg * c_hat[j] + 1j * eg * (arow[j] * (prev.L + 1j * we))
        c_hat[link] = 0.0
        for k in range(prev.n):
            c_hat[prev.c + k] = 1j * eg * prev.phi_tip[k]
            arow[prev.c + k] = prev.dphi_tip[k]
        arow[link] = 1.0
        G2, n2, c2 = cur.G, cur.n, cur.c
        g0 = 1j * G2[0, 1]  # (G ζ)_0 with ζ = [0, i, −q]
        Z = G2[1, 1]  # ζᴴ G ζ
        for k in range(n2):
            g0 -= G2[0, 2 + k] * Q[c2 + k]
            for l in range(n2):
                M[c2 + k, c2 + l] += G2[2 + k, 2 + l]
                Z += Q[c2 + k] * G2[2 + k, 2 + l] * Q[c2 + l]
        m_bar = G2[0, 0]
        up = upstream_rows(link, N, c2)
        for r in range(up):
            i = row_of(link, N, r)
            ai = arow[i]
            ci = c_hat[i]
            ri = ci.real * g0.real + ci.imag * g0.imag  # Re(conj(c_i) g0)
            for s_ in range(r, up):
                j = row_of(link, N, s_)
                aj = arow[j]
                cj = c_hat[j]
                rj = cj.real * g0.real + cj.imag * g0.imag
                M[i, j] += m_bar * (ci.real * cj.real + ci.imag * cj.imag) + aj * ri + ai * rj \
                    + ai * aj * Z
            for k in range(n2):
                M[i, c2 + k] += ci.imag * G2[0, 2 + k] + ai * G2[1, 2 + k]
        # velocity-product accelerations: the root, and the link's own
        acc_root = eg * (acc_root + (-alphad * alphad * (prev.L + 1j * we)
                                     - 2.0 * alphad * wed))
        alphad = alphad + Qd[link] + sed
        v[0] = acc_root
        v[1] = -alphad * alphad
        for k in range(n2):
            v[2 + k] = -1j * alphad * alphad * Q[c2 + k] - 2.0 * alphad * Qd[c2 + k]
        _gram_vector(G2, v, Gv, 2 + n2)
        zeta_gv = Gv[1].imag  # Re(ζᴴ G v)
        for k in range(n2):
            zeta_gv -= Q[c2 + k] * Gv[2 + k].real
            h[c2 + k] += Gv[2 + k].imag
        for r in range(up):
            i = row_of(link, N, r)
            ci = c_hat[i]
            h[i] += ci.real * Gv[0].real + ci.imag * Gv[0].imag + arow[i] * zeta_gv
        if gravity:
            g_hat = eg * g_hat
            gc = g_hat.conjugate()
            for k in range(n2):
                h[c2 + k] -= (gc * (1j * G2[2 + k, 0])).real
            for r in range(up):
                i = row_of(link, N, r)
                h[i] -= (gc * (c_hat[i] * m_bar + arow[i] * g0)).real
        prev = cur
    for i in range(n):
        for j in range(i):
            M[i, j] = M[j, i]


@njit(cache=True, forceinline=True)
def _add_gram(A, G, B, link, links, m, nb, out, gb):
    """out[row i, row j] += Re(conj(A) G Bᵀ)[i, j] over link ``link``'s ``m`` rows, for
    real symmetric G (``nb`` columns); ``gb``: complex scratch (nb,)."""
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
            out[row_of(link, links, i), row_of(link, links, j)] += s


@njit(cache=True, forceinline=True)
def linear_coriolis(ints, reals, wc, wr, Q, Qd, C):
    """The Christoffel-form C(Q, Q̇) into ``C`` (n, n): dense A and Ȧ in the base frame,
    link by link."""
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N = d.links
    C[:, :] = 0.0
    A, Ad, zr, zrd, zt, ztd = ws.A, ws.Ad, ws.zr, ws.zrd, ws.zt, ws.ztd
    E, ad, arow = ws.E, ws.alphad, ws.arow

    # ---- link 0: rows [θ1, q_0*], basis [s, φ_0*].
    prev = link_data(d, 0)
    n1, c1 = prev.n, prev.c
    th1, th1d = Q[0], Qd[0]
    alpha, alphad = th1, th1d
    E1 = np.cos(th1) + 1j * np.sin(th1)
    m, nb = 1 + n1, 1 + n1
    for i in range(m):
        for b in range(nb):
            A[i, b] = 0.0
            Ad[i, b] = 0.0
    A[0, 0] = 1j * E1
    Ad[0, 0] = -th1d * E1
    for k in range(n1):
        q, qd = Q[c1 + k], Qd[c1 + k]
        A[0, 1 + k] = -E1 * q
        Ad[0, 1 + k] = -(1j * th1d * q + qd) * E1
        A[1 + k, 1 + k] = 1j * E1
        Ad[1 + k, 1 + k] = -th1d * E1
    _add_gram(A, prev.G, Ad, 0, N, m, nb, C, ws.Gv)
    zr[0] = 0.0
    zrd[0] = 0.0
    E[0] = E1
    ad[0] = th1d
    for i in range(d.n):
        arow[i] = 0.0
    arow[0] = 1.0

    # ---- links 1…: rows upstream then own, basis [1, s, φ*].
    for link in range(1, N):
        cur = link_data(d, link)
        we, wed, se, sed = _tip_sums(prev, Q, Qd)
        alpha = alpha + Q[link] + se
        alphad = alphad + Qd[link] + sed
        Ea = np.cos(alpha) + 1j * np.sin(alpha)
        Ep = E[link - 1]
        tip = Ep * (prev.L + 1j * we)  # the previous link's tip from its root
        zt[link - 1] = zr[link - 1] + tip
        ztd[link - 1] = zrd[link - 1] + (1j * ad[link - 1] * tip + 1j * Ep * wed)
        zr[link], zrd[link] = zt[link - 1], ztd[link - 1]
        E[link], ad[link] = Ea, alphad
        for k in range(prev.n):
            arow[prev.c + k] = prev.dphi_tip[k]
        arow[link] = 1.0
        n2, c2 = cur.n, cur.c
        up = upstream_rows(link, N, c2)
        m, nb = up + n2, 2 + n2
        for i in range(m):
            for b in range(nb):
                A[i, b] = 0.0
                Ad[i, b] = 0.0
        for r in range(up):
            j = row_of(link, N, r)
            if j < link:  # joint j turns everything beyond its root about it
                A[r, 0] = 1j * (zr[link] - zr[j])
                Ad[r, 0] = 1j * (zrd[link] - zrd[j])
            elif j >= N:  # mode k of an earlier link m: its tip moves, and turns the rest
                m_ = link
                for o in range(link):
                    lo = link_data(d, o)
                    if lo.c <= j < lo.c + lo.n:
                        m_ = o
                lm = link_data(d, m_)
                k = j - lm.c
                A[r, 0] = 1j * E[m_] * lm.phi_tip[k]
                Ad[r, 0] = -ad[m_] * E[m_] * lm.phi_tip[k]
                if m_ < link - 1:
                    A[r, 0] += 1j * lm.dphi_tip[k] * (zr[link] - zt[m_])
                    Ad[r, 0] += 1j * lm.dphi_tip[k] * (zrd[link] - ztd[m_])
            aj = arow[j]
            A[r, 1] = 1j * aj * Ea
            Ad[r, 1] = -aj * alphad * Ea
            for k in range(n2):
                q, qd = Q[c2 + k], Qd[c2 + k]
                A[r, 2 + k] = -aj * Ea * q
                Ad[r, 2 + k] = -aj * (1j * alphad * q + qd) * Ea
        for k in range(n2):
            A[up + k, 2 + k] = 1j * Ea
            Ad[up + k, 2 + k] = -alphad * Ea
        _add_gram(A, cur.G, Ad, link, N, m, nb, C, ws.Gv)
        prev = cur


@njit(cache=True)
def linear_tips(ints, reals, Q, out):
    """``out`` = [x, y of each link's tip (base frame)…, each tip's deflection w_l(L_l)
    across its root frame…] (3N values)."""
    d = unpack_model(ints, reals)
    N = d.links
    x = 0.0
    y = 0.0
    alpha = 0.0
    s_prev = 0.0
    for link in range(N):
        ld = link_data(d, link)
        w = 0.0
        s = 0.0
        for k in range(ld.n):
            w += ld.phi_tip[k] * Q[ld.c + k]
            s += ld.dphi_tip[k] * Q[ld.c + k]
        alpha = Q[0] if link == 0 else alpha + Q[link] + s_prev
        ca, sa = np.cos(alpha), np.sin(alpha)
        x = x + ca * ld.L - sa * w
        y = y + sa * ld.L + ca * w
        out[2 * link] = x
        out[2 * link + 1] = y
        out[2 * N + link] = w
        s_prev = s
