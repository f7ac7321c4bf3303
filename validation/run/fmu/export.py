"""``flexarm export-fmu``: a scenario's reduced plant and its laws as co-simulation FMUs
(FMI 2.0, built with pythonfmu, the ``fmi`` extra), each checked by FMPy's validation
of its model description before it is kept.

The FMUs carry Python sources (`validation.run.fmu.slaves`) and run them with the
interpreter of the environment that imports them, where this project is installed: a
tool importing them (Simulink, Dymola, OpenModelica, FMPy) needs that interpreter and
pythonfmu's runtime library found at load time."""
from __future__ import annotations

import importlib
import json
import os
import tempfile
from pathlib import Path

from reduced_model.arm import arm_to_table

from ..config import ConfigError, check
from ..scenario import Scenario, scenario_to_mapping
from .description import fmpy

__all__ = ["export_plant", "export_law", "SLAVES"]

#: The sources the FMUs run, by what they export.
SLAVES = Path(__file__).resolve().parent / "slaves"


def _builder():
    """pythonfmu's builder, or a ConfigError with the install line (imported by name:
    the run path never builds an FMU)."""
    try:
        return importlib.import_module("pythonfmu.builder").FmuBuilder
    except ImportError:
        raise ConfigError("export-fmu", "needs pythonfmu, the fmi extra: "
                                        "pip install -e '.[fmi]'") from None


def _build(source: str, description: dict, path, key: str) -> Path:
    """The FMU of the slave ``source`` with ``description`` in its resources at
    ``path``, refused (and removed) unless FMPy validates it."""
    path = Path(path)
    check(path.suffix == ".fmu", key, f"must name an .fmu file, got {str(path)!r}")
    check(path.parent.is_dir(), key, f"{path.parent} is not a folder")
    builder = _builder()
    with tempfile.TemporaryDirectory(prefix="flexarm-export-") as tmp:
        resource = Path(tmp) / f"{source}.json"
        resource.write_text(json.dumps(description))
        built = Path(builder.build_FMU(SLAVES / f"{source}.py", dest=path,
                                       project_files=[resource],
                                       canHandleVariableCommunicationStepSize=False))
    fmpy()  # FMPy itself, or the install line
    problems = importlib.import_module("fmpy.validation").validate_fmu(str(built))
    if problems:
        os.unlink(built)
        raise ConfigError(key, f"FMPy does not validate the FMU: {problems[0]}")
    return built


def export_plant(scenario: Scenario, path) -> Path:
    """Write the reduced plant of ``scenario``'s true arm (its plant table's modes,
    kinematics and step where it runs on the reduced plant; else the arm's own modes,
    the paper's kinematics, 1 ms) as a co-simulation FMU at ``path``.

    Parameters
    ----------
    scenario : Scenario
        The arm and plant to export.
    path : str or Path
        The ``.fmu`` file written.

    Returns
    -------
    Path
        ``path``, validated by FMPy (`fmpy.validation.validate_fmu`).
    """
    plant = scenario.plant
    own = plant.kind == "reduced"
    description = {
        "arm": arm_to_table(scenario.true_params),
        "modes_per_link": list(plant.modes_per_link if own and plant.modes_per_link
                               else scenario.true_params.modes()),
        "kinematics": plant.kinematics if own else "linear",
        "step": plant.step if own else 1e-3}
    return _build("arm_plant", description, path, "--plant-fmu")


def export_law(scenario: Scenario, path) -> Path:
    """Write ``scenario``'s controller and observer (on its nominal model, at its
    ``Ts``) as a co-simulation FMU at ``path`` (module `slaves.arm_law`: its inputs,
    outputs and parameters).

    Parameters
    ----------
    scenario : Scenario
        The laws to export (built-in laws or plug-ins importable where the FMU runs).
    path : str or Path
        The ``.fmu`` file written.

    Returns
    -------
    Path
        ``path``, validated by FMPy.
    """
    return _build("arm_law", scenario_to_mapping(scenario), path, "--law-fmu")
