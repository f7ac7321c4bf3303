"""Scenario: everything one closed-loop run needs, as frozen dataclasses.

A scenario names the plant (reduced or Exudyn), the true arm, the nominal arm the
controller and observer believe in, the controller and observer with their gains, the
reference, sensors and noise, disturbances, saturation, timing and the seed.  It is
built from a mapping (TOML, JSON) with `from_mapping`; `check_scenario` rejects bad
combinations before anything is simulated.  Every error names the dotted key.
"""
from __future__ import annotations

import dataclasses
import functools
import weakref
from dataclasses import dataclass

import numpy as np

from reduced_model import (STRAIN_QUANTITIES, ArmParameters, measured_names,
                           validate_modes_per_link)

from .arms import (PAPER_ARMS, PARAMETER_TABLES, arm_label, arm_of, check_scales_on_arm,
                   own_parameters, params_from_table)
from .config import ConfigError, check, from_mapping, to_mapping
from .laws import check_laws, nominal_model
from .plants import PLANTS, PlantTable
from .requirements import Requirement, check_requirements
from .specs import _REFERENCE_FIELDS, reference_defaults
from .specs import (ControllerSpec, DisturbanceSpec, DivergenceSpec, ModelSpec, ObserverSpec,
                    ReferenceSpec, SensorSpec, class_path, one_of, positive)

__all__ = [
    "Scenario", "PlantTable", "ModelSpec", "ControllerSpec", "ObserverSpec", "ReferenceSpec",
    "SensorSpec", "DisturbanceSpec", "DivergenceSpec", "check_scenario",
    "scenario_from_mapping", "scenario_to_mapping", "own_parameters", "check_scales_on_arm",
    "PARAMETER_TABLES", "PLANT_KINDS", "PAPER_ARMS", "DEFAULT_TRANSIENT", "default_transient",
]

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
    arm : str
        The arm both parameter tables start from: a shipped arm's name
        (`reduced_model.named_arms`: the practical default — Table 1 + a motor-2 stator
        inertia + structural damping —, the paper's Table 1 exactly, the default arm
        behind small harmonic drives, and arms of 1 to 3 links, rigid or flexible,
        horizontal or vertical), the path of an arm file, or an inline ``[arm]`` table
        (named by its ``name``); runs are grouped by it.
    plant : PlantTable
        The plant simulated, chosen by its ``kind``: the settings of a built-in plant
        (`reduced_model.ReducedPlant.Settings`, `plant_exudyn.ExudynPlant.Settings`) or
        of a plug-in (`validation.run.plants.PluginSettings`).
    true_params : reduced_model.ArmParameters
        The arm simulated: ``arm``'s parameters, changed by flat key (``EI1``,
        ``coulomb2``, ``Mp``, ``gravity``); stored in full.
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
    true_params: ArmParameters = dataclasses.field(default_factory=ArmParameters)
    nominal_params: ArmParameters = dataclasses.field(default_factory=ArmParameters)
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
        arm_label(self.arm)
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
        N = self.nominal_params.n_links
        n = N + sum(self.model_modes)
        err = self.observer.initial_error
        if len(err) == 2 * n:
            return np.asarray(err, dtype=float)
        out = np.zeros(2 * n)
        if len(err) == 4:
            signs = lambda k: (-1.0) ** np.arange(k)  # noqa: E731
            out[:N], out[N:n] = err[0] * signs(N), err[1] * signs(n - N)
            out[n:n + N], out[n + N:] = err[2] * signs(N), err[3] * signs(n - N)
        return out

    @property
    def model_modes(self) -> tuple[int, ...]:
        """The laws' modes per link (``model.modes_per_link``, else the nominal arm's)."""
        modes = self.model.modes_per_link
        return tuple(modes) if modes is not None else self.nominal_params.modes()

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
    true, nominal = s.true_params, s.nominal_params
    check(true.n_links == nominal.n_links, "nominal_params.links",
          f"must be as many as true_params' ({true.n_links}), got {nominal.n_links}")
    for i, (a, b) in enumerate(zip(true.links, nominal.links), start=1):
        check(a.length == b.length, f"nominal_params.L{i}",
              f"must equal true_params.L{i}: the modal coordinates of links of different "
              "lengths cannot be compared")
        check(a.rigid == b.rigid, f"nominal_params.modes{i}",
              f"link {i} must be rigid (0) or flexible in both arms")
    for key, modes, arm in (("model.modes_per_link", s.model.modes_per_link, nominal),
                            ("plant.modes_per_link", getattr(s.plant, "modes_per_link", None),
                             true)):
        if modes is not None:
            try:
                validate_modes_per_link(modes, arm, where=key)
            except ValueError as exc:
                raise ConfigError(key, str(exc).removeprefix(key).lstrip(": ")) from None
    for key in PARAMETER_TABLES:
        _check_modelable(getattr(s, key), s.model_modes, key)
    s.plant.check_with(true, s.model_modes, measured_names(
        s.model_modes, modal=s.sensors.modal != "none", rates=s.sensors.rates,
        tip_position=s.sensors.tip_position))
    for name in ("amplitude", "omega", "start", "goal"):
        value = getattr(s.reference, name)
        check(value is None or len(value) == nominal.n_links, f"reference.{name}",
              f"needs one value per joint ({nominal.n_links}), got {list(value or ())}")
    check_laws(s)
    N = nominal.n_links
    n = N + sum(s.model_modes)
    check(len(s.observer.initial_error) in (0, 4, 2 * n), "observer.initial_error",
          f"needs {2 * n} values (the model state), 4 (per group) or none, got "
          f"{len(s.observer.initial_error)}")
    if s.sensors.modal == "gauges":
        check(N == 2, "sensors.modal", "strain gauges are placed on two-link arms "
                                       "(gauges_link1, gauges_link2)")
        model = nominal_model(s.nominal_params, s.model_modes)
        quantity = STRAIN_QUANTITIES[s.sensors.strain_quantity]
        for link, gauges in enumerate((s.sensors.gauges_link1, s.sensors.gauges_link2)):
            key = f"sensors.gauges_link{link + 1}"
            modes = s.model_modes[link]
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
def _has_positive_frequencies(params: ArmParameters, modes: tuple[int, ...]) -> bool:
    with np.errstate(all="raise"):
        f = nominal_model(params, modes).natural_frequencies()
    return bool(np.all(np.isfinite(f)) and np.all(f > 0))


