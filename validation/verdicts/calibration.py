"""Calibration: the plant's physical parameters fitted to measured experiments, with
honest uncertainty (``flexarm calibrate``).

The fit minimises the weighted output error, a bounded nonlinear least-squares problem
solved by SciPy's ``least_squares``::

    r = [(y_sim,s(t_k; x) − y_meas,s(t_k)) / σ_s   for every experiment, signal s, sample k]
      + [ln(G(jω; x) / G_meas(jω)) / σ_frf   re and im, for every response and frequency]

x are scenario fields (``true_params.EI1``…) in units of their starting values; σ_s is
the noise level of signal s (the scenario's sensor noise, or ``[calibrate.noise]``);
σ_frf the relative error of a measured response (``frf_noise``, 1 %).  A response is
compared by the logarithm of its ratio (log-magnitude and phase error, equal to the
relative error where they agree): the difference of two sharp resonances a few per cent
apart is dominated by the peaks, the logarithm of their ratio is not.  G is the plant
linearised about rest (`linear_response`: the FE arm of the scenario's mesh, or the
reduced model), no time simulation.  As the time series grow their horizon (below), the
responses grow their band: from ``frf_band`` (1 Hz, below the free arm's first bending
mode) doubling to the highest frequency measured — fitting all of 0.5-40 Hz at once
from EI 30 % off stopped 30 % off (from 5 % off it converged); the growing band
converged from 30 % off on both plants.

**Inputs.**  A time-domain experiment is reproduced on the scenario's plant by replaying
its recorded joint torques open loop (``inputs = "replay"``, the ``replay`` law) or by
running the experiment's own controller and observer in the loop (``"closed-loop"``:
the scenario as it is, its sensor noise and seed included).  Replay is the default
because it conditions the fit better on a free-joint arm: with the controller in the
loop, feedback corrects the very deviations a parameter error causes — that is what a
robust tracking loop is for — so the outputs see the arm's parameters less.  Measured on
the reduced plant (PBC fed the true state, eq. (37), 10 s, the campaigns' sensor noise),
fitting EI1, EI2 and Mp: cond(J) 8.2 replayed against 68 in the loop, standard errors
5.0e-7, 2.2e-6, 3.7e-6 (relative) against 1.5e-6, 1.5e-5, 3.7e-5.  Replay also needs
nothing the lab cannot record: the torques are what the arm received, noise and
disturbances included, where a closed-loop fit must reproduce the experiment's noise
realisation as well (with the experiment's own seed the residual is zero, and so is
the standard error it would report).  Its price is a narrow basin: open loop, an error
in the arm's inertia or stiffness accumulates (the joints integrate the torque twice,
the vibration drifts out of phase), so a 10 s output error is far from quadratic.
From five starts 20 % to 5× off, a fit of the whole 10 s record converged (all three
within 1 %) in 0 of 5 cases replayed and 2 of 5 in the loop.  The fit therefore *grows
its horizon*: it is solved on the first ``horizon`` seconds (0.1 s: a fraction of the
first vibration period, where the output error is nearly linear in the parameters),
then on twice that, and so on up to the whole record, each stage starting from the last
estimate: 5 of 5 converged either way (744 simulations replayed, 522 in the loop).

**Method.**  SciPy's dogleg with rectangular trust regions (``method="dogbox"``), not its
trust-region reflective method (``"trf"``): both took about as many simulations on a
well-posed fit (EI1, EI2, Mp from three starts up to 5× off: 121, 145, 152 against 127,
135, 118), but where the data cannot see a direction (mh2 and stator_mass, mh1, with
EI1) the reflective method's scaling damped every step: 30 evaluations took its cost
from 3.2e7 to 7.6e3, at a linear rate of 0.8 per step, where dogbox reached the data's
floor (5e-7) in 6.  The directions the Jacobian cannot resolve are removed from it
before each step (`_without_invisible`).

**Jacobians** are forward differences (``fd_step`` relative to the starting values,
1e-3): the simulations of one Jacobian are independent runs, submitted together to the
campaign runner (local worker processes or Dask), stored in the output folder like any
run (sweep ``calibrate``) and read back from it — so an interrupted calibration, rerun,
replays what is stored and continues to the same answer.  A replayed experiment's
torques are a file in the output folder, named in the scenario by path and SHA-256: Dask
workers must see that folder at the same path.

**Uncertainty.**  At the estimate the Jacobian is recomputed by central differences
(truncation error O(h²), so an exact degeneracy shows as one), and with the residual
variance s² = rᵀr / (m − p) the covariance is s² (JᵀJ)⁻¹, by the singular value
decomposition J = U S Vᵀ.  A direction v_k of parameter space is *not identifiable*
when the data cannot see it: its singular value is within the Jacobian's own error (the
float32 resolution of stored signals over the difference step, ×10), or the data
determine it only to more than ±100 % of the starting values (s / S_k > 1).  Every
parameter with a weight |v_k,i| ≥ 0.1 on such a direction is reported *not
identifiable*, with the direction (e.g. +0.45 mh2 − 0.89 stator_mass: two masses at
the same point, which the arm sees only as their sum) and no standard error; the others
get their standard error, a 95 % interval (Student t, m − p degrees of freedom) and
their correlations, from the identifiable directions alone.  A parameter whose estimate
sits on a bound has no valid interval either (the data ask for a value beyond it).  The
intervals assume what the weighting says: white measurement noise of the stated levels
and a model that can reproduce the data; the residual RMS of every signal is reported
next to its noise level so that a model error (RMS well above the noise) shows.
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.optimize
import scipy.stats

from reduced_model import ArmParameters, cached_model

from ..batch.store import run_id
from ..run._config import ConfigError, check
from ..run.experiments import Experiment, FrequencyResponse, check_experiment, write_experiment
from ..run.laws import measurement_names, nominal_model
from ..run.loop import measurement_noise
from ..run.results import write_atomic
from ..run.scenario import Scenario, scenario_from_mapping, scenario_to_mapping
from ..run.tomlfiles import deep_merge, flatten, set_dotted, toml_text, toml_value
from ..batch.resimulate import every_signal
from .verify import Evaluations

__all__ = ["Parameter", "CalibrationSettings", "calibration_settings", "Target", "Plan",
           "plan_calibration", "calibrate", "parameter_uncertainty", "linear_response",
           "base_scenario", "INPUT_MODES", "FIT_SWEEP"]

INPUT_MODES = ("replay", "closed-loop")
#: The sweep the calibration's simulations are stored under (reports keep them apart).
FIT_SWEEP = "calibrate"
#: A stored run's settings that describe its experiment rather than the arm: a run used
#: as data keeps them (its timing, initial state, sensors and their modal basis).
_EXPERIMENT_KEYS = ("Ts", "initial_state", "reference", "sensors", "nominal_params", "model")
_SETTINGS = {"fit", "start", "bounds", "inputs", "horizon", "fd_step", "max_iterations",
             "noise", "experiment", "frf_theta", "frf_noise", "frf_band"}
#: Arm fields a fit may not change: the links' lengths are measured with a rule, and the
#: modal coordinates of links of different lengths cannot be compared.
_FIXED = {"L1", "L2"}
#: Residual, in noise levels, of a sample a simulation did not reach (it diverged or
#: failed at a trial point): far beyond any fit, so the step is rejected.
_PENALTY = 1e3
#: A direction is invisible when its singular value is below this many times the noise
#: the float32 storage of the signals puts into a difference column.
_RESOLUTION_MARGIN = 10.0
#: ... or when the data determine it only to more than this (relative to the starts).
_MAX_RELATIVE_STD = 1.0
#: A parameter whose weight on an unidentifiable direction is at least this is named.
_NAMED_WEIGHT = 0.1
#: Weight of a signal whose noise level is not declared: this fraction of its RMS.
_UNDECLARED_NOISE = 1e-3


# --- settings --------------------------------------------------------------------------------
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


def _parameter(name: str, table: dict, base: Scenario) -> Parameter:
    where = f"--fit {name}"
    head, _, field = name.partition(".")
    if head == "sensors":
        raise ConfigError(where, "the sensor model has no gain or bias, and its delay is a "
                                 "whole number of samples, not a least-squares parameter: set "
                                 "sensors.delay in the scenario")
    known = {f.name for f in dataclasses.fields(ArmParameters)}
    check(head == "true_params" and field in known, where,
          f"not a fittable field (true_params.<one of {', '.join(sorted(known - _FIXED))}>)")
    check(field not in _FIXED, where, "the links' lengths are not fitted (measure them; the "
                                      "controller's model must have the same)")
    start = _number(table.get("start", {}).get(name, getattr(base.true_params, field)),
                    f"calibrate.start.{name}")
    lower, upper = 0.0, math.inf
    if name in table.get("bounds", {}):
        pair = table["bounds"][name]
        check(isinstance(pair, list) and len(pair) == 2, f"calibrate.bounds.{name}",
              "must be [lower, upper]")
        lower = _number(pair[0], f"calibrate.bounds.{name}[0]")
        upper = pair[1] if pair[1] == math.inf else _number(pair[1], f"calibrate.bounds.{name}[1]")
    check(0 <= lower < upper, f"calibrate.bounds.{name}",
          f"needs 0 <= lower < upper (an arm's values are >= 0), got [{lower}, {upper}]")
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
        check(key in _SETTINGS, f"calibrate.{key}", f"unknown key (allowed: "
                                                    f"{', '.join(sorted(_SETTINGS))})")
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
    for key in ("start", "bounds"):
        for name in table[key]:
            check(name in names, f"calibrate.{key}.{name}", "not a fitted field (--fit)")
    parameters = tuple(_parameter(n, table, base) for n in names)
    inputs = table.get("inputs", "replay")
    check(inputs in INPUT_MODES, "calibrate.inputs", f"must be one of "
                                                     f"{', '.join(INPUT_MODES)}, got {inputs!r}")
    noise = {k: _number(v, f"calibrate.noise.{k}", positive=True)
             for k, v in table["noise"].items()}
    experiment = table.get("experiment", {})
    check(isinstance(experiment, dict) and all(isinstance(v, dict) for v in experiment.values()),
          "calibrate.experiment", "must be a table of tables ([calibrate.experiment.NAME])")
    theta = table.get("frf_theta", [0.0, 0.0])
    check(isinstance(theta, list) and len(theta) == 2, "calibrate.frf_theta",
          "must be [theta1, theta2] [rad]")
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


# --- the plan: everything checked before anything is written -----------------------------------
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
    data = copy.deepcopy(base)
    for key in _EXPERIMENT_KEYS if own is not None else ():
        data[key] = copy.deepcopy(own[key])
    for key, value in overrides.items():
        check(key not in settings.names, f"calibrate.experiment.{exp.name}.{key}",
              "is fitted: one value for every experiment")
        set_dotted(data, key, value, defaults=base)
    data["duration"] = exp.duration
    data.pop("transient", None)  # the default of the new duration
    return data


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
        Naming the file, column or key.
    """
    check(bool(experiments) or bool(responses), "DATA", "no experiment and no --frf file")
    names = [e.name for e, _ in experiments] + [r.name for r in responses]
    twice = sorted({n for n in names if names.count(n) > 1})
    check(not twice, "DATA", f"two experiments are called {', '.join(twice)} (rename a file)")
    for name in settings.experiment:
        check(name in names, f"calibrate.experiment.{name}", "no experiment of that name")
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
    for response in responses:
        outputs = _linear_outputs(base)
        for out, inp in response.pairs:
            check(out in outputs, f"{response.source}: column {out}/{inp}.re",
                  f"{out!r} is not an output of the linear model ({', '.join(outputs)})")
            check(inp in ("tau1", "tau2"), f"{response.source}: column {out}/{inp}.re",
                  f"{inp!r} is not an input (tau1, tau2)")
    return Plan(settings, mapping, tuple(targets), tuple(responses))


