"""The parts of a scenario: the tables a scenario file holds besides its top-level keys
(the laws' model, controller, observer, reference, sensors, disturbances, divergence
bounds), as frozen dataclasses that check their own values and name the offending key.
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field

import numpy as np

from controllers import ReferenceKind
from reduced_model import KINEMATICS, STRAIN_QUANTITIES, validate_modes_per_link

from .sample import DISTURBANCE_TARGETS, DisturbanceKind
from .config import ConfigError, check, did_you_mean

__all__ = ["ModelSpec", "ControllerSpec", "ObserverSpec", "ReferenceSpec", "SensorSpec",
           "DisturbanceSpec", "DivergenceSpec", "class_path", "one_of", "positive",
           "REFERENCE_KINDS", "reference_defaults", "MODAL_SENSORS", "DISTURBANCE_KINDS", "DISTURBANCE_TARGETS",
           "MAX_NOISE"]

REFERENCE_KINDS = tuple(k.name.lower() for k in ReferenceKind)
MODAL_SENSORS = ("direct", "gauges", "none")
DISTURBANCE_KINDS = tuple(k.name.lower() for k in DisturbanceKind)
#: Largest noise standard deviation accepted (rad, m, rad/s or m/s): beyond it nothing is
#: measured at all.
MAX_NOISE = 1e3


def one_of(value, allowed, name) -> None:
    check(value in allowed, name, f"must be one of {', '.join(map(repr, allowed))}, "
                                  f"got {value!r}{did_you_mean(value, allowed, quote=True)}")


def positive(value, name, *, allow_zero=False) -> None:
    check(math.isfinite(value), name, f"must be finite, got {value!r}")
    check(value >= 0 if allow_zero else value > 0, name,
          f"must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")


def _modes(value) -> None:
    if value is None:
        return
    try:
        validate_modes_per_link(value)
    except ValueError:
        raise ConfigError("modes_per_link", f"must be one integer in 0..4 per link (0: a "
                                            f"rigid link), got {list(value)!r}") from None





@dataclass(frozen=True)
class ModelSpec:
    """The controller's and observer's model.

    Parameters
    ----------
    modes_per_link : list of int, optional
        Assumed modes of each link in the model the laws are built on (1..4; 0 for a
        rigid link; default: the nominal arm's ``modes``).
    kinematics : {"linear", "exact"}
        The kinematics of that model: the paper's linear kinematics, or exact
        inextensible kinematics (`reduced_model.ArmModel`).  The PBC, the observers and
        the EKF use its dynamics; the rigid-arm laws (PD, computed torque) and the LQR,
        designed at q = 0 where both kinematics agree, are the same on either.
    """

    modes_per_link: tuple[int, ...] | None = None
    kinematics: str = "linear"

    def __post_init__(self):
        _modes(self.modes_per_link)
        one_of(self.kinematics, KINEMATICS, "kinematics")


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


#: The settings each reference kind uses.
_REFERENCE_FIELDS = {"paper": ("amplitude", "omega"), "quintic": ("start", "goal", "move_time")}


def reference_defaults(joints: int) -> dict:
    """The reference's defaults for an arm of ``joints`` joints: eq. (37)'s amplitude 2 rad
    and ω_i = 0.1π·i rad/s (the paper's (0.1π, 0.2π) on two joints); a move from 0 to ±1
    rad, alternating, in 4 s."""
    return {"amplitude": (2.0,) * joints,
            "omega": tuple(0.1 * np.pi * (i + 1) for i in range(joints)),
            "start": (0.0,) * joints, "goal": (1.0, -1.0, 1.0, -1.0)[:joints],
            "move_time": 4.0}


_REFERENCE_DEFAULTS = reference_defaults(2)


@dataclass(frozen=True)
class ReferenceSpec:
    """The reference trajectory of the joint angles.  Each kind takes only its own
    settings.

    Parameters
    ----------
    kind : {"paper", "quintic"}
        "paper": eq. (37), θ_d = amplitude·sin(omega·t); "quintic": rest-to-rest from
        ``start`` to ``goal`` in ``move_time``, then hold.
    amplitude : list of float
        Amplitudes of eq. (37), one per joint [rad] (only "paper"; default 2 each).
    omega : list of float
        Angular frequencies of eq. (37), one per joint [rad/s] (only "paper"; default
        0.1π·i for joint i: the paper's (0.1π, 0.2π)).
    start : list of float
        Joint angles at the start of the move [rad] (only "quintic"; default 0 each).
    goal : list of float
        Joint angles at its end [rad] (only "quintic"; default 1, −1, 1, … alternating).
    move_time : float
        Duration of the move [s] (only "quintic"; default 4).
    """

    kind: str = "paper"
    amplitude: tuple[float, ...] | None = None
    omega: tuple[float, ...] | None = None
    start: tuple[float, ...] | None = None
    goal: tuple[float, ...] | None = None
    move_time: float | None = None

    def __post_init__(self):
        one_of(self.kind, REFERENCE_KINDS, "kind")
        used = _REFERENCE_FIELDS[self.kind]
        _only_where_used(self, used, _REFERENCE_DEFAULTS, f"by a {self.kind!r} reference")
        for name in used:
            if name == "move_time":
                positive(self.move_time, name)
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
        one_of(self.modal, MODAL_SENSORS, "modal")
        _only_where_used(self, tuple(_GAUGE_DEFAULTS) if self.modal == "gauges" else (),
                         _GAUGE_DEFAULTS, "unless modal = 'gauges'")
        if self.modal == "gauges":
            one_of(self.strain_quantity, tuple(STRAIN_QUANTITIES), "strain_quantity")
            for name in ("gauges_link1", "gauges_link2"):
                check(all(math.isfinite(v) and v >= 0 for v in getattr(self, name)), name,
                      "positions must be finite and >= 0 [m]")
        for name in ("encoder_resolution", "encoder_noise", "modal_noise", "rate_noise"):
            positive(getattr(self, name), name, allow_zero=True)
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
        one_of(self.kind, DISTURBANCE_KINDS, "kind")
        one_of(self.target, DISTURBANCE_TARGETS, "target")
        check(math.isfinite(self.amplitude), "amplitude", "must be finite")
        positive(self.start, "start", allow_zero=True)
        _only_where_used(self, _DISTURBANCE_FIELDS[self.kind], _DISTURBANCE_DEFAULTS,
                         f"by a {self.kind!r} disturbance")
        for name in _DISTURBANCE_FIELDS[self.kind]:
            positive(getattr(self, name), name)


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
        positive(self.max_angle, "max_angle")
        positive(self.max_rate, "max_rate")
        positive(self.max_deflection, "max_deflection")
