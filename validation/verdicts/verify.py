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
- **falsify** — a truth-confirmed counterexample (or the worst case) found by CMA-ES on
  the reduced plant, with its robustness on the refined sequence
  (`validation.verdicts.falsify`).
- **conform** — maximise the disagreement between the two plants on the same scenario,
  max over time and joints of |θ_truth − θ_reduced|, with CMA-ES; every point costs one
  simulation of each plant; the difference in each requirement's ρ is reported there.

The evaluations are runs of the results store (`validation.verdicts.evaluations`): a
search resumed after an interruption replays them to the same answer.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..batch.queue import answer_all
from ..batch.store.resimulate import every_signal
from ..run.config import ConfigError
from ..run.requirements import Requirement
from .evaluations import (Evaluations, asked, effective_rho, number, point_axes,
                          write_scenario, write_verdict)
from .falsify import falsify, falsify_question
from .search import CMASearch
from .statistics import clopper_pearson, sprt
from .uncertainty import System

__all__ = ["estimate", "estimate_question", "falsify", "falsify_question",
           "conform_question"]


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
        batch = ev.batch([(scenarios[i], "estimate", point_axes(points[i], draw=i,
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
            "rho_min": number(min(done)) if done else None,
            "rho_median": number(float(np.median(finite))) if finite else None,
            "rho_max": number(max(finite)) if finite else None}


# --- conform --------------------------------------------------------------------------------------
def conform_question(system: System, out, *, budget: int, seed: int, log=print):
    """The largest disagreement between the two plants over the set (module docstring), as
    a question of the queue (`validation.batch.queue.answer_all`)."""
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
                              point_axes(p, plant=role)))
        rows = yield from asked(ev, items)
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
                      "distance": number(best[0]) if best else None})
        log(f"  {system.name}: {ev.count['truth']}/{budget} points, largest |θ_truth − "
            f"θ_reduced| {best[0] if best else float('nan'):.4g} rad")
    verdict = {"mode": "conform", "system": system.name, "distance": None, "scenario": None,
               "simulations": ev.simulations}
    if best is not None:
        d, point, reduced, truth = best
        comment = (f"Largest disagreement between the plants found for {system.name}: max |theta"
                   f"_truth - theta_reduced| = {d!r} rad.\nThis is the truth-plant scenario; "
                   "set plant.kind = \"reduced\" for the other.")
        verdict |= {"distance": number(d), "unit": "rad",
                    "scenario": write_scenario(out, "conform.toml", truth.config, comment),
                    "point": point_axes(point),
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
