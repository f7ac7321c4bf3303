"""The finite-element discretisation of the truth plant's links, described without Exudyn
(a scenario names its mesh; only building the arm needs the solver)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reduced_model import FieldError

__all__ = ["Mesh", "ELEMENTS", "mesh_label"]

ELEMENTS = ("ancf", "geometrically_exact")


@dataclass(frozen=True)
class Mesh:
    """Finite-element discretisation of both links.

    Parameters
    ----------
    element : {"ancf", "geometrically_exact"}
        ANCF cable elements (Euler–Bernoulli; cubic Hermite position field with nodal
        slopes) or geometrically exact 2D beams (Reissner; linear interpolation).
    elements_per_link : (int, int)
        Default 4 per link: the locked and free frequencies of Table 1 are then within
        0.04 % of the converged values (convergence study in tests/test_exudyn_fidelity.py).
    axial_stiffness : float
        EA [N] of both links.  1e7 puts the first axial mode near 520 Hz, far above the
        bending modes of interest, without changing them.  The
        geometrically exact beam also derives its shear stiffness (0.4 EA) and
        cross-section rotary inertia per length (ρ EI/EA = ρ I/A) from it.
    """

    element: str = "ancf"
    elements_per_link: tuple[int, int] = (4, 4)
    axial_stiffness: float = 1e7

    def __post_init__(self) -> None:
        if self.element not in ELEMENTS:
            raise FieldError("mesh", "element", f"must be one of {ELEMENTS}, got {self.element!r}")
        epl = self.elements_per_link
        if (isinstance(epl, (int, np.integer)) and not isinstance(epl, bool)):
            epl = (int(epl), int(epl))
        if (not isinstance(epl, (tuple, list)) or len(epl) != 2
                or not all(isinstance(n, (int, np.integer)) and not isinstance(n, bool)
                           and 1 <= n <= 64 for n in epl)):
            raise FieldError("mesh", "elements_per_link", "must be an integer 1..64 or two of "
                             f"them, got {self.elements_per_link!r}")
        object.__setattr__(self, "elements_per_link", (int(epl[0]), int(epl[1])))
        ea = self.axial_stiffness
        if isinstance(ea, bool) or not isinstance(ea, (int, float)) or not np.isfinite(ea) \
                or ea <= 0:
            raise FieldError("mesh", "axial_stiffness", f"must be a finite number > 0, got {ea!r}")
        object.__setattr__(self, "axial_stiffness", float(ea))


def mesh_label(mesh: Mesh) -> str:
    """How tables name a mesh.

    Parameters
    ----------
    mesh : Mesh
        The finite elements of both links.

    Returns
    -------
    str
        "ANCF 4 el/link", "GE 16 el/link", or "ANCF 4+8 el/link" where the links differ.

    Examples
    --------
    >>> from plant_exudyn import Mesh, mesh_label
    >>> mesh_label(Mesh("geometrically_exact", (16, 8)))
    'GE 16+8 el/link'
    """
    n1, n2 = mesh.elements_per_link
    name = "ANCF" if mesh.element == "ancf" else "GE"
    return f"{name} {n1 if n1 == n2 else f'{n1}+{n2}'} el/link"
