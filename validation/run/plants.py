"""Plants as registered roles: what a scenario's ``[plant]`` table names, and what
verdicts ask of it.

A plant *kind* is a frozen dataclass subclassing `PlantSpec`, registered in `PLANTS` (or
named ``kind = "package.module:Class"``: a plug-in plant, `PluginPlantSpec`).  The
contract of a kind, as SciPy writes its ``OdeSolver``'s:

1. ``kind``: its name in a scenario (the dataclass field's default);
2. ``role``: "truth" — the arm every verdict trusts, checked for convergence — or
   "reduced" — the paper's model; verdicts, reports, ``verify`` and the time limits ask
   the role, never the name;
3. ``label``: how tables and figures name it ("truth plant (Exudyn)");
4. ``build(params, model, sensors)``: the `reduced_model.Plant` of the true arm
   ``params``, measuring with ``sensors`` in the modal basis of ``model`` (the
   controller's nominal model);
5. ``discretisation()``: a label of its own resolution ("ANCF 4 el/link"; "" if none);
6. ``refined(level)``: its settings 2^level times finer in space and time — the refined
   sequence of the convergence checks and of the stability map (itself for a plant
   without a discretisation);
7. ``refinements()``: the checks a result on it must survive (`Refinement`: level k of
   the sequence, or another formulation with ``level`` None); none for a reduced plant;
8. ``step_cost()``: a pessimistic wall time per internal step [s], for time limits;
9. ``actuated``: the joint torques it takes (2; the reduced plant also takes n generalised
   forces: the idealised PBC runs only there).

Adding an engine is this file's registration and its own package; a user's plant is a
`reduced_model.Plant` subclass with a ``role`` class attribute, named by
``kind = "package.module:Class"`` with its ``options``.
"""
from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field
from typing import ClassVar

from controllers import PluginError, accepted_options, resolve
from plant_exudyn import Mesh
from reduced_model import ArmModel, ArmParameters, Plant, SensorConfig, validate_modes_per_link

from ._config import ConfigError, check
from .processes import checked_apart

__all__ = ["PlantSpec", "ReducedPlantSpec", "ExudynPlantSpec", "PluginPlantSpec", "PLANTS",
           "ROLES", "LEVELS", "DEFAULT_TRUTH", "Refinement", "plant_spec", "role_of",
           "label_of", "is_truth", "truth_spec", "plant_for_role", "with_plant", "mesh_label"]

#: The roles a plant plays: the arm verdicts trust, and the paper's model.
ROLES = ("truth", "reduced")
#: Element-count ratio of the geometrically exact beam to ANCF in a check: it converges
#: slower (open-loop 4th-mode error: GE 16 el/link 0.6 %, ANCF 4 0.04 %).
_GE_PER_ANCF = 8
_MAX_ELEMENTS = 64
#: The levels of the refined sequence a truth result is checked on.
LEVELS = (1, 2)


def _positive(value, name) -> None:
    check(math.isfinite(value) and value > 0, name, f"must be > 0, got {value!r}")


@dataclass(frozen=True)
class Refinement:
    """One check of a truth-plant result: its label ("ANCF 8 el/link, step/2"), the
    plant table it runs on and its level (k: 2^k times finer in mesh and step; None: the
    other formulation)."""

    label: str
    plant: dict
    level: int | None


class PlantSpec:
    """What every plant kind shares (module docstring: the contract)."""

    role: ClassVar[str]
    label: ClassVar[str]
    actuated: ClassVar[int] = 2

    def build(self, params: ArmParameters, model: ArmModel, sensors: SensorConfig) -> Plant:
        raise NotImplementedError

    def check(self) -> None:
        """What only running can check (a plug-in's class and options); nothing here."""

    def discretisation(self) -> str:
        return ""

    def refined(self, level: int) -> dict:
        return dataclasses.asdict(self)

    def refinements(self) -> list[Refinement]:
        return []

    def step_cost(self) -> float:
        raise NotImplementedError

    def linear_model(self, params: ArmParameters, *, theta, modal_basis):
        """The plant linearised about rest at joint angles ``theta`` (a
        `control.StateSpace` with inputs tau1, tau2 and the reduced model's outputs), for
        the linear verdicts (stability prediction, ν-gap); NotImplementedError for a kind
        that has none."""
        raise NotImplementedError(f"the {self.label} has no linearisation")


