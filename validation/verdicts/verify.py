"""Verdicts over uncertainty: how likely a requirement holds, where its worst case is, and
where the reduced model stops being valid (``flexarm verify``).

Three questions about one system (`validation.verdicts.uncertainty.System`) over its
uncertainty set, each answered in ``OUT/verdict.json``:

- **estimate** — N seeded draws on the system's own plant; P(holds) with an exact
  two-sided Clopper-Pearson interval at the stated level over every completed draw
  (``n``), and Wald's sequential test, with the draws at which it decided
  (``sequential.draws``; with ``[verify] sequential`` no further chunk of draws is
  run once it has: `validation.verdicts.statistics`).  A run
  that diverged fails every requirement; a run that failed (solver, law) is not data.
- **falsify** — minimise the requirement's robustness ρ over the set with CMA-ES
  (`validation.verdicts.search`) on the reduced plant (the designer's own model), and
  confirm candidates on the truth plant.  A candidate is a point whose *corrected*
  reduced robustness ρ_R + c is negative; the truth plant refuting one (ρ_T ≥ 0) makes
  it *spurious*, and every truth evaluation refits the correction c — an RBF
  interpolant of ρ_T − ρ_R over the evaluated points (a constant offset while there is
  one), so the search stops believing the reduced model where the truth plant has
  disagreed.  When a CMA-ES run stops without a candidate, its best point is confirmed
  anyway (the truth-confirmed worst case).  The search stops at the first counterexample
  the truth plant confirms — or, with ``[verify] worst_case = true``, goes on to the end
  of its budget confirming only points predicted below the lowest ρ confirmed so far
  (the worst case, not just a case).  A counterexample is written as a scenario file
  that ``flexarm run --config`` replays to the same ρ.  The truth-plant run behind the
  answer is repeated on the check meshes and with a quarter of its step
  (`validation.verdicts.mesh`): the answer is *converged* only if ρ keeps its sign in
  every check (a counterexample stays one), else *not converged*, with every check's ρ.
- **conform** — maximise the disagreement between the two plants on the same scenario,
  max over time and joints of |θ_truth − θ_reduced|, with CMA-ES; every point costs one
  simulation of each plant; the difference in each requirement's ρ is reported there.

Every evaluation is a run on the campaign runner (`run_campaign` on a local pool or
Dask), stored in the results folder as it finishes.  A search is a deterministic
function of its seed and of the stored values (the optimiser's randomness is seeded,
values are read back from the store), so after an interruption the same command replays
the stored evaluations without simulating them and continues to the same answer.
Simulations are counted per plant as the distinct scenarios a search asked for.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..batch.campaign import PlannedRun
from ..batch.queue import Batch, answer_all
from ..batch.resimulate import every_signal
from ..batch.store import ResultStore, run_id
from ..run.config import ConfigError
from ..run.requirements import Requirement
from ..run.results import write_atomic
from ..run.scenario import scenario_to_mapping
from ..run.tomlfiles import toml_text
from .mesh import MESH_SWEEP, check_runs, checks_of
from .search import CMASearch
from .statistics import clopper_pearson, sprt
from .uncertainty import System

__all__ = ["estimate", "estimate_question", "falsify", "falsify_question", "conform",
           "conform_question", "ROBUST_SWEEPS",
           "REDUCED_PER_TRUTH", "effective_rho", "write_verdict", "Evaluations"]

#: The sweep names the evaluations are stored under (reports keep them apart).
ROBUST_SWEEPS = ("estimate", "falsify", "conform")
#: The reduced-plant simulations a falsification may spend per truth-plant simulation of
#: its budget (a 20 s reduced run costs ~0.2 s, a truth run ~6 s).
REDUCED_PER_TRUTH = 20


def effective_rho(row, requirement: Requirement) -> float | None:
    """ρ of a stored run as the verdicts count it: −∞ for a run that diverged (it failed
    every requirement), None for a run that failed (no data); ConfigError if the
    requirement does not apply to the run (e.g. an estimation claim without observer)."""
    if row.status == "diverged":
        return -math.inf
    if row.status != "ok":
        return None
    value = row.metrics.get(requirement.metric, math.nan)
    if not isinstance(value, float) or math.isnan(value):
        raise ConfigError(f"--requirement {requirement.name}",
                          f"{requirement.text} has no value on run {row.run_id} (it does not "
                          "apply to this system)")
    return value


@dataclass
class Evaluations:
    """Scenarios run on the campaign runner into ``out`` (a folder, or a `BaseStore`: an
    in-memory one) and read back; simulations counted per plant role (distinct scenarios
    asked for).  A search asks with `run`; a question answered beside others (`queue`)
    yields `batch` and hands the rows it is sent to `record`."""

    out: object
    runner: object
    name: str
    seen: set = field(default_factory=set)
    count: dict = field(default_factory=lambda: {"reduced": 0, "truth": 0})
    failed: list = field(default_factory=list)
    description: str = "verdicts over uncertainty (flexarm verify)"  # the campaign's

    def __post_init__(self):
        self.store = ResultStore(self.out) if isinstance(self.out, (str, Path)) else self.out

    def batch(self, items: list[tuple]) -> Batch:
        """The batch of ``items`` = [(scenario, sweep, axes)]."""
        planned = [PlannedRun(run_id(scenario_to_mapping(scenario)), scenario, sweep, axes)
                   for scenario, sweep, axes in items]
        return Batch(self.out, self.name, planned, description=self.description)

    def record(self, batch: Batch, rows: list) -> list:
        """``rows`` (a batch's, in order), counted: simulations per plant, failed runs."""
        for p, row in zip(batch.runs, rows):
            if p.run_id not in self.seen:
                self.seen.add(p.run_id)
                self.count[p.scenario.plant.role] += 1
                if row.status == "failed":
                    self.failed.append(p.run_id)
        return rows

    def run(self, items: list[tuple]) -> list:
        """Rows of ``items`` = [(scenario, sweep, axes)], in order (run if not stored)."""
        batch = self.batch(items)
        return self.record(batch, answer_all([_ask(batch)], self.runner)[0])

    def finish(self) -> None:
        """Export metrics.csv and manifest.json once (not after every batch)."""
        self.store.export()
        self.store.close()

    @property
    def simulations(self) -> dict:
        return dict(self.count)


def _ask(batch: Batch):
    """A question of one batch: its answer is the batch's rows."""
    return (yield batch)


def _point_axes(point: dict, **extra) -> dict:
    return {**extra, **{k: (float(v) if isinstance(v, (float, np.floating)) else v)
                        for k, v in point.items()}}


def _number(value):
    """A JSON-safe number: None for NaN and ±∞ (the verdict says why elsewhere)."""
    return float(value) if value is not None and math.isfinite(value) else None


def write_verdict(out: Path, verdict: dict) -> Path:
    path = Path(out) / "verdict.json"
    write_atomic(path, lambda fh: json.dump(verdict, fh, indent=1, allow_nan=False))
    return path


def _write_scenario(out: Path, name: str, mapping: dict, comment: str) -> str:
    """Write a stored run's scenario ``mapping`` as the scenario file ``out/name`` that
    ``flexarm run --config`` replays: its run named by its label, as a scenario file
    names its one run (a plain name; "<campaign>/<label>" is a campaign's run)."""
    mapping = dict(mapping, name=mapping["name"].split("/")[-1])
    text = "".join(f"# {line}\n" for line in comment.splitlines()) + toml_text(mapping)
    write_atomic(Path(out) / name, lambda fh: fh.write(text))
    return name


# --- estimate ------------------------------------------------------------------------------------
def estimate(system: System, requirement: Requirement, out, *, runner, samples: int,
             seed: int, log=print) -> dict:
    """P(requirement holds) over ``samples`` seeded draws (module docstring)."""
    return answer_all([estimate_question(system, requirement, out, workers=runner.workers,
                                         samples=samples, seed=seed, log=log)], runner)[0]


def estimate_question(system: System, requirement: Requirement, out, *, workers: int,
                      samples: int, seed: int, log=print):
    """`estimate` as a question of the queue (`validation.batch.queue.answer_all`: the
    systems of ``flexarm verify`` are answered together on one runner of ``workers``).
    Every completed draw counts: the interval is over all of them (``n``); the
    sequential test reports the draws at which it decided (``sequential.draws``), and,
    with ``[verify] sequential``, no further chunk of draws is asked for after it has."""
    points, noise = system.uncertainty.draws(samples, seed)
    scenarios = [system.scenario(p, seed=s) for p, s in zip(points, noise)]  # all checked
    ev = Evaluations(Path(out), None, f"verify-estimate/{system.name}")
    settings = system.settings
    # Draws are run in order, in chunks when the sequential test may stop them early;
    # its decision uses the draws in order, so it does not depend on the chunk size.
    chunk = max(8, 4 * workers) if settings.sequential else samples
    rows: list = []
    while len(rows) < samples:
        draws = range(len(rows), min(samples, len(rows) + chunk))
        batch = ev.batch([(scenarios[i], "estimate", _point_axes(points[i], draw=i,
                                                                  seed=noise[i])) for i in draws])
        rows += ev.record(batch, (yield batch))
        outcomes = _outcomes(rows, requirement)
        decision, used = sprt(outcomes, settings.test)
        log(f"  {system.name}: {len(rows)}/{samples} draws, "
            f"{sum(not o for o in outcomes)} failures of {requirement.name}")
        if settings.sequential and decision != "inconclusive":
            break
    verdict = {"mode": "estimate", "system": system.name, "plant": system.nominal["plant"]["kind"],
               **_estimate_numbers(rows, requirement, system),
               "samples": samples, "draws": len(rows), "seed": seed,
               "noise_seeds": noise[:len(rows)], "distribution": system.uncertainty.describe(),
               "requirements": {r.name: _estimate_numbers(rows, r, system)
                                for r in system.requirements},
               "runs": [r.run_id for r in rows],
               "simulations": ev.simulations, "failed_runs": ev.failed}
    ev.finish()
    write_verdict(out, verdict)
    return verdict


def _outcomes(rows, requirement) -> list[bool]:
    """Held or not, for each completed draw in order (failed runs are not data)."""
    values = [effective_rho(r, requirement) for r in rows]
    return [v >= 0 for v in values if v is not None]


def _estimate_numbers(rows, requirement: Requirement, system: System) -> dict:
    values = [effective_rho(r, requirement) for r in rows]
    done = [v for v in values if v is not None]
    n, failures = len(done), sum(v < 0 for v in done)
    low, high = clopper_pearson(n - failures, n, system.settings.level)
    test = system.settings.test
    decision, draws = sprt([v >= 0 for v in done], test)
    finite = [v for v in done if math.isfinite(v)]
    return {"requirement": requirement.name, "criterion": requirement.text,
            "n": n, "failures": failures, "diverged": sum(r.status == "diverged" for r in rows),
            "p_hat": (n - failures) / n if n else None, "p_low": low, "p_high": high,
            "level": system.settings.level, "method": "Clopper-Pearson exact, two-sided",
            "sequential": {"method": "Wald SPRT", "p0": test.p0,
                           "indifference": test.indifference, "alpha": test.alpha,
                           "beta": test.beta, "decision": decision, "draws": draws},
            "rho_min": _number(min(done)) if done else None,
            "rho_median": _number(float(np.median(finite))) if finite else None,
            "rho_max": _number(max(finite)) if finite else None}


# --- falsify --------------------------------------------------------------------------------------
class _Correction:
    """c(u) ≈ ρ_truth − ρ_reduced: a constant offset from one truth evaluation, an RBF
    interpolant (linear kernel plus a constant, SciPy) from two or more."""

    def __init__(self) -> None:
        self.points, self.differences, self._rbf = [], [], None

    def add(self, u: np.ndarray, difference: float) -> None:
        if not math.isfinite(difference):
            return  # a divergence on one plant: no finite difference to learn from
        self.points.append(np.asarray(u, float))
        self.differences.append(float(difference))
        if len(self.points) >= 2:
            from scipy.interpolate import RBFInterpolator
            self._rbf = RBFInterpolator(np.array(self.points), np.array(self.differences),
                                        kernel="linear", degree=0)

    def __call__(self, U: np.ndarray) -> np.ndarray:
        if not self.points:
            return np.zeros(len(U))
        if self._rbf is None:
            return np.full(len(U), self.differences[0])
        return self._rbf(np.asarray(U, float))


def falsify(system: System, requirement: Requirement, out, *, runner, budget: int,
            seed: int, log=print) -> dict:
    """A truth-confirmed counterexample — or with ``[verify] worst_case``, the lowest ρ
    the truth plant confirms within the budget — over the set (module docstring)."""
    return answer_all([falsify_question(system, requirement, out, budget=budget, seed=seed,
                                        log=log)], runner)[0]


def _asked(ev: Evaluations, items: list[tuple]):
    """Ask for ``items``' rows (a question's step: ``rows = yield from _asked(...)``)."""
    batch = ev.batch(items)
    return ev.record(batch, (yield batch))


def falsify_question(system: System, requirement: Requirement, out, *, budget: int,
                     seed: int, log=print):
    """`falsify` as a question of the queue (`validation.batch.queue.answer_all`: the
    systems of ``flexarm verify`` searched together on one runner)."""
    out = Path(out)
    u_dim = system.uncertainty.dim
    ev = Evaluations(out, None, f"verify-falsify/{system.name}")
    search = CMASearch(u_dim, seed)
    correction = _Correction()
    truth: dict[tuple, dict] = {}  # point key -> {u, rho_reduced, rho_truth, row}
    reduced_budget = REDUCED_PER_TRUTH * budget
    best_run = None  # the current CMA-ES run's best (value, u, rho_reduced)
    best_reduced = None  # (rho, u) over the whole search
    trace, spurious, found = [], [], None
    worst_case = system.settings.worst_case
    # A point is confirmed on the truth plant when its corrected reduced ρ is below this:
    # 0 (a counterexample); when looking for the worst case, then the lowest ρ confirmed.
    threshold = 0.0

    def confirm(u, rho_reduced: float, predicted: float) -> bool:
        """Run the truth plant at ``u`` (``predicted``: the corrected reduced ρ there);
        True when the search is over."""
        nonlocal found, threshold
        point = system.uncertainty.at(u)
        (row,) = yield from _asked(ev, [(system.scenario(point, plant="truth"), "falsify",
                                         _point_axes(point, role="confirm"))])
        rho_truth = effective_rho(row, requirement)
        entry = {"u": u, "point": point, "rho_reduced": rho_reduced, "rho_truth": rho_truth,
                 "row": row}
        truth[tuple(u)] = entry
        log(f"  truth plant at {_label(point)}: ρ = {requirement.rho_text(rho_truth)} "
            f"(reduced {requirement.rho_text(rho_reduced)})")
        if rho_truth is None:
            return False  # the run failed: nothing learnt
        correction.add(u, rho_truth - rho_reduced)
        if rho_truth >= 0:
            if predicted < 0:  # the reduced plant (corrected) said it fails: spurious
                spurious.append(entry)
            return False
        if found is None or rho_truth < found["rho_truth"]:
            found = entry
        threshold = found["rho_truth"] if worst_case else threshold
        return not worst_case or found["rho_truth"] == -math.inf  # nothing is worse

    done = False
    while not done and ev.count["truth"] < budget and ev.count["reduced"] < reduced_budget:
        restarts = search.restarts
        U = search.ask()
        if search.restarts != restarts and best_run is not None:
            # The previous CMA-ES run stopped: its best point is the worst case it found;
            # confirm it on the truth plant.
            if tuple(best_run[1]) not in truth and (yield from confirm(
                    best_run[1], best_run[2], best_run[0])):
                break
            best_run = None
        U = U[:reduced_budget - ev.count["reduced"]]  # the last generation may be cut
        points = [system.uncertainty.at(u) for u in U]
        rows = yield from _asked(ev, [(system.scenario(p, plant="reduced"), "falsify",
                                       _point_axes(p, role="search")) for p in points])
        rho_r = np.array([_search_value(effective_rho(r, requirement)) for r in rows])
        corrected = rho_r + correction(U)
        if len(U) == search.popsize:
            search.tell(corrected)
        for u, value, rho in zip(U, corrected, rho_r):
            if math.isfinite(rho) and (best_reduced is None or rho < best_reduced[0]):
                best_reduced = (float(rho), u)
            if best_run is None or value < best_run[0]:
                best_run = (float(value), u, float(rho))
        candidates = [i for i in np.argsort(corrected, kind="stable")
                      if corrected[i] < threshold and tuple(U[i]) not in truth]
        if candidates and ev.count["truth"] < budget:
            i = candidates[0]
            done = yield from confirm(U[i], float(rho_r[i]), float(corrected[i]))
        trace.append({"reduced": ev.count["reduced"], "truth": ev.count["truth"],
                      "best_rho_reduced": _number(best_reduced[0]) if best_reduced else None,
                      "best_rho_truth": _number(min((e["rho_truth"] for e in truth.values()
                                                     if e["rho_truth"] is not None),
                                                    default=math.inf))})
    if not done and best_run is not None and tuple(best_run[1]) not in truth \
            and ev.count["truth"] < budget:
        yield from confirm(best_run[1], best_run[2], best_run[0])  # the last run's best
    return (yield from _falsify_verdict(system, requirement, out, ev, found, truth,
                                        spurious, trace, budget, seed, search))


def _search_value(rho: float | None) -> float:
    """ρ as the optimiser sees it: a failed run tells nothing (+∞ ranks it last)."""
    return math.inf if rho is None else rho


def _label(point: dict) -> str:
    return ", ".join(f"{p} = {v:.4g}" if isinstance(v, float) else f"{p} = {v}"
                     for p, v in point.items())


def _falsify_verdict(system, requirement, out, ev, found, truth, spurious, trace, budget,
                     seed, search):
    """The verdict of a search (a question's last steps: the checks of its answer)."""
    confirmed = [e for e in truth.values() if e["rho_truth"] is not None]
    worst = found or (min(confirmed, key=lambda e: e["rho_truth"]) if confirmed else None)
    verdict = {"mode": "falsify", "system": system.name, "requirement": requirement.name,
               "criterion": requirement.text, "found": found is not None,
               "rho_reduced": _number(worst["rho_reduced"]) if worst else None,
               "rho_truth": _number(worst["rho_truth"]) if worst else None,
               "counterexample": None, "worst_case": None, "simulations": ev.simulations}
    if worst is not None:
        row = worst["row"]
        comment = (f"{'Counterexample' if found else 'Worst case found'} of requirement "
                   f"{requirement.name} ({requirement.text}) for {system.name}: truth plant, "
                   f"rho = {worst['rho_truth']!r} ({row.status}); reduced plant rho = "
                   f"{worst['rho_reduced']!r}.\nReplay: flexarm run --config THIS_FILE")
        name = _write_scenario(out, "counterexample.toml" if found else "worst-case.toml",
                               row.config, comment)
        verdict["counterexample" if found else "worst_case"] = name
        verdict["point"] = _point_axes(worst["point"])
        verdict["truth_status"] = row.status + (f": {row.message}" if row.message else "")
        verdict["runs"] = {"truth": row.run_id}
        verdict["convergence"] = yield from _convergence(ev, row, requirement,
                                                         worst["rho_truth"])
    verdict |= {"spurious": [{"point": _point_axes(e["point"]),
                              "rho_reduced": _number(e["rho_reduced"]),
                              "rho_truth": _number(e["rho_truth"])} for e in spurious],
                "truth_evaluations": len(truth),
                "budget": {"truth": budget, "reduced": REDUCED_PER_TRUTH * budget},
                "optimiser": f"CMA-ES (cma), IPOP restarts: {search.restarts}",
                "correction": "RBF (linear kernel + constant) of rho_truth - rho_reduced",
                "seed": seed, "distribution": system.uncertainty.describe(),
                "trace": trace, "failed_runs": ev.failed}
    ev.finish()
    write_verdict(out, verdict)
    return verdict


def _convergence(ev: Evaluations, row, requirement: Requirement, rho: float):
    """(A question's step.)  The truth-plant run ``row`` (robustness ``rho``) repeated on the check meshes and
    with a finer step: "converged" if ρ has the same sign in every check, "not
    converged" if it changes sign in one, "check failed" if a check run failed; with
    every check's ρ."""
    planned = check_runs([row])
    yield Batch(ev.out, MESH_SWEEP, planned,
                description="closed-loop convergence of the truth-plant runs")
    by_id = {r.run_id: r for r in ev.store.rows()}
    checks = checks_of(row, by_id)
    rhos = {label: None if check is None else effective_rho(check, requirement)
            for label, check in checks.items()}
    if any(r is not None and (r < 0) != (rho < 0) for r in rhos.values()):
        verdict = "not converged"
    else:
        verdict = "check failed" if any(r is None for r in rhos.values()) else "converged"
    return {"verdict": verdict,
            "checks": {label: {"status": "not run" if check is None else check.status,
                               "rho": None if rhos[label] is None else _number(rhos[label])}
                       for label, check in checks.items()}}


# --- conform --------------------------------------------------------------------------------------
def conform(system: System, out, *, runner, budget: int, seed: int, log=print) -> dict:
    """The largest disagreement between the two plants over the set (module docstring)."""
    return answer_all([conform_question(system, out, budget=budget, seed=seed, log=log)],
                      runner)[0]


def conform_question(system: System, out, *, budget: int, seed: int, log=print):
    """`conform` as a question of the queue (`validation.batch.queue.answer_all`)."""
    out = Path(out)
    ev = Evaluations(out, None, f"verify-conform/{system.name}")
    search = CMASearch(system.uncertainty.dim, seed)
    best, trace = None, []
    while ev.count["truth"] < budget:
        U = search.ask()[:budget - ev.count["truth"]]
        points = [system.uncertainty.at(u) for u in U]
        items = []
        for p in points:
            for role in ("reduced", "truth"):
                items.append((system.scenario(p, plant=role), "conform",
                              _point_axes(p, plant=role)))
        rows = yield from _asked(ev, items)
        distances = []
        for k, p in enumerate(points):
            reduced, truth = rows[2 * k], rows[2 * k + 1]
            d = _distance(ev.store, reduced, truth)
            distances.append(d)
            if d is not None and (best is None or d > best[0]):
                best = (d, p, reduced, truth)
        if len(U) == search.popsize:
            search.tell([-d if d is not None else None for d in distances])
        trace.append({"reduced": ev.count["reduced"], "truth": ev.count["truth"],
                      "distance": _number(best[0]) if best else None})
        log(f"  {system.name}: {ev.count['truth']}/{budget} points, largest |θ_truth − "
            f"θ_reduced| {best[0] if best else float('nan'):.4g} rad")
    verdict = {"mode": "conform", "system": system.name, "distance": None, "scenario": None,
               "simulations": ev.simulations}
    if best is not None:
        d, point, reduced, truth = best
        comment = (f"Largest disagreement between the plants found for {system.name}: max |theta"
                   f"_truth - theta_reduced| = {d!r} rad.\nThis is the truth-plant scenario; "
                   "set plant.kind = \"reduced\" for the other.")
        verdict |= {"distance": _number(d), "unit": "rad",
                    "scenario": _write_scenario(out, "conform.toml", truth.config, comment),
                    "point": _point_axes(point),
                    "status": {"reduced": reduced.status, "truth": truth.status},
                    "rho_difference": {r.name: _rho_difference(reduced, truth, r)
                                       for r in system.requirements},
                    "runs": {"reduced": reduced.run_id, "truth": truth.run_id}}
    verdict |= {"optimiser": f"CMA-ES (cma), IPOP restarts: {search.restarts}", "seed": seed,
                "budget": {"truth": budget}, "distribution": system.uncertainty.describe(),
                "trace": trace, "failed_runs": ev.failed}
    ev.finish()
    write_verdict(out, verdict)
    return verdict


def _distance(store, reduced, truth) -> float | None:
    """max over time and joints of |θ_truth − θ_reduced| (stored signals, common span);
    +∞ when exactly one plant diverged, None when a run failed."""
    if "failed" in (reduced.status, truth.status):
        return None
    if (reduced.status == "diverged") != (truth.status == "diverged"):
        return math.inf
    a, b = every_signal(store, reduced), every_signal(store, truth)
    n = min(a.time.size, b.time.size)
    diff = a.select(["theta1", "theta2"])[:, :n].astype(float) - \
        b.select(["theta1", "theta2"])[:, :n].astype(float)
    return float(np.abs(diff).max()) if n else None


def _rho_difference(reduced, truth, requirement: Requirement):
    try:
        r, t = effective_rho(reduced, requirement), effective_rho(truth, requirement)
    except ConfigError:
        return None
    if r is None or t is None or not (math.isfinite(r) and math.isfinite(t)):
        return None
    return t - r
