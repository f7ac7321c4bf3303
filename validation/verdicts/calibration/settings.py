"""Calibration settings: the ``[calibrate]`` table of a scenario file and ``--fit``,
checked against the scenario before anything runs (``flexarm calibrate``; the fit is
`validation.verdicts.calibration`)."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from reduced_model.arm import flat_key_field

from ...run.config import ConfigError, check, check_known, did_you_mean
from ...run.scenario import Scenario, scenario_from_mapping
from ...run.tomlfiles import flatten
from .joints import check_overlap, check_start_arm, joint_bounds

__all__ = ["Parameter", "CalibrationSettings", "calibration_settings", "base_scenario",
           "INPUT_MODES"]

INPUT_MODES = ("replay", "closed-loop")
_SETTINGS = {"fit", "start", "bounds", "inputs", "horizon", "fd_step", "max_iterations",
             "noise", "experiment", "frf_theta", "frf_noise", "frf_band"}
#: Arm fields a fit may not change: the links' lengths are measured with a rule, and the
#: modal coordinates of links of different lengths cannot be compared.
_FIXED = {"L1", "L2"}


@dataclass(frozen=True)
class Parameter:
    """A fitted scenario field: its dotted ``name``, ``start`` value, bounds and the
    ``scale`` the fit measures it in (its start, or the bounds' span if it starts at 0)."""

    name: str
    start: float
    lower: float
    upper: float
    scale: float

    @property
    def short(self) -> str:
        return self.name.rsplit(".", 1)[-1]


@dataclass(frozen=True)
class CalibrationSettings:
    """``[calibrate]`` of a scenario file, with ``--fit`` (README, *Calibration*)."""

    parameters: tuple[Parameter, ...]
    inputs: str = "replay"
    horizon: float = 0.1
    fd_step: float = 1e-3
    max_iterations: int = 100
    noise: dict = dataclasses.field(default_factory=dict)
    experiment: dict = dataclasses.field(default_factory=dict)
    frf_theta: tuple[float, float] = (0.0, 0.0)
    frf_noise: float = 0.01
    frf_band: float = 1.0

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)


def _number(value, key: str, *, positive: bool = False) -> float:
    check(isinstance(value, (int, float)) and not isinstance(value, bool)
          and math.isfinite(value) and (value > 0 or not positive), key,
          f"must be a finite number{' > 0' if positive else ''}, got {value!r}")
    return float(value)


def _start(name: str, table: dict, base: Scenario) -> float:
    """The start of the fitted field ``name`` (checked to be one first)."""
    where = f"--fit {name}"
    head, _, field = name.partition(".")
    if head == "sensors":
        raise ConfigError(where, "the sensor model has no gain or bias, and its delay is a "
                                 "whole number of samples, not a least-squares parameter: set "
                                 "sensors.delay in the scenario")
    arm = base.true_params
    known = {k for k in arm.keys() if k != "gravity" and not k.startswith("modes")}
    check(head == "true_params" and field != "gravity" and not field.startswith("modes")
          and flat_key_field(field, arm.n_links) is not None, where,
          f"not a fittable field (true_params.<one of {', '.join(sorted(known - _FIXED))}>)")
    check(field not in _FIXED, where, "the links' lengths are not fitted (measure them; the "
                                      "controller's model must have the same)")
    return _number(table.get("start", {}).get(name, getattr(base.true_params, field)),
                   f"calibrate.start.{name}")


def _parameter(name: str, table: dict, base: Scenario, starts: dict) -> Parameter:
    field = name.partition(".")[2]
    start = starts[field]
    lower, upper = 0.0, math.inf
    given = {n.partition(".")[2] for n in table.get("bounds", {})}
    if name in table.get("bounds", {}):
        pair = table["bounds"][name]
        check(isinstance(pair, list) and len(pair) == 2, f"calibrate.bounds.{name}",
              "must be [lower, upper]")
        lower = _number(pair[0], f"calibrate.bounds.{name}[0]")
        upper = pair[1] if pair[1] == math.inf else _number(pair[1], f"calibrate.bounds.{name}[1]")
    check(0 <= lower < upper, f"calibrate.bounds.{name}",
          f"needs 0 <= lower < upper (an arm's values are >= 0), got [{lower}, {upper}]")
    lower, upper = joint_bounds(name, field, base.true_params, given, starts, lower, upper)
    check(lower <= start <= upper, f"calibrate.start.{name}",
          f"{start!r} is outside the bounds [{lower}, {upper}]")
    scale = start if start > 0 else upper - lower
    check(math.isfinite(scale), f"calibrate.start.{name}",
          "starts at 0 with no upper bound: give a start > 0 or finite bounds (the fit "
          "measures a parameter relative to its start)")
    return Parameter(name, start, lower, upper, scale)


