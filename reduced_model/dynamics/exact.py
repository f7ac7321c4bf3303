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

Their cost is mostly the Gram products G A, so M and h apply G to each link's own rows
only (`_link_terms`); the entries are formed in real arithmetic (numba multiplies a
float by a complex as two complex numbers, and LLVM may not drop the products with a
zero imaginary part); and LLVM may fuse a multiply and an add (``fastmath={"contract"}``:
one rounding instead of two, nothing else relaxed), so on a CPU without FMA the results
differ in their last bits.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .exact_rows import (fill_link, fill_root_link, gram_rows, mode_rows, moment_dot,
                         nodes_into, position_row, re_dot, start_rotors,
                         tip_rows, tip_turn, tip_value, velocity_products)
from .layout import link_data, unpack_model, unpack_workspace
from .linear import row_of, upstream_rows
from .linalg import vector_view

__all__ = ["exact_mass_bias", "exact_coriolis", "exact_elastic", "exact_tips",
           "exact_tip_jacobian"]


@njit(cache=True, forceinline=True, fastmath={"contract"})
def _link_terms(link, N, ld, Q, Qd, M, h, ws, gravity, alphad, alpha_vp, root,
                g_hat):
    """Add link ``link``'s part of M and h (module docstring), its hub's and tip's
    rotors' J a aᵀ included, from its own rows only: ζ = i a into ws.A[0] and its modes'
    rows ∂a/∂q_k into ws.A[1 + k]; then turn the root rows ws.c_hat into its tip rows
    and return its tip's velocity-product acceleration v·b(L).

    Every upstream row is da_j ζ + t_j e_0 (t_j = ws.c_hat[j], the root's velocity
    Jacobian; 0 on link 0, whose basis has no 1), so with y = G ζ its products are
    da_i da_j Re(ζᴴ y) + da_i Re(t_j conj(y_0)) + da_j Re(conj(t_i) y_0) + G_00 Re(conj(t_i) t_j)
    and, with a mode's row, da_i Re(ζᴴ G A_k) + Re(conj(t_i) (G A_k)_0): G is applied to
    the 1 + modes rows of the link, not to all of its upstream rows.  The hub's rotor row
    is da on the upstream coordinates (ws.ax, `tip_turn`), the tip's the same plus the
    tip slope's row on the link's modes."""
    o = 0 if link == 0 else 1  # column of s
    n_own, c = ld.n, ld.c
    f = o + 1
    nb = f + n_own + ld.nodes
    G, A, GA, t, v = ld.G, ws.A, ws.GA, ws.c_hat, ws.v
    hub, tip_row = ws.ax[2 * link], ws.ax[2 * link + 1]
    J_tip = ld.J_tip
    up = upstream_rows(link, N, c)
    nodes_into(ld.dphi, Q, Qd, c, ws)
    position_row(A, 0, o, ld, Q, ws)
    mode_rows(A, 1, o, ld, ws)
    gram_rows(G, A, GA, 0, 1 + n_own, nb, o)
    velocity_products(o, ld, Q, Qd, ws, alphad, alpha_vp, root)
    # Re(ζᴴ y), conj(ζ)·G[:, 0] (= conj(y_0) for symmetric G), Re(yᴴ v) and (G v)_0
    Z = ag0r = ag0i = vy = vg0r = vg0i = 0.0
    for b in range(nb):
        ar, ai, yr, yi, g = A[0, b].real, A[0, b].imag, GA[0, b].real, GA[0, b].imag, G[b, 0]
        Z += ar * yr + ai * yi
        ag0r += ar * g
        ag0i -= ai * g
        vy += yr * v[b].real + yi * v[b].imag
        vg0r += g * v[b].real
        vg0i += g * v[b].imag
    y0r, y0i, G00 = GA[0, 0].real, GA[0, 0].imag, G[0, 0]
    Z += ld.J_hub + J_tip  # both rotors' rows are da on the upstream coordinates
    vy += ld.J_hub * ws.vp[2 * link] + J_tip * ws.vp[2 * link + 1]
    for r in range(up):
        i = row_of(link, N, r)
        da_i, tr_i, ti_i = hub[i], t[i].real, t[i].imag
        h[i] += da_i * vy + (tr_i * vg0r + ti_i * vg0i)
        e_i = tr_i * y0r + ti_i * y0i  # Re(conj(t_i) y_0)
        for s in range(r, up):
            j = row_of(link, N, s)
            da_j, tr_j, ti_j = hub[j], t[j].real, t[j].imag
            M[i, j] += da_i * da_j * Z + da_i * (tr_j * ag0r - ti_j * ag0i) + da_j * e_i \
                + G00 * (tr_i * tr_j + ti_i * ti_j)
    for k in range(n_own):
        a_k = J_tip * tip_row[c + k]  # J × the tip rotor's row on the mode
        zk = re_dot(GA[1 + k], A[0], o, nb) + a_k  # Re(ζᴴ G A_k) + the tip rotor's
        yr, yi = GA[1 + k, 0].real, GA[1 + k, 0].imag  # (G A_k)_0
        for r in range(up):
            i = row_of(link, N, r)
            M[i, c + k] += hub[i] * zk + (t[i].real * yr + t[i].imag * yi)
        for l in range(k, n_own):
            M[c + k, c + l] += re_dot(A[1 + k], GA[1 + l], f + k, nb) + a_k * tip_row[c + l]
        h[c + k] += re_dot(GA[1 + k], v, 0, nb) + a_k * ws.vp[2 * link + 1]
    if gravity:  # ∂V/∂Q_j = −Re(conj(ĝ) A_j·μ), μ the first moments
        gc = g_hat.conjugate()
        zeta_mu = moment_dot(A, 0, o, nb, G, ld.moment, o == 1)
        for r in range(up):
            i = row_of(link, N, r)
            mu_i = hub[i] * zeta_mu + t[i] * G00  # t = 0 on link 0
            h[i] -= (gc * mu_i).real
        for k in range(n_own):
            h[c + k] -= (gc * moment_dot(A, 1 + k, f + k, nb, G, ld.moment, o == 1)).real
    if link + 1 == N:
        return 0j
    tip = tip_value(A[0], o, ld)  # the tip rows: da_j ζ(L) + t_j, and the modes'
    for r in range(up):
        j = row_of(link, N, r)
        t[j] = complex(t[j].real + hub[j] * tip.real, t[j].imag + hub[j] * tip.imag)
    for k in range(n_own):
        t[c + k] = tip_value(A[1 + k], o, ld)
    return tip_value(v, o, ld)


