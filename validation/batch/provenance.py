"""What is recorded with every run beside its code fingerprint: the versions of the
packages that made it and the git revision of the checkout."""
from __future__ import annotations

import functools
import platform
import subprocess
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

__all__ = ["environment"]


@functools.lru_cache(maxsize=1)
def environment() -> dict:
    """Versions and git revision recorded with every run."""
    def pkg(name):
        try:
            return version(name)
        except PackageNotFoundError:
            return None
    from ..run.plants import ENGINE_PACKAGES
    env = {name: pkg(name) for name in ("flexarm-validation", *ENGINE_PACKAGES, "numpy",
                                        "numba", "scipy")}
    env["python"] = platform.python_version()
    try:
        env["git"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                    text=True, timeout=5, cwd=Path(__file__).parent
                                    ).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        env["git"] = None
    return env
