"""Scenario: everything one closed-loop run needs, as frozen dataclasses.

A scenario names the plant (reduced or Exudyn), the true arm, the nominal arm the
controller and observer believe in, the controller and observer with their gains, the
reference, sensors and noise, disturbances, saturation, timing and the seed.  It is
built from a mapping (TOML, JSON) with `from_mapping`; `check_scenario` rejects bad
combinations before anything is simulated.  Every error names the dotted key.
"""
from __future__ import annotations

import functools
import inspect
import math
from dataclasses import dataclass, field

import numpy as np

from controllers import ReferenceKind
from reduced_model import KINEMATICS, STRAIN_QUANTITIES, ArmParameters, validate_modes_per_link

from ._config import ConfigError, check, from_mapping, to_mapping
from ._sample import DisturbanceKind, DisturbanceTarget
from .laws import check_laws, nominal_model
from .plants import PLANTS, PlantTable
from .requirements import Requirement, check_requirements

__all__ = [
    "Scenario", "PlantTable", "ModelSpec", "ControllerSpec", "ObserverSpec", "ReferenceSpec",
    "SensorSpec", "DisturbanceSpec", "DivergenceSpec", "check_scenario",
    "scenario_from_mapping", "scenario_to_mapping", "arm_parameters", "PLANT_KINDS", "ARMS",
    "DEFAULT_TRANSIENT", "default_transient",
]

#: The arms a scenario can start from: the practical default (Table 1 + a motor-2 stator
#: inertia of 0.01 kg m² + bending damping 2e-3 N m² s) and the paper's Table 1 exactly.
ARMS = {"default": "practical default arm (Table 1 + stator inertia 0.01 kg m² + damping "
                   "2e-3 N m² s)",
        "table1": "the paper's Table 1 exactly (no stator inertia, no damping)"}
REFERENCE_KINDS = tuple(k.name.lower() for k in ReferenceKind)
MODAL_SENSORS = ("direct", "gauges", "none")
DISTURBANCE_KINDS = tuple(k.name.lower() for k in DisturbanceKind)
DISTURBANCE_TARGETS = tuple(k.name.lower() for k in DisturbanceTarget)
FEEDBACK = ("auto", "true", "estimate")
#: Caps that keep a typo from exhausting memory or hanging a run: samples held in memory
#: (5e6 = 83 min at 1 kHz, ~3 GB of signals) and internal plant steps per run.
MAX_SAMPLES = 5e6
MAX_PLANT_STEPS = 2e8
#: Largest noise standard deviation accepted (rad, m, rad/s or m/s): beyond it nothing is
#: measured at all.
MAX_NOISE = 1e3
INITIAL_STATES = ("rest", "reference")
#: The default transient [s] after which metrics are taken; a run shorter than twice this
#: is measured over its second half (`default_transient`).
DEFAULT_TRANSIENT = 2.0


def default_transient(duration: float) -> float:
    """The transient of a scenario that does not set one: 2 s, or half of a run shorter
    than 4 s (so that ``flexarm run --duration 1`` measures its last 0.5 s)."""
    return min(DEFAULT_TRANSIENT, duration / 2)


def _one_of(value, allowed, name) -> None:
    check(value in allowed, name, f"must be one of {', '.join(map(repr, allowed))}, "
                                  f"got {value!r}")


def _positive(value, name, *, allow_zero=False) -> None:
    check(math.isfinite(value), name, f"must be finite, got {value!r}")
    check(value >= 0 if allow_zero else value > 0, name,
          f"must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")


def _modes(value) -> None:
    try:
        validate_modes_per_link(value)
    except ValueError:
        raise ConfigError("modes_per_link", f"must be two integers in 1..4, got "
                                            f"{list(value)!r}") from None


#: The built-in plant kinds (`validation.run.plants.PLANTS`): a scenario's ``plant`` is a
#: tagged choice of their settings, or "package.module:Class" for a plug-in plant.
PLANT_KINDS = tuple(PLANTS)


@dataclass(frozen=True)
class ModelSpec:
    """The controller's and observer's model.

    Parameters
    ----------
    modes_per_link : (int, int)
        Assumed modes of link 1 and link 2 in the model the laws are built on (1..4 each).
    kinematics : {"linear", "exact"}
        The kinematics of that model: the paper's linear kinematics, or exact
        inextensible kinematics (`reduced_model.ArmModel`).  The PBC, the observers and
        the EKF use its dynamics; the rigid-arm laws (PD, computed torque) and the LQR,
        designed at q = 0 where both kinematics agree, are the same on either.
    """

    modes_per_link: tuple[int, int] = (2, 2)
    kinematics: str = "linear"

    def __post_init__(self):
        _modes(self.modes_per_link)
        _one_of(self.kinematics, KINEMATICS, "kinematics")


