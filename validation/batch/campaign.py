"""Campaigns: a base scenario plus sweeps, expanded into runs and executed in parallel.

A campaign file (TOML)::

    name = "mismatch"
    include = "base.toml"              # optional: files merged under this one, in order
    [scenario]                         # the base scenario (any scenario keys)
    duration = 10.0
    [[sweep]]                          # sweeps expand independently; the runs are their union
    name = "payload"
    grid.plant.kind = ["reduced", "exudyn"]           # cartesian product of all grid axes
    grid.true_params.Mp = [0.0, 0.1, 0.5, 1.0]
    grid.true_params.EI1 = {scale = [0.7, 1.0, 1.3]}  # factors of the base value
    zip.controller.kind = ["pbc", "pd"]               # zip axes: paired, same length
    zip.name = ["pbc", "pd"]
    random.samples = 8                                # random axes: N seeded draws
    random.seed = 1
    random.true_params.Mp = {uniform = [0.0, 1.0]}    # also loguniform, choices
    random.true_params.EI1 = {scale = {uniform = [0.7, 1.3]}, also = ["true_params.EI2"]}
    random."disturbances[0].start" = {uniform = [2.0, 18.0]}   # [i] indexes a list

Within a sweep the grid, zip and random parts combine by product.  A random axis under
``scale`` draws a factor of the base value; ``also`` gives other fields the same draw.  The
same axes declare the uncertainty sets of ``flexarm verify`` (`RandomAxis`).  Each run's
scenario is resolved and checked before anything runs; its id is a hash of the resolved
scenario, so rerunning a campaign into the same folder skips what is done (resume;
running is `validation.batch.queue`'s).
"""
from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..run.config import ConfigError, check, check_known, check_label
from ..run.scenario import (Scenario, check_scales_on_arm, scenario_from_mapping,
                            scenario_to_mapping)
from .axes import draw_points, flatten_axes, numeric_field, random_axis
from .store.runfiles import KEEP_ALL, Keep, keep_from_mapping
from .store.folder import run_id
from ..run.tomlfiles import deep_merge, load_toml, set_dotted

__all__ = ["Campaign", "PlannedRun", "load_campaign", "load_study", "own_name", "is_campaign",
           "CAMPAIGN_KEYS", "campaign_from_mapping", "expand", "MAX_RUNS", "run_name",
           "check_run_name", "campaign_keep"]

#: The most runs one campaign may expand to (a typo in a random sweep should not hang the
#: machine listing a million runs).
MAX_RUNS = 100_000

_TOP_KEYS = {"name", "description", "include", "scenario", "sweep", "report", "attribution",
             "requirement", "uncertainty", "verify", "calibrate", "keep", "stability"}
_SWEEP_KEYS = {"name", "grid", "zip", "random"}
#: Sections a scenario file may have too (``flexarm verify`` reads ``[uncertainty]`` and
#: ``[verify]``, ``calibrate`` ``[calibrate]``, ``stability`` ``[stability]``).
_VERIFY_KEYS = ("uncertainty", "verify", "calibrate", "stability")


@dataclass(frozen=True)
class PlannedRun:
    """One expanded run: its id, resolved scenario, the axis values that made it and what
    its file keeps where a verdict decides it (None: its campaign's ``[keep]``)."""

    run_id: str
    scenario: Scenario
    sweep: str
    axes: dict = field(default_factory=dict)
    keep: Keep | None = None


@dataclass(frozen=True)
class Campaign:
    """A base scenario (a mapping, with the file's ``[[requirement]]`` entries), its sweeps
    and the sections of a campaign file (``uncertainty`` and ``verify`` are read by
    ``flexarm verify``, `validation.verdicts.verify`).  Made by `load_campaign` or
    `campaign_from_mapping`; the keys are those of a campaign file (the configuration
    reference).

    Parameters
    ----------
    name : str
        The campaign's name: its results folder's default and its runs' prefix.
    base : dict
        The ``[scenario]`` every run starts from, as a mapping.
    sweeps : tuple of dict
        The ``[[sweep]]`` tables (``grid``, ``zip``, ``random``; `expand` runs them).
    report : dict
        The ``[report]`` table (which runs' figures the report draws).
    description : str
        What the campaign asks, for the report.
    attribution, uncertainty, verify, calibrate, keep, stability : dict
        The ``[attribution]``, ``[uncertainty]``, ``[verify]``, ``[calibrate]``, ``[keep]``
        and ``[stability]`` tables (empty when the file has none).

    Examples
    --------
    >>> from validation import campaign_from_mapping, expand
    >>> campaign = campaign_from_mapping({
    ...     "name": "gains", "scenario": {"duration": 1.0},
    ...     "sweep": [{"name": "kp", "grid": {"plant.kind": ["reduced", "exudyn"],
    ...                                       "seed": [1, 2, 3]}}]})
    >>> campaign.name, len(expand(campaign))
    ('gains', 6)
    """

    name: str
    base: dict
    sweeps: tuple[dict, ...]
    report: dict = field(default_factory=dict)
    description: str = ""
    attribution: dict = field(default_factory=dict)
    uncertainty: dict = field(default_factory=dict)
    verify: dict = field(default_factory=dict)
    calibrate: dict = field(default_factory=dict)
    keep: dict = field(default_factory=dict)
    stability: dict = field(default_factory=dict)


