"""A run computes with one thread per numerical library, however its process was started.

The environment `validation.batch.threads.ONE_THREAD` asks for one thread only of the
libraries loaded after it is set: the ``flexarm`` command sets it first, but a run in a
Python session or notebook, or in a worker forked from one, inherited numpy's OpenBLAS
with a thread per core — and a multithreaded product sums in another order: the same
run (ANCF 16 el/link) gave a robustness 2e-12 apart on local workers and on Dask's
(whose nanny sets the environment), where the runners promise identical values.  So
`one_thread` limits the loaded libraries themselves (threadpoolctl, as scikit-learn
does) while a run is built and simulated: the values no longer depend on how the process
started, and two workers no longer share two cores with BLAS threads spinning beside them.
"""
from __future__ import annotations

import functools

__all__ = ["one_thread"]


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
