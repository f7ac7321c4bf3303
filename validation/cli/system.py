"""What the machine must give beyond Python packages, and the one line that names the fix
when it does not: Exudyn's compiled module links OpenGL and X11 libraries (``libGL.so.1``,
``libGLX``, ``libGLdispatch``, ``libX11``, ``libxcb``) that a bare Debian or Ubuntu image
lacks, and ``import exudyn`` then fails before anything of ours runs."""
from __future__ import annotations

import re

__all__ = ["missing_library"]

#: Debian/Ubuntu packages that provide each library Exudyn links.
_PACKAGES = {"libGL": "libgl1", "libGLX": "libgl1", "libGLdispatch": "libgl1",
             "libX11": "libx11-6", "libxcb": "libxcb1"}
_MISSING = re.compile(r"(lib[\w+-]+)(\.so[\w.]*): cannot open shared object file")


def missing_library(exc: BaseException) -> str | None:
    """The message for an ImportError caused by a missing system library (None for any
    other ImportError)."""
    found = _MISSING.search(str(exc)) if isinstance(exc, ImportError) else None
    if found is None:
        return None
    name, package = found.group(1) + found.group(2), _PACKAGES.get(found.group(1))
    fix = f"apt-get install {package} (Debian/Ubuntu)" if package else \
        "your system's package manager"
    return (f"Exudyn (the truth plant) needs the system library {name}, which this machine "
            f"lacks: install it with {fix}, then run again")
