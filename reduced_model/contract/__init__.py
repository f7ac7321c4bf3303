"""The plant contract: what a plant is (`plant`: the base class every plant kind
subclasses, its settings and refinements), what plants and the closed loop exchange
(`signals`: measurements, true states, the truth vector's layout, failures), what a plant
measures (`sensors`), and a plant's compiled form (`compiled`)."""
from .compiled import PLANT_SIGNATURE, CompiledPlant, KernelPointer, kernel_pointer, vector
from .plant import LEVELS, ROLES, Plant, PlantSettings, Refinement
from .sensors import STRAIN_QUANTITIES, SensorConfig, SensorModel, measured_names
from .signals import (Measurement, PlantFailure, TrueState, check_sample_time, coordinate_names,
                      motor_outputs, output_names, true_state_from_vector, truth_extras)

__all__ = ["PLANT_SIGNATURE", "CompiledPlant", "KernelPointer", "kernel_pointer", "vector",
           "LEVELS", "ROLES", "Plant", "PlantSettings", "Refinement", "STRAIN_QUANTITIES",
           "SensorConfig", "SensorModel", "measured_names", "Measurement", "PlantFailure",
           "TrueState", "check_sample_time", "coordinate_names", "motor_outputs",
           "output_names", "true_state_from_vector", "truth_extras"]
