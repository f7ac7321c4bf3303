"""The sampled-data stability map: per controller (+ observer), plant and arm, the largest
control period Ts at which the loop does not diverge and, separately, the largest at which
it keeps tracking.

A design made in continuous time (the paper's) meets the real arm through a sampler and
a zero-order hold.  For each case this module runs short closed loops at control periods
Ts of a lattice over `GRID` (0.1–10 ms): first the two around the case's predicted limit
(below) for a law fed the true state, every grid point for a case with an observer or
without a finite prediction (`_start`), then outwards in steps of
1, 2, 4, … cells until each limit is bracketed, then it bisects each limit on a log
scale between its last good and first bad value until the bracket is within a relative
tolerance (default 1 %, `validation.verdicts.bisection`; each result counts the runs it
took).  So a run is spent where it moves a limit: the grid's short periods, the costliest
runs, are run only where a limit lies below them.  Runs start moving
with the reference (no start-up kick) and last `DURATION` seconds.  Each run has one
*outcome*:

- ``stable``: completed, max |θ_i − θ_i,d| of every joint over its second half ≤
  `TRACKING_LIMIT` (0.1 rad, five times the paper's 0.02 rad yardstick: a loop that rings
  up slowly is caught even if it has not crossed the divergence bounds);
- ``lost tracking``: completed without diverging, beyond the tracking limit;
- ``diverged``: left the divergence bounds, or grows faster than `GROWTH_LIMIT` over its
  second half (a loop just beyond its limit grows slowly: 2 s would not take it out of
  the bounds);
- ``failed``: the plant's solver or a law gave up — no verdict about stability at all;
  the stability command exits 1 when a case has one.

Two limits, each a claim about every tested Ts at or below it (below the first bracket
tested, the prediction speaks, not a run): the largest Ts with **no divergence** and the
largest Ts that **keeps tracking**.  A failed run ends a limit's
scan (nothing is known there).  Each limit is monotone in what it claims; a tested Ts
above a limit that nevertheless did not diverge (or kept tracking) is reported as a
*non-monotone* case, never smoothed over.  On the truth plant each limit is then judged
on the refined sequence at that resolution: the case is bisected again one level finer
(twice the elements per link, half the step), starting from the brackets of the level
before, until every limit's bracket moved by less than its width ("converged") or up to
`MAX_LEVEL`, where a limit still moving carries a Richardson estimate of the converged
limit and its error, or reads "not converged" with the levels' brackets side by side —
"beyond the grid" where every level, one finer at least, finds no bad run up to the
largest period (`validation.verdicts.resolution.resolve_limit`).  A level's bracket that
runs off the grid (`validation.verdicts.bisection.Lattice.runs_off`: Table 1's arm with a
sign SMO, 0.29 → 0.13 ms → below 0.1 ms) is left unbisected while the finer level finds
no bracket — 26 runs a case instead of 38 —, and bisected after all if it does.

The *predicted* limit is the exact zero-order-hold eigenvalue analysis of the case's own
linearised sampled loop (`validation.verdicts.sampled`): the law linearised from its
object (every gain it applies) at points of the reference, the plant linearised there —
the reduced model, or the FE arm with the case's mesh.
"""
from __future__ import annotations

import dataclasses
import json
import math
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass, field

from ..batch.campaign import PlannedRun

from ..batch.queue import run_planned
from ..batch.executor import Runner
from ..batch.store.runfiles import KEEP_NONE
from ..run.laws import applies_generalised_forces
from ..run.plants import is_truth, plant_settings, with_plant
from ..run.scenario import own_parameters, scenario_from_mapping, scenario_to_mapping
from ..batch.store.folder import ResultStore, run_id
from .bisection import GOOD, TOLERANCE, Lattice, Limit, limit_of, next_points
from .predictions import Predictions, prediction_key, read_predictions, write_predictions
from .resolution import ResolvedLimit, resolve_limit

__all__ = ["GRID", "DURATION", "TRACKING_LIMIT", "GROWTH_LIMIT", "MAX_LEVEL", "OUTCOMES",
           "StabilityCase", "Limit", "StabilityResult", "cases_from_scenarios",
           "stability_map", "load_stability", "outcome"]

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
OUTCOMES = ("stable", "lost tracking", "diverged", "failed")
_MAX_PLANT_STEP = 1e-3


