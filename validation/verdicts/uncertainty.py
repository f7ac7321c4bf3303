"""Uncertainty sets: the conditions a verdict must hold over, and the systems judged on them.

A scenario or campaign file declares, next to its ``[[requirement]]`` entries::

    [uncertainty]                                   # the random-sweep syntax
    "true_params.Mp" = { uniform = [0.0, 1.0] }     # kg
    "true_params.EI1" = { scale = { uniform = [0.7, 1.3] }, also = ["true_params.EI2"] }
    "disturbances[0].amplitude" = { uniform = [0.0, 3.0] }
    "sensors.encoder_noise" = { scale = { loguniform = [0.1, 10.0] },
                                also = ["sensors.modal_noise", "sensors.rate_noise"] }

    [verify]                                        # optional: the statistics' settings
    level = 0.95                                    # of the Clopper-Pearson interval
    p0 = 0.95                                       # the sequential test: p0 ± indifference,
    indifference = 0.025                            #   error probabilities alpha and beta
    alpha = 0.05
    beta = 0.05
    sequential = true                               # stop drawing once the test decides
    worst_case = false                              # falsify: stop at the first counterexample
                                                    #   (true: spend the budget on the lowest ρ)
    calibration = "inadequate"                      # written by flexarm calibrate: the set's
                                                    #   ranges come from a fit of that verdict

Any scenario field can be uncertain — true parameters, sensor noise, a disturbance's
amplitude and start, the reference's amplitude and frequency, the initial state and the
observer's initial error, Ts, a law's options — by its dotted path (``[i]`` indexes a
list), with the distributions of a campaign's random sweeps (`RandomAxis`: uniform,
loguniform, choices; ``scale`` for factors of the nominal value; ``also`` for fields
that share one draw).  Every dimension's ends (and each choice) are checked as scenarios
before anything runs.

An ``uncertainty.toml`` of ``flexarm calibrate`` says what the fit thought of its model
(``calibration``): the ranges of a model the residual tests call inadequate (or did not
judge) are effective parameters of that model, not 95 % intervals of the arm, and every
verdict over them says so in its description of the set (`UncertaintySet.caveat`).

A *system* is one nominal scenario: a scenario file is one; a campaign file has one per
run it expands to (``--system NAME`` picks one).  `System.scenario` builds the scenario
at a point of the set, on the nominal plant or on either of the two fidelities the
searches use: the reduced plant (the designer's own model order) and the truth plant.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..batch.axes import RandomAxis, draw_points, flatten_axes, random_axis
from ..batch.campaign import expand, load_study
from ..run.config import ConfigError, check, check_known
from ..run.plants import ROLES, plant_for_role
from ..run.requirements import Requirement
from ..run.scenario import (Scenario, check_scales_on_arm, own_parameters,
                            scenario_from_mapping, scenario_to_mapping)
from ..run.tomlfiles import set_dotted
from .calibration import CALIBRATION_VERDICTS
from .statistics import SequentialTest

__all__ = ["UncertaintySet", "System", "VerifySettings", "load_systems"]

_SETTINGS = {"level", "p0", "indifference", "alpha", "beta", "sequential", "worst_case",
             "calibration"}


@dataclass(frozen=True)
class UncertaintySet:
    """Independent dimensions (`RandomAxis`), in the order of their paths; ``caveat``:
    what the set's ranges are not (from an inadequate calibration), "" if nothing."""

    axes: tuple[RandomAxis, ...]
    caveat: str = ""

    @property
    def dim(self) -> int:
        return len(self.axes)

    def draws(self, samples: int, seed: int) -> tuple[list[dict], list[int]]:
        """``samples`` seeded points (as a random sweep with this seed draws them) and a
        noise seed for each (the runs' ``seed``: the noise realisation is drawn too)."""
        rng = np.random.default_rng(seed)
        points = draw_points(list(self.axes), samples, rng)
        noise = [int(s) for s in rng.integers(0, 2**31 - 1, samples)]
        return points, noise

    def at(self, u) -> dict:
        """The point at ``u`` ∈ [0, 1]^dim (the searches' coordinates)."""
        point = {}
        for axis, ui in zip(self.axes, np.asarray(u, float)):
            point |= axis.assign(axis.from_unit(ui))
        return point

    def corners(self) -> list[dict]:
        """Each dimension at its ends (and every choice), the others at the nominal values:
        the points checked before anything runs."""
        out = []
        for axis in self.axes:
            ends = axis.arg if axis.kind == "choices" else (0.0, 1.0)
            for end in ends:
                draw = end if axis.kind == "choices" else axis.from_unit(end)
                out.append(axis.assign(draw))
        return out

    def describe(self) -> list[str]:
        return [axis.describe() for axis in self.axes] + ([self.caveat] if self.caveat else [])


@dataclass(frozen=True)
class VerifySettings:
    """``[verify]``: the interval's level and the sequential test (module docstring)."""

    level: float = 0.95
    sequential: bool = True
    test: SequentialTest = SequentialTest()
    worst_case: bool = False


