"""The rows of a link's coefficients in the exact inextensible kinematics, link by link
(the kernels that sum them: `reduced_model.dynamics.exact`, whose docstring states the
formulation): a link's nodes g(p(s_h)), its rows (upstream: da_j (i a) + t_j e_0; its
own modes: ∂a/∂q_k) and their rates, its velocity-product accelerations, its tip rows
for the next link, and the rotor rows its tip slope turns.

A link's basis is [1, s, φ*, r*], link 0's [s, φ*, r*] (its root never moves): ``o``,
the column of s, is 1 or 0; the φ columns start at o + 1, the r columns at o + 1 + modes.
Every row has zeros before a known column (i a before s, a mode's row before its φ), so
the sums over a row start there."""
from __future__ import annotations

import numpy as np
from numba import njit

from .linear import row_of, upstream_rows

__all__ = ["slope", "nodes_into", "position_row", "mode_rows", "velocity_products",
           "fill_root_link", "fill_link", "tip_value", "tip_rows", "tip_turn", "gram_rows",
           "re_dot", "moment_dot", "start_rotors"]


@njit(cache=True, forceinline=True, fastmath={"contract"})
def slope(dphi, Q, Qd, c, k):
    """p and ṗ of the field with slopes ``dphi[:, k]`` of the coordinates from ``c``."""
    p = 0.0
    pd = 0.0
    for j in range(dphi.shape[0]):
        p += dphi[j, k] * Q[c + j]
        pd += dphi[j, k] * Qd[c + j]
    return p, pd


@njit(cache=True, forceinline=True, fastmath={"contract"})
def nodes_into(dphi, Q, Qd, c, ws):
    """g(p), g'(p), g''(p) and ṗ at a link's nodes into ``ws``: with e^{iβ} = (1 + i p) w,
    w = 1/√(1 + p²), u = w², g = e^{iβ} − 1 − i p, g' = i (e^{iβ} u − 1) and
    g'' = −e^{iβ} (1 + 2 i p) u²."""
    for k in range(dphi.shape[1]):
        p, pd = slope(dphi, Q, Qd, c, k)
        u = 1.0 / (1.0 + p * p)
        w = np.sqrt(u)
        er, ei = w, p * w  # e^{iβ}
        ws.g[k] = complex(er - 1.0, ei - p)
        ws.g1[k] = complex(-(ei * u), er * u - 1.0)
        p2 = 2.0 * p
        ws.g2[k] = complex(-(er - ei * p2) * u * u, -(er * p2 + ei) * u * u)
        ws.pd[k] = pd


@njit(cache=True, forceinline=True, fastmath={"contract"})
def position_row(z, r, o, ld, Q, ws):
    """ζ = i a, i × the link's position coefficients [0, i, −q*, i g*] (link 0: from its
    s column ``o`` = 0), into row ``r`` of ``z``; ws.g holds the nodes' g."""
    if o == 1:
        z[r, 0] = 0j
    z[r, o] = 1j
    for k in range(ld.n):
        z[r, o + 1 + k] = -Q[ld.c + k]
    for h in range(ld.nodes):
        g = ws.g[h]
        z[r, o + 1 + ld.n + h] = complex(-g.imag, g.real)


@njit(cache=True, forceinline=True, fastmath={"contract"})
def mode_rows(A, first, o, ld, ws):
    """The link's own rows ∂a/∂q_k = i e_φk + Σ_h g'(p_h) φ_k'(s_h) e_rh into rows
    ``first`` + k of ``A``."""
    f, n = o + 1, ld.n
    for k in range(n):
        row = first + k
        for j in range(f + n):
            A[row, j] = 0j
        A[row, f + k] = 1j
        for h in range(ld.nodes):
            g1, slope_kh = ws.g1[h], ld.dphi[k, h]
            A[row, f + n + h] = complex(g1.real * slope_kh, g1.imag * slope_kh)


