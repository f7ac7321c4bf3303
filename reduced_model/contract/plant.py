"""The plant contract: one class per kind of plant, what the closed loop of `validation`
needs of it, and the base class that owns what every plant shares (after SciPy's
``OdeSolver``: the base owns the public methods and their checks, a plant fills the
private hooks).

A plant simulates an arm (`reduced_model.ArmParameters`: N links) from joint torques held
over each control period and reports what really happened in the reduced model's
coordinates.  To write one (a second
FE engine, a user's model, hardware), subclass `Plant` — or a built-in plant, whose
settings and behaviour it then inherits:

1. Declare ``role``: "truth" (the arm verdicts trust; its results are checked under
   refinement) or "reduced" (the paper's model).  Nothing defaults it: a class that
   declares none is refused.  ``label`` names it in tables and figures.
2. Declare its configuration as a frozen dataclass ``Settings`` (the keys of a
   scenario's ``[plant]`` table; a plug-in's ``options``) and take them as keyword
   arguments of the constructor ``Cls(params, *, model, sensors, Ts, **settings)``:
   ``params`` is the true arm, ``model`` the `ArmModel` whose mode shapes q is expressed
   in (the controller's nominal model; None: the plant's own), ``sensors`` a
   `SensorConfig`, ``Ts`` the control period (given once, as to a law).  Call
   ``Plant.__init__(self, sensors, modal_basis, step, Ts)`` once the plant can answer
   the sensor primitives (7.).
3. ``state_size``: the length of [θ, q, θ̇, q̇] that ``reset`` takes (q in the modal
   basis).
4. ``_reset(x0)``: place the arm at the state ``x0`` (checked: finite, ``state_size``).
5. ``_advance(tau, tip_force)``: hold the joint torques ``tau`` and the payload force
   ``tip_force`` ((Fx, Fy) [N, base frame] or None) over one control period, ``steps``
   internal steps of ``h`` (a zero-order hold).  A solver that cannot complete raises
   `PlantFailure` with its reason: the run is then recorded as failed, never lost.
6. ``truth_into(out)``: write the truth vector [θ, q, θ̇, q̇, *truth_extras(N)] into
   ``out`` (no allocation: the loop calls it every sample).
7. The sensor primitives `SensorModel` reads: ``joint_state()`` → (θ, θ̇),
   ``modal_state()`` → (q, q̇) in the modal basis, ``field_sampler(link, x,
   derivative)`` → a callable giving the transverse deflection (or its s-derivatives) at
   points ``x`` of link ``link`` (from 0), ``tip_positions()`` → (N, 2).
8. Optionally, what verdicts ask of the kind (methods of its ``Settings``):
   ``discretisation``, ``refined``, ``refinements`` (the checks a truth result must
   survive), ``step_cost`` (for time limits) and ``linear_model``; and ``compiled()``,
   its compiled form (`reduced_model.contract.compiled.CompiledPlant`): a compiled loop
   then steps it itself.

The base class gives the rest: ``reset``, ``advance`` (the checks, then ``_advance``),
``step`` (advance, then measure), ``measure``, ``measurement_index``, ``truth`` and
``truth_vector``.
"""
from __future__ import annotations

import abc
import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .compiled import CompiledPlant
from .sensors import SensorConfig, SensorModel
from .signals import Measurement, TrueState, check_sample_time, true_state_from_vector

__all__ = ["Plant", "PlantSettings", "Refinement", "ROLES", "LEVELS"]

#: The roles a plant plays: the arm verdicts trust, and the paper's model.
ROLES = ("truth", "reduced")
#: The levels of the refined sequence a truth result is checked on.
LEVELS = (1, 2)


@dataclass(frozen=True)
class Refinement:
    """One check of a truth-plant result.

    Parameters
    ----------
    label : str
        What it runs on ("ANCF 8 el/link, step/2").
    plant : dict
        The plant table it runs on.
    level : int or None
        k: 2^k times finer in mesh and step; None: the other formulation.
    """

    label: str
    plant: dict
    level: int | None