# --- the plant's frequency response ---------------------------------------------------------
def _linear_outputs(s: Scenario) -> tuple[str, ...]:
    from plant_exudyn._linear import output_names  # one list of names for both plants
    return output_names(nominal_model(s.nominal_params, s.model.modes_per_link).mode_shapes)


def linear_response(s: Scenario, theta, frequency: np.ndarray, pairs) -> np.ndarray:
    """The frequency responses ``pairs`` = [(output, input)] of the scenario's plant
    linearised about rest at ``theta``, at ``frequency`` [Hz]: (len(pairs), F) complex.
    The q outputs are in the basis the sensors report them in (the controller's model).
    The reduced plant is the model of its own order; any other plant is the FE arm of
    its mesh (`plant_exudyn.linear_model`)."""
    from .linear import reduced_linear_model
    basis = nominal_model(s.nominal_params, s.model.modes_per_link).mode_shapes
    if s.plant.kind == "reduced":
        own = cached_model(s.true_params, tuple(s.plant.modes_per_link))
        system = reduced_linear_model(own, theta=theta, modal_basis=basis)
    else:
        from plant_exudyn import linear_model
        system = linear_model(s.true_params, s.plant.mesh, theta=theta, modal_basis=basis)
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


# --- the fit -----------------------------------------------------------------------------
def _doubling(first: float, last: float) -> list[float]:
    """first, 2·first, 4·first… below ``last``, then ``last`` (the module docstring's
    growing horizon; a last step shorter than a quarter of the one before is merged)."""
    out, h = [], first
    while h < last * 0.75:
        out.append(h)
        h *= 2
    return out + [last]