@njit(cache=True, fastmath={"contract"})
def exact_mass_bias(ints, reals, wc, wr, Q, Qd, M, h):
    """M(Q) into ``M`` and h = C(Q, Q̇) Q̇ + ∂V_gravity/∂Q into ``h``:
    link by link (`_link_terms`)."""
    # Borrowed (`reduced_model.dynamics.linalg`): the workspace then holds no reference
    # that each helper it is passed to would count up and down, atomically.
    wc, wr = vector_view(wc, 0, wc.shape[0]), vector_view(wr, 0, wr.shape[0])
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N, n = d.links, d.n
    gravity = d.gx != 0.0 or d.gy != 0.0
    for i in range(n):
        h[i] = 0.0
        ws.c_hat[i] = 0j
        for j in range(n):
            M[i, j] = 0.0
    start_rotors(ws, n)
    g_hat = 0j  # gravity in the current link's frame
    if gravity:
        g_hat = (np.cos(Q[0]) - 1j * np.sin(Q[0])) * (d.gx + 1j * d.gy)
    alphad, alpha_vp, root = Qd[0], 0.0, 0j
    pe = b = ped = vp = 0.0  # the previous tip's slope, β', ṗ and β̈'s velocity product
    for link in range(N):
        ld = link_data(d, link)
        if link > 0:  # the previous tip turns this link's frame by its joint and atan p(L)
            gamma = Q[link] + np.arctan(pe)
            eg = np.cos(gamma) - 1j * np.sin(gamma)
            alphad = alphad + Qd[link] + b * ped
            alpha_vp = alpha_vp + vp
            root = eg * root
            g_hat = eg * g_hat
            for r in range(upstream_rows(link, N, ld.c)):
                j = row_of(link, N, r)
                ws.c_hat[j] = eg * ws.c_hat[j]
        pe, b, ped, vp = tip_turn(ld, link, Q, Qd, ws, False)
        root = _link_terms(link, N, ld, Q, Qd, M, h, ws, gravity, alphad,
                           alpha_vp, root, g_hat)
    for i in range(n):
        for j in range(i):
            M[i, j] = M[j, i]


