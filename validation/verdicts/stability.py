"""The sampled-data stability map: per controller (+ observer), plant and arm, the largest
control period Ts at which the loop does not diverge and, separately, the largest at which
it keeps tracking.

A design made in continuous time (the paper's) meets the real arm through a sampler and
a zero-order hold.  For each case this module runs short closed loops on a grid of Ts
(`GRID`, 0.1–10 ms) and refines each limit by bisection on a log scale between its last
good and first bad grid value.  Runs start moving with the reference (no start-up kick)
and last `DURATION` seconds.  Each run has one *outcome*:

- ``stable``: completed, max |θ − θ_d| over its second half ≤ `TRACKING_LIMIT` (0.1 rad,
  five times the paper's 0.02 rad yardstick: a loop that rings up slowly is caught even if
  it has not crossed the divergence bounds);
- ``lost tracking``: completed without diverging, beyond the tracking limit;
- ``diverged``: left the divergence bounds, or grows faster than `GROWTH_LIMIT` over its
  second half (a loop just beyond its limit grows slowly: 2 s would not take it out of
  the bounds);
- ``failed``: the plant's solver or a law gave up — no verdict about stability at all;
  the stability command exits 1 when a case has one.

Two limits, each a claim about every tested Ts at or below it: the largest Ts with **no
divergence** and the largest Ts that **keeps tracking**.  A failed run ends a limit's
scan (nothing is known there).  Each limit is monotone in what it claims; a tested Ts
above a limit that nevertheless did not diverge (or kept tracking) is reported as a
*non-monotone* case, never smoothed over.  On the truth plant the runs that define the
limits are repeated on the check meshes and with a finer integration step
(`validation.verdicts.mesh`); a limit whose outcomes differ between them is "not
converged".

The *predicted* limit is the exact zero-order-hold eigenvalue analysis of the case's own
linearised sampled loop (`validation.verdicts.sampled`): the law linearised from its
object (every gain it applies) at points of the reference, the plant linearised there —
the reduced model, or the FE arm with the case's mesh.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..batch.campaign import PlannedRun

from ..batch.queue import run_planned
from ..batch.executor import Runner
from ..run.laws import applies_generalised_forces
from ..run.plants import is_truth, plant_settings, with_plant
from ..run.scenario import arm_parameters, scenario_from_mapping, scenario_to_mapping
from ..batch.store import ResultStore, run_id
from .sampled import predicted_period

__all__ = ["GRID", "DURATION", "TRACKING_LIMIT", "GROWTH_LIMIT", "MAX_LEVEL", "OUTCOMES",
           "StabilityCase",
           "StabilityResult", "cases_from_scenarios", "stability_map", "load_stability",
           "outcome"]

GRID = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2)
DURATION = 2.0
TRACKING_LIMIT = 0.1
#: A run whose fastest motion grows faster than this [1/s] over its second half (the
#: metric ``growth_rate``) is diverging even if it has not left the divergence bounds
#: yet.  Measured over 2 s runs at Ts = 1 ms (PBC with and without observers, PD, CT, LQR,
#: both plants, both starts): −2.6 to +0.68 1/s, the largest from rest as the reference's
#: demand rises; the default arm's PBC fed the true state on the truth plant: −2.6 at
#: 2.6-2.7 ms (stable), +4 to +5.5 at 2.76 ms (diverging, at 1.3-3.3 s).  1.5 sits 2× above
#: the stable ones; slower growth is beyond what a 2 s run resolves.
GROWTH_LIMIT = 1.5
BISECTIONS = 3
OUTCOMES = ("stable", "lost tracking", "diverged", "failed")
_MAX_PLANT_STEP = 1e-3


#: The finest discretisation a truth-plant case is re-bisected at when its limits move
#: under refinement: level k has 2^k times the elements per link and 1/2^k of the step
#: (`validation.verdicts.mesh`); level 2's own checks reach ANCF 16 × 4 = 64 el/link.
MAX_LEVEL = 2


@dataclass(frozen=True)
class StabilityCase:
    label: str  # e.g. "pbc+smo-paper"
    plant: str
    arm: str
    base: dict  # a resolved scenario mapping (Ts and plant step are set per run)
    level: int = 0  # truth plant: the mesh and step refined 2^level times (MAX_LEVEL)

    def refined(self) -> "StabilityCase":
        """The same case one level finer."""
        return StabilityCase(self.label, self.plant, self.arm, self.base, self.level + 1)

    @property
    def truth(self) -> bool:
        """Whether the case runs on a truth plant (its limits are checked on the refined
        sequence)."""
        return is_truth(self.base)


@dataclass(frozen=True)
class Limit:
    """One limit of a case: the largest Ts at or below which every tested run was good
    (NaN if the smallest was not), the first Ts that was not (NaN if none), its outcome
    and why, and the tested Ts above ``first_bad`` that were good again."""

    largest: float
    first_bad: float
    outcome: str
    reason: str
    non_monotone: tuple[float, ...] = ()


@dataclass
class StabilityResult:
    case: StabilityCase
    tested: dict  # Ts -> (outcome, detail)
    divergence: Limit  # good = did not diverge (stable or lost tracking)
    tracking: Limit  # good = stable
    predicted: float  # NaN when no prediction exists for the law
    mesh: str = ""  # truth plant: the mesh check of the runs defining the limits
    mesh_converged: bool | None = None  # None: reduced plant, or not checked
    discretisation: str = ""  # truth plant: "ANCF 8 el/link, step Ts/2" of its runs

    @property
    def controller(self) -> str:
        return self.case.base["controller"]["kind"]

    @property
    def observer(self) -> str:
        return self.case.base["observer"]["kind"]

    @property
    def failed(self) -> list[float]:
        """The tested Ts whose run failed (the solver or a law gave up)."""
        return [Ts for Ts, (o, _) in self.tested.items() if o == "failed"]

    @property
    def non_monotone(self) -> list[str]:
        """Every tested Ts that contradicts a limit, in words."""
        out = []
        for limit, good in ((self.divergence, "no divergence"), (self.tracking, "kept tracking")):
            for Ts in limit.non_monotone:
                out.append(f"{good} at {1e3 * Ts:.3g} ms above the first {limit.outcome} "
                           f"at {1e3 * limit.first_bad:.3g} ms")
        return out


def _label(config: dict) -> str:
    c, o = config["controller"]["kind"], config["observer"]["kind"]
    return c if o == "none" else f"{c}+{o}"


def cases_from_scenarios(scenarios, *, plants=None, arms=None) -> list[StabilityCase]:
    """One case per distinct (controller + options, observer + options, plant, arm) among
    ``scenarios``; ``plants``/``arms`` (if given) replace the scenarios' own."""
    cases: dict[tuple, StabilityCase] = {}
    for s in scenarios:
        data = scenario_to_mapping(s)
        for plant in plants or (data["plant"]["kind"],):
            for arm in arms or (data["arm"],):
                base = dict(data, disturbances=[], initial_state="reference",
                            duration=DURATION, transient=DURATION / 2, requirement=[])
                base["plant"] = with_plant(base["plant"], plant)
                base["arm"] = arm
                params = scenario_to_mapping(arm_parameters(arm))
                if arm != data["arm"]:  # start the parameter tables from the other arm
                    base["true_params"] = base["nominal_params"] = params
                if plant_settings(base["plant"]).actuated == 2 and \
                        applies_generalised_forces(s):
                    continue  # two actuators: a law of forces on every coordinate cannot run
                label = _label(base)
                key = (label, _options_key(base), plant, arm)
                base["name"] = f"stability/{label}"
                if key not in cases:  # resolved: every setting of its plant written out
                    resolved = scenario_to_mapping(scenario_from_mapping(base))
                    cases[key] = StabilityCase(label, plant, arm, resolved)
    return list(cases.values())


