"""The shapes a link's deflection is written in: clamped-mass assumed modes
(`reduced_model.shapes.modes`) and, for the exact kinematics, the inextensible
centreline they define (`reduced_model.shapes.inextensible`)."""
from .inextensible import InextensibleLink, interpolation_nodes, readout_matrix
from .modes import (LinkModes, block_diagonal, clamped_mass_roots, gauss_legendre, projection,
                    weighted_projector)

__all__ = ["InextensibleLink", "interpolation_nodes", "readout_matrix", "LinkModes",
           "block_diagonal", "clamped_mass_roots", "gauss_legendre", "projection",
           "weighted_projector"]