@dataclass(frozen=True)
class ReducedPlantSpec(PlantSpec):
    """``kind = "reduced"``: the paper's model as the plant (fixed-step RK4).

    Parameters
    ----------
    kind : {"reduced"}
        Selects this plant.
    modes_per_link : (int, int)
        The plant's own model order, assumed modes of link 1 and link 2 (1..4 each).
    step : float
        Internal RK4 step [s]; ``Ts`` must be a whole multiple of it.
    """

    role: ClassVar[str] = "reduced"
    label: ClassVar[str] = "reduced plant"
    actuated: ClassVar[int] = 0  # any: two joint torques, or n generalised forces

    kind: str = "reduced"
    modes_per_link: tuple[int, int] = (2, 2)
    step: float = 1e-3

    def __post_init__(self):
        check(self.kind == "reduced", "kind", f"must be 'reduced', got {self.kind!r}")
        try:
            validate_modes_per_link(self.modes_per_link)
        except ValueError:
            raise ConfigError("modes_per_link", f"must be two integers in 1..4, got "
                                                f"{list(self.modes_per_link)!r}") from None
        _positive(self.step, "step")

    def build(self, params, model, sensors):
        from reduced_model import ReducedPlant
        own = params == model.params and tuple(self.modes_per_link) == model.modes_per_link
        return ReducedPlant(params, modes_per_link=self.modes_per_link, step=self.step,
                            modal_basis=None if own else model.mode_shapes, sensors=sensors)

    def step_cost(self) -> float:
        return 1e-4  # RK4 of 2n states, pessimistic


def mesh_label(mesh: dict) -> str:
    """"ANCF 4 el/link", "GE 16 el/link" (or "ANCF 4+8 el/link" if the links differ)."""
    n1, n2 = mesh["elements_per_link"]
    name = "ANCF" if mesh["element"] == "ancf" else "GE"
    return f"{name} {n1 if n1 == n2 else f'{n1}+{n2}'} el/link"