def calibration_settings(table: dict, fit: list[str] | None, base: Scenario) -> CalibrationSettings:
    """The settings of a ``[calibrate]`` table, checked against a scenario.

    Parameters
    ----------
    table : dict
        The ``[calibrate]`` table of a scenario or campaign file.
    fit : list of str or None
        Scenario fields named by ``--fit``; they win over ``calibrate.fit``.
    base : Scenario
        The scenario the fitted fields must exist in.

    Returns
    -------
    CalibrationSettings
        The parameters with their start values and bounds, the noise and the weights.

    Raises
    ------
    ConfigError
        Naming the offending key.
    """
    check(isinstance(table, dict), "calibrate", "must be a table")
    for key in table:
        check_known(key, _SETTINGS, f"calibrate.{key}")
    table = dict(table)
    for key in ("start", "bounds", "noise"):
        check(isinstance(table.get(key, {}), dict), f"calibrate.{key}", "must be a table")
        table[key] = flatten(table.get(key, {}))
    names = fit if fit is not None else table.get("fit")
    check(isinstance(names, list) and names and all(isinstance(n, str) for n in names),
          "--fit", "name the scenario fields to fit (e.g. --fit true_params.EI1,true_params.Mp "
                   "or fit = [...] in [calibrate])")
    twice = sorted({n for n in names if names.count(n) > 1})
    check(not twice, "--fit", f"{', '.join(twice)} named more than once")
    own = table.get("fit") if isinstance(table.get("fit"), list) else []
    for key in ("start", "bounds"):
        for name in table[key]:
            if name in names:
                continue
            if fit is not None and name in own:
                every = ",".join(dict.fromkeys([*own, *names]))
                raise ConfigError(f"calibrate.{key}.{name}", (
                    f"not fitted: --fit {','.join(names)} replaces the file's fit list "
                    f"({', '.join(own)}); to fit both, name every field in --fit "
                    f"(--fit {every})"))
            raise ConfigError(f"calibrate.{key}.{name}", "not a fitted field (--fit)"
                                                          f"{did_you_mean(name, names)}")
    starts = {n.partition(".")[2]: _start(n, table, base) for n in names}
    parameters = tuple(_parameter(n, table, base, starts) for n in names)
    check_overlap({p.name.partition(".")[2]: (p.name, p.lower, p.upper) for p in parameters})
    check_start_arm(base.true_params, starts)
    inputs = table.get("inputs", "replay")
    check(inputs in INPUT_MODES, "calibrate.inputs", f"must be one of "
                                                     f"{', '.join(INPUT_MODES)}, got {inputs!r}")
    noise = {k: _number(v, f"calibrate.noise.{k}", positive=True)
             for k, v in table["noise"].items()}
    experiment = table.get("experiment", {})
    check(isinstance(experiment, dict) and all(isinstance(v, dict) for v in experiment.values()),
          "calibrate.experiment", "must be a table of tables ([calibrate.experiment.NAME])")
    joints = base.true_params.n_links
    theta = table.get("frf_theta", [0.0] * joints)
    check(isinstance(theta, list) and len(theta) == joints, "calibrate.frf_theta",
          f"must be one angle per joint, [{', '.join(f'theta{i + 1}' for i in range(joints))}]"
          " [rad]")
    iterations = table.get("max_iterations", 100)
    check(isinstance(iterations, int) and not isinstance(iterations, bool) and iterations >= 1,
          "calibrate.max_iterations", f"must be an integer >= 1, got {iterations!r}")
    step = _number(table.get("fd_step", 1e-3), "calibrate.fd_step", positive=True)
    check(step <= 0.1, "calibrate.fd_step", f"must be <= 0.1 (relative), got {step!r}")
    return CalibrationSettings(
        parameters=parameters, inputs=inputs, max_iterations=iterations, fd_step=step,
        horizon=_number(table.get("horizon", 0.1), "calibrate.horizon", positive=True),
        noise=noise, experiment={k: flatten(v) for k, v in experiment.items()},
        frf_theta=tuple(_number(v, f"calibrate.frf_theta[{i}]") for i, v in enumerate(theta)),
        frf_noise=_number(table.get("frf_noise", 0.01), "calibrate.frf_noise", positive=True),
        frf_band=_number(table.get("frf_band", 1.0), "calibrate.frf_band", positive=True))



def base_scenario(path) -> tuple[Scenario, dict]:
    """The scenario a calibration starts from and its ``[calibrate]`` table.

    Parameters
    ----------
    path : path-like
        A scenario file, or a campaign file (its ``[scenario]`` base).

    Returns
    -------
    (Scenario, dict)
        The scenario, named as the file names it (else after the file or campaign), and
        the ``[calibrate]`` table (empty when there is none).
    """
    from ...batch.campaign import load_study, own_name
    study = load_study(path)
    return (scenario_from_mapping({"name": study.name} | study.base | own_name(study)),
            study.calibrate)