#: The finest discretisation a truth-plant case is bisected at when its limits move
#: under refinement: level k has 2^k times the elements per link and 1/2^k of the step
#: (the default ANCF 4 el/link reaches 16 at level 2).
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
    def key(self) -> tuple:
        """What makes two cases one: the laws with their options, the plant and the arm."""
        return self.label, _options_key(self.base), self.plant, self.arm

    @property
    def truth(self) -> bool:
        """Whether the case runs on a truth plant."""
        return is_truth(self.base)

    @property
    def refines(self) -> bool:
        """Whether its limits are judged on the refined sequence: a truth plant with a
        discretisation to refine (the FE plant; a plug-in that declares no
        refinements has none)."""
        return self.truth and bool(plant_settings(self.base["plant"]).refinements())


@dataclass
class StabilityResult:
    case: StabilityCase
    tested: dict  # Ts -> (outcome, detail)
    divergence: Limit  # good = did not diverge (stable or lost tracking)
    tracking: Limit  # good = stable
    predicted: float  # NaN when no prediction exists for the law
    discretisation: str = ""  # truth plant: "ANCF 8 el/link, step ≤ 0.5 ms" of its runs
    #: Each limit ("divergence", "tracking") judged on the refined sequence.
    resolved: dict = field(default_factory=dict)
    runs: int = 0  # the runs the case took, every level together

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
        own = own_parameters(data)  # the scenario's own values, over whichever arm
        for plant in plants or (data["plant"]["kind"],):
            for arm in arms or (data["arm"],):
                base = dict(own, disturbances=[], initial_state="reference",
                            duration=DURATION, transient=DURATION / 2, requirement=[])
                base["plant"] = with_plant(base["plant"], plant)
                base["arm"] = arm
                if not plant_settings(base["plant"]).generalised_forces and \
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
    return json.dumps([config["controller"], config["observer"]], sort_keys=True)


def _scenario_at(case: StabilityCase, Ts: float) -> dict:
    data = dict(case.base, Ts=Ts)
    plant = plant_settings(case.base["plant"]).refined(case.level)
    if "step" in plant:  # a plug-in plant steps as it likes within a control period
        steps = math.ceil(Ts / _MAX_PLANT_STEP - 1e-9) * 2 ** case.level
        plant = dict(plant, step=Ts / steps)
    data["plant"] = plant
    return data


def outcome(row) -> tuple[str, str]:
    """(outcome, detail) of a stored stability run (module docstring)."""
    if row.status in ("diverged", "failed"):
        return row.status, row.message or row.status
    growth = row.metrics.get("growth_rate", math.nan)
    if growth > GROWTH_LIMIT:
        return "diverged", f"growing at {growth:.2g} 1/s (the torques' second difference " \
                           "over the second half)"
    worst = max((value for key, value in row.metrics.items() if key.startswith("track_max_")),
                default=math.inf)  # every joint's
    if not worst <= TRACKING_LIMIT:
        return "lost tracking", f"max |θ − θd| = {worst:.3g} rad over the second half"
    return "stable", f"max |θ − θd| = {worst:.3g} rad over the second half"


def _planned(case: StabilityCase, Ts: float) -> PlannedRun:
    scenario = scenario_from_mapping(_scenario_at(case, Ts))
    rid = run_id(scenario_to_mapping(scenario))
    return PlannedRun(rid, scenario, "stability", {"Ts": Ts, "plant.kind": case.plant,
                                                   "arm": case.arm, "level": case.level},
                      keep=KEEP_NONE)  # an outcome is a status and metrics


