"""Controllers and observers of a scenario: found, checked and built the same way for the
built-in laws and for plug-ins (``kind = "package.module:Class"``).

Every law is built as ``Cls(model, Ts=Ts, **options)``: the control period is the
scenario's ``Ts``, given once, when the law is built (`controllers._interface`), never an
option.

`check_laws` runs before anything is simulated: the class must resolve, accept the
options and construct on the nominal model, have the methods of the interface
(`controllers._interface`), and an observer must find the measurements it needs among
the scenario's sensors.  Every failure is a `ConfigError` naming the key.  Each distinct
law is constructed once per process (a campaign of a thousand runs checks each law once);
the command line constructs a plug-in apart from itself (`processes.checked_apart`): its
import or constructor may exit, crash or hang, and the command says so.
"""
from __future__ import annotations

import functools
import inspect
import json

from controllers import CONTROLLERS, OBSERVERS, PluginError, accepted_options, resolve
from reduced_model import ArmModel, ArmParameters, cached_model, measured_names

from .config import ConfigError, check, did_you_mean
from .processes import checked_apart

__all__ = ["check_laws", "build_controller", "build_observer", "nominal_model",
           "measurement_names", "applies_generalised_forces", "law_name",
           "name_of"]

#: Options of the realisable PBC that eq. (20) puts only in the unactuated rows.
_IDEALISED_ONLY = {"kv_flex", "compensate_damping"}
_OBSERVER_METHODS = ("reset", "update")


def nominal_model(params: ArmParameters, modes_per_link: tuple[int, ...] | None,
                  kinematics: str = "linear") -> ArmModel:
    """The `ArmModel` the laws are built on (`reduced_model.cached_model`: built once
    per process; laws must not mutate it)."""
    return cached_model(params, None if modes_per_link is None else tuple(modes_per_link),
                        kinematics)


def measurement_names(scenario, model: ArmModel) -> tuple[str, ...]:
    """Names the plant will measure with the scenario's sensors (the order of
    `reduced_model.SensorModel`): θ, then q, then rates, then the payload position."""
    s = scenario.sensors
    return measured_names(model.modes_per_link, modal=s.modal != "none", rates=s.rates,
                          tip_position=s.tip_position)


def _class(role: str, kind: str) -> type:
    registry = CONTROLLERS if role == "controller" else OBSERVERS
    try:
        return resolve(kind, registry, role)
    except PluginError as exc:
        raise ConfigError(f"{role}.kind", str(exc)) from None


def _construct(role: str, kind: str, cls: type, options: dict, model: ArmModel, Ts: float):
    check("Ts" not in options, f"{role}.options.Ts", "the control period is the scenario's "
                                                     "Ts (every law is built at it)")
    accepted = accepted_options(cls)
    if accepted is not None:
        check("Ts" in accepted, f"{role}.kind",
              f"{kind} does not take the control period: a law is built as "
              f"Cls(model, *, Ts, **options) (add the keyword argument Ts)")
        own = [k for k in accepted if k != "Ts"]
        for key in options:
            if key in own:
                continue
            hint = ""
            if kind == "pbc" and key in _IDEALISED_ONLY:
                hint = ("; it enters only the unactuated rows of eq. (20), so it cannot change "
                        "the realisable PBC's torque (kind = \"pbc-idealised\" applies them)")
            raise ConfigError(f"{role}.options.{key}", f"not an option of {kind} (options: "
                                                       f"{', '.join(own) or 'none'}){hint}"
                                                       f"{did_you_mean(key, own)}")
        missing = [k for k in own if accepted[k] is inspect.Parameter.empty
                   and k not in options]
        if missing:
            raise ConfigError(f"{role}.options", f"{kind} needs option(s) {', '.join(missing)}")
    try:
        law = cls(model, Ts=Ts, **options)
    except Exception as exc:  # noqa: BLE001 - a plug-in may raise anything; say what
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        named = next((k for k in options if message.startswith(k)), None)
        raise ConfigError(f"{role}.options" + (f".{named}" if named else ""),
                          f"{kind}: {message}") from None
    return law


def _build(scenario, role: str, model: ArmModel):
    spec = getattr(scenario, role)
    return _construct(role, spec.kind, _class(role, spec.kind), dict(spec.options), model,
                      scenario.Ts)


