"""The truth plant: the two-link flexible arm as an Exudyn flexible multibody model.

Both links are ANCF cable elements (default) or geometrically exact 2D beams, built from
the same `reduced_model.ArmParameters` as the reduced model; the deflection field is
projected onto the reduced model's mode shapes so that both plants report the same
coordinates.  `ExudynPlant` implements the plant interface (`reduced_model._plant_interface`); `linear_model`
linearises the FE arm about a configuration (a `control.StateSpace`).
"""
import importlib

from ._build import ELEMENTS, ArmSystem, Mesh, build_arm
from ._fields import LinkField
from ._modal import natural_frequencies
from ._plant import ExudynPlant, simulation_settings

__all__ = ["ExudynPlant", "Mesh", "ELEMENTS", "ArmSystem", "build_arm", "LinkField",
           "natural_frequencies", "simulation_settings", "linear_model"]


def __getattr__(name: str):
    # Loaded on first use: the linear analysis (and python-control) is no part of a run,
    # so it stays out of the simulation path and of the runs' code fingerprint.
    if name == "linear_model":
        return importlib.import_module("._linear", __name__).linear_model
    raise AttributeError(f"module 'plant_exudyn' has no attribute {name!r}")
