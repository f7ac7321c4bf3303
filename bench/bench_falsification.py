"""Verdicts over uncertainty, measured: the planted counterexample and the cost of a
statistical verdict on the truth plant.

Parts (``--part``, default all but ``cost``):

- ``volume``: the planted counterexample (bench/planted.toml: the PBC detuned so that the
  disturbance claim fails only in a corner of a 4-D set) — its failing fraction of the
  set's volume from ``--samples`` (20 000) seeded reduced-plant draws, with the exact
  95 % interval.  Target: ≤ 0.5 %.
- ``search``: ARCH-COMP style over ``--seeds`` (20) seeds with a truth budget of 50: the
  two-fidelity falsification (`flexarm verify --mode falsify`) against uniform random
  search on the truth plant with the same budget — success rate, mean and median
  simulations per plant of the successful runs.  Targets: ≥ 19/20 found with a median
  ≤ 50 truth simulations; random search ≤ 5/20.
- ``optimisers``: which optimiser drives the reduced-plant search best — CMA-ES (the
  ``cma`` package), SciPy's ``differential_evolution`` and ``dual_annealing`` — as the
  reduced-plant simulations until the first point with ρ < 0 (cap 400), over
  ``--seeds`` seeds.
- ``cost``: 59 truth-plant draws of campaigns/robust.toml's PBC + boundary-layer SMO
  (20 s runs, two workers).  Target: ≤ 5 min.  The load average is printed with it:
  the machine is shared.

Runs go to ``--out`` (default results/bench-falsification); the tables to stdout and
bench/results/falsification-<part>.json.  Rerunning resumes from the stored runs (the
searches replay them without simulating: the printed wall times are only meaningful on
a fresh folder).
"""
from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench._report import report, target  # noqa: E402
from validation.batch.executor import make_runner  # noqa: E402
from validation.verdicts.uncertainty import load_systems  # noqa: E402
from validation.verdicts.evaluations import Evaluations, effective_rho  # noqa: E402
from validation.verdicts.verify import estimate, falsify  # noqa: E402
from validation.verdicts.search import CMASearch  # noqa: E402

PLANTED = ROOT / "bench" / "planted.toml"
TRUTH_BUDGET = 50
OPTIMISER_CAP = 400


def quiet(*_args, **_kwargs) -> None:
    pass


def part_volume(system, out, runner, samples: int) -> None:
    req = system.requirements[0]
    t0 = time.perf_counter()
    v = estimate(system, req, out / "volume", runner=runner, samples=samples, seed=0, log=quiet)
    fraction = v["failures"] / v["n"]
    low, high = 1 - v["p_high"], 1 - v["p_low"]
    rows = [{"what": "failing fraction of the set (reduced plant)", "samples": v["n"],
             "failures": v["failures"], "fraction": fraction, "ci95_low": low, "ci95_high": high,
             "wall_s": time.perf_counter() - t0, **target(fraction, "<=", 0.005)},
            {"what": "exact 95 % upper end of the fraction", "samples": v["n"],
             "fraction": high, **target(high, "<=", 0.005)}]
    report("falsification-volume", rows, title="Planted counterexample: failing volume",
           columns=["what", "samples", "failures", "fraction", "ci95_low", "ci95_high",
                    "wall_s", "target", "met"])


def _summary(method: str, results: list[dict]) -> dict:
    """ARCH-COMP columns: successes, and mean / median simulations of the successful runs."""
    won = [r for r in results if r["found"]]
    row = {"method": method, "success": f"{len(won)}/{len(results)}"}
    for plant in ("truth", "reduced"):
        sims = [r[plant] for r in won]
        row[f"mean_{plant}"] = statistics.fmean(sims) if sims else math.nan
        row[f"median_{plant}"] = statistics.median(sims) if sims else math.nan
    row["found"] = len(won)
    return row


def part_search(system, out, runner, seeds: int) -> None:
    req = system.requirements[0]
    ours = []
    for seed in range(seeds):
        v = falsify(system, req, out / "falsify", runner=runner, budget=TRUTH_BUDGET, seed=seed,
                    log=quiet)
        ours.append({"found": v["found"], **v["simulations"], "spurious": len(v["spurious"])})
        print(f"  falsify seed {seed}: found {v['found']}, simulations {v['simulations']}, "
              f"spurious {len(v['spurious'])}", flush=True)
    rand = []
    for seed in range(seeds):
        rand.append(_random_search(system, req, out / "random", runner, seed))
        print(f"  random seed {seed}: {rand[-1]}", flush=True)
    a, b = _summary("two-fidelity CMA-ES (verify --mode falsify)", ours), \
        _summary("uniform random search, truth plant", rand)
    a |= target(a["found"], ">=", 19 * seeds / 20)
    a_median = dict(method=a["method"] + ": median truth simulations", success=a["success"],
                    median_truth=a["median_truth"], **target(a["median_truth"], "<=", TRUTH_BUDGET))
    b |= target(b["found"], "<=", 5 * seeds / 20)
    a["spurious_total"] = sum(r["spurious"] for r in ours)
    report("falsification-search", [a, a_median, b],
           title=f"Planted counterexample: {seeds} seeds, truth budget {TRUTH_BUDGET} (ARCH-COMP "
                 "style: means and medians over the successful runs)",
           columns=["method", "success", "mean_truth", "median_truth", "mean_reduced",
                    "median_reduced", "spurious_total", "target", "met"])


