"""A whole calibration (``flexarm calibrate``): the fit and its verdict, the physics an
inadequate model lacks searched for, the comparison with other fits, and the files.

Where the model is inadequate, the candidates the screen found significant
(`validation.verdicts.calibration.extensions`) are fitted as extensions of the user's
model, most significant first, until one is adequate or `extensions.FITTED` have been
tried, and ranked by AIC = 2 cost + 2p.  The adequate one is written beside the fit
(``OUT/extended/``: its calibration, ``calibrated.toml`` and, if every parameter of it
is identifiable, ``uncertainty.toml``: with one that is not, the others' intervals hold
only at its estimate — the reduced plant with a Stribeck effect left out (breakaway
0.375), its velocity 0.01 rad/s barely seen by the data and fitted as 0.0102: EI1, EI2,
Mp 2.2-2.5 standard errors off; a drive with backlash left out, the backlash 2.04e-4
(2e-4) not identifiable: the gear's stiffness 3006 ± 1.1 N m/rad (3000), its damping 4.8
standard errors off).  An inadequate model's intervals are of effective parameters and
need not hold the physical arm (the drive with backlash left out: the payload 38 %
high), so its ``uncertainty.toml`` — the set ``flexarm verify`` draws the arm from — is
not written unless asked for (``export_inadequate``, ``--export-inadequate``), and then
with a warning in it.  An extension whose fit cannot be computed (`FitFailed`: its
simulations failed) is named in the search's record and verdict, and the next one is
tried.

A calibration whose own fit cannot be computed — every simulation failed, or those its
estimate or intervals rest on did — raises `FitFailed` and writes no result files (the
simulations stay in the folder, as runs).
"""
from __future__ import annotations

from pathlib import Path

from ..evaluations import FIT_SWEEP, Evaluations
from .comparison import comparison
from .extensions import FITTED, candidates, extended
from .fit import fit_plan
from .outputs import EXTENDED, write_inputs, write_results
from .plan import Plan
from .problem import FitFailed, Problem

__all__ = ["calibrate"]


def _estimate(plan: Plan, result: dict) -> dict:
    return {q.name: result["parameters"][q.name]["estimate"] for q in plan.settings.parameters}


def _fit(plan: Plan, extension, probe: dict, start: dict, evals, inputs, log) -> tuple:
    """The plan's model with ``extension`` (its new fields from ``probe``, the plan's
    own from ``start``) fitted: its plan, fit and AIC."""
    own = {q.name: start[q.name] for q in plan.settings.parameters}
    wider = extended(plan, extension, {k: probe[k] for k in extension.changes},
                     start=own)
    log(f"  trying the model with {extension.name}")
    fit = fit_plan(wider, Problem(wider, evals, inputs), lambda line: log("  " + line),
                   screened=False)
    return wider, fit, 2 * fit["cost"] + 2 * len(wider.settings.parameters)


