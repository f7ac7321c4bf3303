"""What code a module can run, read without importing it (`imports`: the import walk the
code fingerprint, the numba cache guard and the house tests use), and the guard that keeps
numba's on-disk caches consistent with the code (`cache_guard`)."""
from .cache_guard import (KEYS_FILE, cache_dirs, fresh_kernel_caches,
                          invalidate_stale_plugin_caches, kernel_keys)
from .imports import Walk, imports, installed, walk

__all__ = ["KEYS_FILE", "cache_dirs", "fresh_kernel_caches", "invalidate_stale_plugin_caches",
           "kernel_keys", "Walk", "imports", "installed", "walk"]
