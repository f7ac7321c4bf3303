"""Scenario: everything one closed-loop run needs, as frozen dataclasses.

A scenario names the plant (reduced or Exudyn), the true arm, the nominal arm the
controller and observer believe in, the controller and observer with their gains, the
reference, sensors and noise, disturbances, saturation, timing and the seed.  It is
built from a mapping (TOML, JSON) with `from_mapping`; `check_scenario` rejects bad
combinations before anything is simulated.  Every error names the dotted key.
"""
from __future__ import annotations

import functools
import weakref
from dataclasses import dataclass

import numpy as np

from reduced_model import STRAIN_QUANTITIES, ArmParameters

from .config import ConfigError, check, from_mapping, to_mapping
from .laws import check_laws, nominal_model
from .plants import PLANTS, PlantTable
from .requirements import Requirement, check_requirements
from .specs import (ControllerSpec, DisturbanceSpec, DivergenceSpec, ModelSpec, ObserverSpec,
                    ReferenceSpec, SensorSpec, class_path, one_of, positive)

__all__ = [
    "Scenario", "PlantTable", "ModelSpec", "ControllerSpec", "ObserverSpec", "ReferenceSpec",
    "SensorSpec", "DisturbanceSpec", "DivergenceSpec", "check_scenario",
    "scenario_from_mapping", "scenario_to_mapping", "arm_parameters", "own_parameters",
    "check_scales_on_arm", "PARAMETER_TABLES", "PLANT_KINDS", "ARMS",
    "PAPER_ARMS",
    "DEFAULT_TRANSIENT", "default_transient",
]

#: The arms a scenario can start from: the practical default (Table 1 + a motor-2 stator
#: inertia of 0.01 kg m² + bending damping 2e-3 N m² s), the paper's Table 1 exactly, and
#: the default arm behind small harmonic drives (`ArmParameters.lab`).
ARMS = {"default": "practical default arm (Table 1 + stator inertia 0.01 kg m² + damping "
                   "2e-3 N m² s)",
        "table1": "the paper's Table 1 exactly (no stator inertia, no damping)",
        "lab": "the default arm behind small harmonic drives: joint friction with "
               "stiction, gear compliance, rotor inertia, backlash, a 500 Hz current loop"}
#: The arms a single scenario's stability map and validity are judged on (unless --arm).
PAPER_ARMS = ("default", "table1")
#: The scenario's tables that start from the parameters of its ``arm`` (`arm_parameters`).
PARAMETER_TABLES = ("true_params", "nominal_params")
FEEDBACK = ("auto", "true", "estimate")
#: Caps that keep a typo from exhausting memory or hanging a run: samples held in memory
#: (5e6 = 83 min at 1 kHz, ~3 GB of signals) and internal plant steps per run.
MAX_SAMPLES = 5e6
MAX_PLANT_STEPS = 2e8
INITIAL_STATES = ("rest", "reference")
#: The default transient [s] after which metrics are taken; a run shorter than twice this
#: is measured over its second half (`default_transient`).
DEFAULT_TRANSIENT = 2.0


def default_transient(duration: float) -> float:
    """The transient of a scenario that does not set one: 2 s, or half of a run shorter
    than 4 s (so that ``flexarm run --duration 1`` measures its last 0.5 s)."""
    return min(DEFAULT_TRANSIENT, duration / 2)


#: The built-in plant kinds (`validation.run.plants.PLANTS`): a scenario's ``plant`` is a
#: tagged choice of their settings, or "package.module:Class" for a plug-in plant.
PLANT_KINDS = tuple(PLANTS)


