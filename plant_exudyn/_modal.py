"""Natural frequencies of the FE arm linearised at a configuration (the reference the
reduced model's eq. 2 is judged against)."""
from __future__ import annotations

import exudyn as exu
import numpy as np

from reduced_model import ArmParameters

from ._build import Mesh, build_arm

__all__ = ["natural_frequencies"]


def natural_frequencies(params: ArmParameters, mesh: Mesh = Mesh(), *, theta=None,
                        joints: str = "locked", n: int = 4,
                        include_rigid: bool = False) -> np.ndarray:
    """First ``n`` bending frequencies [Hz] of the undamped FE arm at joint angles ``theta``.

    Exudyn linearises about the reference configuration and projects onto the nullspace
    of the constraint Jacobian (dense SVD; the rigid modes come out at ~1e-4 Hz rather
    than 0).  Joint friction is left out (a stuck joint would be a stiff bristle); drives
    are in.  Gravity is not: its loads are constant, and the undeformed arm about which
    Exudyn linearises is not in equilibrium in it (no prestress).

    Parameters
    ----------
    params, mesh, theta
        The arm, its mesh and joint angles [rad] (default 0), as `build_arm`'s.
    joints : {"locked", "free"}
        "locked" clamps every joint at ``theta``; "free" leaves them free.
    n : int
        How many frequencies.
    include_rigid : bool
        With free joints, keep the N rigid-body (zero) modes.

    Returns
    -------
    ndarray (n,)
        Frequencies [Hz], ascending.

    Examples
    --------
    The paper's Table 1 arm, joints locked at θ = 0 (the converged independent
    references: 0.6316, 3.8312, 6.3499, 33.665 Hz):

    >>> from plant_exudyn import Mesh, natural_frequencies
    >>> from reduced_model import named_arm
    >>> natural_frequencies(named_arm("table1"), Mesh(elements_per_link=(16, 16))).round(3)
    array([ 0.632,  3.831,  6.35 , 33.665])
    """
    if joints not in ("locked", "free"):
        raise ValueError(f"joints must be 'locked' or 'free', got {joints!r}")
    system = build_arm(params.without("friction"), mesh, theta=theta,
                       lock_joints=(joints == "locked"))
    freqs, _ = system.mbs.ComputeODE2Eigenvalues(
        exu.SimulationSettings(), useSparseSolver=False, convert2Frequencies=True,
        useAbsoluteValues=True, ignoreAlgebraicEquations=False)
    freqs = np.sort(np.asarray(freqs))
    skip = params.n_links if joints == "free" and not include_rigid else 0
    return freqs[skip:skip + n]