# --- loading ------------------------------------------------------------------------------
#: Top-level keys only a campaign file has (a scenario file may have ``name``, ``include``,
#: ``[[requirement]]``, ``[uncertainty]`` and ``[verify]``).
CAMPAIGN_KEYS = frozenset(_TOP_KEYS - {"name", "include", "requirement", *_VERIFY_KEYS})


def is_campaign(data: dict) -> bool:
    """Whether a file's mapping is a campaign (it has a key of `CAMPAIGN_KEYS`) rather
    than a scenario."""
    return bool(CAMPAIGN_KEYS & set(data))


def load_campaign(path: str | Path) -> Campaign:
    """Read a campaign TOML (with includes) and check its structure.

    Parameters
    ----------
    path : str or pathlib.Path
        The campaign file.

    Returns
    -------
    Campaign
        Its base scenario, sweeps and sections (expand it with `expand`).
    """
    return campaign_from_mapping(load_toml(path), source=str(path))


def load_study(path: str | Path, *, name: str | None = None) -> Campaign:
    """A scenario file or a campaign file, read the one way every command reads them: a
    campaign (`is_campaign`) as it is; a scenario as a campaign of that one run, named
    after the file (the run keeps the scenario's own ``name``, if it has one, or
    ``name`` if given: a name from the command line replaces the file's)."""
    data = load_toml(path)
    if is_campaign(data):
        return campaign_from_mapping(data, source=str(path))
    if name is not None:
        data = dict(data, name=name)
    label = re.sub(r"[^A-Za-z0-9._+-]", "-", Path(path).stem).lstrip(".") or "scenario"
    sweep = {"name": data["name"]} if "name" in data else {}
    if sweep:
        check_label(sweep["name"], "name")  # names its run: the rule of every run's name
    base = {k: v for k, v in data.items() if k not in ("name", *_VERIFY_KEYS)}
    sections = {k: data.get(k, {}) for k in _VERIFY_KEYS}
    for key, value in sections.items():
        check(isinstance(value, dict), key, "must be a table")
    return Campaign(name=label[:100], base=base, sweeps=(sweep,) if sweep else (), **sections)


def own_name(study: Campaign) -> dict:
    """``{"name": NAME}`` of a scenario file read by `load_study` that names its run (its
    one sweep), else ``{}`` (a campaign's sweeps name its runs)."""
    single = len(study.sweeps) == 1 and set(study.sweeps[0]) == {"name"}
    return dict(study.sweeps[0]) if single else {}


