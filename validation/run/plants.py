"""Plants as registered roles: what a scenario's ``[plant]`` table names, and what
verdicts ask of it.

A plant kind is one class (`reduced_model.Plant`'s contract): its settings (the plant
table), its declared role — "truth", the arm every verdict trusts, checked for
convergence, or "reduced", the paper's model; verdicts, reports, ``verify`` and the time
limits ask the role, never the name —, its refinements, its linear model and its cost.
`PLANTS` maps a built-in kind to its class (as SciPy's ``METHODS`` maps a name to an
``OdeSolver``); ``kind = "fmu"`` runs a co-simulation FMU (`validation.run.fmu`);
``kind = "package.module:Class"`` names a user's plant, described in the
scenario by `PluginSettings` (its role written there, so that a stored run says what it
was without its code being imported, and checked against the class's own).  Adding an
engine is this file's registration and its own package.
"""
from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass, field

from controllers import PluginError, accepted_options, resolve
from plant_exudyn import ExudynPlant
from reduced_model import LEVELS, ROLES, Plant, PlantSettings, ReducedPlant, Refinement

from .config import ConfigError, check, did_you_mean
from .fmu import FmuSettings
from .processes import checked_apart

__all__ = ["PluginSettings", "FmuSettings", "PlantTable", "PLANTS", "ROLES", "LEVELS",
           "DEFAULT_TRUTH",
           "ENGINE_PACKAGES", "Refinement", "plant_settings", "role_of", "label_of",
           "is_truth", "truth_settings", "plant_for_role", "with_plant"]


@dataclass(frozen=True)
class PluginSettings(PlantSettings):
    """``kind = "package.module:Class"``: a user's plant.

    A `reduced_model.Plant` subclass (of the base or of a built-in plant), constructed as
    ``Class(params, model=..., sensors=..., Ts=..., **options)`` (``params``: the true
    arm; ``model``: the controller's nominal `ArmModel`, whose mode shapes its q are
    expressed in; ``Ts``: the control period).

    Parameters
    ----------
    kind : str
        ``"package.module:Class"``, importable from the working directory or
        ``PYTHONPATH``.
    role : {"truth", "reduced"}
        The class's own role, required: written in the scenario so that a stored run says
        what it was without its code being imported (checked against the class's).
    options : dict
        Keyword options of its constructor (a subclass of a built-in plant: that plant's
        settings).
    step_cost_s : float
        A pessimistic wall time per control period [s], for the runs' time limits.
    """

    kind: str = ""
    role: str | None = None
    options: dict = field(default_factory=dict)
    step_cost_s: float = 1e-3

    def __post_init__(self):
        check(self.role is not None, "role", "a plug-in plant must say its role: 'truth' "
                                             "(the arm verdicts trust) or 'reduced'")
        check(self.role in ROLES, "role", f"must be one of {', '.join(map(repr, ROLES))}, "
                                          f"got {self.role!r}")
        check(math.isfinite(self.step_cost_s) and self.step_cost_s > 0, "step_cost_s",
              f"must be > 0, got {self.step_cost_s!r}")

    @property
    def label(self) -> str:
        return f"{self.role} plant ({self.kind})"

    @property
    def generalised_forces(self) -> bool:
        return False  # known without importing it: the joint torques only

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
            own = [k for k in accepted if k not in ("params", "model", "sensors", "Ts")]
            for key in self.options:
                check(key in own, f"plant.options.{key}",
                      f"not an option of {self.kind} (options: {', '.join(own) or 'none'})"
                      f"{did_you_mean(key, own)}")
        return cls

    def build(self, params, model, sensors, Ts):
        cls = self._checked_class()
        try:
            plant = cls(params, model=model, sensors=sensors, Ts=Ts, **self.options)
        except Exception as exc:  # noqa: BLE001 - a plug-in may raise anything; say what
            message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ConfigError("plant.options", f"{self.kind}: {message}") from None
        return plant

    def step_cost(self) -> float:
        return self.step_cost_s


def _plugin_checks(settings: PluginSettings) -> None:
    settings._checked_class()  # the class itself stays in the process that imported it


