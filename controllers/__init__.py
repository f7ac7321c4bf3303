"""Controllers and observers: the paper's passivity-based controller (eq. 14–20), its
sliding-mode observer (eq. 21–36) with practical variants, baselines, and reference
trajectories (eq. 37).  All of them use a `reduced_model.ArmModel` as their model.

A controller is called as ``tau = controller(t, x_hat, ref)``; an observer has
``reset(x_hat0)`` and ``update(t, y, tau, Ts) -> x_hat``.
"""
from ._baselines import JointPD, RigidComputedTorque
from ._pbc import PassivityBasedController
from ._reference import PaperReference, QuinticMove
from ._smo import OBSERVER_VARIANTS, SlidingModeObserver

__all__ = ["PassivityBasedController", "SlidingModeObserver", "OBSERVER_VARIANTS", "JointPD",
           "RigidComputedTorque", "PaperReference", "QuinticMove"]
