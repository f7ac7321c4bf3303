"""A model packed for compiled code: the constants of an N-link arm in two flat buffers
(``ints``, ``reals``), unpacked into views inside compiled code, and the scratch space
its kernels work in.

From Python, numba checks a namedtuple argument field by field (~5 µs per call), so a
model and its workspace travel as flat buffers and the kernels `unpack_model` and
`unpack_workspace` them into views (no copy, no reference: `reduced_model.dynamics.
linalg.matrix_view`), which live only inside the kernel that unpacked them.  Per link the buffers hold its modes, its
first modal coordinate, its interpolation nodes (exact kinematics), its Gram matrix, its
tip values and, for the exact kinematics, the slopes and curvatures of its modes at the
nodes; then the constant rotor mass matrix, K and D.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .linalg import matrix_view, vector_view

__all__ = ["ModelData", "LinkData", "Workspace", "pack_model", "unpack_model", "link_data",
           "new_workspace", "unpack_workspace", "LinkPack"]

_HEADER = 8  # links, n, nodes, nb_max, M_rotors, K, D offsets, gravity offset
LINK_INTS = 12  # per link: modes, first coordinate, nodes, nb, then 8 reals offsets


class ModelData(NamedTuple):
    """The constants of one `ArmModel` (read-only in kernels)."""

    links: int  # N links (= joints)
    n: int  # coordinates: N joint angles, then each link's modal coordinates
    nodes: int  # interpolation nodes of a flexible link (0: the paper's linear kinematics)
    nb_max: int  # the largest basis of a link
    ints: np.ndarray  # the packed ints (per-link offsets: `link_data`)
    reals: np.ndarray  # the packed reals
    M_rotors: np.ndarray  # (n, n) Σ J a aᵀ of the hubs and tips (linear kinematics)
    K: np.ndarray  # (n, n) stiffness
    D: np.ndarray  # (n, n) Kelvin–Voigt damping
    gx: float  # gravity in the base frame [m/s²]
    gy: float


class LinkData(NamedTuple):
    """One link's constants (views into a packed model)."""

    n: int  # modes (0: rigid)
    c: int  # index of its first modal coordinate in Q
    nodes: int  # interpolation nodes (0: linear kinematics or a rigid link)
    L: float
    EI: float
    damping: float
    J_hub: float  # the hub's inertia at its root [kg m²]
    J_tip: float  # the rotary inertia at its tip: the next stator, or the payload
    G: np.ndarray  # (nb, nb) Gram of its basis: [s, φ, r] for link 0, [1, s, φ, r] after
    phi_tip: np.ndarray  # (n,) φ_k(L)
    dphi_tip: np.ndarray  # (n,) φ_k'(L)
    dphi: np.ndarray  # (n, nodes) φ_k' at the nodes
    ddphi: np.ndarray  # (n, nodes) φ_k''
    w: np.ndarray  # (nodes,) Gauss weights on [0, L] = r_h(L)
    moment: np.ndarray  # (nb,) first moments ∫ρ b + m_tip b(L) (link 0: its basis has no 1)


class LinkPack(NamedTuple):
    """What `pack_model` packs of one link."""

    n: int
    nodes: int
    L: float
    EI: float
    damping: float
    J_hub: float
    J_tip: float
    G: np.ndarray
    phi_tip: np.ndarray
    dphi_tip: np.ndarray
    dphi: np.ndarray
    ddphi: np.ndarray
    w: np.ndarray
    moment: np.ndarray


def pack_model(links: list[LinkPack], *, M_rotors, K, D, gravity) -> tuple[np.ndarray, np.ndarray]:
    """(ints, reals) buffers holding a model, in the order `unpack_model` reads them."""
    N = len(links)
    n = N + sum(link.n for link in links)
    nodes = max(link.nodes for link in links)
    nb_max = max(link.G.shape[0] for link in links)
    parts: list[np.ndarray] = []
    offset = 0

    def put(array, shape) -> int:
        nonlocal offset
        array = np.asarray(array, dtype=float)
        if array.shape != shape:
            raise ValueError(f"model part has shape {array.shape}, expected {shape}")
        start = offset
        parts.append(np.ravel(array))
        offset += array.size
        return start

    ints = [N, n, nodes, nb_max, put(M_rotors, (n, n)), put(K, (n, n)), put(D, (n, n)),
            put(gravity, (2,))]
    c = N
    for link in links:
        nb = link.G.shape[0]
        ints += [link.n, c, link.nodes, nb, put([link.L, link.EI, link.damping, link.J_hub, link.J_tip], (5,)),
                 put(link.G, (nb, nb)), put(link.phi_tip, (link.n,)),
                 put(link.dphi_tip, (link.n,)), put(link.dphi, (link.n, link.nodes)),
                 put(link.ddphi, (link.n, link.nodes)), put(link.w, (link.nodes,)),
                 put(link.moment, (nb,))]
        c += link.n
    return np.array(ints, dtype=np.int64), np.concatenate(parts)


@njit(cache=True, inline="always")
def unpack_model(ints, reals):
    """`ModelData` of views into the packed buffers (no copy)."""
    n = ints[1]
    og = ints[7]
    return ModelData(ints[0], n, ints[2], ints[3], ints, reals,
                     matrix_view(reals, ints[4], n, n), matrix_view(reals, ints[5], n, n),
                     matrix_view(reals, ints[6], n, n), reals[og], reals[og + 1])