@njit(cache=True, fastmath={"contract"})
def exact_coriolis(ints, reals, wc, wr, Q, Qd, C):
    """The Christoffel-form C(Q, Q̇) into ``C`` (n, n)."""
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N, n = d.links, d.n
    C[:, :] = 0.0
    start_rotors(ws, n)
    ld = link_data(d, 0)
    m, nb = fill_root_link(ld, Q, Qd, ws, True)
    gram_rows(ld.G, ws.A, ws.GA, 0, m, nb, 0)
    for r in range(m):
        i = row_of(0, N, r)
        for s in range(m):
            C[i, row_of(0, N, s)] += re_dot(ws.GA[r], ws.Ad[s], 0, nb)
    alphad = Qd[0]
    for link in range(1, N):
        tip_rows(ld, link > 1, m, ws, True)
        pe, b, ped, _ = tip_turn(ld, link - 1, Q, Qd, ws, True)
        gamma = Q[link] + np.arctan(pe)
        eg = np.cos(gamma) - 1j * np.sin(gamma)
        alphad = alphad + Qd[link] + b * ped
        ld = link_data(d, link)
        m, up, nb = fill_link(link, N, ld, Q, Qd, ws, True, eg, alphad)
        G, A, GA = ld.G, ws.A, ws.GA
        hub = ws.ax[2 * link]
        gram_rows(G, A, GA, link, link + 1, nb, 0)
        gram_rows(G, A, GA, up, m, nb, 0)
        for r in range(up):  # upstream rows: da (G i a) + t (G e_0)
            if r != link:
                da, root = hub[row_of(link, N, r)], A[r, 0]
                for b_ in range(nb):
                    GA[r, b_] = da * GA[link, b_] + root * G[b_, 0]
        for r in range(m):
            i = row_of(link, N, r)
            for s in range(m):
                C[i, row_of(link, N, s)] += re_dot(GA[r], ws.Ad[s], 0, nb)
    tip_turn(ld, N - 1, Q, Qd, ws, True)
    for r in range(2 * N):
        J = link_data(d, r // 2).J_hub if r % 2 == 0 else link_data(d, r // 2).J_tip
        for i in range(n):
            a_ = J * ws.ax[r, i]
            for j in range(n):
                C[i, j] += a_ * ws.axd[r, j]


@njit(cache=True, forceinline=True, fastmath={"contract"})
def exact_elastic(ints, reals, Q, Qd, f, with_damping):
    """Add the exact bending forces beyond K Q (and, ``with_damping``, beyond D Q̇) to
    ``f``: ∂/∂q of ½ EI ∫ (κ² − w''²) and d ∫ (κ̇ ∂κ/∂q − ẇ'' φ'')."""
    d = unpack_model(ints, reals)
    for link in range(d.links):
        ld = link_data(d, link)
        c, EI, damping = ld.c, ld.EI, ld.damping
        for h in range(ld.nodes):
            p = pd = pp = ppd = 0.0  # p, ṗ, p', ṗ' at the node, in one pass over the modes
            for j in range(ld.n):
                q, qd, slope_jh, curv_jh = Q[c + j], Qd[c + j], ld.dphi[j, h], ld.ddphi[j, h]
                p += slope_jh * q
                pd += slope_jh * qd
                pp += curv_jh * q
                ppd += curv_jh * qd
            u = 1.0 / (1.0 + p * p)
            along_dd = EI * pp * (u * u - 1.0)  # coefficient of φ'' (elastic)
            along_d = -2.0 * EI * pp * pp * p * u * u * u  # coefficient of φ'
            if with_damping:
                dk_dp = -2.0 * p * pp * u * u  # ∂κ/∂p; ∂κ/∂p' = u
                kd = ppd * u + dk_dp * pd  # κ̇
                along_dd += damping * (kd * u - ppd)
                along_d += damping * kd * dk_dp
            w = ld.w[h]
            for k in range(ld.n):
                f[c + k] += w * (along_dd * ld.ddphi[k, h] + along_d * ld.dphi[k, h])


@njit(cache=True, forceinline=True, fastmath={"contract"})
def _link_end(ld, Q):
    """ρ(L) = L + i w(L) + Σ_h w_h g(p_h) of a link, in its root frame (real arithmetic:
    g = (1 + i p)/√(1 + p²) − 1 − i p)."""
    x, y = ld.L, 0.0
    for k in range(ld.n):
        y += ld.phi_tip[k] * Q[ld.c + k]
    for h in range(ld.nodes):
        p = 0.0
        for k in range(ld.n):
            p += ld.dphi[k, h] * Q[ld.c + k]
        c = 1.0 / np.sqrt(1.0 + p * p)
        x += ld.w[h] * (c - 1.0)
        y += ld.w[h] * (p * c - p)
    return complex(x, y)


@njit(cache=True, fastmath={"contract"})
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


@njit(cache=True, fastmath={"contract"})
def exact_tip_jacobian(ints, reals, wc, wr, Q, J):
    """∂(payload position)/∂Q into ``J`` (2, n): the last link's rows at s = L, b(L) =
    [1, L, φ(L), w_h], turned into the base frame."""
    d, ws = unpack_model(ints, reals), unpack_workspace(ints, wc, wr)
    N, n = d.links, d.n
    start_rotors(ws, n)
    ld = link_data(d, 0)
    m, nb = fill_root_link(ld, Q, Q, ws, False)
    alpha = Q[0]
    for link in range(1, N):
        tip_rows(ld, link > 1, m, ws, False)
        pe, _, _, _ = tip_turn(ld, link - 1, Q, Q, ws, False)
        gamma = Q[link] + np.arctan(pe)
        eg = np.cos(gamma) - 1j * np.sin(gamma)
        alpha = alpha + Q[link] + np.arctan(pe)
        ld = link_data(d, link)
        m, up, nb = fill_link(link, N, ld, Q, Q, ws, False, eg, 0.0)
    ea = np.cos(alpha) + 1j * np.sin(alpha)
    J[:, :] = 0.0
    o = 0 if N == 1 else 1  # the last link's basis: link 0's has no 1
    for r in range(m):
        z = tip_value(ws.A[r], o, ld) * ea
        j = row_of(N - 1, N, r)
        J[0, j] = z.real
        J[1, j] = z.imag