def _stages(plan: Plan) -> list[dict]:
    """The horizon [s] of the time series and the band [Hz] of the frequency responses
    fitted at each stage, both doubling until every sample and frequency is in."""
    settings = plan.settings
    longest = max([t.experiment.duration for t in plan.targets], default=0.0)
    Ts = min([t.experiment.Ts for t in plan.targets], default=0.0)
    highest = max([float(r.frequency[-1]) for r in plan.responses], default=0.0)
    horizons = _doubling(max(settings.horizon, 2 * Ts), longest) if plan.targets else [0.0]
    bands = _doubling(settings.frf_band, highest) if plan.responses else [0.0]
    n = max(len(horizons), len(bands))
    pad = lambda v: v + [v[-1]] * (n - len(v))  # noqa: E731
    return [{"horizon": h, "band": b} for h, b in zip(pad(horizons), pad(bands))]


def _samples(exp: Experiment, horizon: float) -> int:
    """The samples of ``exp`` within its first ``horizon`` seconds (at least two)."""
    if horizon >= exp.duration:
        return exp.samples
    return max(2, round(horizon / exp.Ts))


class _Problem:
    """The residuals of a plan at points u (the parameters over their scales), each
    simulation a stored run on the campaign runner."""

    def __init__(self, plan: Plan, out, runner, inputs: list[dict]) -> None:
        self.plan, self.settings = plan, plan.settings
        self.scale = np.array([p.scale for p in plan.settings.parameters])
        self.inputs = inputs  # per target: the scenario keys that reproduce its input
        self.evals = Evaluations(out, runner, f"{FIT_SWEEP}")
        self.horizon = self.band = math.inf

    # scenarios
    def scenario(self, i: int, u: np.ndarray, horizon: float) -> Scenario | None:
        """Target ``i``'s scenario at ``u`` over its first ``horizon`` seconds (None if the
        arm there cannot be modelled: a trial point the fit must reject)."""
        target = self.plan.targets[i]
        data = deep_merge(target.scenario, self.inputs[i])
        for p, x in zip(self.settings.parameters, u * self.scale):
            set_dotted(data, p.name, float(x))
        exp = target.experiment
        data["duration"] = _samples(exp, horizon) * exp.Ts
        data.pop("transient", None)
        data["name"] = f"{FIT_SWEEP}/{exp.name}"
        try:
            return scenario_from_mapping(data)
        except ConfigError:
            return None

    def _axes(self, i: int, u: np.ndarray, horizon: float) -> dict:
        exp = self.plan.targets[i].experiment
        return {"experiment": exp.name, "horizon": _samples(exp, horizon) * exp.Ts,
                **{p.name: float(x) for p, x in zip(self.settings.parameters, u * self.scale)}}

    # residuals
    def residuals(self, points: list[np.ndarray]) -> list[np.ndarray]:
        """The weighted residual vector at each of ``points`` (their simulations run as
        one batch)."""
        items, where = [], {}
        for n, u in enumerate(points):
            for i in range(len(self.plan.targets)):
                s = self.scenario(i, u, self.horizon)
                if s is not None:
                    where[n, i] = len(items)
                    items.append((s, FIT_SWEEP, self._axes(i, u, self.horizon)))
        rows = self.evals.run(items) if items else []
        out = []
        for n, u in enumerate(points):
            parts = [self._time_residual(i, rows[where[n, i]] if (n, i) in where else None)
                     for i in range(len(self.plan.targets))]
            parts += [self._frf_residual(r, u) for r in self.plan.responses]
            out.append(np.concatenate(parts) if parts else np.zeros(0))
        return out

    def samples(self, i: int) -> int:
        return _samples(self.plan.targets[i].experiment, self.horizon)

    def _time_residual(self, i: int, row) -> np.ndarray:
        target, k = self.plan.targets[i], self.samples(i)
        exp = target.experiment
        measured = exp.signals[:, :k]
        r = np.full(measured.shape, _PENALTY)
        if row is not None and row.status != "failed":
            result = every_signal(self.evals.store, row)
            done = min(k, len(result.time))
            sim = result.select([f"y_{n}" for n in exp.names])[:, :done].astype(np.float64)
            r[:, :done] = (sim - measured[:, :done]) / target.sigma[:, None]
        return r.ravel()

    def _frf_residual(self, response: FrequencyResponse, u: np.ndarray) -> np.ndarray:
        data = copy.deepcopy(self.plan.base)
        for p, x in zip(self.settings.parameters, u * self.scale):
            set_dotted(data, p.name, float(x))
        try:
            s = scenario_from_mapping(data)
            G = linear_response(s, self.settings.frf_theta, response.frequency, response.pairs)
        except (ConfigError, ArithmeticError, np.linalg.LinAlgError):
            return np.full(2 * response.values.size, _PENALTY)
        e = np.log(G / response.values) / self.settings.frf_noise
        e = e[:, :self.frequencies(response)]
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    def frequencies(self, response: FrequencyResponse) -> int:
        """How many of the response's frequencies the current band holds (at least 2)."""
        return max(2, int(np.searchsorted(response.frequency, self.band, side="right")))

    # the fit's callables
    def jacobian(self, u: np.ndarray, f: np.ndarray, lower, upper, *, central: bool) -> np.ndarray:
        """Finite differences at ``u`` (``f`` its residual): forward, or central; one
        batch of simulations.  A step that would cross a bound goes the other way."""
        h = self.settings.fd_step * np.maximum(np.abs(u), 1.0)
        h = np.where(u + h > upper, -h, h)
        points = [u + h[j] * np.eye(len(u))[j] for j in range(len(u))]
        if central:
            points += [u - h[j] * np.eye(len(u))[j] for j in range(len(u))]
        values = self.residuals(points)
        p = len(u)
        if central:
            return np.column_stack([(values[j] - values[p + j]) / (2 * h[j]) for j in range(p)])
        return np.column_stack([(values[j] - f) / h[j] for j in range(p)])

    def resolution(self, central: bool) -> float:
        """The noise the float32 storage of the simulated signals puts into one column of
        the difference Jacobian (norm, in the residual's units per unit of u): a rounding
        error of spacing δ is uniform, variance δ²/12, and a difference of two of them
        over the step h has variance δ²/(6 h²) (forward) or δ²/(24 h²) (central)."""
        total = 0.0
        for i, target in enumerate(self.plan.targets):
            k = self.samples(i)
            spacing = np.spacing(np.abs(target.experiment.signals[:, :k]).astype(np.float32))
            total += float(np.sum((spacing.astype(np.float64) / target.sigma[:, None]) ** 2))
        h = self.settings.fd_step
        return math.sqrt(total / (24.0 if central else 6.0)) / h