def class_path(cls, where: str) -> str:
    """The import path ``"module:Class"`` of a law's or plant's class given from Python
    (a class defined in a notebook or a script: ``"__main__:Class"``, found in the process
    that runs it); ConfigError naming ``where`` for anything else."""
    if not inspect.isclass(cls):
        hint = (f"the class {type(cls).__name__}, not an instance of it (it is built for "
                "each run from its options)"
                if callable(cls) or hasattr(cls, "update") or hasattr(cls, "step")
                else "a class or its name")
        raise ConfigError(where, f"give {hint}, got {cls!r}")
    check("<locals>" not in cls.__qualname__, where,
          f"{cls.__qualname__} is defined inside a function: define it at module level, "
          "where its import path finds it")
    return f"{cls.__module__}:{cls.__qualname__}"


def _law_kind(value) -> None:
    check(isinstance(value, str) and value.strip() == value and value != "", "kind",
          f"must be a law's name or \"package.module:Class\", got {value!r}")


@dataclass(frozen=True)
class ControllerSpec:
    """The controller: a built-in law or a plug-in.

    Parameters
    ----------
    kind : str
        A built-in controller ("pbc", "pbc-idealised", "pd", "ct", "lqr", or "replay":
        recorded torques, what ``flexarm calibrate`` runs) or a plug-in
        ``"package.module:Class"``.
    options : dict
        Its keyword options; the class's own defaults for the rest (an option it does not
        take is refused).
    """

    kind: str = "pbc"
    options: dict = field(default_factory=dict)

    def __post_init__(self):
        _law_kind(self.kind)


@dataclass(frozen=True)
class ObserverSpec:
    """The observer: none, a built-in one or a plug-in.

    Parameters
    ----------
    kind : str
        "none", a built-in observer ("smo-paper": sign, full state measured; "smo-bl":
        boundary layer; "smo-pos": positions measured, Barbot's step-by-step injection;
        "ekf", "ekf-pos": extended Kalman filter) or a plug-in ``"package.module:Class"``.
    options : dict
        Its keyword options; the class's own defaults for the rest.
    initial_error : tuple of float
        x̂(0) − x(0) [rad, m, rad/s, m/s]: empty (exact start), the full 2n-vector, or four
        values (angles, modal positions, angle rates, modal rates) applied to every state
        of their group with alternating signs — valid for any model order.
    """

    kind: str = "none"
    options: dict = field(default_factory=dict)
    initial_error: tuple[float, ...] = ()

    def __post_init__(self):
        _law_kind(self.kind)
        check(all(math.isfinite(v) for v in self.initial_error), "initial_error",
              "must be finite numbers")


#: The settings each reference kind uses, and their defaults.
_REFERENCE_FIELDS = {"paper": ("amplitude", "omega"), "quintic": ("start", "goal", "move_time")}
_REFERENCE_DEFAULTS = {"amplitude": (2.0, 2.0), "omega": (0.1 * np.pi, 0.2 * np.pi),
                       "start": (0.0, 0.0), "goal": (1.0, -1.0), "move_time": 4.0}


@dataclass(frozen=True)
class ReferenceSpec:
    """The reference trajectory of the joint angles.  Each kind takes only its own
    settings.

    Parameters
    ----------
    kind : {"paper", "quintic"}
        "paper": eq. (37), θ_d = amplitude·sin(omega·t); "quintic": rest-to-rest from
        ``start`` to ``goal`` in ``move_time``, then hold.
    amplitude : (float, float)
        Amplitudes of eq. (37) per joint [rad] (only "paper"; default (2, 2)).
    omega : (float, float)
        Angular frequencies of eq. (37) per joint [rad/s] (only "paper"; default
        (0.1π, 0.2π)).
    start : (float, float)
        Joint angles at the start of the move [rad] (only "quintic"; default (0, 0)).
    goal : (float, float)
        Joint angles at its end [rad] (only "quintic"; default (1, −1)).
    move_time : float
        Duration of the move [s] (only "quintic"; default 4).
    """

    kind: str = "paper"
    amplitude: tuple[float, float] | None = None
    omega: tuple[float, float] | None = None
    start: tuple[float, float] | None = None
    goal: tuple[float, float] | None = None
    move_time: float | None = None

    def __post_init__(self):
        _one_of(self.kind, REFERENCE_KINDS, "kind")
        used = _REFERENCE_FIELDS[self.kind]
        _only_where_used(self, used, _REFERENCE_DEFAULTS, f"by a {self.kind!r} reference")
        for name in used:
            if name == "move_time":
                _positive(self.move_time, name)
            else:
                check(all(math.isfinite(v) for v in getattr(self, name)), name,
                      f"must be finite, got {getattr(self, name)!r}")