class _Search:
    """One case's bracket search, level by level: {Ts: (outcome, detail)} per level, and
    the level being searched (the finest, or one before it bisected after all)."""

    def __init__(self, case: StabilityCase, start: set[float] | Future, stored=()) -> None:
        # the levels a map in the folder measured ({Ts: outcome} each) start from there
        self.case, self.stored, self.level, self.levels = case, list(stored), 0, []
        self.start = set() if self.stored else start
        self._add_level()

    @property
    def waiting(self) -> bool:
        """Whether the search waits for its start: the prediction it starts from."""
        return isinstance(self.start, Future) and not self.start.done()

    @property
    def at(self) -> StabilityCase:
        """The case at the level being searched."""
        return StabilityCase(self.case.label, self.case.plant, self.case.arm, self.case.base,
                             self.level)

    def next_points(self, lattice: Lattice, refine: bool) -> set[float]:
        """The periods to test next at the level being searched.  When it is resolved:
        the next level's hints if a limit has not converged (and ``refine``); else, once
        the finest level brackets a limit, the bisection of a level before it left as it
        ran off the grid (`Lattice.runs_off`: no verdict reads a bracket that was not
        bisected); else nothing."""
        deeper = refine and self.case.refines
        while True:
            finest = len(self.levels) - 1
            if self.level == 0 and isinstance(self.start, Future):
                if self.waiting:
                    return set()
                hints = lattice.cell(self.start.result())
            else:
                hints = self.start if self.level == 0 else self.hints(self.level)
            before = self._limits_at(self.level - 1) \
                if deeper and 0 < self.level == finest < MAX_LEVEL else None
            points = next_points(self.levels[self.level], lattice, hints, before)
            if points:
                return points
            if self.level < finest:  # bisected after all: the finest is resolved
                self.level = finest
            elif deeper and finest < MAX_LEVEL and self._unconverged():
                self._add_level()
                self.level += 1
            elif (left := self._left_unbisected(lattice)) is not None:
                self.level = left
            else:
                return set()

    def _add_level(self) -> None:
        level = len(self.levels)
        self.levels.append(dict(self.stored[level]) if level < len(self.stored) else {})

    def _limits_at(self, level: int) -> dict[str, Limit]:
        return {name: limit_of(self.levels[level], good) for name, good in GOOD.items()}

    def _unconverged(self) -> bool:
        """Whether a limit of the levels so far is not converged (and none ends at a
        failed run: a failure is no bracket to refine)."""
        limits = _limits(self.levels).values()
        return not any(lim[-1].outcome == "failed" for lim in limits) and any(
            _resolve(self.case, lim, final=False).verdict in ("not checked", "not converged")
            for lim in limits)

    def _left_unbisected(self, lattice: Lattice) -> int | None:
        """The first level before the finest that has a bracket left as it ran off the
        grid, once the finest level brackets a limit after all (else None)."""
        if not any(math.isfinite(lim.largest) and math.isfinite(lim.first_bad)
                   for lim in self._limits_at(-1).values()):
            return None
        return next((level for level in range(1, len(self.levels) - 1)
                     if next_points(self.levels[level], lattice, self.hints(level))), None)

    def hints(self, level: int) -> set[float]:
        """The ends of the brackets of the level before ``level``."""
        return {Ts for lim in self._limits_at(level - 1).values()
                for Ts in (lim.largest, lim.first_bad) if not math.isnan(Ts)}


def _start(case: StabilityCase, lattice: Lattice, prediction: Future) -> set[float] | Future:
    """The periods a case tests first: the lattice cell of its predicted limit — for a law
    fed the true state, whose loop the prediction is — else the whole grid.  With an
    observer in the loop the prediction is the same law's without it, and the loop need
    not be monotone: the PBC with the position-only sign SMO on the default arm's reduced
    plant diverges at 2.51 ms and not at 3.05 ms, where its prediction lies.  The cell is
    the ``prediction`` (a `Future` of the period, `predictions.Predictions`) until it is
    known."""
    if case.base["observer"]["kind"] != "none":
        return set(lattice.grid)
    return prediction


def _limits(levels: list[dict]) -> dict[str, list[Limit]]:
    """Each limit's `Limit` per level."""
    return {name: [limit_of(tested, good) for tested in levels] for name, good in GOOD.items()}


def _resolve(case: StabilityCase, limits: list[Limit], *, final: bool) -> ResolvedLimit:
    levels = [(_discretisation(case.base, level), lim.largest, lim.first_bad)
              for level, lim in enumerate(limits)]
    return resolve_limit(levels, final=final, refined=case.refines)