def _options_key(config: dict) -> str:
    import json
    return json.dumps([config["controller"], config["observer"]], sort_keys=True)


def _scenario_at(case: StabilityCase, Ts: float) -> dict:
    data = dict(case.base, Ts=Ts)
    steps = math.ceil(Ts / _MAX_PLANT_STEP - 1e-9) * 2 ** case.level
    data["plant"] = dict(plant_settings(case.base["plant"]).refined(case.level), step=Ts / steps)
    return data


def outcome(row) -> tuple[str, str]:
    """(outcome, detail) of a stored stability run (module docstring)."""
    if row.status in ("diverged", "failed"):
        return row.status, row.message or row.status
    growth = row.metrics.get("growth_rate", math.nan)
    if growth > GROWTH_LIMIT:
        return "diverged", f"growing at {growth:.2g} 1/s (the torques' second difference " \
                           "over the second half)"
    worst = max(row.metrics.get("track_max_1", math.inf), row.metrics.get("track_max_2", math.inf))
    if not worst <= TRACKING_LIMIT:
        return "lost tracking", f"max |θ − θd| = {worst:.3g} rad over the second half"
    return "stable", f"max |θ − θd| = {worst:.3g} rad over the second half"


_GOOD = {"divergence": ("stable", "lost tracking"), "tracking": ("stable",)}


