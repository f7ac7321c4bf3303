"""The rows of a link's coefficients in the exact inextensible kinematics, link by link
(the kernels that sum them: `reduced_model.dynamics.exact`, whose docstring states the
formulation): a link's nodes g(p(s_h)), its rows (upstream: da_j (i a) + t_j e_0; its
own modes: ∂a/∂q_k) and their rates, its tip rows for the next link, and the rotor rows
its tip slope turns."""
from __future__ import annotations

import numpy as np
from numba import njit

from .linear import row_of, upstream_rows

__all__ = ["slope", "fill_root_link", "fill_link", "tip_rows", "tip_turn", "gram_rows",
           "re_dot", "re_dot_vector", "start_rotors", "gravity_rows"]


@njit(cache=True, forceinline=True)
def slope(dphi, Q, Qd, c, k):
    """p and ṗ of the field with slopes ``dphi[:, k]`` of the coordinates from ``c``."""
    p = 0.0
    pd = 0.0
    for j in range(dphi.shape[0]):
        p += dphi[j, k] * Q[c + j]
        pd += dphi[j, k] * Qd[c + j]
    return p, pd


@njit(cache=True, forceinline=True)
def _nodes(dphi, Q, Qd, c, ws):
    """g(p), g'(p), g''(p) and ṗ at a link's nodes into ``ws`` (e^{iβ} = (1 + i p)/√(1 + p²))."""
    for k in range(dphi.shape[1]):
        p, pd = slope(dphi, Q, Qd, c, k)
        u = 1.0 / (1.0 + p * p)
        e = (1.0 + 1j * p) * np.sqrt(u)
        ws.g[k] = e - 1.0 - 1j * p
        ws.g1[k] = 1j * (e * u - 1.0)
        ws.g2[k] = -e * (1.0 + 2j * p) * u * u
        ws.pd[k] = pd


@njit(cache=True, forceinline=True)
def fill_root_link(ld, Q, Qd, ws, rates):
    """Link 0's rows [θ1, q*] (basis [s, φ*, r*], its own frame) into ws.A (and Ȧ), its
    velocity-product coefficients into ws.v; returns its rows and basis size."""
    n1, c = ld.n, ld.c
    N = ld.nodes
    A, Ad, v = ws.A, ws.Ad, ws.v
    m, nb = 1 + n1, 1 + n1 + N
    for i in range(m):
        for b in range(nb):
            A[i, b] = 0j
            if rates:
                Ad[i, b] = 0j
    th1d = Qd[0]
    r0 = 1 + n1  # first r_h column
    _nodes(ld.dphi, Q, Qd, c, ws)
    A[0, 0] = 1j
    v[0] = -th1d * th1d
    for k in range(n1):
        q, qd = Q[c + k], Qd[c + k]
        A[0, 1 + k] = -q
        A[1 + k, 1 + k] = 1j
        v[1 + k] = -1j * th1d * th1d * q - 2.0 * th1d * qd
    for h in range(N):
        g, g1, g2, pd = ws.g[h], ws.g1[h], ws.g2[h], ws.pd[h]
        A[0, r0 + h] = 1j * g
        v[r0 + h] = -th1d * th1d * g + 2j * th1d * g1 * pd + g2 * pd * pd
        for k in range(n1):
            A[1 + k, r0 + h] = g1 * ld.dphi[k, h]
    if rates:  # Ȧ in the turning frame: i θ̇1 A + d/dt of the coefficients
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


@njit(cache=True, forceinline=True)
def fill_link(link, links, ld, Q, Qd, ws, rates, eg, alphad, alpha_vp, u_prev):
    """Link ``link`` ≥ 1's rows (upstream, then its own modes; basis [1, s, φ*, r*], its
    root frame) into ws.A (and Ȧ), ζ = i a into ws.a, its velocity-product coefficients
    into ws.v.  ``eg`` turns the previous frame into this one; ws.t, ws.td hold the
    previous link's tip rows, ``u_prev`` its tip's velocity-product acceleration.
    Returns its rows, upstream rows and basis size."""
    n2, c2, N = ld.n, ld.c, ld.nodes
    A, Ad, v, a = ws.A, ws.Ad, ws.v, ws.a
    hub = ws.ax[2 * link]
    hubd = ws.axd[2 * link]
    up = upstream_rows(link, links, c2)
    m, s0 = up + n2, 2 + n2
    nb = s0 + N
    for i in range(m):
        for b in range(nb):
            A[i, b] = 0j
            if rates:
                Ad[i, b] = 0j
    _nodes(ld.dphi, Q, Qd, c2, ws)
    a[0] = 0j
    a[1] = 1j
    for k in range(n2):
        a[2 + k] = -Q[c2 + k]
    for h in range(N):
        a[s0 + h] = 1j * ws.g[h]
    for r in range(up):
        j = row_of(link, links, r)
        da = hub[j]
        for b in range(1, nb):
            A[r, b] = da * a[b]
        if j != link:  # the previous link's tip row r' (its rows: joints, then modes)
            A[r, 0] = eg * ws.t[r if j < link else r - 1]
    for k in range(n2):
        A[up + k, 2 + k] = 1j
        for h in range(N):
            A[up + k, s0 + h] = ws.g1[h] * ld.dphi[k, h]
    # v = (i α̈ − α̇²) a + 2 i α̇ ȧ + ä (in i a terms), plus the root's acceleration.
    v[0] = eg * u_prev
    v[1] = 1j * alpha_vp - alphad * alphad
    for k in range(n2):
        q, qd = Q[c2 + k], Qd[c2 + k]
        v[2 + k] = (1j * alpha_vp - alphad * alphad) * 1j * q - 2.0 * alphad * qd
    for h in range(N):
        g, g1, g2, pd = ws.g[h], ws.g1[h], ws.g2[h], ws.pd[h]
        v[s0 + h] = (1j * alpha_vp - alphad * alphad) * g + 2j * alphad * g1 * pd \
            + g2 * pd * pd
    if rates:
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