@dataclass(frozen=True)
class Scenario:
    """One closed-loop run: everything it needs, from a TOML file or a mapping
    (`scenario_from_mapping`).

    Parameters
    ----------
    name : str
        The run's name in results and reports.
    arm : {"default", "table1", "lab"}
        The arm both parameter tables start from: the practical default (Table 1 + a
        motor-2 stator inertia + structural damping), the paper's Table 1 exactly, or the
        default arm behind small harmonic drives (`ARMS`, `ArmParameters.lab`).
    plant : PlantTable
        The plant simulated, chosen by its ``kind``: the settings of a built-in plant
        (`reduced_model.ReducedPlant.Settings`, `plant_exudyn.ExudynPlant.Settings`) or
        of a plug-in (`validation.run.plants.PluginSettings`).
    true_params : reduced_model.ArmParameters
        The arm simulated: ``arm``'s parameters, overridden key by key.
    nominal_params : reduced_model.ArmParameters
        The arm the controller and observer believe in (the same unless a scenario says
        otherwise).
    model : ModelSpec
        The order of the laws' model.
    controller : ControllerSpec
        The controller and its options.
    observer : ObserverSpec
        The observer, its options and its initial error.
    feedback : {"auto", "true", "estimate"}
        The state the controller sees: "true", "estimate" (the observer's), or "auto"
        (the estimate when there is an observer).
    reference : ReferenceSpec
        The reference trajectory.
    sensors : SensorSpec
        What is measured, with which noise.
    disturbances : tuple of DisturbanceSpec
        ``[[disturbances]]`` entries, any number.
    torque_limit : float
        Saturation of each joint torque [N m]; 0: none.
    Ts : float
        Control period [s]; a whole multiple of ``plant.step``.
    duration : float
        Simulated time [s].
    initial_state : {"rest", "reference"}
        Start at rest, or moving with the reference.
    seed : int
        Seeds the measurement noise and noise disturbances.
    divergence : DivergenceSpec
        The bounds beyond which the run ends as "diverged".
    transient : float
        Metrics are taken after it [s]; unset: 2 s, or half of a run shorter than 4 s
        (`default_transient`).
    requirement : tuple of Requirement
        ``[[requirement]]`` entries: each run carries their robustness as ``rho_<name>``.
    """

    name: str = "paper"
    arm: str = "default"
    plant: PlantTable = PLANTS["reduced"].Settings()
    true_params: ArmParameters = ArmParameters()
    nominal_params: ArmParameters = ArmParameters()
    model: ModelSpec = ModelSpec()
    controller: ControllerSpec = ControllerSpec()
    observer: ObserverSpec = ObserverSpec()
    feedback: str = "auto"
    reference: ReferenceSpec = ReferenceSpec()
    sensors: SensorSpec = SensorSpec()
    disturbances: tuple[DisturbanceSpec, ...] = ()
    torque_limit: float = 0.0
    Ts: float = 1e-3
    duration: float = 20.0
    initial_state: str = "rest"
    seed: int = 0
    divergence: DivergenceSpec = DivergenceSpec()
    transient: float | None = None
    requirement: tuple[Requirement, ...] = ()

    def __post_init__(self):
        check(isinstance(self.name, str) and self.name.strip() != "" and self.name.isprintable(),
              "name", f"must be a non-empty printable string, got {self.name!r}")
        one_of(self.arm, tuple(ARMS), "arm")
        one_of(self.feedback, FEEDBACK, "feedback")
        one_of(self.initial_state, INITIAL_STATES, "initial_state")
        positive(self.Ts, "Ts")
        positive(self.duration, "duration")
        positive(self.torque_limit, "torque_limit", allow_zero=True)
        if self.transient is None:  # resolved here, so the stored scenario holds the number
            object.__setattr__(self, "transient", default_transient(self.duration))
        positive(self.transient, "transient", allow_zero=True)
        check(self.seed >= 0, "seed", f"must be >= 0, got {self.seed!r}")

    def initial_estimate_error(self) -> "np.ndarray":
        """x̂(0) − x(0) as a model-state vector (see ObserverSpec.initial_error)."""
        n = 2 + sum(self.model.modes_per_link)
        err = self.observer.initial_error
        if len(err) == 2 * n:
            return np.asarray(err, dtype=float)
        out = np.zeros(2 * n)
        if len(err) == 4:
            signs = lambda k: (-1.0) ** np.arange(k)  # noqa: E731
            out[:2], out[2:n] = err[0] * signs(2), err[1] * signs(n - 2)
            out[n:n + 2], out[n + 2:] = err[2] * signs(2), err[3] * signs(n - 2)
        return out

    @property
    def uses_estimate(self) -> bool:
        return self.feedback == "estimate" or (self.feedback == "auto"
                                               and self.observer.kind != "none")


#: The scenario objects checked in this process (a frozen scenario checked stays valid):
#: by id, held weakly (a scenario holds tables, so it has no hash).
_CHECKED: weakref.WeakValueDictionary = weakref.WeakValueDictionary()


