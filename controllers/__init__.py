"""Controllers and observers: the paper's passivity-based controller (eq. 14–20), its
sliding-mode observer (eq. 21–36) with practical variants, baselines, and reference
trajectories (eq. 37).  All are plug-ins of one interface (`controllers._interface`):
``Cls(model, *, Ts, **options)`` on a `reduced_model.ArmModel` at the control period
``Ts``; a controller is called as ``tau = controller(t, x, ref)``; an observer has
``measured``, ``reset(x_hat0)`` and ``update(t, y, tau) -> x_hat``.
"""
from ._baselines import JointPD, RigidComputedTorque
from ._compiled import (CONTROLLER_SIGNATURE, OBSERVER_SIGNATURE, CompiledLaw, absent,
                        compiled_form)
from ._ekf import ExtendedKalmanFilter, PositionEKF
from ._gains import ArmGains, arm_gains
from ._interface import Controller, Observer, ObserverFailure
from ._lqr import GainScheduledLQR
from ._pbc import IdealisedPBC, PassivityBasedController
from ._replay import TorqueReplay
from ._reference import PaperReference, QuinticMove, ReferenceKind, reference_into
from ._registry import CONTROLLERS, OBSERVERS, PluginError, accepted_options, resolve
from ._smo import BoundaryLayerSMO, PaperSMO, PositionOnlySMO

__all__ = ["Controller", "Observer", "PassivityBasedController", "IdealisedPBC", "PaperSMO",
           "BoundaryLayerSMO", "PositionOnlySMO", "ExtendedKalmanFilter", "PositionEKF",
           "JointPD", "RigidComputedTorque", "GainScheduledLQR", "TorqueReplay",
           "PaperReference", "QuinticMove", "ReferenceKind", "reference_into", "CONTROLLERS",
           "OBSERVERS", "PluginError", "resolve", "accepted_options", "CompiledLaw",
           "compiled_form", "absent", "CONTROLLER_SIGNATURE", "OBSERVER_SIGNATURE",
           "ObserverFailure", "arm_gains", "ArmGains"]
