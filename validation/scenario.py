"""Scenario: everything one closed-loop run needs, as frozen dataclasses.

A scenario names the plant (reduced or Exudyn), the true arm, the nominal arm the
controller and observer believe in, the controller and observer with their gains, the
reference, sensors and noise, disturbances, saturation, timing and the seed.  It is
built from a mapping (TOML, JSON) with `from_mapping`; `check_scenario` rejects bad
combinations before anything is simulated.  Every error names the dotted key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plant_exudyn import Mesh
from reduced_model import STRAIN_QUANTITIES, ArmParameters, validate_modes_per_link

from ._config import ConfigError, check, from_mapping, to_mapping

__all__ = [
    "Scenario", "PlantSpec", "ModelSpec", "ControllerSpec", "PBCGains", "PDGains", "CTGains",
    "ObserverSpec", "ReferenceSpec", "SensorSpec", "DisturbanceSpec", "DivergenceSpec",
    "check_scenario", "scenario_from_mapping", "scenario_to_mapping",
    "PLANTS", "CONTROLLERS", "OBSERVERS",
]

PLANTS = ("reduced", "exudyn")
CONTROLLERS = ("pbc", "pd", "ct")
OBSERVERS = ("none", "smo-paper", "smo-bl", "smo-pos")
REFERENCE_KINDS = ("paper", "quintic")
MODAL_SENSORS = ("direct", "gauges", "none")
DISTURBANCE_KINDS = ("step", "pulse", "sine", "noise")
DISTURBANCE_TARGETS = ("tau1", "tau2", "tip_x", "tip_y")
FEEDBACK = ("auto", "true", "estimate")
INITIAL_STATES = ("rest", "reference")


def _one_of(value, allowed, name) -> None:
    check(value in allowed, name, f"must be one of {', '.join(map(repr, allowed))}, "
                                  f"got {value!r}")


def _positive(value, name, *, allow_zero=False) -> None:
    ok = math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
    check(ok, name, f"must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")


def _nonnegative_all(values, name) -> None:
    check(all(math.isfinite(v) and v >= 0 for v in values), name,
          f"must be finite and >= 0, got {list(values)!r}")


@dataclass(frozen=True)
class PlantSpec:
    """``kind``: "reduced" (the model as plant, RK4) or "exudyn" (the FE truth plant).
    ``modes_per_link`` is the reduced plant's own model order; ``mesh``,
    ``spectral_radius`` and ``newton_tolerance`` apply to the Exudyn plant; ``step`` [s] is
    either's internal step."""

    kind: str = "reduced"
    modes_per_link: tuple[int, int] = (2, 2)
    step: float = 1e-3
    mesh: Mesh = Mesh()
    spectral_radius: float = 0.9
    newton_tolerance: float = 1e-6

    def __post_init__(self):
        _one_of(self.kind, PLANTS, "kind")
        _positive(self.newton_tolerance, "newton_tolerance")
        try:
            validate_modes_per_link(self.modes_per_link)
        except ValueError:
            raise ConfigError("modes_per_link", f"must be two integers in 1..4, got "
                                                f"{list(self.modes_per_link)!r}") from None
        _positive(self.step, "step")
        check(0 <= self.spectral_radius <= 1, "spectral_radius",
              f"must be in [0, 1], got {self.spectral_radius!r}")


@dataclass(frozen=True)
class ModelSpec:
    """The controller's and observer's model: assumed modes per link (1..4 each)."""

    modes_per_link: tuple[int, int] = (2, 2)

    def __post_init__(self):
        try:
            validate_modes_per_link(self.modes_per_link)
        except ValueError:
            raise ConfigError("modes_per_link", f"must be two integers in 1..4, got "
                                                f"{list(self.modes_per_link)!r}") from None


@dataclass(frozen=True)
class PBCGains:
    """Eq. (20): Λ and K_v on the joints and on every flexible coordinate; ``idealised``
    applies all n components (reduced plant only)."""

    lambda_joint: tuple[float, float] = (3.0, 3.0)
    lambda_flex: float = 1.0
    kv_joint: tuple[float, float] = (10.0, 5.0)
    kv_flex: float = 5.0
    idealised: bool = False
    compensate_damping: bool = True

    def __post_init__(self):
        _nonnegative_all(self.lambda_joint, "lambda_joint")
        _positive(self.lambda_flex, "lambda_flex", allow_zero=True)
        _nonnegative_all(self.kv_joint, "kv_joint")
        _positive(self.kv_flex, "kv_flex", allow_zero=True)


@dataclass(frozen=True)
class PDGains:
    """Joint PD [N m/rad, N m s/rad], with the rigid arm's feedforward if ``feedforward``."""

    kp: tuple[float, float] = (40.0, 20.0)
    kd: tuple[float, float] = (8.0, 4.0)
    feedforward: bool = True

    def __post_init__(self):
        _nonnegative_all(self.kp, "kp")
        _nonnegative_all(self.kd, "kd")


