"""The reduced model as a plant (`ReducedPlant`), its readout of the laws' modal
coordinates and its linearisation."""
from .linear import reduced_linear_model
from .plant import ReducedPlant, positive_step

__all__ = ["ReducedPlant", "positive_step", "reduced_linear_model"]