@njit(cache=True, forceinline=True, fastmath={"contract"})
def velocity_products(o, ld, Q, Qd, ws, alphad, alpha_vp, root):
    """The link's velocity-product accelerations v into ws.v: with κ = i α_vp − α̇²
    (α_vp: the frame's velocity-product angular acceleration), v = κ a + 2 i α̇ ȧ + ä
    in i a terms, [root, κ, κ i q* − 2 α̇ q̇*, κ g* + 2 i α̇ g'* ṗ* + g''* ṗ*²], ``root``
    the root's own (link 0: none, its basis has no 1)."""
    v = ws.v
    f, n = o + 1, ld.n
    kr, ki = -alphad * alphad, alpha_vp  # κ
    two_ad = 2.0 * alphad
    if o == 1:
        v[0] = root
    v[o] = complex(kr, ki)
    for k in range(n):
        q = Q[ld.c + k]
        v[f + k] = complex(-ki * q - two_ad * Qd[ld.c + k], kr * q)
    for h in range(ld.nodes):
        g, g1, g2, pd = ws.g[h], ws.g1[h], ws.g2[h], ws.pd[h]
        pd2 = pd * pd
        v[f + n + h] = complex(kr * g.real - ki * g.imag - two_ad * g1.imag * pd + g2.real * pd2,
                               kr * g.imag + ki * g.real + two_ad * g1.real * pd + g2.imag * pd2)


@njit(cache=True, forceinline=True, fastmath={"contract"})
def fill_root_link(ld, Q, Qd, ws, rates):
    """Link 0's rows [θ1, q*] (basis [s, φ*, r*], its own frame) into ws.A (and Ȧ);
    returns its rows and basis size."""
    n1, c = ld.n, ld.c
    N = ld.nodes
    A, Ad = ws.A, ws.Ad
    m, nb = 1 + n1, 1 + n1 + N
    th1d = Qd[0]
    r0 = 1 + n1  # first r_h column
    nodes_into(ld.dphi, Q, Qd, c, ws)
    position_row(A, 0, 0, ld, Q, ws)
    mode_rows(A, 1, 0, ld, ws)
    if rates:  # Ȧ in the turning frame: i θ̇1 A + d/dt of the coefficients
        for i in range(m):
            for b in range(nb):
                Ad[i, b] = 0j
        Ad[0, 0] = -th1d
        for k in range(n1):
            Ad[0, 1 + k] = -1j * th1d * Q[c + k] - Qd[c + k]
            Ad[1 + k, 1 + k] = -th1d
        for h in range(N):
            g, g1, g2, pd = ws.g[h], ws.g1[h], ws.g2[h], ws.pd[h]
            Ad[0, r0 + h] = -th1d * g + 1j * g1 * pd
            for k in range(n1):
                Ad[1 + k, r0 + h] = (1j * th1d * g1 + g2 * pd) * ld.dphi[k, h]
    return m, nb


@njit(cache=True, forceinline=True, fastmath={"contract"})
def fill_link(link, links, ld, Q, Qd, ws, rates, eg, alphad):
    """Link ``link`` ≥ 1's rows (upstream, then its own modes; basis [1, s, φ*, r*], its
    root frame) into ws.A (and Ȧ): its own joint's row is ζ = i a, every upstream row
    da_j ζ + t_j e_0.  ``eg`` turns the previous frame into this one; ws.t, ws.td hold
    the previous link's tip rows.  Returns its rows, upstream rows and basis size."""
    n2, c2, N = ld.n, ld.c, ld.nodes
    A, Ad = ws.A, ws.Ad
    hub = ws.ax[2 * link]
    hubd = ws.axd[2 * link]
    up = upstream_rows(link, links, c2)
    m, s0 = up + n2, 2 + n2
    nb = s0 + N
    nodes_into(ld.dphi, Q, Qd, c2, ws)
    position_row(A, link, 1, ld, Q, ws)
    for r in range(up):
        j = row_of(link, links, r)
        if j != link:  # the previous link's tip row r' (its rows: joints, then modes)
            da = hub[j]
            for b in range(1, nb):
                A[r, b] = da * A[link, b]
            A[r, 0] = eg * ws.t[r if j < link else r - 1]
    mode_rows(A, up, 1, ld, ws)
    if rates:
        for i in range(m):
            for b in range(nb):
                Ad[i, b] = 0j
        for r in range(up):
            j = row_of(link, links, r)
            da = hub[j]
            dda = hubd[j]
            c = 1j * alphad * da + dda
            Ad[r, 1] = c * 1j
            for k in range(n2):  # da (i ȧ) on the φ columns: i · i q̇ = −q̇
                Ad[r, 2 + k] = -c * Q[c2 + k] - da * Qd[c2 + k]
            for h in range(N):
                Ad[r, s0 + h] = c * 1j * ws.g[h] + da * 1j * ws.g1[h] * ws.pd[h]
            if j != link:
                Ad[r, 0] = eg * ws.td[r if j < link else r - 1]
        for k in range(n2):
            row = up + k
            Ad[row, 2 + k] = -alphad
            for h in range(N):
                Ad[row, s0 + h] = (1j * alphad * ws.g1[h] + ws.g2[h] * ws.pd[h]) * ld.dphi[k, h]
    return m, up, nb