def _limit(tested: dict, good: tuple[str, ...]) -> Limit:
    """Scan the tested Ts upwards: the last good one before the first that is not
    (module docstring), and the good ones above it."""
    largest = first_bad = math.nan
    outcome_, reason = "", ""
    for Ts in sorted(tested):
        o, detail = tested[Ts]
        if o in good:
            largest = Ts
        else:
            first_bad, outcome_, reason = Ts, o, detail
            break
    above = () if math.isnan(first_bad) else tuple(
        Ts for Ts in sorted(tested) if Ts > first_bad and tested[Ts][0] in good)
    return Limit(largest, first_bad, outcome_, reason, above)


def _planned(case: StabilityCase, Ts: float) -> PlannedRun:
    scenario = scenario_from_mapping(_scenario_at(case, Ts))
    rid = run_id(scenario_to_mapping(scenario))
    return PlannedRun(rid, scenario, "stability", {"Ts": Ts, "plant.kind": case.plant,
                                                   "arm": case.arm, "level": case.level})


def _bisection_points(tested: dict) -> set[float]:
    """The next Ts to test: the geometric middle of each limit's bracket whose upper end
    is a real outcome of the loop (a failure says nothing about where the limit is)."""
    points = set()
    for good in _GOOD.values():
        limit = _limit(tested, good)
        if not (math.isnan(limit.largest) or math.isnan(limit.first_bad)) \
                and limit.outcome != "failed":
            points.add(float(np.sqrt(limit.largest * limit.first_bad)))
    return points


def stability_map(cases: list[StabilityCase], out, *, runner: Runner | None = None,
                  progress: bool = True, mesh_check: bool = True
                  ) -> tuple[list[StabilityResult], object]:
    """Run the grid and the bisections for every case into the results folder ``out``
    (resumable like any campaign; the progress bar names the round: grid, bisection k/3,
    mesh check), then, with ``mesh_check``, the truth-plant runs that define the limits on
    the refined sequence (`validation.verdicts.mesh`).  A truth-plant case whose limits
    move under refinement is mapped again one level finer (mesh and step refined
    together), up to `MAX_LEVEL`: its result is the first level whose limits are
    converged, or the finest tried.  Returns the results and the summary of every round
    together."""
    results, summary = _map_level(cases, out, runner=runner, progress=progress,
                                  mesh_check=mesh_check)
    while mesh_check and not summary.interrupted:
        moved = [r.case.refined() for r in results if r.mesh_converged is False
                 and r.case.level < MAX_LEVEL]
        if not moved:
            break
        finer, more = _map_level(moved, out, runner=runner, progress=progress,
                                 mesh_check=True)
        summary = summary + more
        by_key = {_case_key(r.case): r for r in finer}
        results = [by_key.get(_case_key(r.case), r) for r in results]
    return results, summary


def _case_key(case: StabilityCase) -> tuple:
    return case.label, _options_key(case.base), case.plant, case.arm


def _map_level(cases: list[StabilityCase], out, *, runner, progress, mesh_check):
    """The grid, the bisections and (with ``mesh_check``) the checks of ``cases``, each at
    its own level."""
    tested: dict[int, dict[float, tuple[str, str]]] = {i: {} for i in range(len(cases))}
    store = ResultStore(out)

    def run(points: list[tuple[int, float]], label: str):
        planned = {(i, Ts): _planned(cases[i], Ts) for i, Ts in points}
        summary = run_planned(planned.values(), out, name="stability",
                              description="sampled-data stability map", runner=runner,
                              progress=progress, label=label)
        if summary.interrupted:
            return summary
        rows = {r.run_id: r for r in store.rows()}
        for (i, Ts), p in planned.items():
            tested[i][Ts] = outcome(rows[p.run_id])
        return summary

    summary = run([(i, Ts) for i in range(len(cases)) for Ts in GRID], "stability: grid")
    for round_ in range(1, BISECTIONS + 1):
        if summary.interrupted:
            break
        points = [(i, Ts) for i in range(len(cases)) for Ts in sorted(_bisection_points(tested[i]))]
        if not points:
            break
        summary = summary + run(points, f"stability: bisection {round_}/{BISECTIONS}")
    if mesh_check and not summary.interrupted:
        rows = {r.run_id: r for r in store.rows()}
        defining = [rows[_planned(case, Ts).run_id] for i, case in enumerate(cases)
                    if case.truth for Ts in _defining(tested[i])]
        if defining:
            from .mesh import run_checks
            summary = summary + run_checks(defining, out, runner=runner, progress=progress,
                                           of_checks=True)
    if summary.interrupted:
        return [], summary
    return load_stability(out, cases=cases), summary


