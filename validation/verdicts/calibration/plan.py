"""The plan of a calibration: every experiment and frequency response checked against
the scenario before anything is written, and the plant's linearised frequency response
they are compared with (``flexarm calibrate``)."""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from reduced_model import output_names

from ...run.config import ConfigError, check
from ...run.experiments import Experiment, FrequencyResponse, check_experiment, torque_columns
from ...run.laws import measurement_names, nominal_model
from ...run.loop import measurement_noise
from ...run.scenario import Scenario, own_parameters, scenario_from_mapping, scenario_to_mapping
from ...run.tomlfiles import set_dotted
from .settings import CalibrationSettings
from .units import check_units

__all__ = ["Target", "Plan", "plan_calibration", "linear_response"]

#: A stored run's settings that describe its experiment rather than the arm: a run used
#: as data keeps them (its timing, initial state, sensors and their modal basis).
_EXPERIMENT_KEYS = ("Ts", "initial_state", "reference", "sensors", "nominal_params", "model")
#: Weight of a signal whose noise level is not declared: this fraction of its RMS.
_UNDECLARED_NOISE = 1e-3


@dataclass(frozen=True)
class Target:
    """One time-domain experiment and the scenario that reproduces it (start values).

    ``sigma``: the weight of each signal (its noise level, or `_UNDECLARED_NOISE` of its
    RMS); ``noise``: the declared level (0 where none is)."""

    experiment: Experiment
    scenario: dict
    sigma: np.ndarray
    noise: np.ndarray


@dataclass(frozen=True)
class Plan:
    """A checked calibration: settings, the scenario it starts from, its experiments and
    frequency responses."""

    settings: CalibrationSettings
    base: dict
    targets: tuple[Target, ...]
    responses: tuple[FrequencyResponse, ...]


def _experiment_mapping(base: dict, exp: Experiment, own: dict | None,
                        overrides: dict, settings: CalibrationSettings) -> dict:
    """The scenario of one experiment: the base (the arm and its start values), a stored
    run's own experiment settings, ``[calibrate.experiment.NAME]``, its length."""
    data = own_parameters(copy.deepcopy(base))  # over the experiment's arm
    for key in _EXPERIMENT_KEYS if own is not None else ():
        data[key] = copy.deepcopy(own[key])
    for key, value in overrides.items():
        check(key not in settings.names, f"calibrate.experiment.{exp.name}.{key}",
              "is fitted: one value for every experiment")
        set_dotted(data, key, value, defaults=base)
    data["duration"] = exp.duration
    data.pop("transient", None)  # the default of the new duration
    return data


def _not_given(name: str, experiments: list[Experiment]) -> str:
    """Why the settings of experiment ``name`` have no data, and which file to pass: the
    ``name.csv`` beside a given file if there is one."""
    given = ", ".join(f"{e.name} ({e.source})" for e in experiments) or "none"
    beside = [Path(e.source).with_name(f"{name}.csv") for e in experiments]
    found = next((str(p) for p in beside if p.is_file()), None)
    cure = f"pass {found} too" if found else \
        f"pass its data too ({name}.csv, or a stored run RESULTS/{name})"
    return (f"settings of an experiment that is not given (an experiment is named after its "
            f"file; given: {given}): {cure}, or remove the table")


