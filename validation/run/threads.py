"""One thread per numerical library: the matrices here are small, and idle BLAS or numba
threads busy-wait on the cores the simulations run on (two workers on two cores would
otherwise slow each other down).

Two mechanisms, for two moments.  Before numpy is loaded, the environment `ONE_THREAD`
asks for one thread only of the libraries loaded after it is set (`prefer_one_thread`:
this module imports nothing heavy, so that the command line can apply it first).  A run
in a Python session or notebook, or in a worker forked from one, inherited numpy's OpenBLAS
with a thread per core — and a multithreaded product sums in another order: the same
run (ANCF 16 el/link) gave a robustness 2e-12 apart on local workers and on Dask's
(whose nanny sets the environment), where the runners promise identical values.  So
`one_thread` limits the loaded libraries themselves (threadpoolctl, as scikit-learn
does) while a run is built and simulated: the values do not depend on how the process
started, and two workers do not share two cores with BLAS threads spinning beside them.
"""
from __future__ import annotations

import functools
import os

__all__ = ["one_thread", "ONE_THREAD", "prefer_one_thread"]

#: The environment that keeps each library to one thread.
ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                                     "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")}


def prefer_one_thread() -> None:
    """Set `ONE_THREAD` in this process's environment where the user has not chosen."""
    for name, value in ONE_THREAD.items():
        os.environ.setdefault(name, value)


@functools.cache
def _controller():
    from threadpoolctl import ThreadpoolController
    return ThreadpoolController()  # ~3 ms: the libraries loaded now (a run's are)


def one_thread(fn):
    """``fn`` calling every numerical library loaded with one thread (the limits are
    restored when it returns; ~10 µs a call)."""
    @functools.wraps(fn)
    def limited(*args, **kwargs):
        with _controller().limit(limits=1):
            return fn(*args, **kwargs)
    return limited