def _defining(tested: dict) -> list[float]:
    """The tested Ts that define a case's limits (each limit's last good and first bad;
    a failed run defines nothing: it has no outcome to compare)."""
    out = set()
    for good in _GOOD.values():
        limit = _limit(tested, good)
        out |= {Ts for Ts in (limit.largest, limit.first_bad)
                if not math.isnan(Ts) and tested[Ts][0] != "failed"}
    return sorted(out)


def _mesh_check(tested: dict, rows_at: dict, by_id: dict) -> tuple[str, bool | None]:
    """(text, converged?) of the mesh check of a truth-plant case: the outcome of every
    run defining a limit must be the same in every check (refined meshes, finer step)."""
    from .mesh import checks_of
    moved, missing, labels = [], False, {}
    for Ts in _defining(tested):
        row = rows_at.get(Ts)
        if row is None:
            continue
        for label, other in checks_of(row, by_id).items():
            labels[label] = None
            if other is None:
                missing = True
            elif outcome(other)[0] != tested[Ts][0]:
                moved.append(f"at {1e3 * Ts:.3g} ms {tested[Ts][0]}, {label} "
                             f"{outcome(other)[0]}")
    if moved:
        return "not converged: " + "; ".join(moved), False
    if missing or not labels:
        return "not checked", None
    return "converged against " + ", ".join(labels), True


def load_stability(out, *, fresh_only: bool = False, cases=None) -> list[StabilityResult]:
    """The stability map of a results folder, rebuilt from its stored runs (with
    ``fresh_only``, from the runs made by this code only; with ``cases``, those cases at
    their own level only).  A refined level's run can be stored as another run's check
    (the sequence's level-1 check *is* the next level's run): runs are found by what they
    are, not by the sweep that stored them first."""
    from ..batch.fingerprint import run_fingerprint
    all_rows = [r for r in ResultStore(out).rows()
                if not fresh_only or r.fingerprint == run_fingerprint(r.config)]
    by_id = {r.run_id: r for r in all_rows}
    if cases is None:  # every case mapped in the folder, at each level it may have
        found: dict[tuple, StabilityCase] = {}
        for row in all_rows:
            if row.sweep == "stability" and not row.axes.get("level", 0):
                case = StabilityCase(_label(row.config), row.config["plant"]["kind"],
                                     row.config["arm"], row.config)
                found.setdefault(_case_key(case), case)
        cases = [StabilityCase(c.label, c.plant, c.arm, c.base, level)
                 for c in found.values()
                 for level in range(MAX_LEVEL + 1 if c.truth else 1)]
    cases = sorted(cases, key=lambda c: (c.label, c.truth, c.plant, c.arm != "default",
                                         c.arm, c.level))
    results: dict[tuple, StabilityResult] = {}
    for case in cases:
        tested, rows_at = {}, {}
        plant = plant_settings(case.base["plant"]).refined(case.level)
        for row in all_rows:
            c = row.config
            if (c.get("name") != case.base.get("name") or c["arm"] != case.arm
                    or c["plant"]["kind"] != case.plant
                    or c["plant"].get("mesh") != _plain(plant.get("mesh"))
                    or _options_key(c) != _options_key(case.base)):
                continue  # cheap tests first: the run id below builds a scenario
            Ts = float(c["Ts"])
            if row.run_id == _planned(case, Ts).run_id:
                tested[Ts], rows_at[Ts] = outcome(row), row
        if not tested:
            continue
        result = _result(case, tested, next(iter(rows_at.values())).config)
        if case.truth:
            result.mesh, result.mesh_converged = _mesh_check(tested, rows_at, by_id)
            result.discretisation = _discretisation(next(iter(rows_at.values())).config,
                                                    case.level)
        # Per case, the first level whose limits converged, or the finest mapped.
        best = results.get(_case_key(case))
        if best is None or best.mesh_converged is not True:
            results[_case_key(case)] = result
    return list(results.values())


def _discretisation(config: dict, level: int) -> str:
    """"ANCF 8 el/link, step ≤ 0.5 ms" of a stored truth-plant run at ``level``."""
    return (f"{plant_settings(config['plant']).discretisation()}, step ≤ "
            f"{1e3 * _MAX_PLANT_STEP / 2 ** level:g} ms")


def _plain(value):
    """A plant table's value as a resolved scenario stores it (lists, not tuples)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return [_plain(v) for v in value] if isinstance(value, (list, tuple)) else value


def _result(case: StabilityCase, tested: dict, config: dict | None = None) -> StabilityResult:
    """The limits of ``tested``; the prediction on the plant of ``config`` (one of the
    case's runs: a refined level's own mesh), else of the case's base."""
    tested = dict(sorted(tested.items()))
    return StabilityResult(case, tested, _limit(tested, _GOOD["divergence"]),
                           _limit(tested, _GOOD["tracking"]),
                           predicted_period(config if config is not None else case.base))