def stability_map(cases: list[StabilityCase], out, *, runner: Runner | None = None,
                  progress: bool = True, mesh_check: bool = True,
                  tolerance: float = TOLERANCE) -> tuple[list[StabilityResult], object]:
    """Map every case into the results folder ``out`` (resumable like any campaign): from
    the outcomes of a map stored there (to any tolerance: the lattices nest, so a coarser
    map's brackets are bisected on), else from the lattice cell of its predicted limit
    (or the grid), the bracket searches and bisections to ``tolerance`` and, with
    ``mesh_check``, the truth-plant cases again on the refined sequence until their
    limits converge (module docstring).  Every round asks every case's next periods at once (the progress bar names the round); the
    predictions are computed beside the runs (`predictions.Predictions`), and a case that
    starts from its prediction joins the round after it is known.  Returns the results
    and the summary of every round together."""
    from .sampled import predicted_period  # python-control: not for a report without a map
    lattice, store = Lattice(GRID, tolerance), ResultStore(out)
    fresh = _rows(out, fresh_only=True) if store.exists() else []
    predictions = Predictions([c.base for c in cases], sorted(
        range(len(cases)), key=lambda i: cases[i].base["observer"]["kind"] != "none"),
        predicted_period)
    searches = [_Search(case, _start(case, lattice, predictions.futures[i]),
                        _stored(case, fresh)[0]) for i, case in enumerate(cases)]
    summary, round_ = None, 0
    try:
        while summary is None or not summary.interrupted:
            planned = {(i, s.at.level, Ts): _planned(s.at, Ts) for i, s in enumerate(searches)
                       for Ts in sorted(s.next_points(lattice, mesh_check))}
            if not planned:
                waiting = [s.start for s in searches if s.waiting]
                if waiting:  # nothing to run until a prediction says where to start
                    wait(waiting, return_when=FIRST_COMPLETED)
                    continue
                if summary is not None:
                    break
            round_ += 1
            label = "stability: start" if round_ == 1 else \
                f"stability: bisection {round_ - 1} (to {tolerance:.2g})"
            more = run_planned(planned.values(), out, name="stability", export=False,
                               description="sampled-data stability map", runner=runner,
                               progress=progress, label=label)
            summary = more if summary is None else summary + more
            if more.interrupted:
                break
            rows = {r.run_id: r for r in store.rows()}
            for (i, level, Ts), p in planned.items():
                searches[i].levels[level][Ts] = outcome(rows[p.run_id])
    finally:  # every prediction is made before the results are read (their cache)
        predictions.close(finish=summary is not None and not summary.interrupted)
    if summary.interrupted:
        return [], summary
    write_predictions(out, predictions.periods())  # a report reads them
    store.export()
    return load_stability(out, cases=cases), summary


def load_stability(out, *, fresh_only: bool = False, cases=None) -> list[StabilityResult]:
    """The stability map of a results folder, rebuilt from its stored runs (with
    ``fresh_only``, from the runs made by this code only; with ``cases``, those cases
    only), each case at every level it was mapped at and judged there.  Runs are found by
    what they are, not by the sweep that stored them first."""
    all_rows = _rows(out, fresh_only=fresh_only)
    if cases is None:  # every case mapped in the folder
        found: dict[tuple, StabilityCase] = {}
        for row in all_rows:
            if row.sweep == "stability" and not row.axes.get("level", 0):
                case = StabilityCase(_label(row.config), row.config["plant"]["kind"],
                                     row.config["arm"], row.config)
                found.setdefault(case.key, case)
        cases = list(found.values())
    cases = sorted(cases, key=lambda c: (c.label, c.truth, c.plant, c.arm != "default",
                                         c.arm))
    stored = read_predictions(out)  # the map's, if made by this code
    results = []
    for case in cases:
        levels, growth = _stored(case, all_rows)
        if levels:
            results.append(_result(case, levels, growth, stored.get(prediction_key(case.base))))
    return results


def _rows(out, *, fresh_only: bool) -> list:
    """The stored runs of the results folder ``out``; with ``fresh_only``, those made by
    this code (a campaign runs the others again)."""
    from ..batch.fingerprint import run_fingerprint
    return [r for r in ResultStore(out).rows()
            if not fresh_only or r.fingerprint == run_fingerprint(r.config)]


