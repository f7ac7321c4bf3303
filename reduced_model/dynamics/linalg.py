"""Small linear algebra for compiled code, allocation-free: matrix and vector views of a
flat buffer without the cost of ``reshape`` or of a reference count, and Cholesky
factorisation and solves of small symmetric positive-definite matrices in place (the
mass matrix, the EKF's innovation covariance).

The kernels keep every model, workspace and law state in flat buffers and take their
matrices and vectors as views.  In numba, ``flat[a:b].reshape((r, c))`` calls a C helper
that LLVM cannot inline (~23 ns per view), and every view of a slice holds a reference
to the buffer: an atomic increment and a decrement, each a call LLVM cannot remove,
where a kernel's branches keep numba from pruning them (the exact kinematics make ~40
views per right-hand side: counted, they cost 3-4 times its arithmetic).
`matrix_view` and `vector_view` build the same C-contiguous views directly (the data
pointer moved by ``start``), which LLVM folds into the indexing that follows, and
*borrow* the buffer: they hold no reference, so a view must not outlive the call that
received its buffer — a kernel's arguments outlive the kernel, and no view is ever
returned to Python.  No bounds are checked: the callers compute ``start + rows·cols``
from the buffer's own layout, and the tests compare every kernel against its reshaped
form.
"""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

__all__ = ["matrix_view", "vector_view", "cholesky_factor_inplace", "cholesky_solve_factored",
           "cholesky_solve_inplace"]


def _borrowed_view(flat, start, shape):
    """The typing and code of a C-contiguous view of ``flat`` from ``start`` with
    ``shape`` (integer arguments), holding no reference (module docstring); None if the
    arguments do not type."""
    if not (isinstance(flat, types.Array) and flat.ndim == 1 and flat.layout == "C"):
        return None
    if not all(isinstance(v, types.Integer) for v in (start, *shape)):
        return None
    result = types.Array(flat.dtype, len(shape), "C")

    def codegen(context, builder, sig, args):
        source = make_array(sig.args[0])(context, builder, args[0])
        start, *dims = (context.cast(builder, v, t, types.intp)
                        for v, t in zip(args[1:], sig.args[1:]))
        itemsize = context.get_constant(
            types.intp, context.get_abi_sizeof(context.get_data_type(flat.dtype)))
        strides = [builder.mul(dims[1], itemsize), itemsize] if len(dims) == 2 else [itemsize]
        view = make_array(result)(context, builder)
        populate_array(view, data=builder.gep(source.data, [start]), shape=dims,
                       strides=strides, itemsize=itemsize, meminfo=None, parent=None)
        return impl_ret_borrowed(context, builder, result, view._getvalue())

    return result(flat, start, *shape), codegen


@intrinsic
def matrix_view(typingctx, flat, start, rows, cols):
    """``flat[start:start + rows*cols].reshape((rows, cols))`` for a C-contiguous 1-D
    ``flat``, borrowed (compiled code only)."""
    return _borrowed_view(flat, start, (rows, cols))


@intrinsic
def vector_view(typingctx, flat, start, length):
    """``flat[start:start + length]`` for a C-contiguous 1-D ``flat``, borrowed (compiled
    code only)."""
    return _borrowed_view(flat, start, (length,))


@njit(cache=True, forceinline=True)
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


@njit(cache=True, forceinline=True)
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


@njit(cache=True, forceinline=True)
def cholesky_solve_inplace(M, b):
    """Solve M y = b for symmetric positive definite M; M is overwritten by its factor,
    b by y.  False if M is not positive definite."""
    if not cholesky_factor_inplace(M):
        return False
    cholesky_solve_factored(M, b)
    return True