def _plugin_class(kind: str) -> type:
    try:
        cls = resolve(kind, {}, "plant")
    except PluginError as exc:
        raise ConfigError("plant.kind", str(exc)) from None
    check(issubclass(cls, Plant), "plant.kind",
          f"{kind} is not a reduced_model.Plant subclass (a plant plug-in subclasses it, or "
          "a built-in plant)")
    check(getattr(cls, "role", None) in ROLES, "plant.kind",
          f"{kind} declares no role: set the class attribute role = 'truth' or 'reduced' "
          f"(got {getattr(cls, 'role', None)!r})")
    missing = sorted(getattr(cls, "__abstractmethods__", ()))
    check(not missing, "plant.kind", f"{kind} does not implement {', '.join(missing)} (the "
                                     "Plant contract: reduced_model.Plant)")
    return cls


#: The built-in plant kinds; a "package.module:Class" kind is a `PluginSettings`, and
#: ``kind = "fmu"`` an `FmuSettings` (an FMU's role is its table's, as a plug-in's).
PLANTS: dict[str, type[Plant]] = {"reduced": ReducedPlant, "exudyn": ExudynPlant}
#: What a scenario's ``plant`` table is: a tagged choice of the kinds' settings.
PlantTable = ReducedPlant.Settings | ExudynPlant.Settings | PluginSettings | FmuSettings
#: The truth plant a system on the reduced plant is checked against.
DEFAULT_TRUTH = "exudyn"
#: The Python packages of the registered engines (their versions are recorded with runs).
ENGINE_PACKAGES = ("exudyn",)


def _settings_class(kind) -> type[PlantSettings]:
    if kind == FmuSettings.kind:
        return FmuSettings
    return PLANTS[kind].Settings if kind in PLANTS else PluginSettings


def plant_settings(table) -> PlantSettings:
    """The settings of a plant table (a resolved scenario's ``plant``), or the settings
    themselves."""
    if isinstance(table, PlantSettings):
        return table
    from .config import from_mapping
    return from_mapping(_settings_class(table.get("kind", "reduced")), dict(table), "plant")


def role_of(config: dict) -> str:
    """The role of a scenario mapping's plant ("truth" or "reduced"), read from the
    registry or the table itself: never by importing a plug-in."""
    table = config["plant"]
    kind = table.get("kind", "reduced")
    return PLANTS[kind].role if kind in PLANTS else table["role"]


def label_of(config: dict) -> str:
    """How tables and figures name a scenario mapping's plant."""
    kind = config["plant"].get("kind", "reduced")
    return PLANTS[kind].label if kind in PLANTS else f"{role_of(config)} plant ({kind})"


def truth_settings(config: dict) -> PlantSettings:
    """The truth plant of a scenario mapping: its own if it runs on one, else the
    default truth kind at its step (what the linear verdicts set the reduced model
    against)."""
    return plant_settings(plant_for_role(config, "truth"))


def is_truth(config: dict) -> bool:
    """Whether a scenario mapping runs on a truth plant."""
    return role_of(config) == "truth"


def plant_for_role(nominal: dict, role: str) -> dict:
    """The plant of ``role`` for a system whose nominal scenario is ``nominal``: the
    reduced plant at the controller's own model order and kinematics (the designer's
    model), or its
    truth plant — its own plug-in plant where that plays the role, its own truth plant,
    else the default truth kind —, at the nominal plant's internal step where it has
    one."""
    plant = nominal["plant"]
    own_kind = plant.get("kind", "reduced")
    if role_of(nominal) == role and (role == "truth" or own_kind not in PLANTS):
        return copy.deepcopy(plant)
    if role == "reduced":
        return {"kind": "reduced", "modes_per_link": list(nominal["model"]["modes_per_link"]),
                "kinematics": nominal["model"].get("kinematics", "linear"),
                "step": plant.get("step", ReducedPlant.Settings.step)}
    return {"kind": DEFAULT_TRUTH, "step": plant.get("step", ExudynPlant.Settings.step)}


def with_plant(plant: dict, kind: str, **settings) -> dict:
    """A plant table of ``kind``: the settings of ``plant`` that ``kind`` takes too (the
    step), then ``settings`` (for sweeps and studies that switch a scenario's plant)."""
    keys = {f.name for f in dataclasses.fields(_settings_class(kind))}
    return {**{k: v for k, v in plant.items() if k in keys}, **settings, "kind": kind}
