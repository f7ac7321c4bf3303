"""The equations of motion of the reduced model, the paper's eq. (2),

    M(Q) Q̈ + C(Q, Q̇) Q̇ + D Q̇ + K Q + ∂V_g/∂Q = B τ,   B = [I_N; 0],

for either kinematics, and their integration by RK4 at a zero-order hold.  Each
function takes ``exact`` as a constant and is inlined into the kernels that call it,
compiled once per kinematics (`reduced_model.dynamics.entries`, the laws): numba drops
the other kinematics' branch before it compiles anything of it, so a process that never
builds an exact model never compiles the exact kinematics.  The kinematics themselves
(`linear_mass_bias`, `exact_mass_bias`, …) are called, not inlined: each is compiled
once, on the packed buffers, and linked into every kernel that calls it: numba inlines
by copying a function's IR into each call site, a cost paid at every site of every
kernel's first compile (small helpers are inlined by LLVM instead: ``forceinline``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .exact import exact_coriolis, exact_elastic, exact_mass_bias, exact_tips
from .linalg import cholesky_solve_inplace
from .linear import linear_coriolis, linear_mass_bias, linear_tips

__all__ = ["mass_bias_into", "mass_matrix_into", "coriolis_matrix_into", "elastic_into",
           "bias_forces_into", "acceleration_into", "rhs_into", "rk4_advance", "tips_into"]


@njit(cache=True, inline="always")
def mass_bias_into(d, Q, Qd, M, h, ws, exact):
    """M(Q) into ``M`` and h = C(Q, Q̇) Q̇ + ∂V_g/∂Q into ``h``."""
    if exact:
        exact_mass_bias(d.ints, d.reals, ws.wc, ws.wr, Q, Qd, M, h)
    else:
        linear_mass_bias(d.ints, d.reals, ws.wc, ws.wr, Q, Qd, M, h)


@njit(cache=True, inline="always")
def mass_matrix_into(d, Q, M, ws, exact):
    """M(Q) into ``M`` (n, n); h, computed with it, is left in the scratch ws.f: one
    compiled kinematics kernel serves both (each variant compiles for seconds)."""
    mass_bias_into(d, Q, Q, M, ws.f, ws, exact)


@njit(cache=True, inline="always")
def coriolis_matrix_into(d, Q, Qd, C, ws, exact):
    """The Christoffel-form C(Q, Q̇) into ``C`` (n, n)."""
    if exact:
        exact_coriolis(d.ints, d.reals, ws.wc, ws.wr, Q, Qd, C)
    else:
        linear_coriolis(d.ints, d.reals, ws.wc, ws.wr, Q, Qd, C)


@njit(cache=True, inline="always")
def elastic_into(d, Q, Qd, f, with_damping, exact):
    """Add the elastic forces K Q (+ D Q̇ ``with_damping``) to ``f``; K and D vanish on the
    joint rows and columns (exact kinematics: the exact bending forces)."""
    n, N = f.shape[0], d.links
    for i in range(N, n):
        s = 0.0
        for j in range(N, n):
            s += d.K[i, j] * Q[j] + d.D[i, j] * Qd[j] if with_damping else d.K[i, j] * Q[j]
        f[i] += s
    if exact:
        exact_elastic(d.ints, d.reals, Q, Qd, f, with_damping)


@njit(cache=True, inline="always")
def bias_forces_into(d, Q, Qd, h, ws, exact):
    """h = C(Q,Q̇) Q̇ + D Q̇ + K Q + ∂V_g/∂Q into ``h``, and M(Q) into ws.M."""
    mass_bias_into(d, Q, Qd, ws.M, h, ws, exact)
    elastic_into(d, Q, Qd, h, True, exact)


@njit(cache=True, inline="always")
def acceleration_into(d, Q, Qd, tau, Qdd, ws, exact):
    """Q̈ = M⁻¹(B τ − h) into ``Qdd``, B = [I_N; 0].  ``tau`` holds the N joint torques,
    or n generalised forces (the paper's idealised, unrealisable input)."""
    f = ws.f
    bias_forces_into(d, Q, Qd, f, ws, exact)
    n = f.shape[0]
    for i in range(n):
        Qdd[i] = (tau[i] if i < tau.shape[0] else 0.0) - f[i]
    if not cholesky_solve_inplace(ws.M, Qdd):
        Qdd[:] = np.nan


@njit(cache=True, inline="always")
def rhs_into(d, x, tau, xdot, ws, exact):
    """ẋ for the state x = [Q, Q̇] (length 2n) into ``xdot``."""
    n = x.shape[0] // 2
    for i in range(n):
        xdot[i] = x[n + i]
    acceleration_into(d, x[:n], x[n:], tau, xdot[n:], ws, exact)


@njit(cache=True, inline="always")
def rk4_advance(d, x, tau, h, nsteps, ws, exact):
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
            rhs_into(d, xt, tau, k, ws, exact)
            weight = 2.0 if stage == 1 or stage == 2 else 1.0
            step = h if stage == 2 else 0.5 * h  # where the next stage is evaluated
            for i in range(m):
                acc[i] += weight * k[i]
                xt[i] = x[i] + step * k[i]
        for i in range(m):
            x[i] += h / 6.0 * acc[i]


@njit(cache=True, inline="always")
def tips_into(d, Q, out, exact):
    """The tips: [x, y of each link's tip…, each tip's deflection across its root
    frame…] into ``out`` (3N)."""
    if exact:
        exact_tips(d.ints, d.reals, Q, out)
    else:
        linear_tips(d.ints, d.reals, Q, out)