def _stored(case: StabilityCase, rows) -> tuple[list[dict], dict]:
    """{Ts: outcome} per level of ``case`` among ``rows``, coarsest first, up to the first
    level without a run; and {Ts: growth rate} of the finest level's runs."""
    levels, growth = [], {}
    for level in range(MAX_LEVEL + 1 if case.refines else 1):
        at = _rows_at(StabilityCase(case.label, case.plant, case.arm, case.base, level), rows)
        if not at:
            break
        levels.append({Ts: outcome(row) for Ts, row in at.items()})
        growth = {Ts: row.metrics.get("growth_rate", math.nan) for Ts, row in at.items()}
    return levels, growth


def _rows_at(case: StabilityCase, rows) -> dict:
    """{Ts: stored run} of ``case`` at its level."""
    out = {}
    plant = plant_settings(case.base["plant"]).refined(case.level)
    for row in rows:
        c = row.config
        if (c.get("name") != case.base.get("name") or c["arm"] != case.arm
                or c["plant"]["kind"] != case.plant
                or c["plant"].get("mesh") != _plain(plant.get("mesh"))
                or _options_key(c) != _options_key(case.base)):
            continue  # cheap tests first: the run id below builds a scenario
        Ts = float(c["Ts"])
        if row.run_id == _planned(case, Ts).run_id:
            out[Ts] = row
    return out


def _discretisation(config: dict, level: int) -> str:
    """"ANCF 8 el/link, step ≤ 0.5 ms" of a case's plant at ``level``."""
    plant = plant_settings(plant_settings(config["plant"]).refined(level))
    step = f"step ≤ {1e3 * _MAX_PLANT_STEP / 2 ** level:g} ms"
    return f"{plant.discretisation()}, {step}" if plant.discretisation() else step


def _plain(value):
    """A plant table's value as a resolved scenario stores it (lists, not tuples)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return [_plain(v) for v in value] if isinstance(value, (list, tuple)) else value


def _result(case: StabilityCase, levels: list[dict], growth: dict | None = None,
            predicted: float | None = None) -> StabilityResult:
    """The limits of the finest of ``levels`` ({Ts: outcome} per level, coarsest first),
    each judged on the sequence, the divergence limit with the band of its outcome test
    (`_band`, from ``growth``: {Ts: growth rate} of the finest level's runs); the
    prediction on the case's own plant (its base mesh: the FE prediction has converged at
    ANCF 4 el/link, and on a mesh 4× finer it costs minutes): ``predicted``, or computed
    here."""
    if predicted is None:  # python-control: not imported where the map kept its predictions
        from .sampled import predicted_period
        predicted = predicted_period(case.base)
    finest = len(levels) - 1
    tested = dict(sorted(levels[-1].items()))
    limits = _limits(levels)
    resolved = {name: _resolve(case, lims, final=finest == MAX_LEVEL)
                for name, lims in limits.items()}
    resolved["divergence"] = dataclasses.replace(
        resolved["divergence"], band=_band(limits["divergence"][-1], growth or {}))
    at = StabilityCase(case.label, case.plant, case.arm, case.base, finest)
    return StabilityResult(
        at, tested, limits["divergence"][-1], limits["tracking"][-1], predicted,
        discretisation=_discretisation(case.base, finest) if case.refines else "",
        resolved=resolved, runs=sum(map(len, levels)))


def _band(limit: Limit, growth: dict) -> float:
    """The outcome test's resolution below a divergence limit [s]: a run growing slower
    than `GROWTH_LIMIT` reads "stable", so the period at which the loop turns unstable
    (growth 0) lies up to GROWTH_LIMIT / (dg/dTs) below the bracket — the slope from the
    growth rates of the bracket's two runs (NaN where one has none, or it does not rise).
    Measured on the reduced plant's PBC: growth −1.15, +0.15, +1.43, +2.50 1/s at 3.056,
    3.062, 3.068, 3.073 ms; the band at 1 % is 0.013 ms."""
    low, high = limit.largest, limit.first_bad
    if limit.outcome != "diverged" or math.isnan(low) or math.isnan(high):
        return math.nan
    rise = growth.get(high, math.nan) - growth.get(low, math.nan)
    return GROWTH_LIMIT * (high - low) / rise if rise > 0 else math.nan