@njit(cache=True, forceinline=True)
def tip_rows(ld, root, m, ws, rates):
    """The link's tip rows A·b(L) into ws.t (ws.td) and its tip's velocity-product
    acceleration v·b(L) (returned); ``root``: its basis has the constant 1."""
    A, Ad, v = ws.A, ws.Ad, ws.v
    n1, N = ld.n, ld.nodes
    o = 1 if root else 0  # column of s
    u = v[o] * ld.L
    if root:
        u = v[0] + u
    for r in range(m):
        t = A[r, o] * ld.L
        td = Ad[r, o] * ld.L if rates else 0j
        if root:
            t = A[r, 0] + t
            if rates:
                td = Ad[r, 0] + td
        for k in range(n1):
            t += A[r, o + 1 + k] * ld.phi_tip[k]
            if rates:
                td += Ad[r, o + 1 + k] * ld.phi_tip[k]
        for h in range(N):
            t += A[r, o + 1 + n1 + h] * ld.w[h]
            if rates:
                td += Ad[r, o + 1 + n1 + h] * ld.w[h]
        ws.t[r] = t
        ws.td[r] = td
    for k in range(n1):
        u += v[o + 1 + k] * ld.phi_tip[k]
    for h in range(N):
        u += v[o + 1 + n1 + h] * ld.w[h]
    return u


@njit(cache=True, forceinline=True)
def tip_turn(ld, link, Q, Qd, ws):
    """The rotor rows of the link's tip (its slope β = atan p(L) on top of its frame's)
    and of the next hub; returns (b, ḃ/ṗ, ṗ(L), β̈'s velocity product) of the tip."""
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
        axd[tip, j] = axd[hub, j]
    for k in range(ld.n):
        ax[tip, ld.c + k] = b * ld.dphi_tip[k]
        axd[tip, ld.c + k] = bd * ped * ld.dphi_tip[k]
    vp[tip] = vp[hub] + bd * ped * ped
    if tip + 1 < ax.shape[0]:
        for j in range(n):
            ax[tip + 1, j] = ax[tip, j]
            axd[tip + 1, j] = axd[tip, j]
        ax[tip + 1, link + 1] = 1.0
        vp[tip + 1] = vp[tip]
    return pe, b, ped, bd * ped * ped


@njit(cache=True, forceinline=True)
def gram_rows(G, A, GA, first, last, nb):
    """GA[r] = G A[r] for rows first..last−1 (G real): each entry's sum over c in order,
    in real arithmetic, four entries at a time (independent sums, not one long chain)."""
    for r in range(first, last):
        for b in range(0, nb - 3, 4):
            r0 = i0 = r1 = i1 = r2 = i2 = r3 = i3 = 0.0
            for c in range(nb):
                ar, ai = A[r, c].real, A[r, c].imag
                g0, g1, g2, g3 = G[b, c], G[b + 1, c], G[b + 2, c], G[b + 3, c]
                r0 += g0 * ar
                i0 += g0 * ai
                r1 += g1 * ar
                i1 += g1 * ai
                r2 += g2 * ar
                i2 += g2 * ai
                r3 += g3 * ar
                i3 += g3 * ai
            GA[r, b] = complex(r0, i0)
            GA[r, b + 1] = complex(r1, i1)
            GA[r, b + 2] = complex(r2, i2)
            GA[r, b + 3] = complex(r3, i3)
        for b in range(nb - nb % 4, nb):
            re = im = 0.0
            for c in range(nb):
                re += G[b, c] * A[r, c].real
                im += G[b, c] * A[r, c].imag
            GA[r, b] = complex(re, im)


@njit(cache=True, forceinline=True)
def re_dot(A, r, B, s, nb):
    """Re(Σ_c conj(A[r, c]) B[s, c])."""
    acc = 0.0
    for c in range(nb):
        acc += A[r, c].real * B[s, c].real + A[r, c].imag * B[s, c].imag
    return acc


@njit(cache=True, forceinline=True)
def re_dot_vector(A, r, v, nb):
    """Re(Σ_c conj(A[r, c]) v[c])."""
    acc = 0.0
    for c in range(nb):
        acc += A[r, c].real * v[c].real + A[r, c].imag * v[c].imag
    return acc


@njit(cache=True, forceinline=True)
def start_rotors(ws, n):
    ws.ax[:, :] = 0.0
    ws.axd[:, :] = 0.0
    ws.ax[0, 0] = 1.0
    ws.vp[0] = 0.0


@njit(cache=True, forceinline=True)
def gravity_rows(G, ws, link, links, m, nb, g_hat, h, moment, with_constant):
    """h −= Re(conj(ĝ) A[r]·μ) for the link's ``m`` rows (μ: G's first column, or link
    0's first moments)."""
    gc = g_hat.conjugate()
    for r in range(m):
        s = 0j
        for b in range(nb):
            s += ws.A[r, b] * (G[b, 0] if with_constant else moment[b])
        h[row_of(link, links, r)] -= (gc * s).real