def _search(plan: Plan, evals: Evaluations, inputs: list[dict], result: dict, log):
    """Fit the significant candidates of ``result``'s screen (module docstring): the
    search's record for calibration.json, and the adequate (plan, fit) or None."""
    estimate = _estimate(plan, result)
    found = {e.name: e for e in candidates(plan, estimate)}
    probes = {r["name"]: r["probe"] for r in result["screen"]}
    fits: dict[str, tuple] = {}
    failed: dict[str, str] = {}  # name → why its fit could not be computed
    for row in [r for r in result["screen"] if r["significant"]]:
        chain = [found[row["name"]]]
        while chain[0].builds_on in found and chain[0].builds_on not in fits:
            chain.insert(0, found[chain[0].builds_on])
        for extension in chain:
            if extension.name in fits or extension.name in failed or len(fits) == FITTED:
                continue
            below = fits.get(extension.builds_on)
            start = estimate if below is None else _estimate(below[0], below[1])
            probe = probes[extension.name] if below is None else \
                {**{k: start[k] for k in extension.fitted if k in start},
                 **{k: v for k, v in extension.changes.items() if k not in start}}
            try:
                fits[extension.name] = _fit(plan, extension, probe, start, evals, inputs, log)
            except FitFailed as exc:
                failed[extension.name] = str(exc)
                log(f"  {extension.name}: {exc}")
                continue
            if fits[extension.name][1]["model_adequate"]:
                break
        if any(f[1]["model_adequate"] for f in fits.values()) or len(fits) == FITTED:
            break
    tried = sorted(({"name": name, "fitted": list(wider.settings.names),
                     "model_adequate": fit["model_adequate"],
                     "verdict": fit["adequacy"]["verdict"], "cost": fit["cost"], "aic": aic,
                     "parameters": {n: {k: v[k] for k in ("estimate", "interval",
                                                          "identifiable")}
                                    for n, v in fit["parameters"].items()}}
                    for name, (wider, fit, aic) in fits.items()), key=lambda r: r["aic"])
    for row in tried:
        row["delta_aic"] = row["aic"] - tried[0]["aic"]
    adequate = [r for r in tried if r["model_adequate"]]
    names = ", ".join(r["name"] for r in result["screen"]) or "none applies"
    without = 2 * result["cost"] + 2 * len(plan.settings.parameters)
    if adequate:
        verdict = (f"with {adequate[0]['name']} the model is adequate (AIC "
                   f"{adequate[0]['aic']:.6g}, against {without:.6g} without): its fit is in "
                   f"{EXTENDED}/")
    elif tried:
        verdict = (f"none of the extensions tried makes the model adequate; the best, "
                   f"{tried[0]['name']}, lowers AIC from {without:.6g} to "
                   f"{tried[0]['aic']:.6g} (fitted: {', '.join(r['name'] for r in tried)}; "
                   f"screened: {names})")
    elif failed:
        verdict = f"no extension could be fitted (screened: {names})"
    else:
        verdict = ("no physics extension the toolkit has explains the residual (screened: "
                   f"{names}): the model misses something else")
    if failed:
        verdict += "; not fitted, their simulations failed: " + "; ".join(
            f"{name} ({why})" for name, why in failed.items())
    best = fits[adequate[0]["name"]][:2] if adequate else None
    if best is not None:
        # an unidentifiable parameter's partners have intervals conditional on its
        # value (a Stribeck velocity the data barely see: EI1 5 standard errors off)
        blind = [n for n, p in best[1]["parameters"].items() if not p["identifiable"]]
        best[1]["exported"] = not blind
        if blind:
            best[1]["interval_kind"] += (f"; conditional on {', '.join(blind)} (not "
                                         "identifiable): not exported to uncertainty.toml")
    return {"screen": result["screen"], "fits": tried, "failed": failed,
            "adequate": adequate[0]["name"] if adequate else None, "verdict": verdict}, best


def calibrate(plan: Plan, out, *, runner, log=print, compare=(), store=None,
              search: bool = True, export_inadequate: bool = False) -> dict:
    """Fit the plan's parameters, judge the model and search for what an inadequate one
    lacks (module docstring; the fit: `validation.verdicts.calibration.fit`).

    Parameters
    ----------
    plan : Plan
        From `plan_calibration`.
    out : path-like
        The results folder: the experiments (``experiments/NAME.csv`` and the torques
        replayed, ``.npy``), the simulations (``runs/``, index), ``calibration.json``,
        ``calibrated.toml``, ``uncertainty.toml`` and ``extended/`` are written there.
    runner : callable
        Runs a list of planned scenarios (`make_runner`).
    log : callable
        Receives one line per iteration.
    compare : list of (str, dict)
        Other fits of the same data (`comparison.read_fits`): the result gets
        a ``comparison`` of them and this one.
    store : BaseStore, optional
        Where the simulations are kept (default: the folder ``out``, which a calibration
        stopped and started again resumes from); an in-memory store
        (`validation.batch.store.memory.MemoryStore`) keeps them in this process, every signal
        in float64, nothing written to ``runs/``.
    search : bool
        Fit the physics extensions an inadequate model may lack (module docstring);
        without, the screen alone ranks them.
    export_inadequate : bool
        Write ``uncertainty.toml`` for a model the tests call inadequate (its ranges are
        of effective parameters, and may exclude the arm's values).

    Returns
    -------
    dict
        What ``calibration.json`` holds: estimates, standard errors, correlations,
        residuals, the verdict on the fit and, for an inadequate model, ``extensions``.

    Raises
    ------
    FitFailed
        The fit could not be computed: every simulation failed, or those its estimate or
        its intervals rest on did (module docstring); no result file is written.
    """
    out = Path(out)
    inputs = write_inputs(plan, out)
    evals = Evaluations(store or out, runner, FIT_SWEEP, description=(
        "the plant's parameters fitted to measured experiments (flexarm calibrate)"))
    try:  # a fit that cannot be computed (FitFailed) leaves its simulations, indexed
        result = fit_plan(plan, Problem(plan, evals, inputs), log)
        better = None
        if result["model_adequate"] is False and search:
            result["extensions"], better = _search(plan, evals, inputs, result, log)
    finally:
        if plan.targets:  # a fit of frequency responses alone simulates nothing: no store
            evals.finish()
    result["simulations"] = len(evals.seen)
    result["failed_runs"] = evals.failed
    result["exported"] = result["model_adequate"] is not False or export_inadequate
    if compare:
        result["comparison"] = comparison([(str(out), result), *compare])
    write_results(out, plan, result, better)
    return result