def calibrate(plan: Plan, out, *, runner, log=print, store=None) -> dict:
    """Fit the plan's parameters with scipy's ``least_squares`` (module docstring).

    Parameters
    ----------
    plan : Plan
        From `plan_calibration`.
    out : path-like
        The results folder: the experiments (``experiments/NAME.csv`` and the torques
        replayed, ``.npy``), the simulations (``runs/``, index), ``calibration.json``,
        ``calibrated.toml`` and ``uncertainty.toml`` are written there.
    runner : callable
        Runs a list of planned scenarios (`make_runner`).
    log : callable
        Receives one line per iteration.
    store : BaseStore, optional
        Where the simulations are kept (default: the folder ``out``, which a calibration
        stopped and started again resumes from); an in-memory store
        (`validation.batch.memory.MemoryStore`) keeps them in this process, every signal
        in float64, nothing written to ``runs/``.

    Returns
    -------
    dict
        What ``calibration.json`` holds: estimates, standard errors, correlations,
        residuals and the verdict on the fit.
    """
    out = Path(out)
    settings = plan.settings
    inputs = _write_inputs(plan, out)
    problem = _Problem(plan, store or out, runner, inputs)
    lower = np.array([q.lower for q in settings.parameters]) / problem.scale
    upper = np.array([q.upper for q in settings.parameters]) / problem.scale
    u = np.array([q.start for q in settings.parameters]) / problem.scale
    cache: dict[bytes, np.ndarray] = {}

    def fun(v):
        key = v.tobytes()
        if key not in cache:
            cache[key] = problem.residuals([v])[0]
        return cache[key]

    def jac(v):
        J = problem.jacobian(v, fun(v), lower, upper, central=False)
        return _without_invisible(J, _RESOLUTION_MARGIN * problem.resolution(central=False),
                                  settings.fd_step)

    stages = []
    for stage in _stages(plan):
        problem.horizon, problem.band = stage["horizon"], stage["band"]
        cache.clear()
        res = scipy.optimize.least_squares(
            fun, np.clip(u, lower, upper), jac=jac, bounds=(lower, upper), method="dogbox",
            x_scale=1.0, max_nfev=settings.max_iterations)
        u = res.x
        stages.append({**stage, "iterations": int(res.njev),
                       "evaluations": int(res.nfev), "cost": float(res.cost),
                       "status": int(res.status), "message": res.message})
        where = ", ".join(f"{k} {stage[k]:g} {unit}" for k, unit, on in (
            ("horizon", "s", plan.targets), ("band", "Hz", plan.responses)) if on)
        values = ", ".join(f"{q.short} = {x:.6g}"
                           for q, x in zip(settings.parameters, u * problem.scale))
        log(f"  {where}: cost {res.cost:.6g} after {res.njev} iterations ({values})")
    problem.horizon = problem.band = math.inf
    cache.clear()
    r = fun(u)
    J = problem.jacobian(u, r, lower, upper, central=True)
    floor = _RESOLUTION_MARGIN * problem.resolution(central=True) if plan.targets else 0.0
    estimate = u * problem.scale
    stats = parameter_uncertainty(J, r, settings.names, estimate, problem.scale, floor=floor,
                                  bounds=[(q.lower, q.upper) for q in settings.parameters])
    result = {
        "parameters": stats["parameters"], "correlation": stats["correlation"],
        "residual_rms": _residual_rms(plan, problem, u),
        "cost": float(0.5 * r @ r), "iterations": sum(s["iterations"] for s in stages),
        "simulations": len(problem.evals.seen),
        "residual_variance": stats["residual_variance"], "dof": stats["dof"],
        "singular_values": stats["singular_values"], "jacobian_floor": floor,
        "inputs": settings.inputs, "stages": stages,
        "experiments": [{"name": t.experiment.name, "source": t.experiment.source,
                         "samples": t.experiment.samples, "Ts": t.experiment.Ts,
                         "signals": list(t.experiment.names),
                         "run": run_id(scenario_to_mapping(problem.scenario(i, u, math.inf)))}
                        for i, t in enumerate(plan.targets)],
        "responses": [{"name": r_.name, "source": r_.source,
                       "pairs": [f"{o}/{i}" for o, i in r_.pairs]} for r_ in plan.responses],
        "failed_runs": problem.evals.failed,
    }
    if plan.targets:  # a fit of frequency responses alone simulates nothing: no store
        problem.evals.finish()
    _write_results(out, plan, result)
    return result


