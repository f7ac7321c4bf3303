"""What a worker process needs before it runs anything: the simulation code (models,
plants, laws, the closed loop, metrics) loaded and its kernels compiled — not the command
line and not matplotlib.  `warm_up` runs two tiny scenarios in the parent before the
workers are forked, so numba compiles (first use on a machine) or loads (from its cache)
each kernel once, not once per worker."""
from __future__ import annotations

from pathlib import Path

from . import executor, loop, metrics  # noqa: F401 - loaded once, before the fork

__all__ = ["warm_up", "kernels_cached"]


def kernels_cached() -> bool:
    """Whether numba's cache holds the compiled sample loop (else the first run on this
    machine compiles it: a minute or two)."""
    return any((Path(__file__).parent / "__pycache__").glob("_sample.run_reduced-*.nbi"))


def warm_up() -> None:
    """Compile or load every kernel a run uses: the reduced loop with the built-in laws
    and an observer, and the Exudyn plant's readout."""
    from .loop import run_scenario
    from .scenario import scenario_from_mapping
    for plant in ("reduced", "exudyn"):
        run_scenario(scenario_from_mapping({"duration": 0.002, "transient": 0.0,
                                            "plant": {"kind": plant},
                                            "observer": {"kind": "smo-paper"}}))
