"""Natural frequencies of the FE arm linearised at a configuration (the reference the
reduced model's eq. 2 is judged against)."""
from __future__ import annotations

import exudyn as exu
import numpy as np

from reduced_model import ArmParameters

from ._build import Mesh, build_arm

__all__ = ["natural_frequencies"]


def natural_frequencies(params: ArmParameters, mesh: Mesh = Mesh(), *, theta=(0.0, 0.0),
                        joints: str = "locked", n: int = 4,
                        include_rigid: bool = False) -> np.ndarray:
    """First ``n`` bending frequencies [Hz] of the undamped FE arm at joint angles ``theta``.

    ``joints="locked"`` clamps both joints at ``theta``; ``joints="free"`` leaves them free
    and drops the two rigid-body (zero) modes unless ``include_rigid``.  Exudyn linearises
    about the reference configuration and projects onto the nullspace of the constraint
    Jacobian (dense SVD; the rigid modes come out at ~1e-4 Hz rather than 0).  Joint
    friction is left out (a stuck joint would be a stiff bristle); drives are in.
    """
    if joints not in ("locked", "free"):
        raise ValueError(f"joints must be 'locked' or 'free', got {joints!r}")
    system = build_arm(params.without("friction"), mesh, theta=theta,
                       lock_joints=(joints == "locked"))
    freqs, _ = system.mbs.ComputeODE2Eigenvalues(
        exu.SimulationSettings(), useSparseSolver=False, convert2Frequencies=True,
        useAbsoluteValues=True, ignoreAlgebraicEquations=False)
    freqs = np.sort(np.asarray(freqs))
    skip = 2 if joints == "free" and not include_rigid else 0
    return freqs[skip:skip + n]
