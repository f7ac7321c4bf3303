"""The configuration reference: every key of a scenario file, generated from the scenario
dataclasses (`validation.run.scenario`).

Key, type and default come from the dataclass fields; meaning and unit (the ``[...]`` in
the meaning) from the ``Parameters`` section of the class's docstring; the allowed values
from the code that checks them — each field is given a value no arm can have and the
message of the check that refuses it is shown (a field whose check lives elsewhere shows
what that code accepts, e.g. the law registries).
"""
from __future__ import annotations

import dataclasses
import re
import types
import typing

from .docstrings import entries
from .rst import heading, list_table, literal, split_unit

def _field_docs(cls) -> dict[str, tuple[str, str]]:
    """Field name → (meaning without the unit, unit) from the class's Parameters."""
    out = {}
    for param in entries(cls, "Parameters"):
        out[param.name] = split_unit(param.desc)
    return out


def _type_name(tp) -> str:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        members = [a for a in args if a is not type(None)]
        if len(members) > 1 and all(dataclasses.is_dataclass(a) for a in members):
            return "table (by ``kind``)"
        return " or ".join(_type_name(a) for a in members)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {_type_name(args[0])}s"
        return f"{len(args)} {_type_name(args[0])}s"
    if dataclasses.is_dataclass(tp):
        return "table"
    return {float: "number", int: "integer", str: "string", bool: "boolean",
            dict: "table"}.get(tp, getattr(tp, "__name__", str(tp)))


def _toml(value) -> str:
    """A default as it is written in TOML."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{}" if not value else str(value)
    return str(value)


def _default(f: dataclasses.Field):
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def _probe_value(value):
    """A value of the same type that no arm, plant or sensor can have (-1 or a control
    character), so that the field's own check refuses it and says what it accepts."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return type(value)(-1)
    if isinstance(value, str):
        return "\x00"
    if isinstance(value, tuple) and value and all(isinstance(v, (int, float)) for v in value):
        return tuple(type(v)(-1) for v in value)
    return None


def _allowed(cls, name: str, annotation, required: dict, special: dict) -> str:
    from validation.run.config import ConfigError
    from reduced_model import FieldError
    if (cls, name) in special:
        return special[(cls, name)]
    f = cls.__dataclass_fields__[name]
    default = _default(f)
    if default is None:  # "unset" fields: probe with a value of the annotated type
        members = [a for a in typing.get_args(annotation) if a is not type(None)]
        default = {float: 1.0, str: "", int: 0}.get(members[0]) if members else None
        if default is None and typing.get_origin(members[0]) is tuple:
            default = (1.0,)
    probe = _probe_value(default)
    if probe is None:
        return ""
    try:
        cls(**{**required, name: probe})
    except (ConfigError, FieldError) as exc:
        message = exc.message if isinstance(exc, ConfigError) else exc.reason
        if message.startswith("not used "):  # a key of other kinds than the default's
            return "(per kind: see meaning)"
        message = re.split(r", got ", message)[0]
        return message.removeprefix("must be ")
    return "any"


def _table(cls, required: dict, special: dict, overrides=None) -> str:
    hints = typing.get_type_hints(cls)
    docs = _field_docs(cls)
    rows = []
    for f in dataclasses.fields(cls):
        meaning, unit = docs.get(f.name, ("", ""))
        default = _default(f)
        if dataclasses.is_dataclass(hints[f.name]) or typing.get_origin(hints[f.name]) in (
                typing.Union, types.UnionType) and all(
                dataclasses.is_dataclass(a) for a in typing.get_args(hints[f.name])):
            shown = "(table below)"
        elif typing.get_origin(hints[f.name]) is tuple and typing.get_args(hints[f.name]) \
                and dataclasses.is_dataclass(typing.get_args(hints[f.name])[0]):
            shown = "none (array of tables below)"
        elif default is dataclasses.MISSING:
            shown = "required"
        elif default is None:
            shown = "(see meaning)"
        else:
            shown = literal(_toml(default))
        if overrides and f.name in overrides:
            shown += f" ({overrides[f.name]})"
        allowed = _allowed(cls, f.name, hints[f.name], required, special)
        if (cls, f.name) not in special and allowed not in ("", "any"):
            allowed = literal(allowed)  # a check's own words
        rows.append([literal(f.name), _type_name(hints[f.name]), unit, shown, allowed,
                     meaning])
    return list_table(["key", "type", "unit", "default", "allowed", "meaning"], rows,
                      widths=[14, 10, 8, 12, 16, 40], classes="config-table")


