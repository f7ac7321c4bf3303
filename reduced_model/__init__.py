"""The paper's reduced model: a planar two-link lightweight arm with assumed modes.

Euler–Lagrange, clamped-mass assumed modes (De Luca & Siciliano, IEEE Trans. SMC 21(4),
1991), as used by the paper's eq. (1)–(3) and (22).  Public surface: `ArmParameters`
(Table 1), `LinkModes` (mode shapes), `ArmModel` (M, C, K, D, rhs, kinematics, linear
analysis), `ReducedPlant` (the model used as a plant), and the Plant interface and
sensors shared with the Exudyn plant.
"""
from ._linear import reduced_linear_model
from ._model import KINEMATICS, ArmModel, cached_model, validate_modes_per_link
from ._modes import LinkModes
from ._parameters import ArmParameters, FieldError
from ._plant import ReducedPlant
from ._plant_base import LEVELS, ROLES, Plant, PlantSettings, Refinement
from ._plant_interface import (Measurement, PlantFailure, TrueState, check_sample_time,
                               coordinate_names, output_names)
from ._sensors import STRAIN_QUANTITIES, SensorConfig, SensorModel, measured_names

__all__ = [
    "ArmParameters", "FieldError", "ArmModel", "cached_model", "LinkModes", "ReducedPlant", "Measurement",
    "TrueState", "Plant", "PlantFailure", "SensorConfig", "SensorModel", "STRAIN_QUANTITIES",
    "check_sample_time", "validate_modes_per_link", "PlantSettings", "Refinement", "ROLES",
    "LEVELS", "coordinate_names", "output_names", "reduced_linear_model", "measured_names",
    "KINEMATICS",
]