@dataclass(frozen=True)
class ExudynPlantSpec(PlantSpec):
    """``kind = "exudyn"``: the FE truth plant.

    The default step, 0.5 ms, is half the campaigns' 1 ms period: a sign observer's
    chatter drives the FE arm at the Nyquist frequency, where a 1 ms step moved a 5 s
    PBC + sign-SMO run's tracking error by 40 % (0.0138 rad against 0.0094-0.0111 on
    finer meshes and steps).

    Parameters
    ----------
    kind : {"exudyn"}
        Selects this plant.
    step : float
        Generalised-α integration step [s]; ``Ts`` must be a whole multiple of it.
    mesh : Mesh
        The finite elements of both links (`plant_exudyn.Mesh`).
    spectral_radius : float
        Generalised-α ρ∞ (1: no numerical damping).
    newton_tolerance : float
        Relative tolerance of Exudyn's Newton iterations.
    """

    role: ClassVar[str] = "truth"
    label: ClassVar[str] = "truth plant (Exudyn)"

    kind: str = "exudyn"
    step: float = 5e-4
    mesh: Mesh = Mesh()
    spectral_radius: float = 0.9
    newton_tolerance: float = 1e-6

    def __post_init__(self):
        check(self.kind == "exudyn", "kind", f"must be 'exudyn', got {self.kind!r}")
        _positive(self.step, "step")
        _positive(self.newton_tolerance, "newton_tolerance")
        check(0 < self.spectral_radius <= 1, "spectral_radius",
              f"must be in (0, 1] (the exact zero-order hold needs alpha_f > 0), got "
              f"{self.spectral_radius!r}")

    def build(self, params, model, sensors):
        from plant_exudyn._plant import ExudynPlant  # Exudyn: loaded by the runs that use it
        return ExudynPlant(params, self.mesh, step=self.step, modal_basis=model.mode_shapes,
                           sensors=sensors, spectral_radius=self.spectral_radius,
                           newton_tolerance=self.newton_tolerance)

    def discretisation(self) -> str:
        return mesh_label(dataclasses.asdict(self.mesh))

    def refined(self, level: int) -> dict:
        table = _table(self)
        table["mesh"]["elements_per_link"] = [2 ** level * n for n in
                                              self.mesh.elements_per_link]
        table["step"] = self.step / 2 ** level
        return table

    def refinements(self) -> list[Refinement]:
        """Level 1 and 2 of the same element (mesh and step refined together), then the
        other formulation at a resolution at least as fine with half the step (GE 8× the
        ANCF elements; ANCF 1/8 of GE's); meshes beyond 64 el/link are left out."""
        out = []
        for level in LEVELS:
            table = self.refined(level)
            out.append(Refinement(f"{mesh_label(table['mesh'])}, step/{2 ** level}", table,
                                  level))
        n = self.mesh.elements_per_link
        table = self.refined(1)
        if self.mesh.element == "ancf":
            table["mesh"].update(element="geometrically_exact",
                                 elements_per_link=[_GE_PER_ANCF * k for k in n])
        else:
            table["mesh"].update(element="ancf",
                                 elements_per_link=[max(1, k // _GE_PER_ANCF) for k in n])
        out.append(Refinement(f"{mesh_label(table['mesh'])}, step/2", table, None))
        return [r for r in out if max(r.plant["mesh"]["elements_per_link"]) <= _MAX_ELEMENTS]

    def step_cost(self) -> float:
        return 2.5e-4 + 3e-5 * sum(self.mesh.elements_per_link)  # pessimistic, measured

    def linear_model(self, params, *, theta, modal_basis):
        from plant_exudyn._linear import linear_model
        return linear_model(params, self.mesh, theta=theta, modal_basis=modal_basis)


@dataclass(frozen=True)
class PluginPlantSpec(PlantSpec):
    """``kind = "package.module:Class"``: a user's plant.

    A `reduced_model.Plant` subclass, constructed as ``Class(params, model=...,
    sensors=..., **options)`` (``params``: the true arm; ``model``: the controller's
    nominal `ArmModel`, whose mode shapes its q are expressed in).

    Parameters
    ----------
    kind : str
        ``"package.module:Class"``, importable from the working directory or
        ``PYTHONPATH``.
    role : {"truth", "reduced"}
        The class's own role, written in the scenario so that a stored run says what it
        was without its code being imported.
    options : dict
        Keyword options of its constructor.
    step_cost_s : float
        A pessimistic wall time per control period [s], for the runs' time limits.
    """

    label: ClassVar[str] = "plug-in plant"

    kind: str = ""
    role: str = "truth"
    options: dict = field(default_factory=dict)
    step_cost_s: float = 1e-3

    def __post_init__(self):
        check(self.role in ROLES, "role", f"must be one of {', '.join(map(repr, ROLES))}, "
                                          f"got {self.role!r}")
        _positive(self.step_cost_s, "step_cost_s")

    def check(self) -> None:
        """ConfigError naming the key unless the plug-in class imports and takes the
        options and role (apart from the command: `processes.checked_apart`)."""
        checked_apart(_plugin_checks, self, key="plant.kind", what=self.kind)

    def _checked_class(self) -> type:
        cls = _plugin_class(self.kind)
        check(cls.role == self.role, "plant.role", f"{self.kind} is a {cls.role!r} plant, "
                                                   f"the scenario says {self.role!r}")
        accepted = accepted_options(cls)
        if accepted is not None:
            own = [k for k in accepted if k not in ("params", "model", "sensors")]
            for key in self.options:
                check(key in own, f"plant.options.{key}",
                      f"not an option of {self.kind} (options: {', '.join(own) or 'none'})")
        return cls

    def build(self, params, model, sensors):
        cls = self._checked_class()
        try:
            plant = cls(params, model=model, sensors=sensors, **self.options)
        except Exception as exc:  # noqa: BLE001 - a plug-in may raise anything; say what
            message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ConfigError("plant.options", f"{self.kind}: {message}") from None
        check(isinstance(plant, Plant), "plant.kind",
              f"{self.kind} is not a reduced_model.Plant (subclass it: its contract)")
        return plant

    def step_cost(self) -> float:
        return self.step_cost_s


def _plugin_checks(spec: PluginPlantSpec) -> None:
    spec._checked_class()  # the class itself stays in the process that imported it


def _plugin_class(kind: str) -> type:
    try:
        cls = resolve(kind, {}, "plant")
    except PluginError as exc:
        raise ConfigError("plant.kind", str(exc)) from None
    check(issubclass(cls, Plant), "plant.kind",
          f"{kind} is not a reduced_model.Plant subclass (a plant plug-in subclasses it)")
    check(getattr(cls, "role", None) in ROLES, "plant.kind",
          f"{kind}.role must be one of {', '.join(map(repr, ROLES))}, got "
          f"{getattr(cls, 'role', None)!r}")
    return cls


#: The built-in plant kinds; a "package.module:Class" kind is a `PluginPlantSpec`.
PLANTS: dict[str, type[PlantSpec]] = {"reduced": ReducedPlantSpec, "exudyn": ExudynPlantSpec}
#: The truth plant a system on the reduced plant is checked against.
DEFAULT_TRUTH = "exudyn"
#: The Python packages of the registered engines (their versions are recorded with runs).
ENGINE_PACKAGES = ("exudyn",)


def _table(spec: PlantSpec) -> dict:
    return copy.deepcopy(dataclasses.asdict(spec))


def plant_spec(table) -> PlantSpec:
    """The spec of a plant table (a resolved scenario's ``plant``) or the spec itself."""
    if isinstance(table, PlantSpec):
        return table
    from ._config import from_mapping
    kind = table.get("kind", "reduced")
    return from_mapping(PLANTS.get(kind, PluginPlantSpec), dict(table), "plant")


def role_of(config: dict) -> str:
    """The role of a scenario mapping's plant ("truth" or "reduced"), read from the
    registry or the table itself: never by importing a plug-in."""
    table = config["plant"]
    kind = table.get("kind", "reduced")
    return PLANTS[kind].role if kind in PLANTS else table.get("role", "truth")


def label_of(config: dict) -> str:
    """How tables and figures name a scenario mapping's plant."""
    kind = config["plant"].get("kind", "reduced")
    return PLANTS[kind].label if kind in PLANTS else f"{role_of(config)} plant ({kind})"


def truth_spec(config: dict) -> PlantSpec:
    """The truth plant of a scenario mapping: its own if it runs on one, else the
    default truth kind at its step (what the linear verdicts set the reduced model
    against)."""
    return plant_spec(plant_for_role(config, "truth"))


def is_truth(config: dict) -> bool:
    """Whether a scenario mapping runs on a truth plant."""
    return role_of(config) == "truth"


def plant_for_role(nominal: dict, role: str) -> dict:
    """The plant of ``role`` for a system whose nominal scenario is ``nominal``: the
    reduced plant at the controller's own model order (the designer's model), or its truth
    plant (the nominal one if the system runs on one, else the default truth kind); both
    at the nominal internal step."""
    plant = nominal["plant"]
    if role == "reduced":
        return {"kind": "reduced", "modes_per_link": list(nominal["model"]["modes_per_link"]),
                "step": plant.get("step", ReducedPlantSpec.step)}
    if is_truth(nominal):
        return copy.deepcopy(plant)
    return {"kind": DEFAULT_TRUTH, "step": plant["step"]}


def with_plant(plant: dict, kind: str, **settings) -> dict:
    """A plant table of ``kind``: the settings of ``plant`` that ``kind`` takes too (the
    step), then ``settings`` (for sweeps and studies that switch a scenario's plant)."""
    keys = {f.name for f in dataclasses.fields(PLANTS.get(kind, PluginPlantSpec))}
    return {**{k: v for k, v in plant.items() if k in keys}, **settings, "kind": kind}
