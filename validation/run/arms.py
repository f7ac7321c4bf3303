"""What a scenario's ``arm`` names, and how ``true_params`` and ``nominal_params`` start
from it.

``arm`` is a shipped arm's name (`reduced_model.named_arms`: ``default``, ``table1``,
``lab``, …), the path of an arm file (``--arm my-arm.toml``), or an inline ``[arm]``
table — one form for all three (`reduced_model.arm.files`).  The parameter tables of a
scenario hold the user's own changes by flat key (``EI1``, ``coulomb2``, ``Mp``) over
that arm; a resolved scenario stores each arm in full (``links``, ``joints``,
``payload``, ``gravity``), so that a stored run is re-simulated without the arm's file.
"""
from __future__ import annotations

from pathlib import Path

from reduced_model import ArmFileError, ArmParameters, named_arm, named_arms, read_arm
from reduced_model.arm import ARM_KEYS, arm_from_table

from .config import ConfigError, check

__all__ = ["arm_label", "arm_of", "params_from_table", "STRUCTURE", "PAPER_ARMS",
           "PARAMETER_TABLES", "arm_description", "flat_values", "own_parameters",
           "check_scales_on_arm", "flat_config", "parameter_value", "paper_shaped"]

#: The keys of a parameter table that describe a whole arm (a resolved scenario's form).
STRUCTURE = ("links", "joints", "payload", "gravity")
#: The arms a single scenario's stability map and validity are judged on (unless --arm).
PAPER_ARMS = ("default", "table1")
#: The scenario's tables that start from its ``arm``.
PARAMETER_TABLES = ("true_params", "nominal_params")


def paper_shaped(table: dict) -> bool:
    """Whether a resolved parameter table (a stored run's ``true_params``) is an arm of
    the paper's shape — two flexible links in a horizontal plane —, the arms the paper's
    claims are judged on (other arms get the requirements a user states)."""
    links = table.get("links", ())
    return (len(links) == 2 and all(link["modes"] > 0 for link in links)
            and not any(table.get("gravity", (0.0, 0.0))))


def arm_label(value) -> str:
    """How runs name the arm ``value`` (a name, a file path or an inline table): the
    name, the file path as given, or the table's ``name`` ("custom" without one)."""
    if isinstance(value, dict):
        name = value.get("name", "custom")
        check(isinstance(name, str) and name.strip() != "", "arm.name",
              f"must be a non-empty string, got {name!r}")
        return name
    check(isinstance(value, str) and value.strip() != "", "arm",
          f"must be a shipped arm's name, an arm file (.toml) or an [arm] table, got "
          f"{value!r}")
    return value


def arm_of(value) -> ArmParameters:
    """The arm ``value`` names (ConfigError naming ``arm`` and its key otherwise)."""
    try:
        if isinstance(value, dict):
            table = {k: v for k, v in value.items() if k != "name"}
            return arm_from_table(table, where="arm")
        if value in named_arms() or not (value.endswith(".toml") or "/" in value):
            return named_arm(value)
        return read_arm(Path(value))
    except ArmFileError as exc:
        raise ConfigError("", str(exc)) from None


def arm_description(label: str) -> str:
    """A shipped arm's one-line description; a file's or table's label itself."""
    return named_arms().get(label, label)


def params_from_table(given: dict, arm, key: str) -> ArmParameters:
    """``true_params`` or ``nominal_params`` (``key``) from its table ``given``: a whole
    arm (`STRUCTURE`'s keys) or the arm ``arm`` (resolved only where needed: a callable
    giving it), then the table's flat keys changed."""
    check(isinstance(given, dict), key, f"expected a table, got {given!r}")
    whole = {k: v for k, v in given.items() if k in STRUCTURE}
    flat = {k: v for k, v in given.items() if k not in STRUCTURE}
    if "links" in whole:
        try:
            base = arm_from_table(whole, where=key)
        except ArmFileError as exc:
            raise ConfigError("", str(exc)) from None
    else:
        check(not whole or set(whole) <= {"gravity"}, key,
              f"{', '.join(sorted(whole))} describe a whole arm: give its links too "
              "(or change fields by flat key: EI1, coulomb2, Mp)")
        base = arm()
        if whole:
            flat = {**whole, **flat}
    try:
        return base.replace(**flat)
    except ValueError as exc:
        field = getattr(exc, "field", None)
        reason = getattr(exc, "reason", str(exc))
        raise ConfigError(f"{key}.{field}" if field else key, reason) from None