@dataclass(frozen=True)
class PlantSettings:
    """What every plant kind's ``Settings`` shares: the kind's questions — its role,
    label, refinements, cost, linear model — answered for the class they configure
    (``plant``, set when a `Plant` subclass declares its own ``Settings``).  A built-in
    kind's settings carry a ``kind`` field naming it; they take no parameters here."""

    plant: ClassVar[type]

    @property
    def role(self) -> str:
        """"truth" or "reduced"."""
        return self.plant.role

    @property
    def label(self) -> str:
        """How tables and figures name the plant."""
        return self.plant.label

    @property
    def generalised_forces(self) -> bool:
        """Whether it takes n generalised forces as well as the joint torques."""
        return self.plant.generalised_forces

    def table(self) -> dict:
        """These settings as a plant table (plain data, as a scenario stores it)."""
        def plain(value):
            if dataclasses.is_dataclass(value):
                return {f.name: plain(getattr(value, f.name))
                        for f in dataclasses.fields(value)}
            if isinstance(value, (tuple, list)):
                return [plain(v) for v in value]
            return value
        return plain(self)

    def check(self) -> None:
        """What only running can check (a plug-in's class and options); nothing here."""

    def check_with(self, params, modes_per_link, measured) -> None:
        """What it can check of the true arm ``params`` it will simulate, the laws'
        ``modes_per_link`` and the ``measured`` names (an FMU's variables); nothing
        here."""

    def build(self, params, model, sensors: SensorConfig, Ts: float) -> "Plant":
        """The plant of the true arm ``params``, measuring with ``sensors`` in the modal
        basis of ``model`` (the controller's nominal `ArmModel`), at the control period
        ``Ts``."""
        keywords = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                    if f.name != "kind"}
        return self.plant(params, model=model, sensors=sensors, Ts=Ts, **keywords)

    def discretisation(self) -> str:
        """A label of its own resolution ("ANCF 4 el/link"; "" if none)."""
        return ""

    def refined(self, level: int) -> dict:
        """Its plant table 2^level times finer in space and time (itself without a
        discretisation)."""
        return self.table()

    def refinements(self) -> list[Refinement]:
        """The checks a result on it must survive (none for a plant without a
        discretisation)."""
        return []

    def step_cost(self) -> float:
        """A pessimistic wall time per internal step [s], for time limits."""
        raise NotImplementedError

    def linear_model(self, params, *, theta, model):
        """The plant linearised about rest at joint angles ``theta`` (a
        `control.StateSpace` with inputs tau1 … tauN and the outputs of ``model``'s
        coordinates), for the linear verdicts; NotImplementedError for a kind that has
        none."""
        raise NotImplementedError(f"the {self.label} has no linearisation")


