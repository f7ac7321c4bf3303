"""Falsification (``flexarm verify --mode falsify``): a counterexample of a requirement over
an uncertainty set, found on the reduced plant and confirmed on the truth plant.

Minimise the requirement's robustness ρ over the set with CMA-ES
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
that ``flexarm run --config`` replays to the same ρ.

A point the truth plant fails is a counterexample only at the resolution it is found
at: its run is repeated on the refined sequence (the mesh and the step refined together,
twice and four times) and on the other element formulation (`validation.verdicts.mesh`),
and the verdict carries ρ on every level, the observed order, the Richardson ρ and its
error (`refined_rho`).  A ρ that changes sign under refinement, or whose |ρ| is inside
its error, is "undecided at this resolution" — not a counterexample: the search goes
on.  A counterexample is "converged" when the error is at most 10 % of |ρ|
(`validation.verdicts.resolution.resolve_rho`), else "not converged" (the sign stands,
the value does not).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..batch.queue import Batch, answer_all
from ..run.plants import plant_settings
from ..run.requirements import Requirement
from .evaluations import (Evaluations, asked, effective_rho, number, point_axes,
                          write_scenario, write_verdict)
from .mesh import MESH_SWEEP, check_runs, checks_of, refinements
from .resolution import UNDECIDED, resolve_rho
from .search import CMASearch
from .uncertainty import System

__all__ = ["falsify", "falsify_question", "REDUCED_PER_TRUTH", "refined_rho"]

#: The reduced-plant simulations a falsification may spend per truth-plant simulation of
#: its budget (a 20 s reduced run costs ~0.2 s, a truth run ~6 s).
REDUCED_PER_TRUTH = 20


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
    trace, spurious, undecided, found = [], [], [], None
    worst_case = system.settings.worst_case
    # A point is confirmed on the truth plant when its corrected reduced ρ is below this:
    # 0 (a counterexample); when looking for the worst case, then the lowest ρ confirmed.
    threshold = 0.0

    def confirm(u, rho_reduced: float, predicted: float) -> bool:
        """Run the truth plant at ``u`` (``predicted``: the corrected reduced ρ there);
        True when the search is over."""
        nonlocal found, threshold
        point = system.uncertainty.at(u)
        (row,) = yield from asked(ev, [(system.scenario(point, plant="truth"), "falsify",
                                         point_axes(point, role="confirm"))])
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
        if found is not None and rho_truth >= found["rho_truth"]:
            return found["rho_truth"] == -math.inf  # worst case: no lower than the one found
        entry["refined"] = yield from refined_rho(ev, row, requirement, rho_truth)
        if entry["refined"]["verdict"] == UNDECIDED:
            undecided.append(entry)  # not a counterexample at this resolution
            return False
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
        rows = yield from asked(ev, [(system.scenario(p, plant="reduced"), "falsify",
                                       point_axes(p, role="search")) for p in points])
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
                      "best_rho_reduced": number(best_reduced[0]) if best_reduced else None,
                      "best_rho_truth": number(min((e["rho_truth"] for e in truth.values()
                                                     if e["rho_truth"] is not None),
                                                    default=math.inf))})
    if not done and best_run is not None and tuple(best_run[1]) not in truth \
            and ev.count["truth"] < budget:
        yield from confirm(best_run[1], best_run[2], best_run[0])  # the last run's best
    return (yield from _falsify_verdict(system, requirement, out, ev, found, truth,
                                        spurious, undecided, trace, budget, seed, search))


def _search_value(rho: float | None) -> float:
    """ρ as the optimiser sees it: a failed run tells nothing (+∞ ranks it last)."""
    return math.inf if rho is None else rho


def _label(point: dict) -> str:
    return ", ".join(f"{p} = {v:.4g}" if isinstance(v, float) else f"{p} = {v}"
                     for p, v in point.items())


def _falsify_verdict(system, requirement, out, ev, found, truth, spurious, undecided, trace,
                     budget, seed, search):
    """The verdict of a search (a question's last steps: the refined sequence of its
    answer, if not run yet)."""
    confirmed = [e for e in truth.values() if e["rho_truth"] is not None]
    worst = found or (min(confirmed, key=lambda e: e["rho_truth"]) if confirmed else None)
    verdict = {"mode": "falsify", "system": system.name, "requirement": requirement.name,
               "criterion": requirement.text, "found": found is not None,
               "verdict": "counterexample" if found else UNDECIDED if undecided
               else "no counterexample found",
               "rho_reduced": number(worst["rho_reduced"]) if worst else None,
               "rho_truth": number(worst["rho_truth"]) if worst else None,
               "counterexample": None, "worst_case": None, "simulations": ev.simulations}
    if worst is not None:
        row = worst["row"]
        if "refined" not in worst:
            worst["refined"] = yield from refined_rho(ev, row, requirement, worst["rho_truth"])
        what = "Counterexample" if found else "Worst case found"
        comment = (f"{what} of requirement {requirement.name} ({requirement.text}) for "
                   f"{system.name}: truth plant, rho = {worst['rho_truth']!r} ({row.status}); "
                   f"reduced plant rho = {worst['rho_reduced']!r}; on the refined sequence: "
                   f"{worst['refined']['verdict']}.\nReplay: flexarm run --config THIS_FILE")
        name = write_scenario(out, "counterexample.toml" if found else "worst-case.toml",
                              row.config, comment)
        verdict["counterexample" if found else "worst_case"] = name
        verdict["point"] = point_axes(worst["point"])
        verdict["truth_status"] = row.status + (f": {row.message}" if row.message else "")
        verdict["runs"] = {"truth": row.run_id}
        verdict["convergence"] = worst["refined"]
    verdict |= {"spurious": [{"point": point_axes(e["point"]),
                              "rho_reduced": number(e["rho_reduced"]),
                              "rho_truth": number(e["rho_truth"])} for e in spurious],
                "undecided": [{"point": point_axes(e["point"]),
                               "rho_truth": number(e["rho_truth"]),
                               "convergence": e["refined"]} for e in undecided],
                "truth_evaluations": len(truth),
                "budget": {"truth": budget, "reduced": REDUCED_PER_TRUTH * budget},
                "optimiser": f"CMA-ES (cma), IPOP restarts: {search.restarts}",
                "correction": "RBF (linear kernel + constant) of rho_truth - rho_reduced",
                "seed": seed, "distribution": system.uncertainty.describe(),
                "trace": trace, "failed_runs": ev.failed}
    ev.finish()
    write_verdict(out, verdict)
    return verdict


def refined_rho(ev: Evaluations, row, requirement: Requirement, rho: float):
    """(A question's step.)  ρ of the truth-plant run ``row`` (robustness ``rho``) on the
    refined sequence and the other formulation, judged by
    `validation.verdicts.resolution.resolve_rho`: the verdict, the rule, ρ on every level
    (``levels``, coarsest first), the observed order, the Richardson ρ and its error, and
    every check's status and ρ (null where it is not a finite number: its status says
    why)."""
    yield Batch(ev.out, MESH_SWEEP, check_runs([row]),
                description="closed-loop convergence of the truth-plant runs")
    by_id = {r.run_id: r for r in ev.store.rows()}
    checks = checks_of(row, by_id)
    rhos = {label: None if check is None else effective_rho(check, requirement)
            for label, check in checks.items()}
    level = {r.label: r.level for r in refinements(row.config)}
    sequence = {plant_settings(row.config["plant"]).discretisation(): rho}
    sequence |= {label: v for label, v in rhos.items() if level.get(label)}
    others = {label: v for label, v in rhos.items() if not level.get(label)}
    judged = resolve_rho(sequence, others)
    every = {label: {"status": "not run" if check is None else check.status,
                     "rho": None if rhos[label] is None else number(rhos[label])}
             for label, check in checks.items()}
    own = next(iter(sequence))
    levels = {own: {"status": row.status, "rho": number(rho)}} | {
        label: every[label] for label in sequence if label != own}
    return {"verdict": judged["verdict"], "rule": judged["rule"], "levels": levels,
            "order": number(judged["order"]), "rho": number(judged["rho"]),
            "error": number(judged["error"]), "checks": every}
