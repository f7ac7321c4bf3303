"""The joints as plants and compiled loops use them: their buffers, and `advance_joints`
called through the pointer of `reduced_model._on_demand`, so that it is compiled only in
a process that builds an arm with friction, a drive or a torque lag, not for every run
of the paper's ideal joints.  The entry point it calls is in
`reduced_model._joint_entries`; the joints' model is `reduced_model._joints`."""
from __future__ import annotations

import numpy as np
from numba import njit

from . import _on_demand
from ._joints import PARAMETERS, STATE, joints_active, work_length

__all__ = ["new_joint_buffers", "advance_joints_packed"]

_ENTRIES = "reduced_model._joint_entries"
_ADVANCE = _on_demand.slot(_ENTRIES, "advance")


def new_joint_buffers(params, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(jp, js, jw) for the arm ``params`` (an `ArmParameters`) with ``n`` coordinates;
    where some joint effect is on, `advance_joints_packed`'s kernel is compiled or loaded."""
    jp = np.zeros(2 * len(PARAMETERS))
    for f, name in enumerate(PARAMETERS):
        for i in (1, 2):
            jp[2 * f + i - 1] = (params.static_friction(i) if name == "static"
                                 else getattr(params, f"{name}{i}"))
    if joints_active(jp):
        _on_demand.load(_ENTRIES)
    return jp, np.zeros(STATE), np.zeros(work_length(n))


@njit(cache=True)
def advance_joints_packed(ints, reals, wc, wr, x, tau, ext, h, nsteps, jp, js, jw):
    """`reduced_model._joints.advance_joints` on the model's packed buffers, from Python
    and from compiled loops."""
    _on_demand.call(_on_demand.entry(_ADVANCE), (
        ints, ints.shape[0], reals, reals.shape[0], wc, wc.shape[0], wr, wr.shape[0], x,
        x.shape[0], tau, tau.shape[0], ext, h, nsteps, jp, js, jw))
