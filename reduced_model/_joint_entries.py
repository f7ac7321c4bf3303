"""`reduced_model._joints.advance_joints` as a C-callable entry point, which
`reduced_model._joint_pointers.advance_joints_packed` calls through the pointers of
`reduced_model._on_demand`.

Importing this module compiles it (or loads it from numba's cache): only
`reduced_model._on_demand.load` imports it, the first time a process builds the joint
buffers of an arm with friction, a drive or a torque lag.  It takes the packed model and
workspace (each array as a pointer and its length), the arm state (2n), the held
commands (2, or n) and the external forces (n), the step and the step count, and the
joints' buffers (`reduced_model._joint_pointers.new_joint_buffers`).
"""
from __future__ import annotations

from numba import carray, cfunc, types

from . import _kernels as kern
from ._joints import PARAMETERS, STATE, advance_joints, work_length

__all__ = ["advance"]

_i8, _f8 = types.int64, types.float64
_reals, _ints = types.CPointer(_f8), types.CPointer(_i8)


@cfunc(types.void(_ints, _i8, _reals, _i8, types.CPointer(types.complex128), _i8, _reals, _i8,
                  _reals, _i8, _reals, _i8, _reals, _f8, _i8, _reals, _reals, _reals),
       cache=True)
def advance(ints, n_ints, reals, n_reals, wc, n_wc, wr, n_wr, x, m, tau, n_tau, ext, h,
            nsteps, jp, js, jw):
    model_ints = carray(ints, (n_ints,))
    n = m // 2
    advance_joints(kern.unpack_model(model_ints, carray(reals, (n_reals,))), carray(x, (m,)),
                   carray(tau, (n_tau,)), carray(ext, (n,)), h, nsteps,
                   kern.unpack_workspace(model_ints, carray(wc, (n_wc,)), carray(wr, (n_wr,))),
                   carray(jp, (2 * len(PARAMETERS),)), carray(js, (STATE,)),
                   carray(jw, (work_length(n),)))