def plan_calibration(base: Scenario, settings: CalibrationSettings,
                     experiments: list[tuple[Experiment, dict | None]],
                     responses: list[FrequencyResponse] = ()) -> Plan:
    """Check every experiment and frequency response before anything runs.

    Nothing is written.

    Parameters
    ----------
    base : Scenario
        The scenario being calibrated.
    settings : CalibrationSettings
        From `calibration_settings`.
    experiments : list of (Experiment, dict or None)
        Each experiment with the resolved scenario of the stored run it came from, or
        None for a file.
    responses : list of FrequencyResponse
        Frequency responses, checked against the plant's linear outputs.

    Returns
    -------
    Plan
        What `calibrate` runs.

    Raises
    ------
    ConfigError
        Naming the file, column or key (an angle in degrees: `units.check_units`).
    """
    check(bool(experiments) or bool(responses), "DATA", "no experiment and no --frf file")
    names = [e.name for e, _ in experiments] + [r.name for r in responses]
    twice = sorted({n for n in names if names.count(n) > 1})
    check(not twice, "DATA", f"two experiments are called {', '.join(twice)} (rename a file)")
    for name in settings.experiment:
        check(name in names, f"calibrate.experiment.{name}",
              _not_given(name, [e for e, _ in experiments]))
    mapping = scenario_to_mapping(base)
    targets = []
    for exp, own in experiments:
        data = _experiment_mapping(mapping, exp, own, settings.experiment.get(exp.name, {}),
                                   settings)
        try:
            scenario = scenario_from_mapping(data)
        except ConfigError as exc:
            raise ConfigError(f"{exp.source}: {exc.path}", exc.message) from None
        model = nominal_model(scenario.nominal_params, scenario.model.modes_per_link)
        check_experiment(exp, scenario, measurement_names(scenario, model))
        declared = measurement_noise(scenario.sensors, exp.names)
        for i, name in enumerate(exp.names):
            declared[i] = settings.noise.get(name, declared[i])
        rms = np.sqrt(np.mean(exp.signals ** 2, axis=1))
        sigma = np.where(declared > 0, declared,
                         _UNDECLARED_NOISE * np.where(rms > 0, rms, 1.0))
        targets.append(Target(exp, scenario_to_mapping(scenario), sigma, declared))
    check_units(targets)
    for response in responses:
        outputs = _linear_outputs(base)
        for out, inp in response.pairs:
            check(out in outputs, f"{response.source}: column {out}/{inp}.re",
                  f"{out!r} is not an output of the linear model ({', '.join(outputs)})")
            inputs = torque_columns(base.true_params.n_links)
            check(inp in inputs, f"{response.source}: column {out}/{inp}.re",
                  f"{inp!r} is not an input ({', '.join(inputs)})")
    if responses:  # the plant must have a linearisation (one frequency of one pair)
        try:
            linear_response(base, settings.frf_theta, responses[0].frequency[:1],
                            responses[0].pairs[:1])
        except NotImplementedError as exc:
            raise ConfigError("--frf", f"{exc}: a frequency response is fitted on the "
                                       "plant's linearisation; fit time series, or the "
                                       "responses on a built-in plant") from None
    return Plan(settings, mapping, tuple(targets), tuple(responses))


# --- the plant's frequency response ---------------------------------------------------------
def _linear_outputs(s: Scenario) -> tuple[str, ...]:
    return output_names(tuple(s.model.modes_per_link))


def linear_response(s: Scenario, theta, frequency: np.ndarray, pairs) -> np.ndarray:
    """The frequency responses ``pairs`` = [(output, input)] of the scenario's plant
    linearised about rest at ``theta``, at ``frequency`` [Hz]: (len(pairs), F) complex.
    The q outputs are in the basis the sensors report them in (the controller's model).
    The reduced plant is the model of its own order; any other plant is the FE arm of
    its mesh (`plant_exudyn.linear_model`): the linear model its kind declares
    (NotImplementedError for a kind that has none: a plug-in's)."""
    system = s.plant.linear_model(s.true_params, theta=theta,
                                  model=nominal_model(s.nominal_params, s.model.modes_per_link))
    A, B, C = (np.asarray(m) for m in (system.A, system.B, system.C))
    outs, ins = list(system.output_labels), list(system.input_labels)
    rows = [outs.index(o) for o, _ in pairs]
    cols = [ins.index(i) for _, i in pairs]
    eye = np.eye(A.shape[0])
    out = np.empty((len(pairs), len(frequency)), dtype=complex)
    for j, f in enumerate(frequency):
        X = np.linalg.solve(2j * np.pi * f * eye - A, B)
        G = C @ X
        out[:, j] = G[rows, cols]
    return out