@njit(cache=True, inline="always")
def link_data(d, i):
    """`LinkData` of link ``i`` (from 0) of the model ``d``."""
    o = _HEADER + LINK_INTS * i
    ints, reals = d.ints, d.reals
    nl, c, nodes, nb = ints[o], ints[o + 1], ints[o + 2], ints[o + 3]
    s = ints[o + 4]
    return LinkData(nl, c, nodes, reals[s], reals[s + 1], reals[s + 2], reals[s + 3], reals[s + 4],
                    matrix_view(reals, ints[o + 5], nb, nb),
                    vector_view(reals, ints[o + 6], nl), vector_view(reals, ints[o + 7], nl),
                    matrix_view(reals, ints[o + 8], nl, nodes),
                    matrix_view(reals, ints[o + 9], nl, nodes),
                    vector_view(reals, ints[o + 10], nodes),
                    vector_view(reals, ints[o + 11], nb))


class Workspace(NamedTuple):
    """Scratch space of a model's kernels (one per user: plant, law)."""

    c_hat: np.ndarray  # complex (n,) a link root's velocity Jacobian, in its frame
    v: np.ndarray  # complex (nb_max,) velocity-product acceleration coefficients
    Gv: np.ndarray  # complex (nb_max,) G v
    A: np.ndarray  # complex (n, nb_max) a link's coefficient rows
    Ad: np.ndarray  # complex (n, nb_max) their rates
    GA: np.ndarray  # complex (n, nb_max) G A, row by row
    t: np.ndarray  # complex (n,) the previous link's tip rows
    td: np.ndarray  # complex (n,) their rates
    g: np.ndarray  # complex (nodes,) g, g', g'' at a link's nodes (exact)
    g1: np.ndarray
    g2: np.ndarray
    zr: np.ndarray  # complex (links,) each link's root (base frame) and its velocity
    zrd: np.ndarray
    zt: np.ndarray  # complex (links,) each link's tip and its velocity
    ztd: np.ndarray
    E: np.ndarray  # complex (links,) e^{iα} of each link's frame
    M: np.ndarray  # (n, n)
    f: np.ndarray  # (n,)
    k1: np.ndarray  # (2n,) RK4 stages and trial state
    k2: np.ndarray
    k3: np.ndarray
    k4: np.ndarray
    xt: np.ndarray
    arow: np.ndarray  # (n,) a link frame's angular-velocity row
    alphad: np.ndarray  # (links,) each link frame's angular velocity
    pd: np.ndarray  # (nodes,) ṗ at a link's nodes (exact)
    ax: np.ndarray  # (2 links, n) rotor angular-velocity rows: hub 0, tip 0, hub 1, …
    axd: np.ndarray  # (2 links, n) their rates
    vp: np.ndarray  # (2 links,) rotor velocity-product angular accelerations
    wc: np.ndarray  # the buffers themselves (for kernels that take them packed)
    wr: np.ndarray


def _sizes(ints) -> tuple[int, int]:
    N, n, nodes, nb = (int(v) for v in ints[:4])
    return (2 * nb + 3 * n * nb + 3 * n + 3 * nodes + 5 * N,
            n * n + n + 10 * n + n + N + nodes + 4 * N * n + 2 * N)


def new_workspace(ints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(complex, real) scratch buffers for the model described by ``ints``."""
    nc, nr = _sizes(ints)
    return np.zeros(nc, np.complex128), np.zeros(nr)


@njit(cache=True, inline="always")
def _cut(buffer, o, length):
    return vector_view(buffer, o, length), o + length


@njit(cache=True, inline="always")
def unpack_workspace(ints, wc, wr):
    """`Workspace` of views into the buffers made by `new_workspace`."""
    N, n, nodes, nb = ints[0], ints[1], ints[2], ints[3]
    c_hat, o = _cut(wc, 0, n)
    v, o = _cut(wc, o, nb)
    Gv, o = _cut(wc, o, nb)
    A = matrix_view(wc, o, n, nb)
    Ad = matrix_view(wc, o + n * nb, n, nb)
    GA = matrix_view(wc, o + 2 * n * nb, n, nb)
    o += 3 * n * nb
    t, o = _cut(wc, o, n)
    td, o = _cut(wc, o, n)
    g, o = _cut(wc, o, nodes)
    g1, o = _cut(wc, o, nodes)
    g2, o = _cut(wc, o, nodes)
    zr, o = _cut(wc, o, N)
    zrd, o = _cut(wc, o, N)
    zt, o = _cut(wc, o, N)
    ztd, o = _cut(wc, o, N)
    E, o = _cut(wc, o, N)
    M = matrix_view(wr, 0, n, n)
    o = n * n
    f, o = _cut(wr, o, n)
    k1, o = _cut(wr, o, 2 * n)
    k2, o = _cut(wr, o, 2 * n)
    k3, o = _cut(wr, o, 2 * n)
    k4, o = _cut(wr, o, 2 * n)
    xt, o = _cut(wr, o, 2 * n)
    arow, o = _cut(wr, o, n)
    alphad, o = _cut(wr, o, N)
    pd, o = _cut(wr, o, nodes)
    ax = matrix_view(wr, o, 2 * N, n)
    axd = matrix_view(wr, o + 2 * N * n, 2 * N, n)
    o += 4 * N * n
    vp, o = _cut(wr, o, 2 * N)
    return Workspace(c_hat, v, Gv, A, Ad, GA, t, td, g, g1, g2, zr, zrd, zt, ztd, E, M, f,
                     k1, k2, k3, k4, xt, arow, alphad, pd, ax, axd, vp, wc, wr)
