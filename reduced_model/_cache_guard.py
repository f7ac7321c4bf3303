"""Keep numba's on-disk caches consistent with the project's compiled code.

Numba keys a cached function on its *own* source file, but the machine code it caches
contains what it inlined or called from other files: the controllers inline
`_kernels.py`, the compiled sample (`validation/_sample.py`) calls the laws' kernels.
After any of those files changes, a cached caller would silently run the old callee.
On import we compare a fingerprint of every project file that defines compiled code
with the one the caches were built from and, if it differs, delete the project's cached
kernels so that numba recompiles them.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

_PACKAGES = ("reduced_model", "controllers", "plant_exudyn", "validation")


def invalidate_stale_kernel_caches() -> None:
    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for package in _PACKAGES:
        for source in sorted((here.parent / package).rglob("*.py")):
            text = source.read_bytes()
            if b"@njit" in text:
                h.update(str(source.relative_to(here.parent)).encode() + b"\0" + text)
    fingerprint = h.hexdigest()
    stamp = here / "__pycache__" / "numba_kernels.fingerprint"
    try:
        if stamp.exists() and stamp.read_text() == fingerprint:
            return
        for package in _PACKAGES:
            for pattern in ("*.nbi", "*.nbc"):
                for cached in (here.parent / package).rglob(f"__pycache__/{pattern}"):
                    cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(fingerprint)
    except OSError:  # read-only install: caches cannot be stale there either
        pass