def _only_where_used(spec, used: tuple[str, ...], defaults: dict, where: str) -> None:
    """Settings that ``spec`` (a frozen dataclass) uses get their default when not given
    (None); a setting it does not use must not be given: it would change nothing but the
    run's id."""
    for name, default in defaults.items():
        value = getattr(spec, name)
        if name in used and value is None:
            object.__setattr__(spec, name, default)
        elif name not in used:
            check(value is None, name, f"not used {where} (drop it)")


_GAUGE_DEFAULTS = {"gauges_link1": (0.05, 0.2, 0.35), "gauges_link2": (0.05, 0.2, 0.35),
                   "strain_quantity": "curvature"}


@dataclass(frozen=True)
class SensorSpec:
    """What the sensors measure, and how badly.

    Parameters
    ----------
    modal : {"direct", "gauges", "none"}
        How the modal coordinates q are measured: "direct" (read exactly, the paper's
        assumption), "gauges" (fitted to strain gauges), "none" (encoders only).
    gauges_link1, gauges_link2 : tuple of float
        Gauge positions on each link, from its root [m]; only with ``modal = "gauges"``
        (default three per link, at 0.05, 0.2 and 0.35 m).
    strain_quantity : {"curvature", "deflection"}
        What the gauges read; only with ``modal = "gauges"`` (default curvature).
    rates : bool
        Whether θ̇ and q̇ are measured too (the paper's full-state SMO needs them).
    tip_position : bool
        Whether the payload position is measured.
    encoder_resolution : float
        Encoder quantisation [rad per count]; 0: none.
    encoder_noise : float
        Standard deviation of the encoder noise per reading [rad].
    modal_noise : float
        Standard deviation of the modal-coordinate noise per reading [m].
    rate_noise : float
        Standard deviation of the rate noise per reading [rad/s, m/s].
    delay : int
        Measurement delay [samples].
    """

    modal: str = "direct"
    gauges_link1: tuple[float, ...] | None = None
    gauges_link2: tuple[float, ...] | None = None
    strain_quantity: str | None = None
    rates: bool = True
    tip_position: bool = False
    encoder_resolution: float = 0.0
    encoder_noise: float = 0.0
    modal_noise: float = 0.0
    rate_noise: float = 0.0
    delay: int = 0

    def __post_init__(self):
        _one_of(self.modal, MODAL_SENSORS, "modal")
        _only_where_used(self, tuple(_GAUGE_DEFAULTS) if self.modal == "gauges" else (),
                         _GAUGE_DEFAULTS, "unless modal = 'gauges'")
        if self.modal == "gauges":
            _one_of(self.strain_quantity, tuple(STRAIN_QUANTITIES), "strain_quantity")
            for name in ("gauges_link1", "gauges_link2"):
                check(all(math.isfinite(v) and v >= 0 for v in getattr(self, name)), name,
                      "positions must be finite and >= 0 [m]")
        for name in ("encoder_resolution", "encoder_noise", "modal_noise", "rate_noise"):
            _positive(getattr(self, name), name, allow_zero=True)
            check(getattr(self, name) <= MAX_NOISE, name,
                  f"must be <= {MAX_NOISE:g}, got {getattr(self, name)!r}")
        check(self.delay >= 0, "delay", f"must be >= 0 samples, got {self.delay!r}")


#: The settings each disturbance kind uses beyond kind, target, amplitude and start.
_DISTURBANCE_FIELDS = {"step": (), "pulse": ("duration",), "sine": ("frequency",),
                       "noise": ("bandwidth",)}
_DISTURBANCE_DEFAULTS = {"duration": 0.1, "frequency": 1.0, "bandwidth": 5.0}


