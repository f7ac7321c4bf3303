"""The exact-kinematics kernels as C-callable entry points, which the paper's kernels call
through the pointers of `reduced_model._on_demand` (`reduced_model._exact_pointers`).

Importing this module compiles them (or loads them from numba's cache): only
`reduced_model._on_demand.load` imports it, the first time a process packs a model with
exact kinematics.  Each entry point takes a model's `ExactRef` and a
workspace's `ExactScratch` field by field (each array as a pointer and its length), then
the kernel's own arguments, arrays as pointers (of n, or n × n, values) and flags as
int64, and rebuilds the views its kernel takes.
"""
from __future__ import annotations

from numba import carray, cfunc, njit, types

from ._exact_data import ExactRef, ExactScratch
from ._exact_kernels import (exact_coriolis_matrix_into, exact_elastic_into,
                             exact_mass_bias_into, exact_tips_into)

__all__ = ["mass_bias", "coriolis", "elastic", "tips"]

_i8 = types.int64
_reals, _complex = types.CPointer(types.float64), types.CPointer(types.complex128)
_REF = (_reals, _i8, _i8, _i8, _i8, _i8)  # reals, their length, N, n1, n2, offset
_SCRATCH = (_complex, _i8, _i8, _reals, _i8, _i8)  # wc, its length, oc, wr, its length, orr


@njit(cache=True, inline="always")
def _ref(reals, length, N, n1, n2, offset):
    return ExactRef(N, n1, n2, carray(reals, (length,)), offset)


@njit(cache=True, inline="always")
def _scratch(wc, complex_length, oc, wr, real_length, orr):
    return ExactScratch(carray(wc, (complex_length,)), oc, carray(wr, (real_length,)), orr)


@cfunc(types.void(*_REF, *_SCRATCH, _reals, _reals, _reals, _reals, _i8), cache=True)
def mass_bias(reals, length, N, n1, n2, offset, wc, nc, oc, wr, nr, orr, Q, Qd, M, h,
              with_bias):
    n = 2 + n1 + n2
    exact_mass_bias_into(_ref(reals, length, N, n1, n2, offset),
                         _scratch(wc, nc, oc, wr, nr, orr), carray(Q, (n,)), carray(Qd, (n,)),
                         carray(M, (n, n)), carray(h, (n,)), with_bias != 0)


@cfunc(types.void(*_REF, *_SCRATCH, _reals, _reals, _reals), cache=True)
def coriolis(reals, length, N, n1, n2, offset, wc, nc, oc, wr, nr, orr, Q, Qd, C):
    n = 2 + n1 + n2
    exact_coriolis_matrix_into(_ref(reals, length, N, n1, n2, offset),
                               _scratch(wc, nc, oc, wr, nr, orr), carray(Q, (n,)),
                               carray(Qd, (n,)), carray(C, (n, n)))


@cfunc(types.void(*_REF, _reals, _reals, _reals, _i8), cache=True)
def elastic(reals, length, N, n1, n2, offset, Q, Qd, f, with_damping):
    n = 2 + n1 + n2
    exact_elastic_into(_ref(reals, length, N, n1, n2, offset), carray(Q, (n,)),
                       carray(Qd, (n,)), carray(f, (n,)), with_damping != 0)


@cfunc(types.void(*_REF, _reals, _reals), cache=True)
def tips(reals, length, N, n1, n2, offset, Q, out):
    exact_tips_into(_ref(reals, length, N, n1, n2, offset), carray(Q, (2 + n1 + n2,)),
                    carray(out, (6,)))