def campaign_from_mapping(data: dict, *, source: str = "campaign") -> Campaign:
    """A campaign from a mapping with a campaign file's keys (``name``, ``[scenario]``,
    ``[[sweep]]``, ``[report]``, …); unknown keys raise `ConfigError`.

    Parameters
    ----------
    data : dict
        The campaign, as a TOML file would hold it.
    source : str
        Where it comes from: named in errors, and its stem is the default ``name``.

    Returns
    -------
    Campaign
        The campaign, its structure checked (its runs are checked by `expand`).
    """
    for key in data:
        check_known(key, _TOP_KEYS, key)
    name = data.get("name", Path(source).stem)
    check_label(name, "name")
    base = data.get("scenario", {})
    check(isinstance(base, dict), "scenario", "must be a table")
    requirements = data.get("requirement", [])
    check(isinstance(requirements, list), "requirement",
          "must be an array of tables ([[requirement]])")
    if requirements:  # the file's requirements apply to every run, after the scenario's own
        base = dict(base, requirement=[*base.get("requirement", []), *requirements])
    for key in _VERIFY_KEYS:
        check(isinstance(data.get(key, {}), dict), key, "must be a table")
    sweeps = data.get("sweep", [])
    if isinstance(sweeps, dict):
        sweeps = [sweeps]
    check(isinstance(sweeps, list), "sweep", "must be an array of tables ([[sweep]])")
    for i, sweep in enumerate(sweeps):
        where = f"sweep[{i}]"
        check(isinstance(sweep, dict), where, "must be a table")
        for key in sweep:
            check_known(key, _SWEEP_KEYS, f"{where}.{key}")
        if "name" in sweep:
            check_label(sweep["name"], f"{where}.name")
    report = data.get("report", {})
    check(isinstance(report, dict), "report", "must be a table")
    for key in report:
        check_known(key, ("figures",), f"report.{key}")
    figures = report.get("figures", [])
    check(isinstance(figures, list) and all(isinstance(f, str) for f in figures),
          "report.figures", "must be a list of run names")
    attribution = data.get("attribution", {})
    check(isinstance(attribution, dict), "attribution", "must be a table")
    for key in attribution:
        check_known(key, ("factors",), f"attribution.{key}")
    return Campaign(name=name, base=base, sweeps=tuple(sweeps), report=report,
                    description=str(data.get("description", "")), attribution=attribution,
                    uncertainty=data.get("uncertainty", {}), verify=data.get("verify", {}),
                    calibrate=data.get("calibrate", {}), keep=data.get("keep", {}),
                    stability=data.get("stability", {}))


# --- expansion --------------------------------------------------------------------------------
def _axis_values(path: str, spec, resolved_base: dict, where: str) -> list:
    """The list of values of a grid or zip axis."""
    if isinstance(spec, dict):
        check(set(spec) == {"scale"}, where, "a grid/zip axis is a list or {scale = [...]}")
        base_value = numeric_field(resolved_base, path, where)
        factors = spec["scale"]
        check(isinstance(factors, list) and factors and all(
            isinstance(f, (int, float)) and not isinstance(f, bool) for f in factors), where,
            "scale must be a non-empty list of numbers")
        return [base_value * f for f in factors]
    check(isinstance(spec, list), where, f"must be a list of values, got {spec!r}")
    check(len(spec) > 0, where, "must not be empty")
    return list(spec)


def _sweep_points(sweep: dict, resolved_base: dict, where: str) -> list[dict]:
    """Every combination of one sweep's axes: list of {path: value}."""
    grid = flatten_axes(sweep.get("grid", {}))
    zipped = flatten_axes(sweep.get("zip", {}))
    random = dict(sweep.get("random", {}))
    scaled = {p: f"{where}.{part}.{p}" for part, axes in (("grid", grid), ("zip", zipped))
              for p, v in axes.items() if isinstance(v, dict)}
    grid_axes = [(p, _axis_values(p, v, resolved_base, f"{where}.grid.{p}"))
                 for p, v in grid.items()]
    size = math.prod(len(vals) for _, vals in grid_axes)
    check(size <= MAX_RUNS, f"{where}.grid", f"expands to {size} runs (at most {MAX_RUNS})")
    parts = [[dict(zip([p for p, _ in grid_axes], combo))
              for combo in itertools.product(*[vals for _, vals in grid_axes])]]
    if zipped:
        cols = {p: _axis_values(p, v, resolved_base, f"{where}.zip.{p}") for p, v in zipped.items()}
        lengths = {len(v) for v in cols.values()}
        check(len(lengths) == 1, f"{where}.zip", f"zip axes need equal lengths, got "
                                                 f"{ {p: len(v) for p, v in cols.items()} }")
        n = lengths.pop()
        parts.append([{p: v[i] for p, v in cols.items()} for i in range(n)])
    if random:
        samples, seed = random.pop("samples", None), random.pop("seed", 0)
        check(isinstance(samples, int) and not isinstance(samples, bool)
              and 0 < samples <= MAX_RUNS, f"{where}.random.samples",
              f"must be an integer in 1..{MAX_RUNS}, got {samples!r}")
        check(isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0,
              f"{where}.random.seed", f"must be an integer >= 0, got {seed!r}")
        axes = flatten_axes(random)
        check(len(axes) > 0, f"{where}.random", "needs at least one axis besides samples/seed")
        parsed = [random_axis(p, v, resolved_base, f"{where}.random.{p}")
                  for p, v in sorted(axes.items())]
        parts.append(draw_points(parsed, samples, np.random.default_rng(seed)))
        scaled |= {p: f"{where}.random.{a.path}" for a in parsed if a.base for p in a.paths}
    size = math.prod(len(p) for p in parts)
    check(size <= MAX_RUNS, where, f"expands to {size} runs (at most {MAX_RUNS})")
    points = [dict(itertools.chain.from_iterable(d.items() for d in combo))
              for combo in itertools.product(*parts)]
    arms = {p["arm"] for p in points if isinstance(p.get("arm"), str)}
    check_scales_on_arm(scaled, arms, resolved_base)
    return points


