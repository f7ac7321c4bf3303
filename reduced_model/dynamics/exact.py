"""Exact inextensible kinematics of an N-link arm, compiled: M(Q), h = C(Q, Q̇) Q̇ with
gravity, the Christoffel C(Q, Q̇), the exact bending forces, the tips and the payload's
Jacobian (the set-up of each link: `reduced_model.shapes.InextensibleLink`; the
derivation: the docs' theory page *Exact inextensible kinematics*).

The same formulation as the paper's model (`reduced_model.dynamics.linear`), on a
larger basis: in each link's root frame a point at arc length s is

    ρ(s) = s + i w(s) + Σ_h g_h r_h(s),   g_h = g(p(s_h)),  p = w',

a combination of the fixed functions b = [1, s, φ_k, r_h] with coefficients a(Q).  A
link's tip slope turns the next link's root frame by β = atan p(L) (not p(L)); the stator
there turns with it, the next hub by θ + β.  Velocity Jacobians are again combinations of
b (rows of A), so with the constant Gram matrices G of b

    M = Σ_links Re(conj(A) G Aᵀ) + Σ_rotors J a aᵀ,
    C = Σ_links Re(conj(A) G Ȧᵀ) + Σ_rotors J a ȧᵀ,    h = C Q̇,

where Ȧ is the time derivative of A (in the rotating frame, the frame's turning
included) and a the rotors' angular-velocity rows.  Positions are integrable, so C is the
Christoffel matrix (Ṁ − 2C skew) and the model conserves its energy without damping.

A link's rows: the coordinates upstream of it give da_j (i a) + t_j e_0 (t_j the previous
link's tip row turned into this frame, da_j this frame's angular row), its own modes
∂a/∂q_k.  Elastic forces: the bending energy ½ EI ∫ κ² of the exact curvature
κ = p'/(1 + p²), as the linear ½ qᵀ K q plus a correction of fourth order in q, and the
Kelvin–Voigt damping d ∫ κ̇ ∂κ/∂q as D q̇ plus its correction; both by the nodes' Gauss
quadrature.  The kernels take the model and its workspace packed, not inlined: a caller
compiles a call, not the kinematics.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .exact_rows import (fill_link, fill_root_link, gram_rows, gravity_rows, re_dot,
                         re_dot_vector, slope, start_rotors, tip_rows, tip_turn)
from .layout import link_data, unpack_model, unpack_workspace
from .linear import row_of

__all__ = ["exact_mass_bias", "exact_coriolis", "exact_elastic", "exact_tips",
           "exact_tip_jacobian"]


@njit(cache=True)
def exact_mass_bias(ints, reals, wc, wr, Q, Qd, M, h, with_bias):
    """M(Q) into ``M`` and, ``with_bias``, h = C(Q, Q̇) Q̇ + ∂V_gravity/∂Q into ``h``."""
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N, n = d.links, d.n
    gravity = with_bias and (d.gx != 0.0 or d.gy != 0.0)
    for i in range(n):
        h[i] = 0.0
        for j in range(n):
            M[i, j] = 0.0
    start_rotors(ws, n)
    ld = link_data(d, 0)
    m, nb = fill_root_link(ld, Q, Qd, ws, False)
    gram_rows(ld.G, ws.A, ws.GA, 0, m, nb)
    for r in range(m):
        i = row_of(0, N, r)
        if with_bias:  # h = Re(conj(A) G v) = Re(conj(G A) v), G real symmetric
            h[i] += re_dot_vector(ws.GA, r, ws.v, nb)
        for s in range(r, m):
            M[i, row_of(0, N, s)] += re_dot(ws.A, r, ws.GA, s, nb)
    g_hat = 0j
    if gravity:
        g_hat = (np.cos(Q[0]) - 1j * np.sin(Q[0])) * (d.gx + 1j * d.gy)
        gravity_rows(ld.G, ws, 0, N, m, nb, g_hat, h, ld.moment, False)
    alphad = Qd[0]
    alpha_vp = 0.0
    for link in range(1, N):
        u = tip_rows(ld, link > 1, m, ws, False)
        pe, b, ped, vp = tip_turn(ld, link - 1, Q, Qd, ws)
        gamma = Q[link] + np.arctan(pe)
        eg = np.cos(gamma) - 1j * np.sin(gamma)
        alphad = alphad + Qd[link] + b * ped
        alpha_vp = alpha_vp + vp
        ld = link_data(d, link)
        m, up, nb = fill_link(link, N, ld, Q, Qd, ws, False, eg, alphad, alpha_vp, u)
        G, A, GA, a = ld.G, ws.A, ws.GA, ws.a
        gram_rows(G, A, GA, link, link + 1, nb)
        gram_rows(G, A, GA, up, m, nb)
        # Rows i, j upstream are da (i a) + t e_0 with G (i a) = y (the own joint's row)
        # and G e_0 = g0: their products are da_i da_j Re(aᴴ y) + da_i Re(t_j aᴴ g0)
        # + da_j Re(conj(t_i) y_0) + G_00 Re(conj(t_i) t_j), from four sums.
        hub = ws.ax[2 * link]
        y = GA[link]
        Z, ag0, vy, vg0 = 0.0, 0j, 0.0, 0j
        for c in range(nb):
            Z += a[c].real * y[c].real + a[c].imag * y[c].imag
            ag0 += a[c].conjugate() * G[c, 0]
            vy += y[c].real * ws.v[c].real + y[c].imag * ws.v[c].imag
            vg0 += G[c, 0] * ws.v[c]
        for r in range(up):
            i = row_of(link, N, r)
            da_i, t_i = hub[i], A[r, 0].conjugate()
            if with_bias:
                h[i] += da_i * vy + (t_i * vg0).real
            for s in range(r, up):
                j = row_of(link, N, s)
                da_j, t_j = hub[j], A[s, 0]
                M[i, j] += da_i * da_j * Z + da_i * (t_j * ag0).real \
                    + da_j * (t_i * y[0]).real + G[0, 0] * (t_i * t_j).real
            for s in range(up, m):  # own rows: da_i Re(aᴴ G A_j) + Re(conj(t_i) (G A_j)_0)
                M[i, row_of(link, N, s)] += da_i * re_dot_vector(GA, s, a, nb) \
                    + (t_i * GA[s, 0]).real
        for r in range(up, m):
            i = row_of(link, N, r)
            for s in range(r, m):
                M[i, row_of(link, N, s)] += re_dot(A, r, GA, s, nb)
            if with_bias:
                h[i] += re_dot_vector(GA, r, ws.v, nb)
        if gravity:
            g_hat = eg * g_hat
            gravity_rows(G, ws, link, N, m, nb, g_hat, h, ld.moment, True)
    tip_turn(ld, N - 1, Q, Qd, ws)
    for r in range(2 * N):
        J = link_data(d, r // 2).J_hub if r % 2 == 0 else link_data(d, r // 2).J_tip
        for i in range(n):
            a_ = J * ws.ax[r, i]
            if a_ != 0.0:
                if with_bias:
                    h[i] += a_ * ws.vp[r]
                for j in range(i, n):
                    M[i, j] += a_ * ws.ax[r, j]
    for i in range(n):
        for j in range(i):
            M[i, j] = M[j, i]


@njit(cache=True)
def exact_coriolis(ints, reals, wc, wr, Q, Qd, C):
    """The Christoffel-form C(Q, Q̇) into ``C`` (n, n)."""
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N, n = d.links, d.n
    C[:, :] = 0.0
    start_rotors(ws, n)
    ld = link_data(d, 0)
    m, nb = fill_root_link(ld, Q, Qd, ws, True)
    gram_rows(ld.G, ws.A, ws.GA, 0, m, nb)
    for r in range(m):
        i = row_of(0, N, r)
        for s in range(m):
            C[i, row_of(0, N, s)] += re_dot(ws.GA, r, ws.Ad, s, nb)
    alphad = Qd[0]
    alpha_vp = 0.0
    for link in range(1, N):
        u = tip_rows(ld, link > 1, m, ws, True)
        pe, b, ped, vp = tip_turn(ld, link - 1, Q, Qd, ws)
        gamma = Q[link] + np.arctan(pe)
        eg = np.cos(gamma) - 1j * np.sin(gamma)
        alphad = alphad + Qd[link] + b * ped
        alpha_vp = alpha_vp + vp
        ld = link_data(d, link)
        m, up, nb = fill_link(link, N, ld, Q, Qd, ws, True, eg, alphad, alpha_vp, u)
        G, A, GA = ld.G, ws.A, ws.GA
        hub = ws.ax[2 * link]
        gram_rows(G, A, GA, link, link + 1, nb)
        gram_rows(G, A, GA, up, m, nb)
        for r in range(up):  # upstream rows: da (G i a) + t (G e_0)
            if r != link:
                da, root = hub[row_of(link, N, r)], A[r, 0]
                for b_ in range(nb):
                    GA[r, b_] = da * GA[link, b_] + root * G[b_, 0]
        for r in range(m):
            i = row_of(link, N, r)
            for s in range(m):
                C[i, row_of(link, N, s)] += re_dot(GA, r, ws.Ad, s, nb)
    tip_turn(ld, N - 1, Q, Qd, ws)
    for r in range(2 * N):
        J = link_data(d, r // 2).J_hub if r % 2 == 0 else link_data(d, r // 2).J_tip
        for i in range(n):
            a_ = J * ws.ax[r, i]
            for j in range(n):
                C[i, j] += a_ * ws.axd[r, j]


@njit(cache=True, forceinline=True)
def exact_elastic(ints, reals, Q, Qd, f, with_damping):
    """Add the exact bending forces beyond K Q (and, ``with_damping``, beyond D Q̇) to
    ``f``: ∂/∂q of ½ EI ∫ (κ² − w''²) and d ∫ (κ̇ ∂κ/∂q − ẇ'' φ'')."""
    d = unpack_model(ints, reals)
    for link in range(d.links):
        ld = link_data(d, link)
        c, EI, damping = ld.c, ld.EI, ld.damping
        for h in range(ld.nodes):
            p, pd = slope(ld.dphi, Q, Qd, c, h)
            pp, ppd = slope(ld.ddphi, Q, Qd, c, h)
            u = 1.0 / (1.0 + p * p)
            along_dd = EI * pp * (u * u - 1.0)  # coefficient of φ'' (elastic)
            along_d = -2.0 * EI * pp * pp * p * u * u * u  # coefficient of φ'
            if with_damping:
                dk_dp = -2.0 * p * pp * u * u  # ∂κ/∂p; ∂κ/∂p' = u
                kd = ppd * u + dk_dp * pd  # κ̇
                along_dd += damping * (kd * u - ppd)
                along_d += damping * kd * dk_dp
            for k in range(ld.n):
                f[c + k] += ld.w[h] * (along_dd * ld.ddphi[k, h] + along_d * ld.dphi[k, h])


@njit(cache=True, forceinline=True)
def _link_end(ld, Q):
    """ρ(L) of a link, in its root frame."""
    z = ld.L + 0j
    for k in range(ld.n):
        z += 1j * ld.phi_tip[k] * Q[ld.c + k]
    for h in range(ld.nodes):
        p, _ = slope(ld.dphi, Q, Q, ld.c, h)
        z += ld.w[h] * ((1.0 + 1j * p) / np.sqrt(1.0 + p * p) - 1.0 - 1j * p)
    return z


@njit(cache=True)
def exact_tips(ints, reals, Q, out):
    """``out`` = [x, y of each link's tip (base frame)…, each tip's displacement across
    its root frame (its transverse position)…] (3N values)."""
    d = unpack_model(ints, reals)
    N = d.links
    z = 0j
    alpha = 0.0
    for link in range(N):
        ld = link_data(d, link)
        r = _link_end(ld, Q)
        if link == 0:
            alpha = Q[0]
        z = z + (np.cos(alpha) + 1j * np.sin(alpha)) * r
        out[2 * link] = z.real
        out[2 * link + 1] = z.imag
        out[2 * N + link] = r.imag
        pe = 0.0
        for k in range(ld.n):
            pe += ld.dphi_tip[k] * Q[ld.c + k]
        if link + 1 < N:
            alpha = alpha + Q[link + 1] + np.arctan(pe)


@njit(cache=True)
def exact_tip_jacobian(ints, reals, wc, wr, Q, J):
    """∂(payload position)/∂Q into ``J`` (2, n): the last link's rows at s = L, b(L) =
    [1, L, φ(L), w_h], turned into the base frame."""
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N, n = d.links, d.n
    start_rotors(ws, n)
    ld = link_data(d, 0)
    m, nb = fill_root_link(ld, Q, Q, ws, False)
    alpha = Q[0]
    rows_root = True
    alphad = Q[0]
    alpha_vp = 0.0
    for link in range(1, N):
        u = tip_rows(ld, link > 1, m, ws, False)
        pe, b, ped, vp = tip_turn(ld, link - 1, Q, Q, ws)
        gamma = Q[link] + np.arctan(pe)
        eg = np.cos(gamma) - 1j * np.sin(gamma)
        alpha = alpha + Q[link] + np.arctan(pe)
        alphad = alphad + Q[link] + b * ped
        alpha_vp = alpha_vp + vp
        ld = link_data(d, link)
        m, up, nb = fill_link(link, N, ld, Q, Q, ws, False, eg, alphad, alpha_vp, u)
        rows_root = False
    ea = np.cos(alpha) + 1j * np.sin(alpha)
    J[:, :] = 0.0
    o = 0 if rows_root else 1
    for r in range(m):
        z = ws.A[r, 0] if not rows_root else 0j
        z += ws.A[r, o] * ld.L
        for k in range(ld.n):
            z += ws.A[r, o + 1 + k] * ld.phi_tip[k]
        for h in range(ld.nodes):
            z += ws.A[r, o + 1 + ld.n + h] * ld.w[h]
        z *= ea
        j = row_of(N - 1, N, r)
        J[0, j] = z.real
        J[1, j] = z.imag
