"""Controllers and observers: the paper's passivity-based controller (eq. 14–20), its
sliding-mode observer (eq. 21–36) with practical variants, baselines, and reference
trajectories (eq. 37).  All of them use a `reduced_model.ArmModel` as their model.
"""
from ._baselines import JointPD
from ._reference import REFERENCES, PaperReference, QuinticMove

__all__ = ["JointPD", "PaperReference", "QuinticMove", "REFERENCES"]
