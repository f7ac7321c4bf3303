"""The plug-in interface every controller and observer implements, built-in or not.

A controller is a class constructed as ``Cls(model, *, Ts, **options)``: ``model`` is the
nominal `reduced_model.ArmModel` (what the controller believes), ``Ts`` the control period
[s] — set once, when the law is built, as python-control's ``dt``: no method receives it
again —, ``options`` the keyword options of the scenario's ``[controller] options`` table.  Calling it returns the N joint
torques::

    tau = controller(t, x, ref)      # float array (N,) [N m]

``x`` is the state the loop feeds back — the observer's estimate or the true state —
as ``[Q, Q̇]`` in the model's coordinates (length 2n); ``ref(t)`` returns
``(θ_d, θ̇_d, θ̈_d)``, three float arrays of shape (N,).  Optional attributes: ``name``
(a label) and ``residual`` (a float array, recorded every sample as ``residual_*``, like
the PBC's unrealisable forces).

An observer is constructed the same way and has ``measured`` (the tuple of measurement
names it needs, in the order of ``y``), ``reset(x_hat0)`` and
``update(t, y, tau) -> x_hat`` (advance over the last period, of its ``Ts``, with the
torque applied during it, then correct with ``y`` measured at ``t``; the first call after
``reset`` only corrects).  The state names are ``model.state_names``.  An observer that cannot go on
(e.g. a covariance that lost positive definiteness) raises `ObserverFailure`: the run
ends as diverged with its message.

Either may also offer a compiled form, ``compiled() -> CompiledLaw``
(`controllers._compiled`; its kernel reads the period from the law's own buffers):
compiled loops then call its numba kernel instead of the Python object.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Controller", "Observer", "ObserverFailure"]


class ObserverFailure(RuntimeError):
    """The observer cannot continue; the message says why (the run ends as diverged)."""


@runtime_checkable
class Controller(Protocol):
    def __call__(self, t: float, x: np.ndarray, ref) -> np.ndarray: ...


@runtime_checkable
class Observer(Protocol):
    measured: tuple[str, ...]

    def reset(self, x_hat0) -> np.ndarray: ...

    def update(self, t: float, y: np.ndarray, tau: np.ndarray) -> np.ndarray: ...