def _without_invisible(J: np.ndarray, floor: float, collinear: float) -> np.ndarray:
    """J without the directions it cannot resolve, so that a Gauss-Newton step does not
    move along them: those whose singular value is within ``floor`` (the float32
    resolution of the signals), and combinations of columns that are parallel to within
    ``collinear`` (singular values of J with unit columns: a forward difference is wrong
    by O(step) relative to its column).  Without this, the difference error along an
    exact degeneracy (mh2 and stator_mass: 5.7e-5 of the largest singular value, forward
    steps 1e-3) reads as a slope: the step it suggests (mh2 +160 %, stator_mass
    −1800 %) is rejected or cut, and the pair drifts to a bound (measured with dogbox,
    mh2, stator_mass, mh1, EI1 from 0.1 s to 0.5 s: 31 evaluations, stator_mass ending at
    1.5e-4 kg; with it, 10 evaluations, the pair where it started along the invisible
    direction)."""
    norms = np.linalg.norm(J, axis=0)
    unit = J / np.where(norms > 0, norms, 1.0)
    U, S, Vt = np.linalg.svd(unit, full_matrices=False)
    if not S.size:
        return J
    J = ((U * np.where(S <= collinear * S[0], 0.0, S)) @ Vt) * norms
    U, S, Vt = np.linalg.svd(J, full_matrices=False)
    return (U * np.where((S <= floor) | (S <= 1e-12 * S[0]), 0.0, S)) @ Vt


