"""The constants and scratch of the exact inextensible kinematics, packed for compiled
code (the dynamics: `reduced_model._exact_kernels`).

The exact constants follow the paper's model's own in its packed buffers, and the exact
scratch follows its scratch.  `ModelData.exact` (`reduced_model._kernels`) is only an
`ExactRef` to them (N = 0: the paper's linear kinematics) and `Workspace.exact` an
`ExactScratch`: the exact kernels take these two small tuples and unpack the views
themselves, because a call that is not inlined passes every array of a namedtuple one by
one (with ~60 arrays, 1 µs of a 4 µs mass matrix).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ._views import matrix_view

__all__ = ["ExactRef", "ExactScratch", "ExactData", "ExactWork", "exact_reals",
           "unpack_exact", "exact_workspace_sizes", "unpack_exact_workspace"]


class ExactRef(NamedTuple):
    """Where a packed model keeps its exact constants (`ModelData.exact`)."""

    N: int  # interpolation nodes per link (0: the paper's linear kinematics)
    n1: int
    n2: int
    reals: np.ndarray  # the model's packed reals
    offset: int  # where the exact constants start in them


class ExactScratch(NamedTuple):
    """Where a workspace keeps the exact scratch (`Workspace.exact`)."""

    wc: np.ndarray  # the workspace's complex buffer
    oc: int  # where the exact scratch starts in it
    wr: np.ndarray  # its real buffer
    orr: int


class ExactData(NamedTuple):
    """Constants of the exact kinematics (read-only views; built when N > 0)."""

    N: int  # interpolation nodes per link
    n1: int
    n2: int
    L1: float
    L2: float
    phi1_tip: np.ndarray  # (n1,) φ_1k(L1)
    dphi1_tip: np.ndarray  # (n1,) φ_1k'(L1)
    phi2_tip: np.ndarray  # (n2,) φ_2k(L2)
    G1: np.ndarray  # (1+n1+N)² Gram of link 1's basis [s, φ_1*, r_*] (hub 2, stator at the tip)
    G2: np.ndarray  # (2+n2+N)² Gram of link 2's basis [1, s, φ_2*, r_*] (payload at the tip)
    dphi1: np.ndarray  # (n1, N) φ_1k' at the nodes
    ddphi1: np.ndarray  # (n1, N) φ_1k''
    dphi2: np.ndarray  # (n2, N)
    ddphi2: np.ndarray  # (n2, N)
    w1: np.ndarray  # (N,) Gauss weights on [0, L1] = r_h(L1)
    w2: np.ndarray  # (N,)
    dphi2_tip: np.ndarray  # (n2,) φ_2k'(L2)
    inertia: np.ndarray  # (4,) hub 1, stator, hub 2, payload [kg m²]
    EI: np.ndarray  # (2,) bending stiffness of each link
    damping: np.ndarray  # (2,) Kelvin–Voigt bending damping of each link


class ExactWork(NamedTuple):
    """Scratch of the exact kernels (one per user; empty when N = 0)."""

    A1: np.ndarray  # complex (1+n1, nb1) link 1's rows [θ1, q_1*], local frame
    GA1: np.ndarray  # G1 A1ᵀ, row by row
    Ad1: np.ndarray  # Ȧ1
    A2: np.ndarray  # complex (n, nb2) link 2's rows, all coordinates, link 2's frame
    GA2: np.ndarray
    Ad2: np.ndarray
    v1: np.ndarray  # complex (nb1,) velocity-product acceleration of link 1's coefficients
    v2: np.ndarray  # complex (nb2,)
    a2: np.ndarray  # complex (nb2,) i × link 2's position coefficients
    t: np.ndarray  # complex (1+n1,) link-1 tip Jacobian rows (link 1's frame)
    td: np.ndarray  # complex (1+n1,) their rates
    g: np.ndarray  # complex (N,) g, g', g'' at the nodes of the link being filled
    g1: np.ndarray
    g2: np.ndarray
    pd: np.ndarray  # (N,) ṗ at the nodes
    ax: np.ndarray  # (4, n) rotor angular-velocity rows
    axd: np.ndarray  # (4, n) their rates
    vp: np.ndarray  # (4,) rotor velocity-product angular accelerations


def exact_reals(parts: dict | None, n1: int, n2: int) -> tuple[list[int], list[np.ndarray]]:
    """(ints, reals) to append to a packed model: [N] and the `ExactData` arrays in
    their field order (``parts`` None: the linear kinematics, N = 0)."""
    if parts is None:
        return [0], []
    N = parts["w1"].shape[0]
    shapes = {"L": (2,), "phi1_tip": (n1,), "dphi1_tip": (n1,), "phi2_tip": (n2,),
              "G1": (1 + n1 + N,) * 2, "G2": (2 + n2 + N,) * 2, "dphi1": (n1, N),
              "ddphi1": (n1, N), "dphi2": (n2, N), "ddphi2": (n2, N), "w1": (N,), "w2": (N,),
              "dphi2_tip": (n2,), "inertia": (4,), "EI": (2,), "damping": (2,)}
    out = []
    for name, shape in shapes.items():
        if np.shape(parts[name]) != shape:
            raise ValueError(f"exact part {name} has shape {np.shape(parts[name])}, "
                             f"expected {shape}")
        out.append(np.ravel(np.asarray(parts[name], dtype=float)))
    return [N], out


@njit(cache=True, inline="always")
def _take(buffer, o, rows, cols):
    """The (rows, cols) view of ``buffer`` at offset ``o``, and the offset after it."""
    return matrix_view(buffer, o, rows, cols), o + rows * cols


@njit(cache=True, inline="always")
def unpack_exact(ref):
    """`ExactData` of views into the packed model ``ref`` points to (N > 0)."""
    N, n1, n2, reals, o = ref.N, ref.n1, ref.n2, ref.reals, ref.offset
    nb1, nb2 = 1 + n1 + N, 2 + n2 + N
    L1, L2 = reals[o], reals[o + 1]
    phi1_tip, o = _take(reals, o + 2, 1, n1)
    dphi1_tip, o = _take(reals, o, 1, n1)
    phi2_tip, o = _take(reals, o, 1, n2)
    G1, o = _take(reals, o, nb1, nb1)
    G2, o = _take(reals, o, nb2, nb2)
    dphi1, o = _take(reals, o, n1, N)
    ddphi1, o = _take(reals, o, n1, N)
    dphi2, o = _take(reals, o, n2, N)
    ddphi2, o = _take(reals, o, n2, N)
    w1, o = _take(reals, o, 1, N)
    w2, o = _take(reals, o, 1, N)
    dphi2_tip, o = _take(reals, o, 1, n2)
    inertia, o = _take(reals, o, 1, 4)
    EI, o = _take(reals, o, 1, 2)
    damping, o = _take(reals, o, 1, 2)
    return ExactData(N, n1, n2, L1, L2, phi1_tip[0], dphi1_tip[0], phi2_tip[0], G1, G2, dphi1,
                     ddphi1, dphi2, ddphi2, w1[0], w2[0], dphi2_tip[0], inertia[0], EI[0],
                     damping[0])


def exact_workspace_sizes(n1: int, n2: int, N: int) -> tuple[int, int]:
    """(complex, real) scratch lengths of `ExactWork` (0, 0 when N = 0)."""
    if N == 0:
        return 0, 0
    n, nb1, nb2 = 2 + n1 + n2, 1 + n1 + N, 2 + n2 + N
    return 3 * (1 + n1) * nb1 + 3 * n * nb2 + nb1 + 2 * nb2 + 2 * (1 + n1) + 3 * N, \
        N + 8 * n + 4


@njit(cache=True, inline="always")
def unpack_exact_workspace(ref, scratch):
    """`ExactWork` of views into the scratch ``scratch`` points to, for the model ``ref``
    points to (N > 0)."""
    N, n1, n2 = ref.N, ref.n1, ref.n2
    wc, oc, wr, orr = scratch.wc, scratch.oc, scratch.wr, scratch.orr
    n = 2 + n1 + n2
    r1, nb1, nb2 = 1 + n1, 1 + n1 + N, 2 + n2 + N
    A1, oc = _take(wc, oc, r1, nb1)
    GA1, oc = _take(wc, oc, r1, nb1)
    Ad1, oc = _take(wc, oc, r1, nb1)
    A2, oc = _take(wc, oc, n, nb2)
    GA2, oc = _take(wc, oc, n, nb2)
    Ad2, oc = _take(wc, oc, n, nb2)
    v1, oc = _take(wc, oc, 1, nb1)
    v2, oc = _take(wc, oc, 1, nb2)
    a2, oc = _take(wc, oc, 1, nb2)
    t, oc = _take(wc, oc, 1, r1)
    td, oc = _take(wc, oc, 1, r1)
    g, oc = _take(wc, oc, 1, N)
    g1, oc = _take(wc, oc, 1, N)
    g2, oc = _take(wc, oc, 1, N)
    pd, orr = _take(wr, orr, 1, N)
    ax, orr = _take(wr, orr, 4, n)
    axd, orr = _take(wr, orr, 4, n)
    vp, orr = _take(wr, orr, 1, 4)
    return ExactWork(A1, GA1, Ad1, A2, GA2, Ad2, v1[0], v2[0], a2[0], t[0], td[0], g[0], g1[0],
                     g2[0], pd[0], ax, axd, vp[0])
