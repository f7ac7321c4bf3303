"""The compiled form of a law: a numba kernel with its role's fixed signature, and the
buffers it works on.

A compiled loop (`validation.run.sample`) calls a law through a typed function pointer of
the role's signature (`reduced_model.contract.compiled.KernelPointer`, as it calls a
plant), so the loop is compiled once for every law, and each law's kernel is compiled —
and cached by numba — on its own, the first time a run uses it; a kernel that does not
take its role's signature fails there, with a `TypeError` naming it.  A law
offers its compiled form with a method ``compiled() -> CompiledLaw`` on the class that
defines its Python form (``__call__`` for a controller, ``update`` for an observer);
the buffers are copies, so a compiled run never changes the Python object.  Any law may
do so, built-in or plug-in; a law without it runs as the Python object it is.

Controller kernel::

    n_tau = kernel(t, x, ref, ints, reals, state, model_ints, model_reals,
                   work_complex, work_real, tau, residual)

writes the torques into ``tau`` (its first ``n_tau`` entries: N, or n for a law that
applies generalised forces to every coordinate) and what it cannot apply into
``residual``; ``x`` is the state it is fed, ``ref`` = [θ_d, θ̇_d, θ̈_d] (3N,).

Observer kernel::

    status = kernel(t, y, tau, ints, reals, state, model_ints, model_reals,
                    work_complex, work_real, x_hat)

advances over the last period (of the law's own control period, which its buffers
carry) with ``tau`` (skipped on the first call after a reset),
corrects with ``y`` (in the order of ``measured``) and writes the estimate into
``x_hat``; ``status`` is 0, or non-zero when the observer failed (its `CompiledLaw.failure`
says how).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, types

from reduced_model.contract import KernelPointer, kernel_pointer
from reduced_model.contract import vector as _vector

__all__ = ["CONTROLLER_SIGNATURE", "OBSERVER_SIGNATURE", "CompiledLaw", "compiled_form",
           "absent"]

_f8, _i8, _c16 = types.float64, types.int64, types.complex128


#: The compiled controller's signature (module docstring).
CONTROLLER_SIGNATURE = _i8(_f8, _vector(_f8), _vector(_f8), _vector(_i8), _vector(_f8),
                           _vector(_f8), _vector(_i8), _vector(_f8), _vector(_c16),
                           _vector(_f8), _vector(_f8), _vector(_f8))
#: The compiled observer's signature (module docstring).
OBSERVER_SIGNATURE = _i8(_f8, _vector(_f8), _vector(_f8), _vector(_i8), _vector(_f8),
                         _vector(_f8), _vector(_i8), _vector(_f8), _vector(_c16),
                         _vector(_f8), _vector(_f8))


class CompiledLaw(NamedTuple):
    """A law's kernel and the buffers it works on: what a law's ``compiled()`` returns
    (the kernels' signatures are in this module's docstring).

    A plug-in builds it with `CompiledLaw.of` from a numba kernel of its role's signature
    (`CONTROLLER_SIGNATURE`, `OBSERVER_SIGNATURE`), its options, gains and state; the
    compiled loop passes the buffers to the kernel at every sample.

    Parameters
    ----------
    pointer : KernelPointer
        The kernel as a function pointer of its role's signature.
    ints : ndarray of int64
        Integer options and flags (the kernel's ``ints``).
    reals : ndarray of float64
        Gains and constants (``reals``).
    state : ndarray of float64
        State and scratch, a copy of the law's own: the run changes it, never the object.
    model_ints, model_reals : ndarray
        The law's model, packed (`reduced_model.ArmModel.packed`).
    work_complex, work_real : ndarray
        The model's scratch space (`reduced_model.ArmModel.new_workspace`).
    failure : str
        What a non-zero status of an observer kernel means ("" for a controller).

    Examples
    --------
    A controller that returns zero torques, compiled:

    >>> from numba import njit
    >>> from controllers import CONTROLLER_SIGNATURE, CompiledLaw
    >>> from reduced_model import ArmModel
    >>> @njit(cache=False)
    ... def idle(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    ...     tau[0] = tau[1] = 0.0
    ...     return 2
    >>> law = CompiledLaw.of(idle, CONTROLLER_SIGNATURE, ArmModel(), reals=[30.0, 15.0])
    >>> law.reals, law.state.size, law.failure
    (array([30., 15.]), 0, '')
    """

    pointer: KernelPointer
    ints: np.ndarray
    reals: np.ndarray
    state: np.ndarray
    model_ints: np.ndarray
    model_reals: np.ndarray
    work_complex: np.ndarray
    work_real: np.ndarray
    failure: str = ""

    @classmethod
    def of(cls, kernel, signature, model, *, ints=(), reals=(), state=(), failure: str = ""):
        """The compiled form of a law on ``model``: buffers converted to the kernel's
        types, the model packed with fresh scratch space.

        Parameters
        ----------
        kernel : numba dispatcher
            The law's kernel (``@njit``), of the role's signature.
        signature : numba signature
            `CONTROLLER_SIGNATURE` or `OBSERVER_SIGNATURE`.
        model : ArmModel
            The law's model.
        ints, reals, state : sequence of numbers
            The law's integer options, its gains, and its state (copied).
        failure : str
            What a non-zero status of an observer kernel means.

        Returns
        -------
        CompiledLaw

        Raises
        ------
        TypeError
            When ``kernel`` does not take ``signature``.
        """
        work_complex, work_real = model.new_workspace()
        return cls(kernel_pointer(kernel, signature),
                   np.ascontiguousarray(ints, dtype=np.int64),
                   np.ascontiguousarray(reals, dtype=np.float64),
                   np.array(state, dtype=np.float64, order="C"),  # always a copy
                   *model.packed, work_complex, work_real, failure)


def compiled_form(law, role: str) -> CompiledLaw | None:
    """The compiled form of ``law``, if it has one that computes what its Python form
    does.

    A law runs compiled only when the class that defines its Python form (``__call__``
    for a controller, ``update`` for an observer) also defines ``compiled``: a subclass
    that changes ``__call__`` but not ``compiled`` must not run its parent's kernel, so
    it runs as the Python object it is.

    Parameters
    ----------
    law : object
        A controller or observer (built-in or plug-in).
    role : str
        ``"controller"`` or ``"observer"``.

    Returns
    -------
    CompiledLaw or None
        ``law.compiled()``, or None when the law runs as a Python object.

    Raises
    ------
    TypeError
        Naming the law, when what ``compiled`` returns is not a `CompiledLaw` of the
        role's signature (the run then fails saying so).

    Examples
    --------
    >>> from controllers import JointPD, compiled_form
    >>> from reduced_model import ArmModel
    >>> class Softer(JointPD):  # a plug-in changing the law, not its kernel
    ...     def __call__(self, t, x, ref):
    ...         return 0.5 * super().__call__(t, x, ref)
    >>> compiled_form(Softer(ArmModel(), Ts=1e-3), "controller") is None
    True
    >>> compiled_form(JointPD(ArmModel(), Ts=1e-3), "controller").reals.size > 0
    True
    """
    method = "__call__" if role == "controller" else "update"
    cls = type(law)
    defining = next((c for c in cls.__mro__ if method in c.__dict__), None)
    if defining is None or "compiled" not in defining.__dict__:
        return None
    form = law.compiled()
    signature = CONTROLLER_SIGNATURE if role == "controller" else OBSERVER_SIGNATURE
    if not (isinstance(form, CompiledLaw) and isinstance(form.pointer, KernelPointer)
            and form.pointer.signature() == signature):
        text = " ".join(repr(form).split())
        raise TypeError(f"{cls.__module__}:{cls.__qualname__}.compiled() returned {text[:60]}{'...' if len(text) > 60 else ''}"
                        f": a compiled {role} is a controllers.CompiledLaw made by "
                        f"CompiledLaw.of(kernel, {role.upper()}_SIGNATURE, model, ...)")
    return form


@njit(cache=True)
def _no_controller(t, x, ref, ints, reals, state, mi, mr, wc, wr, tau, residual):
    return 0


@njit(cache=True)
def _no_observer(t, y, tau, ints, reals, state, mi, mr, wc, wr, x_hat):
    return 0


def absent(role: str, model) -> CompiledLaw:
    """What fills a law's place in a compiled sample when there is no observer, or when
    the laws run as Python objects (never called: the loop knows).

    Parameters
    ----------
    role : {"controller", "observer"}
        The place it fills.
    model : ArmModel
        The model the loop's laws are built on.

    Returns
    -------
    CompiledLaw
        A law of that role's signature that does nothing.
    """
    if role == "controller":
        return CompiledLaw.of(_no_controller, CONTROLLER_SIGNATURE, model)
    return CompiledLaw.of(_no_observer, OBSERVER_SIGNATURE, model)
