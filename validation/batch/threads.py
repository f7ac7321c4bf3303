"""One thread per numerical library: the matrices here are small, and idle BLAS or numba
threads busy-wait on the cores the simulations run on (two workers on two cores would
otherwise slow each other down).  Imports nothing, so that the command line can apply it
before numpy is loaded; `validation.run.threads` holds the libraries already loaded to
one thread while a run is built and simulated."""
from __future__ import annotations

import os

__all__ = ["ONE_THREAD", "prefer_one_thread"]

#: The environment that keeps each library to one thread.
ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                     "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}


def prefer_one_thread() -> None:
    """Set `ONE_THREAD` in this process's environment where the user has not chosen."""
    for name, value in ONE_THREAD.items():
        os.environ.setdefault(name, value)
