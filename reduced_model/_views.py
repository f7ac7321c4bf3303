"""A matrix view of a flat buffer for compiled code, without the cost of ``reshape``.

The kernels keep every model, workspace and law state in flat buffers and take their
matrices as views.  In numba, ``flat[a:b].reshape((r, c))`` calls a C helper that LLVM
cannot inline (~23 ns per view on our machine, `bench/bench_reduced_model.py`); a run's
sample unpacks ~40 views, about 1 µs of a 7 µs step.  `matrix_view` builds the same
C-contiguous view directly (the data pointer moved by ``start``, the buffer's memory
kept alive as ``reshape`` does), which LLVM folds into the indexing that follows.  No
bounds are checked: the callers compute ``start + rows·cols`` from the buffer's own
layout, and the tests compare every kernel against its reshaped form.
"""
from __future__ import annotations

from numba import types
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

__all__ = ["matrix_view"]


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