def flat_values(params: ArmParameters) -> dict:
    """Every field of ``params`` by flat key (``gravity`` as a list)."""
    return {key: list(params.gravity) if key == "gravity" else params.get(key)
            for key in params.keys()}


def own_parameters(data: dict) -> dict:
    """A scenario mapping (a stored run's resolved one) with each parameter table
    (`PARAMETER_TABLES`) reduced to the user's own layer: the fields, by flat key, whose
    values differ from its ``arm``'s.  `scenario_from_mapping` lays that layer over
    whichever arm is named then, so a rerun with another ``arm`` takes that arm's
    physics and keeps the user's own values.  A value equal to the old arm's cannot be
    told from it: it follows the new arm.  A table whose arm cannot be read again (an
    inline table, a file since removed) or has another number of links stays whole.

    Parameters
    ----------
    data : dict
        A scenario mapping; not changed.

    Returns
    -------
    dict
        A copy of ``data`` whose parameter tables hold only the user's own values (a table
        that is not a table is left for `scenario_from_mapping` to refuse).
    """
    try:
        arm = arm_of(data.get("arm", "default"))
    except ConfigError:
        return dict(data)
    base = flat_values(arm)
    out = dict(data)
    for key in PARAMETER_TABLES:
        table = data.get(key, {})
        if not isinstance(table, dict):
            continue
        params = params_from_table(table, lambda: arm, key)
        if params.n_links == arm.n_links:
            out[key] = {k: v for k, v in flat_values(params).items() if base[k] != v}
    return out


def check_scales_on_arm(scaled: dict[str, str], arms, base: dict) -> None:
    """A scale axis multiplies the base scenario's value, resolved on the base's arm.  On
    a parameter (`PARAMETER_TABLES`) that the base leaves to its arm, beside an axis that
    runs an arm whose value differs, it would give that arm the base arm's value: refused
    (`ConfigError` naming the axis).

    Parameters
    ----------
    scaled : dict
        The dotted fields scaled, each with the axis that scales it (for the error).
    arms : iterable of str
        The arms the axes run (an arm that is not one is left to the run's own check).
    base : dict
        The resolved base scenario (`scenario_to_mapping`).
    """
    own = own_parameters(base)
    for path, where in scaled.items():
        table, _, key = path.partition(".")
        if table not in PARAMETER_TABLES or key in own[table]:
            continue  # not the arm's, or the base's own value: the same on every arm
        ours = flat_values(params_from_table(base[table], lambda: None, table)).get(key)
        for arm in sorted(set(arms) - {base["arm"]}):
            try:
                value = flat_values(arm_of(arm)).get(key)
            except ConfigError:
                continue
            check(value == ours, where,
                  f"scales {path} of the {base['arm']} arm ({ours!r}), but the axes also run "
                  f"the {arm} arm, whose value is {value!r}: give values, not factors, or "
                  f"set arm = {arm!r} in the base scenario")


def flat_config(config: dict) -> dict:
    """A scenario mapping by dotted key, its parameter tables by flat key
    (``true_params.EI1``): what a rerun's note compares."""
    from .tomlfiles import flatten
    out = flatten({k: v for k, v in config.items() if k not in PARAMETER_TABLES})
    for key in PARAMETER_TABLES:
        if isinstance(config.get(key), dict):
            params = params_from_table(config[key], lambda: arm_of(config.get("arm", "default")),
                                       key)
            out.update({f"{key}.{k}": v for k, v in flat_values(params).items()})
    return out


def parameter_value(config: dict, path: str):
    """The value at the dotted ``path`` of a resolved scenario mapping, a parameter table's
    fields by flat key (``true_params.Mp``); KeyError if there is none."""
    table, _, key = path.partition(".")
    if table in PARAMETER_TABLES and isinstance(config.get(table), dict):
        try:
            return flat_values(params_from_table(config[table], lambda: None, table))[key]
        except (ConfigError, KeyError):
            raise KeyError(path) from None
    from .tomlfiles import get_dotted
    return get_dotted(config, path)