def _check_interface(role: str, kind: str, law) -> None:
    if role == "controller":
        check(callable(law), "controller.kind", f"{kind} is not callable as "
                                                "controller(t, x, ref)")
        return
    for method in _OBSERVER_METHODS:
        check(callable(getattr(law, method, None)), "observer.kind",
              f"{kind} has no method {method}() (an observer needs measured, reset, update)")
    measured = getattr(law, "measured", None)
    check(isinstance(measured, (tuple, list)) and all(isinstance(m, str) for m in measured),
          "observer.kind", f"{kind}.measured must be a tuple of measurement names, "
                           f"got {measured!r}")


def _check_here(role: str, kind: str, options_json: str, Ts: float, params: ArmParameters,
                modes: tuple[int, int]) -> tuple[str, ...]:
    """Construct and check; returns the law's name (`law_name`), then the observer's
    measured names, or for a controller "generalised forces" if it applies forces to every
    coordinate (its class says so: ``generalised_forces = True``)."""
    cls = _class(role, kind)
    law = _construct(role, kind, cls, json.loads(options_json), nominal_model(params, modes),
                     Ts)
    _check_interface(role, kind, law)
    if role == "observer":
        return (name_of(law), *law.measured)
    return (name_of(law), _GENERALISED) if getattr(law, "generalised_forces", False) is True \
        else (name_of(law),)


def name_of(law) -> str:
    """What a law is called: its ``name`` (a plug-in's own, as its class declares it; a
    built-in's is its kind), else its class's name."""
    name = getattr(law, "name", None)
    return name if isinstance(name, str) and name.strip() else type(law).__name__


#: What `_check_here` says of a controller that applies forces to every coordinate.
_GENERALISED = "generalised forces"


@functools.lru_cache(maxsize=256)
def _checked(role: str, kind: str, options_json: str, Ts: float, params: ArmParameters,
             modes: tuple[int, int]) -> tuple[str, ...]:
    """`_check_here` once per law; a plug-in's apart from the command
    (`processes.checked_apart`)."""
    if ":" not in kind:
        return _check_here(role, kind, options_json, Ts, params, modes)
    return checked_apart(_check_here, role, kind, options_json, Ts, params, modes,
                         key=f"{role}.kind", what=kind)


def check_laws(scenario) -> None:
    """Raise `ConfigError` unless the scenario's controller and observer can be built."""
    s = scenario
    key = (s.Ts, s.nominal_params, s.model.modes_per_link)
    check(not (applies_generalised_forces(s) and not s.plant.generalised_forces), "controller.kind",
          f"the {s.plant.label} has two actuators; {s.controller.kind} applies forces to "
          "every coordinate (the idealised PBC: all n rows of eq. 20), which runs only on "
          "the reduced plant")
    if s.observer.kind == "none":
        check(not s.observer.options, "observer.options", "there is no observer "
                                                          "(observer.kind = 'none')")
        return
    measured = _checked("observer", s.observer.kind,
                        json.dumps(s.observer.options, sort_keys=True), *key)[1:]
    available = measurement_names(s, nominal_model(s.nominal_params, s.model.modes_per_link))
    missing = [m for m in measured if m not in available]
    check(not missing, "observer.kind",
          f"{s.observer.kind} needs the measurements {', '.join(missing)}, which the sensors "
          f"do not provide (measured: {', '.join(available)}); set sensors.modal to 'direct' "
          "or 'gauges' for q, sensors.rates = true for rates")


def applies_generalised_forces(scenario) -> bool:
    """Whether the scenario's controller applies forces to every coordinate, not only the
    two joint torques (a property of its class, ``generalised_forces``; the law is checked
    once, a plug-in apart from the command)."""
    return _GENERALISED in _law_checked(scenario, "controller")[1:]


def law_name(scenario, role: str) -> str:
    """The name of the scenario's controller or observer (``role``, `name_of`): what a run
    that raises in it says (`validation.run.loop`) and what ``flexarm run`` names the run
    after."""
    return _law_checked(scenario, role)[0]


def _law_checked(scenario, role: str) -> tuple[str, ...]:
    s, spec = scenario, getattr(scenario, role)
    return _checked(role, spec.kind, json.dumps(spec.options, sort_keys=True), s.Ts,
                    s.nominal_params, s.model.modes_per_link)


def build_controller(scenario, model: ArmModel):
    """A fresh controller for one run (laws keep state; never share one between runs)."""
    return _build(scenario, "controller", model)


def build_observer(scenario, model: ArmModel):
    """A fresh observer for one run, or None."""
    if scenario.observer.kind == "none":
        return None
    return _build(scenario, "observer", model)