def check_scenario(s: Scenario) -> None:
    """Reject combinations that cannot run, before anything is simulated (once per
    scenario object: a frozen scenario checked stays valid)."""
    if _CHECKED.get(id(s)) is s:
        return
    samples = s.duration / s.Ts
    check(samples <= MAX_SAMPLES, "duration", f"{s.duration:g} s at Ts = {s.Ts:g} s is "
                                              f"{samples:.3g} samples (at most {MAX_SAMPLES:.0e}: "
                                              "they are held in memory)")
    if "step" in s.plant.__dataclass_fields__:  # a plug-in plant steps as it likes
        check(s.duration / s.plant.step <= MAX_PLANT_STEPS, "plant.step",
              f"{s.plant.step:g} s over {s.duration:g} s is {s.duration / s.plant.step:.3g} "
              f"internal steps (at most {MAX_PLANT_STEPS:.0e})")
        n_steps = round(s.Ts / s.plant.step)
        check(n_steps >= 1 and abs(n_steps * s.plant.step - s.Ts) <= 1e-9 * s.Ts, "Ts",
              f"{s.Ts!r} s is not a whole multiple of plant.step = {s.plant.step!r} s")
    check(s.duration >= s.Ts, "duration", f"must be at least one sample (Ts = {s.Ts}), "
                                          f"got {s.duration!r}")
    check(s.sensors.delay * s.Ts < s.duration, "sensors.delay",
          f"{s.sensors.delay} samples ({s.sensors.delay * s.Ts:g} s) is not shorter than the "
          f"{s.duration:g} s run")
    check(s.transient < s.duration, "transient", f"{s.transient!r} s leaves nothing of the "
                                                 f"{s.duration!r} s run to measure")
    s.plant.check()
    check(not (s.feedback == "estimate" and s.observer.kind == "none"), "feedback",
          "'estimate' needs an observer (observer.kind is 'none')")
    for link, name in ((1, "L1"), (2, "L2")):
        check(getattr(s.true_params, name) == getattr(s.nominal_params, name),
              f"nominal_params.{name}", f"must equal true_params.{name}: the modal "
                                        "coordinates of links of different lengths "
                                        "cannot be compared")
    for key in PARAMETER_TABLES:
        _check_modelable(getattr(s, key), s.model.modes_per_link, key)
    check_laws(s)
    n = 2 + sum(s.model.modes_per_link)
    check(len(s.observer.initial_error) in (0, 4, 2 * n), "observer.initial_error",
          f"needs {2 * n} values (the model state), 4 (per group) or none, got "
          f"{len(s.observer.initial_error)}")
    if s.sensors.modal == "gauges":
        model = nominal_model(s.nominal_params, s.model.modes_per_link)
        quantity = STRAIN_QUANTITIES[s.sensors.strain_quantity]
        for link, gauges in enumerate((s.sensors.gauges_link1, s.sensors.gauges_link2)):
            key = f"sensors.gauges_link{link + 1}"
            modes = s.model.modes_per_link[link]
            check(len(gauges) >= modes, key, f"{len(gauges)} gauge(s) for {modes} modes; "
                                             f"need at least {modes}")
            L = s.true_params.L1 if link == 0 else s.true_params.L2
            check(all(x <= L for x in gauges), key, f"positions must lie on the link "
                                                    f"(0..{L} m), got {list(gauges)}")
            basis = model.mode_shapes[link].evaluate(np.asarray(gauges, float), quantity).T
            check(np.linalg.matrix_rank(basis) >= modes, key,
                  f"gauges at {list(gauges)} cannot tell the link's {modes} modes apart "
                  "(coincident, or at nodes of a mode)")
    check_requirements(s)
    _CHECKED[id(s)] = s


def arm_parameters(arm: str) -> ArmParameters:
    """The parameters of a named arm (`ARMS`)."""
    one_of(arm, tuple(ARMS), "arm")
    return {"table1": ArmParameters.table1, "lab": ArmParameters.lab}.get(arm, ArmParameters)()


def own_parameters(data: dict) -> dict:
    """A scenario mapping (a stored run's resolved one) with each parameter table
    (`PARAMETER_TABLES`) reduced to the user's own layer: the values that differ from the
    parameters of its ``arm``.  `scenario_from_mapping` merges that layer over whichever
    arm is named then, so a rerun with another ``arm`` takes that arm's physics and keeps
    the user's own values.  A value equal to the old arm's cannot be told from it: it
    follows the new arm.

    Parameters
    ----------
    data : dict
        A scenario mapping; not changed.

    Returns
    -------
    dict
        A copy of ``data`` whose parameter tables hold only the user's own values (a table
        that is not a table is left for `scenario_from_mapping` to refuse).
    """
    base = to_mapping(arm_parameters(data.get("arm", "default")))
    out = dict(data)
    for key in PARAMETER_TABLES:
        table = data.get(key, {})
        if isinstance(table, dict):
            out[key] = {k: v for k, v in table.items() if k not in base or base[k] != v}
    return out