@dataclass(frozen=True)
class System:
    """One nominal scenario to judge over ``uncertainty``."""

    name: str
    nominal: dict  # the resolved nominal scenario
    uncertainty: UncertaintySet
    settings: VerifySettings

    @property
    def requirements(self) -> tuple[Requirement, ...]:
        return tuple(Requirement(**r) for r in self.nominal["requirement"])

    def requirement(self, name: str | None) -> Requirement:
        """The requirement called ``name`` (the only one if None)."""
        reqs = {r.name: r for r in self.requirements}
        if name is None:
            check(len(reqs) == 1, "--requirement", f"{self.name} has {len(reqs)} requirements "
                                                   f"({', '.join(reqs)}); choose one")
            return next(iter(reqs.values()))
        check(name in reqs, "--requirement", f"no requirement {name!r} (requirements of "
                                             f"{self.name}: {', '.join(reqs)})")
        return reqs[name]

    def mapping(self, point: dict, *, plant: str | None = None, seed: int | None = None) -> dict:
        """The scenario mapping at ``point`` on the nominal plant (``plant`` None) or on
        the plant of the role "reduced" or "truth" (`plant_for_role`); ``seed`` replaces
        the noise seed."""
        data = own_parameters(copy.deepcopy(self.nominal))  # over the point's arm
        for path, value in point.items():
            try:
                set_dotted(data, path, value)
            except ConfigError as exc:
                raise ConfigError(f"uncertainty.{path}", f"{exc.path}: {exc.message} (in "
                                                         f"{self.name})") from None
        if plant is not None:
            data["plant"] = plant_for_role(self.nominal, plant)
        if seed is not None:
            data["seed"] = seed
        return data

    def scenario(self, point: dict, **kwargs) -> Scenario:
        """`mapping`, checked (ConfigError naming the point if the set reaches a scenario
        that cannot run)."""
        try:
            return scenario_from_mapping(self.mapping(point, **kwargs))
        except ConfigError as exc:
            label = ", ".join(f"{p} = {v!r}" for p, v in point.items())
            raise ConfigError(f"uncertainty: {exc.path}",
                              f"{exc.message} (at {label or 'the nominal point'})") from None


def _caveat(table: dict) -> str:
    """What ``[verify] calibration`` says about the set's ranges (module docstring)."""
    verdict = table.get("calibration", CALIBRATION_VERDICTS[True])
    check(verdict in CALIBRATION_VERDICTS.values(), "verify.calibration",
          f"must be one of {', '.join(map(repr, CALIBRATION_VERDICTS.values()))}, "
          f"got {verdict!r}")
    if verdict == CALIBRATION_VERDICTS[True]:
        return ""
    return (f"CAVEAT: the ranges come from a calibration whose model was {verdict} "
            "(flexarm calibrate): effective parameters of that model, not 95 % intervals "
            "of the physical arm")


def _settings(table: dict) -> VerifySettings:
    for key in table:
        check_known(key, _SETTINGS, f"verify.{key}")
    numbers = {k: table[k] for k in ("level", "p0", "indifference", "alpha", "beta")
               if k in table}
    for key, value in numbers.items():
        check(isinstance(value, (int, float)) and not isinstance(value, bool), f"verify.{key}",
              f"must be a number, got {value!r}")
    level = numbers.pop("level", 0.95)
    check(0 < level < 1, "verify.level", f"must be in (0, 1), got {level!r}")
    flags = {k: table.get(k, default) for k, default in (("sequential", True),
                                                          ("worst_case", False))}
    for key, value in flags.items():
        check(isinstance(value, bool), f"verify.{key}", "must be true or false")
    return VerifySettings(float(level), flags["sequential"], SequentialTest(**numbers),
                          flags["worst_case"])


def _uncertainty(table: dict, nominal: dict, caveat: str) -> UncertaintySet:
    check(isinstance(table, dict) and table, "uncertainty",
          "needs at least one uncertain field, e.g. \"true_params.Mp\" = {uniform = [0, 1]}")
    axes = tuple(random_axis(p, spec, nominal, f"uncertainty.{p}")
                 for p, spec in sorted(flatten_axes(table).items()))
    check_scales_on_arm({p: f"uncertainty.{a.path}" for a in axes if a.base for p in a.paths},
                        {v for a in axes if "arm" in a.paths and a.kind == "choices"
                         for v in a.arg if isinstance(v, str)}, nominal)
    fields = [p for axis in axes for p in axis.paths]
    twice = sorted({p for p in fields if fields.count(p) > 1})
    check(not twice, "uncertainty", f"{', '.join(twice)} set by more than one dimension")
    return UncertaintySet(axes, caveat)


def load_systems(path: str | Path) -> list[System]:
    """The systems of a scenario or campaign file with ``[uncertainty]`` (module
    docstring; `load_study` reads either), each checked at its nominal point and at every
    dimension's ends."""
    campaign = load_study(path)
    settings, caveat = _settings(campaign.verify), _caveat(campaign.verify)
    check(bool(campaign.uncertainty), "uncertainty", f"{path} declares no [uncertainty]")
    systems = []
    for run in expand(campaign):
        name, nominal = run.scenario.name.split("/")[-1], scenario_to_mapping(run.scenario)
        check(bool(nominal["requirement"]), "requirement",
              f"{name} has no [[requirement]] to verify")
        system = System(name, nominal, _uncertainty(campaign.uncertainty, nominal, caveat),
                        settings)
        for point in system.uncertainty.corners():
            for role in ROLES:
                system.scenario(point, plant=role)
        systems.append(system)
    return systems
