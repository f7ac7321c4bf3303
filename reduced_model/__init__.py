"""The reduced model of a planar flexible arm with assumed modes, and what every plant
shares.

Euler–Lagrange, clamped-mass assumed modes (De Luca & Siciliano, IEEE Trans. SMC 21(4),
1991), as the paper's eq. (1)–(3) and (22) use for its two links, for any planar serial
arm of 1 to 4 rigid or flexible links, horizontal or in gravity.  Rooms: the arm
description (`arm`), the mode shapes (`shapes`), the compiled dynamics (`dynamics`), the
joints (`joints`), the model (`ArmModel`), the plant contract every plant kind fulfils
(`contract`), the reduced plant (`plant`), and the code walk behind fingerprints and
numba's caches (`code`).
"""
from .arm import (ArmFileError, ArmParameters, FieldError, Joint, Link, Payload, named_arm,
                  named_arms, read_arm)
from .contract import (LEVELS, ROLES, STRAIN_QUANTITIES, CompiledPlant, Measurement, Plant,
                       PlantFailure, PlantSettings, Refinement, SensorConfig, SensorModel,
                       TrueState, check_sample_time, coordinate_names, measured_names,
                       motor_outputs, output_names, truth_extras)
from .model import KINEMATICS, ArmModel, cached_model, validate_modes_per_link
from .plant import ReducedPlant, reduced_linear_model
from .shapes import LinkModes

__all__ = [
    "ArmFileError", "ArmParameters", "FieldError", "Joint", "Link", "Payload", "named_arm",
    "named_arms", "read_arm", "LEVELS", "ROLES", "STRAIN_QUANTITIES", "CompiledPlant",
    "Measurement", "Plant", "PlantFailure", "PlantSettings", "Refinement", "SensorConfig",
    "SensorModel", "TrueState", "check_sample_time", "coordinate_names", "measured_names",
    "motor_outputs", "output_names", "truth_extras", "KINEMATICS", "ArmModel", "cached_model",
    "validate_modes_per_link", "ReducedPlant", "reduced_linear_model", "LinkModes",
]
