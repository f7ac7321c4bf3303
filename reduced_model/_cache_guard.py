"""Keep numba's on-disk caches consistent with `_kernels.py`.

Numba keys a cached function on its *own* source file.  Kernels elsewhere in the
project (controllers, observers) inline `_kernels.py` functions and the layout of its
packed buffers; after `_kernels.py` changes, their cached machine code would silently
read the old layout.  On import we compare a fingerprint of `_kernels.py` with the one
the caches were built from and, if it differs, delete the project's cached kernels so
that numba recompiles them.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

_PACKAGES = ("reduced_model", "controllers", "plant_exudyn", "validation")


def invalidate_stale_kernel_caches() -> None:
    here = Path(__file__).resolve().parent
    fingerprint = hashlib.sha256((here / "_kernels.py").read_bytes()).hexdigest()
    stamp = here / "__pycache__" / "numba_kernels.fingerprint"
    try:
        if stamp.exists() and stamp.read_text() == fingerprint:
            return
        for package in _PACKAGES:
            for pattern in ("*.nbi", "*.nbc"):
                for cached in (here.parent / package / "__pycache__").glob(pattern):
                    cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(fingerprint)
    except OSError:  # read-only install: caches cannot be stale there either
        pass