def _write_inputs(plan: Plan, out: Path) -> list[dict]:
    """Write each experiment as read (``experiments/NAME.csv``: what the report compares
    with) and, for replay, its torques (``.npy``); the scenario keys that reproduce each
    experiment's input."""
    folder = out / "experiments"
    out.mkdir(parents=True, exist_ok=True)
    if plan.targets:
        folder.mkdir(exist_ok=True)
    inputs = []
    for target in plan.targets:
        exp = target.experiment
        write_atomic(folder / f"{exp.name}.csv", lambda fh, e=exp: write_experiment(
            e, fh, f"experiment {e.name}, read from {e.source}"))
        if plan.settings.inputs == "closed-loop":
            inputs.append({})
            continue
        buffer = io.BytesIO()
        np.save(buffer, np.ascontiguousarray(exp.torques, dtype=np.float64), allow_pickle=False)
        data = buffer.getvalue()
        path = (folder / f"{exp.name}.npy").resolve()
        write_atomic(path, lambda fh, d=data: fh.write(d), binary=True)
        inputs.append({
            "controller": {"kind": "replay", "options": {
                "file": str(path), "sha256": hashlib.sha256(data).hexdigest()}},
            "observer": {"kind": "none", "options": {}, "initial_error": []},
            "feedback": "true", "disturbances": [], "torque_limit": 0.0, "requirement": [],
            "sensors": {"encoder_noise": 0.0, "modal_noise": 0.0, "rate_noise": 0.0}})
    return inputs