@dataclass(frozen=True)
class CTGains:
    """Rigid computed torque: error dynamics ë + K_d ė + K_p e = 0 [1/s², 1/s]."""

    kp: tuple[float, float] = (16.0, 16.0)
    kd: tuple[float, float] = (8.0, 8.0)

    def __post_init__(self):
        _nonnegative_all(self.kp, "kp")
        _nonnegative_all(self.kd, "kd")


@dataclass(frozen=True)
class ControllerSpec:
    kind: str = "pbc"
    pbc: PBCGains = PBCGains()
    pd: PDGains = PDGains()
    ct: CTGains = CTGains()

    def __post_init__(self):
        _one_of(self.kind, CONTROLLERS, "kind")


@dataclass(frozen=True)
class ObserverSpec:
    """``kind``: "none", "smo-paper" (sign, full state measured), "smo-bl" (boundary
    layer), "smo-pos" (positions measured, Barbot's step-by-step injection).  Gains as
    (joint, flexible) pairs.  ``initial_error`` = x̂(0) − x(0): empty (exact start), the
    full 2n-vector, or four values (angles, modal positions, angle rates, modal rates)
    applied to every state of their group with alternating signs — valid for any model
    order."""

    kind: str = "none"
    l_position: tuple[float, float] = (1.0, 0.5)
    l_velocity: tuple[float, float] = (5.0, 2.0)
    boundary_layer: float = 2.0
    filter_time: float = 5e-3
    initial_error: tuple[float, ...] = ()

    def __post_init__(self):
        _one_of(self.kind, OBSERVERS, "kind")
        _nonnegative_all(self.l_position, "l_position")
        _nonnegative_all(self.l_velocity, "l_velocity")
        _positive(self.boundary_layer, "boundary_layer")
        _positive(self.filter_time, "filter_time")
        check(all(math.isfinite(v) for v in self.initial_error), "initial_error",
              "must be finite numbers")


@dataclass(frozen=True)
class ReferenceSpec:
    """"paper": eq. (37) θ_d = amplitude·sin(omega·t); "quintic": rest-to-rest from
    ``start`` to ``goal`` in ``move_time`` seconds, then hold."""

    kind: str = "paper"
    amplitude: tuple[float, float] = (2.0, 2.0)
    omega: tuple[float, float] = (0.1 * np.pi, 0.2 * np.pi)
    start: tuple[float, float] = (0.0, 0.0)
    goal: tuple[float, float] = (1.0, -1.0)
    move_time: float = 4.0

    def __post_init__(self):
        _one_of(self.kind, REFERENCE_KINDS, "kind")
        check(all(math.isfinite(v) for v in (*self.amplitude, *self.omega, *self.start,
                                              *self.goal)), "amplitude", "must be finite")
        _positive(self.move_time, "move_time")


@dataclass(frozen=True)
class SensorSpec:
    """``modal``: "direct" (q read exactly, the paper's assumption), "gauges" (q fitted
    to strain gauges at ``gauges_link1``/``gauges_link2`` [m] reading
    ``strain_quantity``), "none" (encoders only).  Noise standard deviations are per
    reading; ``delay`` is in whole samples."""

    modal: str = "direct"
    gauges_link1: tuple[float, ...] = (0.05, 0.2, 0.35)
    gauges_link2: tuple[float, ...] = (0.05, 0.2, 0.35)
    strain_quantity: str = "curvature"
    rates: bool = True
    tip_position: bool = False
    encoder_resolution: float = 0.0
    encoder_noise: float = 0.0
    modal_noise: float = 0.0
    rate_noise: float = 0.0
    delay: int = 0

    def __post_init__(self):
        _one_of(self.modal, MODAL_SENSORS, "modal")
        _one_of(self.strain_quantity, tuple(STRAIN_QUANTITIES), "strain_quantity")
        for name in ("encoder_resolution", "encoder_noise", "modal_noise", "rate_noise"):
            _positive(getattr(self, name), name, allow_zero=True)
        check(self.delay >= 0, "delay", f"must be >= 0 samples, got {self.delay!r}")
        for name in ("gauges_link1", "gauges_link2"):
            check(all(math.isfinite(v) and v >= 0 for v in getattr(self, name)), name,
                  "positions must be finite and >= 0 [m]")


@dataclass(frozen=True)
class DisturbanceSpec:
    """A disturbance on a joint torque (``tau1``, ``tau2`` [N m]) or on the payload
    (``tip_x``, ``tip_y`` [N], base frame): "step" from ``start``; "pulse" during
    [``start``, ``start`` + ``duration``]; "sine" amplitude·sin(2π·frequency·(t − start));
    "noise": Gaussian, standard deviation ``amplitude``, low-passed at ``bandwidth`` Hz."""

    kind: str = "step"
    target: str = "tau1"
    amplitude: float = 0.0
    start: float = 0.0
    duration: float = 0.1
    frequency: float = 1.0
    bandwidth: float = 5.0

    def __post_init__(self):
        _one_of(self.kind, DISTURBANCE_KINDS, "kind")
        _one_of(self.target, DISTURBANCE_TARGETS, "target")
        check(math.isfinite(self.amplitude), "amplitude", "must be finite")
        _positive(self.start, "start", allow_zero=True)
        _positive(self.duration, "duration")
        _positive(self.frequency, "frequency")
        _positive(self.bandwidth, "bandwidth")