@njit(cache=True, forceinline=True, fastmath={"contract"})
def tip_value(z, o, ld):
    """z·b(L), a row's value at the link's tip (b(L) = [1, L, φ*(L), w*]: r_h(L) is node
    h's Gauss weight; ``o`` = 0: link 0's basis, without the 1)."""
    n1 = ld.n
    tr, ti = z[o].real * ld.L, z[o].imag * ld.L
    if o == 1:
        tr, ti = z[0].real + tr, z[0].imag + ti
    for k in range(n1):
        tr += z[o + 1 + k].real * ld.phi_tip[k]
        ti += z[o + 1 + k].imag * ld.phi_tip[k]
    for h in range(ld.nodes):
        tr += z[o + 1 + n1 + h].real * ld.w[h]
        ti += z[o + 1 + n1 + h].imag * ld.w[h]
    return complex(tr, ti)


@njit(cache=True, forceinline=True, fastmath={"contract"})
def tip_rows(ld, root, m, ws, rates):
    """The link's tip rows A·b(L) into ws.t (and Ȧ·b(L) into ws.td); ``root``: its
    basis has the constant 1."""
    o = 1 if root else 0  # column of s
    for r in range(m):
        ws.t[r] = tip_value(ws.A[r], o, ld)
        ws.td[r] = tip_value(ws.Ad[r], o, ld) if rates else 0j


@njit(cache=True, forceinline=True, fastmath={"contract"})
def tip_turn(ld, link, Q, Qd, ws, rates):
    """The rotor rows of the link's tip (its slope β = atan p(L) on top of its frame's)
    and of the next hub (``rates``: and their rates); returns (b, ḃ/ṗ, ṗ(L), β̈'s
    velocity product) of the tip."""
    ax, axd, vp = ws.ax, ws.axd, ws.vp
    pe, ped = 0.0, 0.0
    for k in range(ld.n):
        pe += ld.dphi_tip[k] * Q[ld.c + k]
        ped += ld.dphi_tip[k] * Qd[ld.c + k]
    b = 1.0 / (1.0 + pe * pe)  # β' = d atan p / dp
    bd = -2.0 * pe * b * b  # β''
    n = ax.shape[1]
    hub, tip = 2 * link, 2 * link + 1
    for j in range(n):
        ax[tip, j] = ax[hub, j]
        if rates:
            axd[tip, j] = axd[hub, j]
    for k in range(ld.n):
        ax[tip, ld.c + k] = b * ld.dphi_tip[k]
        if rates:
            axd[tip, ld.c + k] = bd * ped * ld.dphi_tip[k]
    vp[tip] = vp[hub] + bd * ped * ped
    if tip + 1 < ax.shape[0]:
        for j in range(n):
            ax[tip + 1, j] = ax[tip, j]
            if rates:
                axd[tip + 1, j] = axd[tip, j]
        ax[tip + 1, link + 1] = 1.0
        vp[tip + 1] = vp[tip]
    return pe, b, ped, bd * ped * ped


