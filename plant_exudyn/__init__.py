"""The truth plant: a planar arm of 1–4 links as an Exudyn flexible multibody model.

Flexible links are ANCF cable elements (default) or geometrically exact 2D beams, rigid
links rigid bodies, in gravity or not, built from the same `reduced_model.ArmParameters`
as the reduced model; the deflection field is projected onto the reduced model's mode
shapes so that both plants report the same coordinates.  `ExudynPlant` implements the plant contract (`reduced_model.Plant`);
`linear_model` linearises the FE arm about a configuration (a `control.StateSpace`).

Loading the package (`Mesh`, the `ExudynPlant` class and its settings) never loads
Exudyn: the solver (and its OpenGL libraries) is imported when a plant is built, so that
describing a scenario — or reading, reporting and exporting stored results — never loads
it.
"""
import importlib

from ._mesh import ELEMENTS, Mesh, mesh_label
from ._plant import ExudynPlant, linear_model

__all__ = ["ExudynPlant", "Mesh", "ELEMENTS", "mesh_label", "ArmSystem", "build_arm",
           "LinkField", "natural_frequencies", "simulation_settings", "linear_model"]

_LAZY = {"simulation_settings": "._build", "ArmSystem": "._build", "build_arm": "._build",
         "LinkField": "._fields", "natural_frequencies": "._modal"}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name], __name__), name)
    raise AttributeError(f"module 'plant_exudyn' has no attribute {name!r}")