def render(docs) -> str:
    from controllers import CONTROLLERS, OBSERVERS
    from plant_exudyn import Mesh
    from reduced_model import ArmParameters, named_arm
    from validation.run.requirements import Requirement
    from validation.run.plants import PLANTS, FmuSettings, PluginSettings
    from validation.run.scenario import (ControllerSpec, DisturbanceSpec, DivergenceSpec,
                                         ModelSpec, ObserverSpec, ReferenceSpec, Scenario,
                                         SensorSpec)
    law = 'a built-in kind ({}) or a plug-in ``"package.module:Class"``'
    # The law kinds are checked against the registries when the laws are built, not by
    # the dataclass: show what the registries hold.
    special = {(ControllerSpec, "kind"): law.format(", ".join(map(literal, CONTROLLERS))),
               (ObserverSpec, "kind"): '``"none"``, ' + law.format(
                   ", ".join(map(literal, OBSERVERS)))}
    default = ArmParameters()
    arms = {"table1": named_arm("table1"), "lab": named_arm("lab")}
    arm_overrides = {f.name: "; ".join(f"``{arm}``: {_toml(getattr(p, f.name))}"
                                       for arm, p in arms.items()
                                       if getattr(p, f.name) != getattr(default, f.name))
                     for f in dataclasses.fields(ArmParameters)
                     if any(getattr(p, f.name) != getattr(default, f.name)
                            for p in arms.values())}
    sections = [
        ("Top-level keys", Scenario, {}, None,
         "The keys of a scenario file (or of a campaign's ``[scenario]`` table)."),
        ('``[plant]`` with ``kind = "reduced"``', PLANTS["reduced"].Settings, {}, None,
         "The paper's model as the plant (the default)."),
        ('``[plant]`` with ``kind = "exudyn"``', PLANTS["exudyn"].Settings, {}, None,
         "The finite-element truth plant.  Each kind takes only its own keys."),
        ('``[plant]`` with ``kind = "package.module:Class"``', PluginSettings, {}, None,
         "A plant of your own: a ``reduced_model.Plant`` subclass, or a subclass of a "
         "built-in plant (the guide's *Write your own plant*)."),
        ('``[plant]`` with ``kind = "fmu"``', FmuSettings, {}, None,
         "A co-simulation FMU (FMI 2.0 or 3.0) as the plant, its variables mapped to the "
         "plant contract (the guide's *FMUs: plants and laws that cross tools*)."),
        ("``[plant.mesh]``", Mesh, {}, None,
         'The truth plant\'s finite elements (``kind = "exudyn"`` only).'),
        ("``[true_params]`` and ``[nominal_params]``", ArmParameters, {}, arm_overrides,
         "The arm simulated and the arm the laws believe in, SI units; both start from "
         "the parameters of ``arm`` (the defaults shown; ``table1``'s and ``lab``'s "
         "where they differ) and override them key by key."),
        ("``[model]``", ModelSpec, {}, None, "The laws' model."),
        ("``[controller]``", ControllerSpec, {}, None,
         "The options each built-in law takes are listed on its API page."),
        ("``[observer]``", ObserverSpec, {}, None, ""),
        ("``[reference]``", ReferenceSpec, {}, None, ""),
        ("``[sensors]``", SensorSpec, {}, None, ""),
        ("``[[disturbances]]``", DisturbanceSpec, {}, None,
         "An array of tables: any number of disturbances, added to the torques or to "
         "the payload force."),
        ("``[divergence]``", DivergenceSpec, {}, None, ""),
        ("``[[requirement]]``", Requirement, {"name": "probe", "claim": "tracking"}, None,
         "An array of tables: what must hold, each with its robustness ρ as the metric "
         "``rho_<name>``."),
    ]
    out = [".. This file is generated by docs/_ext/flexarm_docs/configref.py.\n\n"]
    for title, cls, required, overrides, intro in sections:
        out.append(heading(title, "-"))
        if intro:
            out.append(intro + "\n\n")
        out.append(_table(cls, required, special, overrides))
    return "".join(out)