def expand(campaign: Campaign) -> list[PlannedRun]:
    """All runs of a campaign, each scenario resolved and checked; duplicates (the same
    resolved scenario reached twice) are kept once.  ``[report] figures`` must name runs
    of the campaign.

    Parameters
    ----------
    campaign : Campaign
        The campaign.

    Returns
    -------
    list of PlannedRun
        Each run's id, name, sweep, swept values and checked scenario.
    """
    runs = _expand(campaign)
    names = {r.scenario.name for r in runs}
    for wanted in campaign.report.get("figures", []):
        shown = ", ".join(sorted(n.split("/")[-1] for n in names))
        check(any(n == wanted or n.endswith("/" + wanted) for n in names), "report.figures",
              f"no run named {wanted!r} (runs: {shown})")
    return runs


def campaign_keep(campaign: Campaign) -> Keep:
    """What the runs of ``campaign`` keep (its ``[keep]`` table, `runfiles.Keep`; default:
    every signal); ConfigError naming the key."""
    if not campaign.keep:
        return KEEP_ALL
    from ..run.requirements import signal_names
    try:
        base_scenario = scenario_from_mapping(campaign.base)
    except ConfigError as exc:
        raise exc.under("scenario") from None
    return keep_from_mapping(campaign.keep, signal_names(base_scenario))


def _expand(campaign: Campaign) -> list[PlannedRun]:
    campaign_keep(campaign)  # checked with the rest, before anything runs
    try:
        base_scenario = scenario_from_mapping(campaign.base)
    except ConfigError as exc:
        raise exc.under("scenario") from None
    resolved_base = scenario_to_mapping(base_scenario)
    sweeps = campaign.sweeps or ({},)
    runs: dict[str, PlannedRun] = {}
    for i, sweep in enumerate(sweeps):
        where = f"sweep[{i}]"
        sweep_name = sweep.get("name", f"sweep{i}" if campaign.sweeps else campaign.name)
        for point in _sweep_points(sweep, resolved_base, where):
            data = deep_merge({}, campaign.base)
            for path, value in point.items():
                try:
                    set_dotted(data, path, value, defaults=resolved_base)
                except ConfigError as exc:
                    raise ConfigError(where, f"{path}: {exc.message}") from None
            set_dotted(data, "name", run_name(campaign.name, point.get("name", sweep_name),
                                              _name_axis(sweep, where)))
            try:
                scenario = scenario_from_mapping(data)
            except ConfigError as exc:
                label = ", ".join(f"{p}={v!r}" for p, v in point.items())
                raise ConfigError(exc.path, f"{exc.message} (in {where}"
                                            f"{': ' + label if label else ''})") from None
            rid = run_id(scenario_to_mapping(scenario))
            runs.setdefault(rid, PlannedRun(rid, scenario, sweep_name, point))
            check(len(runs) <= MAX_RUNS, "sweep", f"the campaign expands to more than "
                                                  f"{MAX_RUNS} runs")
    return list(runs.values())


def run_name(campaign: str, label, where: str) -> str:
    """A campaign's run's name, ``"<campaign>/<label>"``, both plain names (`check_label`;
    the label from a name axis or the sweep's name): the rule for every run name."""
    check_label(label, where)
    return f"{campaign}/{label}"


def check_run_name(name, where: str) -> None:
    """A run's name: a plain name, or ``"<campaign>/<label>"`` of two (`run_name`)."""
    parts = name.split("/") if isinstance(name, str) else [name]
    check(len(parts) <= 2, where, f"must be a plain name or campaign/label, got {name!r}")
    for part in parts:
        check_label(part, where)


def _name_axis(sweep: dict, where: str) -> str:
    """The dotted key of a sweep's name axis (for errors), or of its name."""
    for part in ("grid", "zip", "random"):
        if "name" in sweep.get(part, {}):
            return f"{where}.{part}.name"
    return f"{where}.name"
