"""The paper's reduced model: a planar two-link lightweight arm with assumed modes.

Euler–Lagrange, clamped-mass assumed modes (De Luca & Siciliano, IEEE Trans. SMC 21(4),
1991), as used by the paper's eq. (1)–(3) and (22).  Public surface: `ArmParameters`
(Table 1), `LinkModes` (mode shapes), `ArmModel` (M, C, K, D, rhs, kinematics, linear
analysis) and `ReducedPlant` (the model used as a plant).
"""
from ._model import ArmModel, validate_modes_per_link
from ._modes import LinkModes
from ._parameters import ArmParameters
from ._plant import ReducedPlant
from ._plant_interface import Measurement, Plant, PlantFailure, TrueState, check_sample_time
from ._sensors import SensorConfig, SensorModel

__all__ = [
    "ArmParameters", "ArmModel", "LinkModes", "ReducedPlant", "Measurement", "TrueState",
    "Plant", "PlantFailure", "SensorConfig", "SensorModel", "check_sample_time",
    "validate_modes_per_link",
]
