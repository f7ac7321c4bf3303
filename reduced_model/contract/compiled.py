"""Compiled forms: a kernel of a declared signature, called through a typed function
pointer (numba's first-class functions), and the buffers it works on.

Laws (`controllers.CompiledLaw`) and plants (`CompiledPlant`) hand a compiled loop their
kernel this way: the loop is compiled once for every law and plant (it calls a pointer,
it does not link the kernel), and each kernel is compiled — and cached — on its own, the
first time a run uses it.  The pointer is made for its role's signature: a kernel that
does not take it fails there, with a `TypeError` naming the kernel and the signature
(SciPy's ``LowLevelCallable`` checks a callback's signature the same way), never as a
call with the wrong arguments.

Plant kernel::

    kernel(advance, tau, ext, ints, reals, state, model_ints, model_reals,
           work_complex, work_real, truth)

holds the commands ``tau`` (the joint torques, or n generalised forces where the plant
takes them) and the generalised forces ``ext`` for one control period when ``advance``
is true, then writes the truth vector (`reduced_model.contract.signals.truth_extras`)
into ``truth``.
"""
from __future__ import annotations

import functools
import warnings
from typing import NamedTuple

import numpy as np
from numba import types
from numba.core.errors import NumbaError, NumbaExperimentalFeatureWarning
from numba.experimental.function_type import _get_wrapper_address

__all__ = ["KernelPointer", "kernel_pointer", "PLANT_SIGNATURE", "CompiledPlant", "vector"]

# Function pointers are numba's "experimental" first-class functions (stable since 0.53,
# tested here on every path): say it once in this docstring, not at every compilation.
warnings.filterwarnings("ignore", "First-class function type feature is experimental",
                        NumbaExperimentalFeatureWarning)


def vector(dtype):
    """numba's type of a C-contiguous 1-D array of ``dtype``."""
    return types.Array(dtype, 1, "C")


_f8, _i8, _c16, _b1 = types.float64, types.int64, types.complex128, types.boolean
#: The compiled plant's signature (module docstring).
PLANT_SIGNATURE = types.void(_b1, vector(_f8), vector(_f8), vector(_i8), vector(_f8),
                             vector(_f8), vector(_i8), vector(_f8), vector(_c16), vector(_f8),
                             vector(_f8))


class KernelPointer(types.WrapperAddressProtocol):
    """A kernel as a first-class function of a declared signature: compiled loops take it
    as an argument, so they are compiled once for every kernel.  It carries its numba
    type, so passing it costs no type inference.

    Raises
    ------
    TypeError
        When the kernel cannot be compiled for ``signature`` (wrong arguments or types),
        naming the kernel and the signature.
    """

    def __init__(self, kernel, signature) -> None:
        try:
            kernel.compile(signature.args)  # on first use; numba's cache keeps it
            address = _get_wrapper_address(kernel, signature)
        except (NumbaError, TypeError) as exc:
            name = getattr(kernel, "__qualname__", None) or getattr(
                getattr(kernel, "py_func", None), "__qualname__", repr(kernel))
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise TypeError(f"kernel {name} does not take the signature {signature} "
                            f"({first})") from None
        self._address = address
        self._signature = signature
        self._numba_type_ = types.FunctionType(signature)
        self.kernel = kernel

    def __wrapper_address__(self) -> int:
        return self._address

    def signature(self):
        return self._signature


@functools.cache
def kernel_pointer(kernel, signature) -> KernelPointer:
    """The `KernelPointer` of ``kernel`` (made once per process)."""
    return KernelPointer(kernel, signature)


class CompiledPlant(NamedTuple):
    """A plant's kernel (`PLANT_SIGNATURE`) and the buffers it works on: what a plant's
    ``compiled()`` returns.  The buffers are the plant's own (its state is shared, so
    the plant object sees what a compiled run did).

    Parameters
    ----------
    pointer : KernelPointer
        The kernel.
    ints, reals, state : ndarray
        Its integer settings, its constants, its state and scratch.
    model_ints, model_reals : ndarray
        Its model, packed (`reduced_model.ArmModel.packed`).
    work_complex, work_real : ndarray
        The model's scratch space.
    """

    pointer: KernelPointer
    ints: np.ndarray
    reals: np.ndarray
    state: np.ndarray
    model_ints: np.ndarray
    model_reals: np.ndarray
    work_complex: np.ndarray
    work_real: np.ndarray
