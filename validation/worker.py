"""What a local worker process imports once, before it runs anything: the simulation
code (models, plants, laws, the closed loop, metrics) and its compiled kernels — not the
command line and not matplotlib.  The forkserver preloads this module, so each worker
starts as a fork with all of it in memory."""
from . import executor, loop, metrics  # noqa: F401
from .laws import nominal_model
from reduced_model import ArmParameters

# Load the numba kernels from their cache once, in the server, rather than in each worker.
nominal_model(ArmParameters(), (2, 2))
