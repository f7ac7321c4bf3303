"""Co-simulation FMUs as plants (``[plant] kind = "fmu"``, through FMPy, the ``fmi`` extra):
`settings` (the plant table, its mapping of the plant contract to the FMU's variables,
its checks), `plant` (the FMU stepped one control period per communication step),
`description` (reading and checking an FMU, its hash)."""
from .description import file_sha256, fmpy, read_description, signal_names
from .plant import FmuPlant
from .settings import FmuSettings

__all__ = ["FmuSettings", "FmuPlant", "file_sha256", "fmpy", "read_description",
           "signal_names"]