# --- uncertainty -------------------------------------------------------------------------
def _direction(v: np.ndarray, names, scale) -> str:
    """A direction of parameter space in words: its components relative to the starts,
    then in the parameters' own units (largest 1), e.g. +0.24 mh2 −0.97 stator_mass
    (ΔSI: +1 mh2 −1 stator_mass: only their sum is seen)."""
    relative = " ".join(f"{x:+.3g} {n}" for x, n in zip(v, names) if abs(x) >= 1e-3)
    si = v * scale
    si = si / np.abs(si).max()
    own = " ".join(f"{x:+.3g} {n.rsplit('.', 1)[-1]}" for x, n in zip(si, names)
                   if abs(x) >= 1e-3)
    return f"{relative} (relative to the starts; in their own units {own})"


def parameter_uncertainty(J: np.ndarray, r: np.ndarray, names, estimate, scale, *,
                          floor: float = 0.0, bounds=None, level: float = 0.95) -> dict:
    """Standard errors, intervals, correlations and identifiability (module docstring).

    Parameters
    ----------
    J : ndarray (m, p)
        Jacobian of the weighted residual with respect to u = x / ``scale``.
    r : ndarray (m,)
        The weighted residual at the estimate.
    names : sequence of str
        The parameters.
    estimate, scale : ndarray (p,)
        The estimate x and the scale of each parameter.
    floor : float
        The Jacobian's own error (norm of one column's noise): a direction whose singular
        value is not above it is invisible to the data.
    bounds : list of (lower, upper), optional
        An estimate on a bound has no valid interval.
    level : float
        Of the interval (Student t with m − p degrees of freedom).

    Returns
    -------
    dict
        ``parameters`` (name → estimate, std, ci95, identifiable, reason),
        ``correlation`` (names, matrix), ``residual_variance``, ``dof``,
        ``singular_values`` (relative to the largest).
    """
    m, p = J.shape
    dof = max(m - p, 1)
    s2 = float(r @ r) / dof
    _, S, Vt = np.linalg.svd(J, full_matrices=False)
    reasons: dict[int, list[str]] = {i: [] for i in range(p)}
    keep = []
    top = S[0] if S.size and S[0] > 0 else 1.0
    for k in range(p):
        if S[k] <= floor or S[k] <= 1e-12 * top:
            why = (f"J is singular along {_direction(Vt[k], names, scale)}: its singular "
                   f"value, {S[k] / top:.2g} of the largest, is within the Jacobian's own error "
                   f"({floor / top:.2g}): the data do not see this change")
        elif math.sqrt(s2) / S[k] > _MAX_RELATIVE_STD:
            why = (f"the data determine {_direction(Vt[k], names, scale)} only to "
                   f"±{100 * math.sqrt(s2) / S[k]:.3g} % of the starts")
        else:
            keep.append(k)
            continue
        for i in np.flatnonzero(np.abs(Vt[k]) >= _NAMED_WEIGHT):
            reasons[int(i)].append(why)
    cov_u = sum((s2 / S[k] ** 2) * np.outer(Vt[k], Vt[k]) for k in keep) if keep \
        else np.zeros((p, p))
    std = scale * np.sqrt(np.clip(np.diag(cov_u), 0.0, None))
    quantile = float(scipy.stats.t.ppf(0.5 + level / 2, dof))
    for i, (lo, hi) in enumerate(bounds or [(-math.inf, math.inf)] * p):
        near = 1e-6 * scale[i]
        if estimate[i] - lo <= near or hi - estimate[i] <= near:
            reasons[i].append(f"the estimate is at its bound [{lo:g}, {hi:g}]: the data ask for "
                              "a value beyond it (no valid interval)")
    parameters = {}
    for i, name in enumerate(names):
        ok = not reasons[i]
        parameters[name] = {
            "estimate": float(estimate[i]),
            "std": float(std[i]) if ok else None,
            "ci95": [float(estimate[i] - quantile * std[i]),
                     float(estimate[i] + quantile * std[i])] if ok else None,
            "identifiable": ok, "reason": "; ".join(reasons[i])}
    ident = [i for i in range(p) if parameters[names[i]]["identifiable"]]
    d = np.sqrt(np.diag(cov_u))
    matrix = [[float(cov_u[i, j] / (d[i] * d[j])) if i in ident and j in ident and d[i] * d[j] > 0
               else None for j in range(p)] for i in range(p)]
    return {"parameters": parameters, "correlation": {"names": list(names), "matrix": matrix},
            "residual_variance": s2, "dof": dof,
            "singular_values": [float(v / top) for v in S]}