@njit(cache=True, forceinline=True, fastmath={"contract"})
def gram_rows(G, A, GA, first, last, nb, c0):
    """GA[r] = G A[r] for rows first..last−1 (G real) whose columns before ``c0`` are
    zero: each entry's sum over c in order, in real arithmetic, four entries of two rows
    at a time (independent sums that share G's loads; an odd last row alone); the last
    four end at nb (they may overlap the previous ones, which they write again with the
    same sums)."""
    if nb < 4:  # a rigid link's basis: [s] or [1, s]
        for r in range(first, last):
            for b in range(nb):
                re = im = 0.0
                for c in range(c0, nb):
                    re += G[b, c] * A[r, c].real
                    im += G[b, c] * A[r, c].imag
                GA[r, b] = complex(re, im)
        return
    for r in range(first, last - 1, 2):
        for b_ in range(0, nb, 4):
            b = b_ if b_ + 4 <= nb else nb - 4
            x0 = y0 = x1 = y1 = x2 = y2 = x3 = y3 = 0.0  # row r
            u0 = w0 = u1 = w1 = u2 = w2 = u3 = w3 = 0.0  # row r + 1
            for c in range(c0, nb):
                ar, ai, sr, si = A[r, c].real, A[r, c].imag, A[r + 1, c].real, A[r + 1, c].imag
                g0, g1, g2, g3 = G[b, c], G[b + 1, c], G[b + 2, c], G[b + 3, c]
                x0 += g0 * ar
                y0 += g0 * ai
                x1 += g1 * ar
                y1 += g1 * ai
                x2 += g2 * ar
                y2 += g2 * ai
                x3 += g3 * ar
                y3 += g3 * ai
                u0 += g0 * sr
                w0 += g0 * si
                u1 += g1 * sr
                w1 += g1 * si
                u2 += g2 * sr
                w2 += g2 * si
                u3 += g3 * sr
                w3 += g3 * si
            GA[r, b] = complex(x0, y0)
            GA[r, b + 1] = complex(x1, y1)
            GA[r, b + 2] = complex(x2, y2)
            GA[r, b + 3] = complex(x3, y3)
            GA[r + 1, b] = complex(u0, w0)
            GA[r + 1, b + 1] = complex(u1, w1)
            GA[r + 1, b + 2] = complex(u2, w2)
            GA[r + 1, b + 3] = complex(u3, w3)
    if (last - first) % 2 == 1:  # the odd row last, alone
        r = last - 1
        for b_ in range(0, nb, 4):
            b = b_ if b_ + 4 <= nb else nb - 4
            x0 = y0 = x1 = y1 = x2 = y2 = x3 = y3 = 0.0
            for c in range(c0, nb):
                ar, ai = A[r, c].real, A[r, c].imag
                g0, g1, g2, g3 = G[b, c], G[b + 1, c], G[b + 2, c], G[b + 3, c]
                x0 += g0 * ar
                y0 += g0 * ai
                x1 += g1 * ar
                y1 += g1 * ai
                x2 += g2 * ar
                y2 += g2 * ai
                x3 += g3 * ar
                y3 += g3 * ai
            GA[r, b] = complex(x0, y0)
            GA[r, b + 1] = complex(x1, y1)
            GA[r, b + 2] = complex(x2, y2)
            GA[r, b + 3] = complex(x3, y3)


@njit(cache=True, forceinline=True, fastmath={"contract"})
def re_dot(x, y, c0, nb):
    """Re(Σ_c conj(x[c]) y[c]) over c0..nb−1, as four sums (c − c0 mod 4: consecutive
    terms do not wait for each other)."""
    s0 = s1 = s2 = s3 = 0.0
    c = c0
    while c + 3 < nb:
        s0 += x[c].real * y[c].real + x[c].imag * y[c].imag
        s1 += x[c + 1].real * y[c + 1].real + x[c + 1].imag * y[c + 1].imag
        s2 += x[c + 2].real * y[c + 2].real + x[c + 2].imag * y[c + 2].imag
        s3 += x[c + 3].real * y[c + 3].real + x[c + 3].imag * y[c + 3].imag
        c += 4
    while c < nb:
        s0 += x[c].real * y[c].real + x[c].imag * y[c].imag
        c += 1
    return (s0 + s1) + (s2 + s3)


@njit(cache=True, forceinline=True, fastmath={"contract"})
def moment_dot(A, r, c0, nb, G, moment, with_constant):
    """A[r]·μ over the columns c0..nb−1, μ the link's first moments ∫ρ b + m_tip b(L):
    G's first column (a basis with the constant 1), or link 0's ``moment``."""
    sr = si = 0.0
    for b in range(c0, nb):
        mu = G[b, 0] if with_constant else moment[b]
        sr += A[r, b].real * mu
        si += A[r, b].imag * mu
    return complex(sr, si)


@njit(cache=True, forceinline=True, fastmath={"contract"})
def start_rotors(ws, n):
    """Hub 1's rotor row (θ1's) and its rate; `tip_turn` writes the others whole."""
    for j in range(n):
        ws.ax[0, j] = 0.0
        ws.axd[0, j] = 0.0
    ws.ax[0, 0] = 1.0
    ws.vp[0] = 0.0
