"""Controllers and observers of a scenario: found, checked and built the same way for the
built-in laws and for plug-ins (``kind = "package.module:Class"``).

A law with an option named ``Ts`` (a discrete-time design such as the LQR) receives the
scenario's control period there unless the scenario's options set it.

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
from reduced_model import ArmModel, ArmParameters, cached_model

from ._config import ConfigError, check
from .processes import checked_apart

__all__ = ["check_laws", "build_controller", "build_observer", "nominal_model",
           "measurement_names"]

#: Options of the realisable PBC that eq. (20) puts only in the unactuated rows.
_IDEALISED_ONLY = {"kv_flex", "compensate_damping"}
_OBSERVER_METHODS = ("reset", "update")


def nominal_model(params: ArmParameters, modes_per_link: tuple[int, int]) -> ArmModel:
    """The `ArmModel` the laws are built on (`reduced_model.cached_model`: built once
    per process; laws must not mutate it)."""
    return cached_model(params, tuple(modes_per_link))


def measurement_names(scenario, model: ArmModel) -> tuple[str, ...]:
    """Names the plant will measure with the scenario's sensors (the order of
    `reduced_model.SensorModel`): θ, then q, then rates, then the payload position."""
    s = scenario.sensors
    coords = model.coordinate_names
    names = list(coords[:2]) + (list(coords[2:]) if s.modal != "none" else [])
    if s.rates:
        names += [f"{c}_dot" for c in names]
    if s.tip_position:
        names += ["tip_x", "tip_y"]
    return tuple(names)


def _class(role: str, kind: str) -> type:
    registry = CONTROLLERS if role == "controller" else OBSERVERS
    try:
        return resolve(kind, registry, role)
    except PluginError as exc:
        raise ConfigError(f"{role}.kind", str(exc)) from None


def _options(options: dict, cls: type, Ts: float) -> dict:
    """The law's options; a law with an option named ``Ts`` (a discrete-time design)
    receives the scenario's control period there unless the options set it."""
    accepted = accepted_options(cls)
    if "Ts" not in options and accepted is not None and "Ts" in accepted:
        return {**options, "Ts": Ts}
    return dict(options)


def _construct(role: str, kind: str, cls: type, options: dict, model: ArmModel):
    accepted = accepted_options(cls)
    if accepted is not None:
        for key in options:
            if key in accepted:
                continue
            hint = ""
            if kind == "pbc" and key in _IDEALISED_ONLY:
                hint = ("; it enters only the unactuated rows of eq. (20), so it cannot change "
                        "the realisable PBC's torque (kind = \"pbc-idealised\" applies them)")
            raise ConfigError(f"{role}.options.{key}", f"not an option of {kind} (options: "
                                                       f"{', '.join(accepted) or 'none'}){hint}")
        missing = [k for k, v in accepted.items() if v is inspect.Parameter.empty
                   and k not in options]
        if missing:
            raise ConfigError(f"{role}.options", f"{kind} needs option(s) {', '.join(missing)}")
    try:
        law = cls(model, **options)
    except Exception as exc:  # noqa: BLE001 - a plug-in may raise anything; say what
        message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        named = next((k for k in options if message.startswith(k)), None)
        raise ConfigError(f"{role}.options" + (f".{named}" if named else ""),
                          f"{kind}: {message}") from None
    return law


def _build(scenario, role: str, model: ArmModel):
    spec = getattr(scenario, role)
    cls = _class(role, spec.kind)
    return _construct(role, spec.kind, cls, _options(spec.options, cls, scenario.Ts), model)


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
    """Construct and check; returns the observer's measured names (() for a
    controller)."""
    cls = _class(role, kind)
    law = _construct(role, kind, cls, _options(json.loads(options_json), cls, Ts),
                     nominal_model(params, modes))
    _check_interface(role, kind, law)
    return tuple(law.measured) if role == "observer" else ()


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
    _checked("controller", s.controller.kind, json.dumps(s.controller.options, sort_keys=True),
             *key)
    if s.observer.kind == "none":
        check(not s.observer.options, "observer.options", "there is no observer "
                                                          "(observer.kind = 'none')")
        return
    measured = _checked("observer", s.observer.kind,
                        json.dumps(s.observer.options, sort_keys=True), *key)
    available = measurement_names(s, nominal_model(s.nominal_params, s.model.modes_per_link))
    missing = [m for m in measured if m not in available]
    check(not missing, "observer.kind",
          f"{s.observer.kind} needs the measurements {', '.join(missing)}, which the sensors "
          f"do not provide (measured: {', '.join(available)}); set sensors.modal to 'direct' "
          "or 'gauges' for q, sensors.rates = true for rates")


def build_controller(scenario, model: ArmModel):
    """A fresh controller for one run (laws keep state; never share one between runs)."""
    return _build(scenario, "controller", model)


def build_observer(scenario, model: ArmModel):
    """A fresh observer for one run, or None."""
    if scenario.observer.kind == "none":
        return None
    return _build(scenario, "observer", model)