class Plant(abc.ABC):
    """Base class of every plant (module docstring: the contract).

    Parameters
    ----------
    sensors : SensorConfig
        What the plant measures.
    modal_basis : tuple of LinkModes
        The mode shapes its modal coordinates q are expressed in, one per link.
    step : float
        Its internal step [s]: a control period is a whole number of them.
    Ts : float
        The control period [s] it holds each command for.
    """

    #: "truth" or "reduced": declared by every plant class (never defaulted).
    role: ClassVar[str]
    #: How tables and figures name it.
    label: ClassVar[str] = "plug-in plant"
    #: Whether it takes n generalised forces as well as the N joint torques.
    generalised_forces: ClassVar[bool] = False
    #: Its configuration (module docstring, 2.).
    Settings: ClassVar[type] = PlantSettings
    #: What each joint's encoder reads: "link" (θ) or "motor" (a drive's rotor; set by
    #: the plant before ``Plant.__init__`` where its arm has drives; default all "link").
    encoder_side: tuple[str, ...] = ()

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if "Settings" in cls.__dict__:  # the class that declares them answers for them
            cls.Settings.plant = cls

    def __init__(self, sensors: SensorConfig, modal_basis, step: float, Ts: float) -> None:
        if not (np.isfinite(step) and step > 0.0):
            raise ValueError(f"step must be a positive number of seconds, got {step!r}")
        #: The internal step [s].
        self.h = float(step)
        #: The control period [s] and its internal steps.
        self.Ts = float(Ts)
        self.steps = check_sample_time(self.Ts, self.h)
        self.modal_basis = tuple(modal_basis)
        #: The arm's joints (and links).
        self.n_joints = len(self.modal_basis)
        if not self.encoder_side:
            self.encoder_side = ("link",) * self.n_joints
        self.sensors = SensorModel(sensors, self.modal_basis, self)
        self._steps = 0  # internal steps since reset: time = steps · h, no drift
        self.time = 0.0

    # --- what a subclass implements ------------------------------------------------------
    @property
    @abc.abstractmethod
    def state_size(self) -> int:
        """Length of [θ, q, θ̇, q̇] that `reset` takes."""

    @abc.abstractmethod
    def _reset(self, x0: np.ndarray) -> None:
        """Place the arm at ``x0`` (checked)."""

    @abc.abstractmethod
    def _advance(self, tau: np.ndarray, tip_force) -> None:
        """Hold ``tau`` and ``tip_force`` over one control period (``steps`` internal
        steps) from ``time``."""

    @abc.abstractmethod
    def truth_into(self, out: np.ndarray) -> None:
        """Write the truth vector into ``out``."""

    @abc.abstractmethod
    def joint_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(θ, θ̇) now."""

    @abc.abstractmethod
    def modal_state(self) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) in the modal basis now."""

    @abc.abstractmethod
    def field_sampler(self, link: int, x, derivative: int):
        """A callable giving link ``link``'s deflection (its ``derivative``-th
        s-derivative) at the points ``x`` [m]."""

    @abc.abstractmethod
    def tip_positions(self) -> np.ndarray:
        """(x, y) [m] of each link's tip (the last: the payload), (N, 2)."""

    def compiled(self) -> CompiledPlant | None:
        """Its compiled form, for a compiled loop to step it itself (None: step it from
        Python, the default)."""
        return None

    # --- what every plant shares ----------------------------------------------------------
    def reset(self, state0=None) -> Measurement:
        """Start at t = 0 from ``state0`` = [θ, q, θ̇, q̇] (length `state_size`; None: at
        rest, undeformed, θ = 0); returns the measurement there."""
        n = self.state_size
        x0 = np.zeros(n) if state0 is None else np.asarray(state0, dtype=float)
        if x0.shape != (n,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"state0 must be {n} finite numbers [theta, q, theta_dot, "
                             f"q_dot], got shape {x0.shape}")
        self._reset(x0)
        self._steps = 0
        self.time = 0.0
        return self.measure()

    def advance(self, tau, *no_Ts, tip_force=None) -> None:
        """Hold joint torques ``tau`` (N,) [N m] (or n generalised forces, where the plant
        takes them) and the payload force ``tip_force`` (Fx, Fy) [N, base frame] for one
        control period ``Ts``.  Raises `PlantFailure` when the plant's solver fails."""
        if no_Ts:
            raise TypeError("Plant.advance(tau, *, tip_force=None) takes no Ts: a plant "
                            "holds each command for the Ts it was built with")
        tau = np.asarray(tau, dtype=float)
        N = self.n_joints
        if tau.shape != (N,) and not (self.generalised_forces
                                      and tau.shape == (self.state_size // 2,)):
            allowed = f"{N} or {self.state_size // 2}" if self.generalised_forces else f"{N}"
            raise ValueError(f"the {self.label} takes {allowed} torques, got shape "
                             f"{tau.shape}")
        self._advance(tau, tip_force)
        self._steps += self.steps
        self.time = self._steps * self.h

    def step(self, tau, *no_Ts, tip_force=None) -> Measurement:
        """Hold ``tau`` (and ``tip_force``) for one control period; return y(t + Ts)
        (`advance`, then `measure`)."""
        self.advance(tau, *no_Ts, tip_force=tip_force)
        return self.measure()

    def measure(self) -> Measurement:
        """The measurement now."""
        index = self.sensors.truth_index
        if index is not None:  # the measured values are part of the truth vector
            return Measurement(self.time, self.sensors.names, self.truth_vector()[index])
        return self.sensors.measure(self.time)

    def measurement_index(self) -> np.ndarray | None:
        """Where the measurement sits in the truth vector (None: gauges, quantisation or
        the payload position make it more than those values)."""
        return self.sensors.truth_index

    @property
    def truth_size(self) -> int:
        """Length of the truth vector: [θ, q, θ̇, q̇] with q in the modal basis, then
        `truth_extras`."""
        N = self.n_joints
        return 2 * (N + sum(m.n for m in self.modal_basis)) + 6 * N

    def truth_vector(self) -> np.ndarray:
        """``[θ, q, θ̇, q̇, *truth_extras(N)]`` now (a new array)."""
        out = np.empty(self.truth_size)
        self.truth_into(out)
        return out

    def truth(self) -> TrueState:
        """The true state now."""
        return true_state_from_vector(self.time, self.truth_vector(), self.n_joints)