def _random_search(system, req, out, runner, seed: int) -> dict:
    """Uniform draws on the truth plant, in order, until one fails or the budget is spent."""
    ev = Evaluations(out, runner, f"bench-random/{system.name}")
    rng = np.random.default_rng([seed, 77])
    U = rng.random((TRUTH_BUDGET, system.uncertainty.dim))
    batch = 2 * getattr(runner, "workers", 1)
    for start in range(0, TRUTH_BUDGET, batch):
        points = [system.uncertainty.at(u) for u in U[start:start + batch]]
        rows = ev.run([(system.scenario(p, plant="exudyn"), "random", {"seed": seed})
                       for p in points])
        for k, row in enumerate(rows):
            rho = effective_rho(row, req)
            if rho is not None and rho < 0:
                return {"found": True, "truth": start + k + 1, "reduced": 0}
    return {"found": False, "truth": TRUTH_BUDGET, "reduced": 0}


class _Found(Exception):
    pass


def _reduced_objective(system, req, ev, counter: dict):
    """ρ on the reduced plant of a batch of unit-cube points; raises _Found at the first
    ρ < 0 or when the cap is reached (counter["n"]: simulations so far)."""
    def f(U):
        U = np.atleast_2d(U)
        points = [system.uncertainty.at(u) for u in U]
        rows = ev.run([(system.scenario(p, plant="reduced"), "optimisers", {}) for p in points])
        values = []
        for row in rows:
            counter["n"] += 1
            rho = effective_rho(row, req)
            values.append(math.inf if rho is None else rho)
            if values[-1] < 0:
                counter["found"] = True
                raise _Found
            if counter["n"] >= OPTIMISER_CAP:
                raise _Found
        return np.array(values)
    return f


def part_optimisers(system, out, runner, seeds: int) -> None:
    from scipy.optimize import differential_evolution, dual_annealing
    req = system.requirements[0]
    dim = system.uncertainty.dim
    bounds = [(0.0, 1.0)] * dim

    def cma(f, seed):
        search = CMASearch(dim, seed)
        while True:
            search.tell(f(search.ask()))

    def de(f, seed):
        differential_evolution(lambda X: f(X.T), bounds, seed=seed, vectorized=True,
                               updating="deferred", polish=False, maxiter=10_000, tol=0)

    def da(f, seed):
        dual_annealing(lambda x: float(f(x)[0]), bounds, seed=seed, maxfun=10 * OPTIMISER_CAP)

    rows = []
    for name, method in (("CMA-ES (cma)", cma), ("differential_evolution (SciPy)", de),
                         ("dual_annealing (SciPy)", da)):
        results = []
        for seed in range(seeds):
            counter = {"n": 0, "found": False}
            ev = Evaluations(out / "optimisers", runner, f"bench-optimisers/{name}")
            try:
                method(_reduced_objective(system, req, ev, counter), seed)
            except _Found:
                pass
            results.append({"found": counter["found"], "reduced": counter["n"], "truth": 0})
            print(f"  {name} seed {seed}: {results[-1]}", flush=True)
        row = _summary(name, results)
        rows.append({k: row[k] for k in ("method", "success", "mean_reduced", "median_reduced")})
    report("falsification-optimisers", rows,
           title=f"Reduced-plant simulations to the first rho < 0 on the planted "
                 f"counterexample (cap {OPTIMISER_CAP}; over the successful runs)",
           columns=["method", "success", "mean_reduced", "median_reduced"])


def part_cost(out, runner) -> None:
    (system,) = [s for s in load_systems(ROOT / "campaigns" / "robust.toml")
                 if s.name == "pbc+smo-bl"]
    load_before = os.getloadavg()
    t0 = time.perf_counter()
    v = estimate(system, system.requirements[0], out / "cost", runner=runner, samples=59,
                 seed=12345, log=quiet)
    wall = time.perf_counter() - t0
    rows = [{"what": "59 truth-plant draws, 20 s each (robust.toml, PBC + smo-bl)",
             "runs": v["simulations"]["truth"] + v["simulations"]["reduced"], "wall_s": wall,
             "load_before": f"{load_before[0]:.1f}", "load_after": f"{os.getloadavg()[0]:.1f}",
             **target(wall, "<=", 300.0)}]
    report("falsification-cost", rows, title="Cost of a statistical verdict on the truth plant "
                                             "(2 workers; the load average is the machine's)",
           columns=["what", "runs", "wall_s", "load_before", "load_after", "target", "met"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", action="append",
                        choices=("volume", "search", "optimisers", "cost"))
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--samples", type=int, default=20_000)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="results/bench-falsification")
    args = parser.parse_args()
    parts = args.part or ["volume", "search", "optimisers"]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (system,) = load_systems(PLANTED)
    with make_runner("local", args.workers) as runner:
        if "volume" in parts:
            part_volume(system, out, runner, args.samples)
        if "search" in parts:
            part_search(system, out, runner, args.seeds)
        if "optimisers" in parts:
            part_optimisers(system, out, runner, args.seeds)
        if "cost" in parts:
            part_cost(out, runner)


if __name__ == "__main__":
    main()
