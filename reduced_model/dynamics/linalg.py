"""Small linear algebra for compiled code, allocation-free: a matrix view of a flat buffer
without the cost of ``reshape``, and Cholesky factorisation and solves of small symmetric
positive-definite matrices in place (the mass matrix, the EKF's innovation covariance).

The kernels keep every model, workspace and law state in flat buffers and take their
matrices as views.  In numba, ``flat[a:b].reshape((r, c))`` calls a C helper that LLVM
cannot inline (~23 ns per view); `matrix_view` builds the same C-contiguous view
directly (the data pointer moved by ``start``, the buffer's memory kept alive as
``reshape`` does), which LLVM folds into the indexing that follows.  No bounds are
checked: the callers compute ``start + rows·cols`` from the buffer's own layout, and the
tests compare every kernel against its reshaped form.
"""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

__all__ = ["matrix_view", "cholesky_factor_inplace", "cholesky_solve_factored",
           "cholesky_solve_inplace"]


@intrinsic
def matrix_view(typingctx, flat, start, rows, cols):
    """``flat[start:start + rows*cols].reshape((rows, cols))`` for a C-contiguous 1-D
    ``flat`` (compiled code only)."""
    if not (isinstance(flat, types.Array) and flat.ndim == 1 and flat.layout == "C"):
        return None
    if not all(isinstance(v, types.Integer) for v in (start, rows, cols)):
        return None
    result = types.Array(flat.dtype, 2, "C")

    def codegen(context, builder, sig, args):
        source = make_array(sig.args[0])(context, builder, args[0])
        start, rows, cols = (context.cast(builder, v, t, types.intp)
                             for v, t in zip(args[1:], sig.args[1:]))
        itemsize = context.get_constant(
            types.intp, context.get_abi_sizeof(context.get_data_type(flat.dtype)))
        view = make_array(result)(context, builder)
        populate_array(view, data=builder.gep(source.data, [start]), shape=[rows, cols],
                       strides=[builder.mul(cols, itemsize), itemsize], itemsize=itemsize,
                       meminfo=source.meminfo, parent=source.parent)
        return impl_ret_borrowed(context, builder, result, view._getvalue())

    return result(flat, start, rows, cols), codegen


@njit(cache=True, inline="always")
def cholesky_factor_inplace(M):
    """Overwrite symmetric positive definite M by its lower Cholesky factor L, with
    1/L_jj on the diagonal (for `cholesky_solve_factored`).  False if M is not
    positive definite."""
    n = M.shape[0]
    for j in range(n):
        s = M[j, j]
        for k in range(j):
            s -= M[j, k] * M[j, k]
        if not s > 0.0:
            return False
        inv = 1.0 / np.sqrt(s)
        M[j, j] = inv
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= M[i, k] * M[j, k]
            M[i, j] = s * inv
    return True


@njit(cache=True, inline="always")
def cholesky_solve_factored(L, b):
    """Solve L Lᵀ y = b in place (``b`` becomes y), L from `cholesky_factor_inplace`."""
    n = L.shape[0]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * b[k]
        b[i] = s * L[i, i]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= L[k, i] * b[k]
        b[i] = s * L[i, i]


@njit(cache=True, inline="always")
def cholesky_solve_inplace(M, b):
    """Solve M y = b for symmetric positive definite M; M is overwritten by its factor,
    b by y.  False if M is not positive definite."""
    if not cholesky_factor_inplace(M):
        return False
    cholesky_solve_factored(M, b)
    return True