def scenario_from_mapping(data: dict) -> Scenario:
    """Build and check a scenario from a mapping (unknown keys and bad values raise
    `ConfigError` naming the dotted key).  ``true_params`` and ``nominal_params`` start
    from the arm ``arm`` names and change it by flat key (`validation.run.arms`).

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
    data = dict(data)
    arm = data.get("arm", "default")
    data["arm"] = arm_label(arm)
    base = functools.cache(lambda: arm_of(arm))  # read only where a table needs it
    for role in ("controller", "observer", "plant"):
        spec = data.get(role)
        if isinstance(spec, dict) and "kind" in spec and not isinstance(spec["kind"], str):
            data[role] = dict(spec, kind=class_path(spec["kind"], f"{role}.kind"))
    for key in PARAMETER_TABLES:
        given = data.get(key, {})
        if not isinstance(given, ArmParameters):
            data[key] = params_from_table(given, base, key)
    # The reference's per-joint defaults are for the arm's joints.
    reference = data.get("reference", {})
    if isinstance(reference, dict):
        joints = data["nominal_params"].n_links
        used = _REFERENCE_FIELDS[reference.get("kind", "paper")] if reference.get(
            "kind", "paper") in _REFERENCE_FIELDS else ()
        data["reference"] = {**{k: v for k, v in reference_defaults(joints).items()
                                if k in used}, **reference}
    # Model orders not given are the arms' own, written out in the resolved scenario.
    for role, params in (("model", data["nominal_params"]), ("plant", data["true_params"])):
        table = data.get(role, {})
        if isinstance(table, dict) and table.get("modes_per_link") is None and (
                role == "model" or table.get("kind", "reduced") == "reduced"):
            data[role] = {**table, "modes_per_link": list(params.modes())}
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

