"""The finite-element discretisation of the truth plant's links, described without Exudyn
(a scenario names its mesh; only building the arm needs the solver)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from reduced_model import ArmParameters, FieldError
from reduced_model.arm import MAX_LINKS

__all__ = ["Mesh", "ELEMENTS", "MAX_ELEMENTS", "mesh_label"]

ELEMENTS = ("ancf", "geometrically_exact")
#: The most elements a link may have.
MAX_ELEMENTS = 64


def _count(n) -> bool:
    return isinstance(n, (int, np.integer)) and not isinstance(n, bool) and 1 <= n <= MAX_ELEMENTS


@dataclass(frozen=True)
class Mesh:
    """Finite-element discretisation of the arm's flexible links (a rigid link is one
    rigid body: it has no elements).

    Parameters
    ----------
    element : {"ancf", "geometrically_exact"}
        ANCF cable elements (Euler–Bernoulli; cubic Hermite position field with nodal
        slopes) or geometrically exact 2D beams (Reissner; linear interpolation).
    elements_per_link : int or tuple of int
        One number for every flexible link, or one count per flexible link, from the
        base out (rigid links skipped: ``[8, 16]`` on a rigid–flexible–flexible arm
        gives link 2 eight elements and link 3 sixteen); 1..64 each.  Default 4: the
        locked and free frequencies of the paper's Table 1 arm are then within 0.04 % of
        the converged values (convergence study in tests/test_exudyn_fidelity.py).
    axial_stiffness : float
        EA [N] of every flexible link.  1e7 puts the first axial mode near 520 Hz, far
        above the bending modes of interest, without changing them.  The geometrically
        exact beam also derives its shear stiffness (0.4 EA) and cross-section rotary
        inertia per length (ρ EI/EA = ρ I/A) from it.
    """

    element: str = "ancf"
    elements_per_link: int | tuple[int, ...] = 4
    axial_stiffness: float = 1e7

    def __post_init__(self) -> None:
        if self.element not in ELEMENTS:
            raise FieldError("mesh", "element", f"must be one of {ELEMENTS}, got {self.element!r}")
        epl = self.elements_per_link
        if _count(epl):
            object.__setattr__(self, "elements_per_link", int(epl))
        elif (isinstance(epl, (tuple, list)) and 1 <= len(epl) <= MAX_LINKS
              and all(_count(n) for n in epl)):
            object.__setattr__(self, "elements_per_link", tuple(int(n) for n in epl))
        else:
            raise FieldError("mesh", "elements_per_link", f"must be an integer 1..64 (every "
                             f"flexible link) or one per flexible link (at most {MAX_LINKS}), "
                             f"got {self.elements_per_link!r}")
        ea = self.axial_stiffness
        if isinstance(ea, bool) or not isinstance(ea, (int, float)) or not np.isfinite(ea) \
                or ea <= 0:
            raise FieldError("mesh", "axial_stiffness", f"must be a finite number > 0, got {ea!r}")
        object.__setattr__(self, "axial_stiffness", float(ea))

    def counts(self, arm: ArmParameters) -> tuple[int, ...]:
        """The elements of each link of ``arm`` (0 for a rigid link); FieldError naming
        ``elements_per_link`` where it gives a count for a link that has none.

        Examples
        --------
        >>> from plant_exudyn import Mesh
        >>> from reduced_model import ArmParameters
        >>> Mesh(elements_per_link=8).counts(ArmParameters(modes1=0, EI1=0.0,
        ...                                                bending_damping1=0.0))
        (0, 8)
        """
        flexible = [i for i, link in enumerate(arm.links) if not link.rigid]
        epl = self.elements_per_link
        given = (epl,) * len(flexible) if isinstance(epl, int) else epl
        if len(given) != len(flexible):
            links = ", ".join(str(i + 1) for i in flexible) or "none"
            raise FieldError("mesh", "elements_per_link", f"gives {len(given)} counts, one per "
                             f"flexible link, but the arm's flexible links are {links} (a "
                             "rigid link has no elements): give one number or one count per "
                             "flexible link")
        out = [0] * arm.n_links
        for i, n in zip(flexible, given):
            out[i] = n
        return tuple(out)

    def refined(self, factor: int) -> int | tuple[int, ...]:
        """``elements_per_link`` with every count times ``factor`` (unchecked)."""
        epl = self.elements_per_link
        return factor * epl if isinstance(epl, int) else tuple(factor * n for n in epl)


def mesh_label(mesh: Mesh) -> str:
    """How tables name a mesh.

    Parameters
    ----------
    mesh : Mesh
        The finite elements of the flexible links.

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
    epl = mesh.elements_per_link
    counts = (epl,) if isinstance(epl, int) else epl
    name = "ANCF" if mesh.element == "ancf" else "GE"
    same = len(set(counts)) == 1
    return f"{name} {counts[0] if same else '+'.join(str(n) for n in counts)} el/link"