def check_scales_on_arm(scaled: dict[str, str], arms, base: dict) -> None:
    """A scale axis multiplies the base scenario's value, resolved on the base's arm.  On
    a parameter (`PARAMETER_TABLES`) that the base leaves to its arm, beside an axis that
    runs an arm whose value differs, it would give that arm the base arm's value: refused
    (`ConfigError` naming the axis).

    Parameters
    ----------
    scaled : dict
        The dotted fields scaled, each with the axis that scales it (for the error).
    arms : iterable of str
        The arms the axes run (an arm that is not one is left to the run's own check).
    base : dict
        The resolved base scenario (`scenario_to_mapping`).
    """
    own = own_parameters(base)
    for path, where in scaled.items():
        table, _, key = path.partition(".")
        if table not in PARAMETER_TABLES or key in own[table]:
            continue  # not the arm's, or the base's own value: the same on every arm
        for arm in sorted(set(arms) - {base["arm"]}):
            try:
                value = to_mapping(arm_parameters(arm)).get(key)
            except ConfigError:
                continue
            check(value == base[table].get(key), where,
                  f"scales {path} of the {base['arm']} arm ({base[table].get(key)!r}), but "
                  f"the axes also run the {arm} arm, whose value is {value!r}: give values, "
                  f"not factors, or set arm = {arm!r} in the base scenario")


def _check_modelable(params: ArmParameters, modes, key: str) -> None:
    """The assumed-modes model of ``params`` must exist and have finite, positive
    frequencies (absurd but finite values — L = 1e300, ρ = 5e-324 — overflow in it)."""
    try:
        ok = _has_positive_frequencies(params, tuple(modes))
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
        raise ConfigError(key, f"the arm cannot be modelled with these values "
                               f"({type(exc).__name__}: {exc})") from None
    check(ok, key, "the arm's natural frequencies are not finite and positive with these values")


@functools.lru_cache(maxsize=256)  # an eigenproblem per check; campaigns repeat arms
def _has_positive_frequencies(params: ArmParameters, modes: tuple[int, int]) -> bool:
    with np.errstate(all="raise"):
        f = nominal_model(params, modes).natural_frequencies()
    return bool(np.all(np.isfinite(f)) and np.all(f > 0))


def scenario_from_mapping(data: dict) -> Scenario:
    """Build and check a scenario from a mapping (unknown keys and bad values raise
    `ConfigError` naming the dotted key).  ``true_params`` and ``nominal_params`` start
    from the parameters of ``arm`` and override them key by key.

    Parameters
    ----------
    data : dict
        Any subset of the scenario keys, as a TOML file would hold them; from Python,
        ``controller.kind``, ``observer.kind`` and ``plant.kind`` may also be a class (it
        becomes its import path, ``"__main__:MyPD"`` for a class defined in a notebook or
        script).

    Returns
    -------
    Scenario
        The scenario, every default filled in, checked (`check_scenario`).

    Raises
    ------
    ConfigError
        Naming the dotted key of an unknown key or a bad value.

    Examples
    --------
    >>> from validation import scenario_from_mapping
    >>> s = scenario_from_mapping({"duration": 2.0, "true_params": {"Mp": 0.5}})
    >>> s.duration, s.true_params.Mp, s.nominal_params.Mp, s.controller.kind
    (2.0, 0.5, 0.1, 'pbc')
    >>> scenario_from_mapping({"plant": {"kind": "exudyn", "stepp": 1e-3}})
    Traceback (most recent call last):
        ...
    validation.run.config.ConfigError: plant.stepp: unknown key for kind 'exudyn'; did you
    mean plant.step? (...)
    """
    base = to_mapping(arm_parameters(data.get("arm", "default")))
    data = dict(data)
    for role in ("controller", "observer", "plant"):
        spec = data.get(role)
        if isinstance(spec, dict) and "kind" in spec and not isinstance(spec["kind"], str):
            data[role] = dict(spec, kind=class_path(spec["kind"], f"{role}.kind"))
    for key in PARAMETER_TABLES:
        given = data.get(key, {})
        data[key] = {**base, **given} if isinstance(given, dict) else given
    scenario = from_mapping(Scenario, data)
    check_scenario(scenario)
    return scenario


def scenario_to_mapping(s: Scenario) -> dict:
    """The fully resolved scenario as plain data (stored next to every result).

    Parameters
    ----------
    s : Scenario
        The scenario.

    Returns
    -------
    dict
        Every key, plain numbers, strings, lists and tables (TOML- and JSON-able);
        `scenario_from_mapping` of it gives ``s`` back.
    """
    return to_mapping(s)