def _residual_rms(plan: Plan, problem: _Problem, u: np.ndarray) -> dict:
    """RMS of the fitted residual of every signal of every experiment [SI units], next to
    its declared noise level (None: none declared)."""
    out = {}
    r = problem.residuals([u])[0]
    offset = 0
    for i, target in enumerate(plan.targets):
        exp, k = target.experiment, problem.samples(i)
        block = r[offset:offset + len(exp.names) * k].reshape(len(exp.names), k)
        offset += block.size
        out[exp.name] = {n: {"rms": float(np.sqrt(np.mean(b ** 2)) * sigma),
                             "noise": float(noise) if noise > 0 else None}
                         for n, b, sigma, noise in zip(exp.names, block, target.sigma,
                                                       target.noise)}
    for response in plan.responses:
        size = response.values.size
        e = r[offset:offset + 2 * size]
        offset += 2 * size
        out[response.name] = {"relative_rms": float(np.sqrt(np.mean(e ** 2)) *
                                                    plan.settings.frf_noise),
                              "noise": plan.settings.frf_noise}
    return out


# --- what it writes ------------------------------------------------------------------------
def _write_results(out: Path, plan: Plan, result: dict) -> None:
    write_atomic(out / "calibration.json",
                 lambda fh: json.dump(result, fh, indent=1, allow_nan=False))
    calibrated = copy.deepcopy(plan.base)
    for name, p in result["parameters"].items():
        set_dotted(calibrated, name, p["estimate"])
    lines = [f"{n} = {p['estimate']:.6g}" + (f" ± {p['std']:.2g}" if p["identifiable"]
                                             else " (not identifiable)")
             for n, p in result["parameters"].items()]
    head = ("The scenario calibrated by flexarm calibrate (calibration.json): "
            + "; ".join(lines) + "\nRun it: flexarm run --config calibrated.toml\n")
    text = "".join(f"# {ln}\n" for ln in head.splitlines()) + toml_text(calibrated)
    write_atomic(out / "calibrated.toml", lambda fh: fh.write(text))
    ranges = {}
    for (name, p), q in zip(result["parameters"].items(), plan.settings.parameters):
        if p["identifiable"]:
            lo, hi = max(p["ci95"][0], q.lower), min(p["ci95"][1], q.upper)
            ranges[name] = (lo, hi)
    path = out / "uncertainty.toml"
    if not ranges:
        path.unlink(missing_ok=True)
        return
    text = ("# The calibrated arm's 95 % intervals (flexarm calibrate, calibration.json) as the\n"
            "# set flexarm verify draws from: each uniform over its interval, independently\n"
            "# (correlations are in calibration.json).  Include it next to calibrated.toml.\n"
            "[uncertainty]\n" + "".join(f'"{n}" = {{ uniform = {toml_value([lo, hi])} }}\n'
                                        for n, (lo, hi) in ranges.items()))
    write_atomic(path, lambda fh: fh.write(text))


def base_scenario(path) -> tuple[Scenario, dict]:
    """The scenario a calibration starts from and its ``[calibrate]`` table.

    Parameters
    ----------
    path : path-like
        A scenario file, or a campaign file (its ``[scenario]`` base).

    Returns
    -------
    (Scenario, dict)
        The scenario and the ``[calibrate]`` table (empty when there is none).
    """
    from ..batch.campaign import load_study
    study = load_study(path)
    return scenario_from_mapping(study.base), study.calibrate