@dataclass(frozen=True)
class DivergenceSpec:
    """The run ends as "diverged" when |θ| > ``max_angle`` [rad], |θ̇| > ``max_rate``
    [rad/s] or a tip deflection exceeds ``max_deflection`` × its link length."""

    max_angle: float = 50.0
    max_rate: float = 100.0
    max_deflection: float = 0.5

    def __post_init__(self):
        _positive(self.max_angle, "max_angle")
        _positive(self.max_rate, "max_rate")
        _positive(self.max_deflection, "max_deflection")


@dataclass(frozen=True)
class Scenario:
    """One closed-loop run.  ``true_params`` builds the plant, ``nominal_params`` the
    controller's and observer's model (they differ only if a scenario says so).
    ``feedback``: the state the controller sees — "true", "estimate" (the observer's),
    or "auto" (the estimate when there is an observer).  ``torque_limit`` [N m] saturates
    each joint (0: none).  ``transient`` [s]: metrics of tracking start after it."""

    name: str = "paper"
    plant: PlantSpec = PlantSpec()
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
    transient: float = 2.0

    def __post_init__(self):
        _one_of(self.feedback, FEEDBACK, "feedback")
        _one_of(self.initial_state, INITIAL_STATES, "initial_state")
        _positive(self.Ts, "Ts")
        _positive(self.duration, "duration")
        _positive(self.torque_limit, "torque_limit", allow_zero=True)
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
    """Reject combinations that cannot run, before anything is simulated."""
    n_steps = round(s.Ts / s.plant.step)
    check(n_steps >= 1 and abs(n_steps * s.plant.step - s.Ts) <= 1e-9 * s.Ts, "Ts",
          f"{s.Ts!r} s is not a whole multiple of plant.step = {s.plant.step!r} s")
    check(s.duration >= s.Ts, "duration", f"must be at least one sample (Ts = {s.Ts}), "
                                          f"got {s.duration!r}")
    check(not (s.controller.kind == "pbc" and s.controller.pbc.idealised
               and s.plant.kind == "exudyn"), "controller.pbc.idealised",
          "the Exudyn plant has two actuators; the idealised PBC (all n components of "
          "eq. 20 applied) runs only on the reduced plant")
    check(not (s.feedback == "estimate" and s.observer.kind == "none"), "feedback",
          "'estimate' needs an observer (observer.kind is 'none')")
    for link, name in ((1, "L1"), (2, "L2")):
        check(getattr(s.true_params, name) == getattr(s.nominal_params, name),
              f"nominal_params.{name}", f"must equal true_params.{name}: the modal "
                                        "coordinates of links of different lengths "
                                        "cannot be compared")
    obs = s.observer.kind
    if obs == "smo-pos":
        check(s.sensors.modal != "none", "observer.kind",
              "smo-pos needs the modal positions: set sensors.modal to 'direct' or "
              "'gauges' (strain sensors)")
    if obs in ("smo-paper", "smo-bl"):
        check(s.sensors.modal != "none" and s.sensors.rates, "observer.kind",
              f"{obs} measures the full state (the paper's y = x): needs sensors.rates = "
              "true and sensors.modal 'direct' or 'gauges'")
    n = 2 + sum(s.model.modes_per_link)
    check(len(s.observer.initial_error) in (0, 4, 2 * n), "observer.initial_error",
          f"needs {2 * n} values (the model state), 4 (per group) or none, got "
          f"{len(s.observer.initial_error)}")
    if s.sensors.modal == "gauges":
        for link, gauges in enumerate((s.sensors.gauges_link1, s.sensors.gauges_link2)):
            key = f"sensors.gauges_link{link + 1}"
            modes = s.model.modes_per_link[link]
            check(len(gauges) >= modes, key, f"{len(gauges)} gauge(s) for {modes} modes; "
                                             f"need at least {modes}")
            L = s.true_params.L1 if link == 0 else s.true_params.L2
            check(all(x <= L for x in gauges), key, f"positions must lie on the link "
                                                    f"(0..{L} m), got {list(gauges)}")


def scenario_from_mapping(data: dict) -> Scenario:
    """Build and check a scenario from a mapping (unknown keys and bad values raise
    `ConfigError` naming the dotted key)."""
    scenario = from_mapping(Scenario, data)
    check_scenario(scenario)
    return scenario


def scenario_to_mapping(s: Scenario) -> dict:
    """The fully resolved scenario as plain data (stored next to every result)."""
    return to_mapping(s)