@dataclass(frozen=True)
class DisturbanceSpec:
    """A disturbance on a joint torque or on the payload.  Each kind takes only its own
    settings.

    Parameters
    ----------
    kind : {"step", "pulse", "sine", "noise"}
        "step" from ``start``; "pulse" during [``start``, ``start`` + ``duration``];
        "sine": amplitude·sin(2π·frequency·(t − start)); "noise": Gaussian, standard
        deviation ``amplitude``, low-passed at ``bandwidth``.
    target : {"tau1", "tau2", "tip_x", "tip_y"}
        A joint torque, or a force on the payload in the base frame.
    amplitude : float
        Its size [N m on a joint, N on the payload].
    start : float
        When it starts [s].
    duration : float
        Length of a pulse [s] (only "pulse"; default 0.1).
    frequency : float
        Frequency of a sine [Hz] (only "sine"; default 1).
    bandwidth : float
        Low-pass cut-off of the noise [Hz] (only "noise"; default 5).
    """

    kind: str = "step"
    target: str = "tau1"
    amplitude: float = 0.0
    start: float = 0.0
    duration: float | None = None
    frequency: float | None = None
    bandwidth: float | None = None

    def __post_init__(self):
        _one_of(self.kind, DISTURBANCE_KINDS, "kind")
        _one_of(self.target, DISTURBANCE_TARGETS, "target")
        check(math.isfinite(self.amplitude), "amplitude", "must be finite")
        _positive(self.start, "start", allow_zero=True)
        _only_where_used(self, _DISTURBANCE_FIELDS[self.kind], _DISTURBANCE_DEFAULTS,
                         f"by a {self.kind!r} disturbance")
        for name in _DISTURBANCE_FIELDS[self.kind]:
            _positive(getattr(self, name), name)


@dataclass(frozen=True)
class DivergenceSpec:
    """When a run ends as "diverged".

    Parameters
    ----------
    max_angle : float
        Largest |θ| of either joint [rad].
    max_rate : float
        Largest |θ̇| of either joint [rad/s].
    max_deflection : float
        Largest tip deflection [× its link's length].
    """

    max_angle: float = 50.0
    max_rate: float = 100.0
    max_deflection: float = 0.5

    def __post_init__(self):
        _positive(self.max_angle, "max_angle")
        _positive(self.max_rate, "max_rate")
        _positive(self.max_deflection, "max_deflection")


@dataclass(frozen=True)
class Scenario:
    """One closed-loop run: everything it needs, from a TOML file or a mapping
    (`scenario_from_mapping`).

    Parameters
    ----------
    name : str
        The run's name in results and reports.
    arm : {"default", "table1"}
        The arm both parameter tables start from: the practical default (Table 1 + a
        motor-2 stator inertia + structural damping) or the paper's Table 1 exactly
        (`ARMS`).
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
        _one_of(self.arm, tuple(ARMS), "arm")
        _one_of(self.feedback, FEEDBACK, "feedback")
        _one_of(self.initial_state, INITIAL_STATES, "initial_state")
        _positive(self.Ts, "Ts")
        _positive(self.duration, "duration")
        _positive(self.torque_limit, "torque_limit", allow_zero=True)
        if self.transient is None:  # resolved here, so the stored scenario holds the number
            object.__setattr__(self, "transient", default_transient(self.duration))
        _positive(self.transient, "transient", allow_zero=True)
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


def check_scenario(s: Scenario) -> None:
    """Reject combinations that cannot run, before anything is simulated (once per
    scenario object: a frozen scenario checked stays valid)."""
    if s.__dict__.get("_checked"):
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
    for key in ("true_params", "nominal_params"):
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
    object.__setattr__(s, "_checked", True)  # frozen: what passed once passes again


def arm_parameters(arm: str) -> ArmParameters:
    """The parameters of a named arm (`ARMS`)."""
    _one_of(arm, tuple(ARMS), "arm")
    return ArmParameters.table1() if arm == "table1" else ArmParameters()


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
    """
    base = to_mapping(arm_parameters(data.get("arm", "default")))
    data = dict(data)
    for role in ("controller", "observer", "plant"):
        spec = data.get(role)
        if isinstance(spec, dict) and "kind" in spec and not isinstance(spec["kind"], str):
            data[role] = dict(spec, kind=class_path(spec["kind"], f"{role}.kind"))
    for key in ("true_params", "nominal_params"):
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

