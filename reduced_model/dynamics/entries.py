"""The model's kernels as Python and plants call them: compiled entry points on packed
buffers, one per kinematics (the ``_exact`` ones compile the exact kinematics, the others
never do), chosen by `kernels` from a model's kinematics."""
from __future__ import annotations

from typing import NamedTuple

from numba import njit

from .layout import unpack_model, unpack_workspace
from .motion import (acceleration_into, coriolis_matrix_into, elastic_into, mass_bias_into,
                     mass_matrix_into, rk4_advance, tips_into)
from .exact import exact_tip_jacobian

__all__ = ["Kernels", "kernels"]


@njit(cache=True)
def advance_linear(ints, reals, wc, wr, x, tau, h, nsteps):
    """`rk4_advance` on packed buffers (the paper's kinematics)."""
    rk4_advance(unpack_model(ints, reals), x, tau, h, nsteps, unpack_workspace(ints, wc, wr),
                False)


@njit(cache=True)
def advance_exact(ints, reals, wc, wr, x, tau, h, nsteps):
    """`rk4_advance` on packed buffers (exact kinematics)."""
    rk4_advance(unpack_model(ints, reals), x, tau, h, nsteps, unpack_workspace(ints, wc, wr),
                True)


@njit(cache=True)
def mass_matrix_linear(ints, reals, wc, wr, Q, M):
    mass_matrix_into(unpack_model(ints, reals), Q, M, unpack_workspace(ints, wc, wr), False)


@njit(cache=True)
def mass_matrix_exact(ints, reals, wc, wr, Q, M):
    mass_matrix_into(unpack_model(ints, reals), Q, M, unpack_workspace(ints, wc, wr), True)


@njit(cache=True)
def coriolis_linear(ints, reals, wc, wr, Q, Qd, C):
    coriolis_matrix_into(unpack_model(ints, reals), Q, Qd, C, unpack_workspace(ints, wc, wr),
                         False)


@njit(cache=True)
def coriolis_exact(ints, reals, wc, wr, Q, Qd, C):
    coriolis_matrix_into(unpack_model(ints, reals), Q, Qd, C, unpack_workspace(ints, wc, wr),
                         True)


@njit(cache=True)
def acceleration_linear(ints, reals, wc, wr, Q, Qd, tau, out):
    acceleration_into(unpack_model(ints, reals), Q, Qd, tau, out,
                      unpack_workspace(ints, wc, wr), False)


@njit(cache=True)
def acceleration_exact(ints, reals, wc, wr, Q, Qd, tau, out):
    acceleration_into(unpack_model(ints, reals), Q, Qd, tau, out,
                      unpack_workspace(ints, wc, wr), True)


@njit(cache=True)
def bias_linear(ints, reals, wc, wr, Q, Qd, M, h):
    mass_bias_into(unpack_model(ints, reals), Q, Qd, M, h, unpack_workspace(ints, wc, wr),
                   False)


@njit(cache=True)
def bias_exact(ints, reals, wc, wr, Q, Qd, M, h):
    mass_bias_into(unpack_model(ints, reals), Q, Qd, M, h, unpack_workspace(ints, wc, wr),
                   True)


@njit(cache=True)
def elastic_linear(ints, reals, Q, Qd, f):
    f[:] = 0.0
    elastic_into(unpack_model(ints, reals), Q, Qd, f, True, False)


@njit(cache=True)
def elastic_exact(ints, reals, Q, Qd, f):
    f[:] = 0.0
    elastic_into(unpack_model(ints, reals), Q, Qd, f, True, True)


@njit(cache=True)
def tips_linear(ints, reals, Q, out):
    tips_into(unpack_model(ints, reals), Q, out, False)


@njit(cache=True)
def tips_exact(ints, reals, Q, out):
    tips_into(unpack_model(ints, reals), Q, out, True)


class Kernels(NamedTuple):
    """A model's compiled entry points (each takes the packed model and workspace, then its
    own arguments)."""

    advance: object  # (x, tau, h, nsteps): RK4 at a zero-order hold, x in place
    mass_matrix: object  # (Q, M)
    coriolis: object  # (Q, Qd, C)
    acceleration: object  # (Q, Qd, tau, out)
    bias: object  # (Q, Qd, M, h): M(Q), and h = C Q̇ + ∂V_g/∂Q
    elastic: object  # (ints, reals, Q, Qd, f): f = K Q + D Q̇ (+ the exact bending terms)
    tips: object  # (ints, reals, Q, out): no workspace
    tip_jacobian: object | None  # (Q, J); None: the model computes it in Python


_KERNELS = {
    False: Kernels(advance_linear, mass_matrix_linear, coriolis_linear, acceleration_linear,
                   bias_linear, elastic_linear, tips_linear, None),
    True: Kernels(advance_exact, mass_matrix_exact, coriolis_exact, acceleration_exact,
                  bias_exact, elastic_exact, tips_exact, exact_tip_jacobian),
}


def kernels(exact: bool) -> Kernels:
    """The entry points of the kinematics ``exact`` (True: exact; False: the paper's)."""
    return _KERNELS[bool(exact)]
