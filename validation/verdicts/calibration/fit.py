"""Calibration: the plant's physical parameters fitted to measured experiments, with
honest uncertainty (``flexarm calibrate``).

The fit minimises the weighted output error r (`validation.verdicts.calibration.problem`),
a bounded nonlinear least-squares problem solved by SciPy's ``least_squares``.  A response is
compared by the logarithm of its ratio (log-magnitude and phase error, equal to the
relative error where they agree): the difference of two sharp resonances a few per cent
apart is dominated by the peaks, the logarithm of their ratio is not.  G is the plant
linearised about rest (`linear_response`: the FE arm of the scenario's mesh, or the
reduced model), no time simulation.  As the time series grow their horizon (below), the
responses grow their band: from ``frf_band`` (1 Hz, below the free arm's first bending
mode) doubling to the highest frequency measured — fitting all of 0.5-40 Hz at once
from EI 30 % off stopped 30 % off (from 5 % off it converged); the growing band
converged from 30 % off on both plants.

**Inputs.**  A time-domain experiment is reproduced on the scenario's plant by replaying
its recorded joint torques open loop (``inputs = "replay"``, the ``replay`` law) or by
running the experiment's own controller and observer in the loop (``"closed-loop"``:
the scenario as it is, its sensor noise and seed included).  Replay is the default
because it conditions the fit better on a free-joint arm: with the controller in the
loop, feedback corrects the very deviations a parameter error causes — that is what a
robust tracking loop is for — so the outputs see the arm's parameters less.  Measured on
the reduced plant (PBC fed the true state, eq. (37), 10 s, the campaigns' sensor noise),
fitting EI1, EI2 and Mp: cond(J) 8.2 replayed against 68 in the loop, standard errors
5.0e-7, 2.2e-6, 3.7e-6 (relative) against 1.5e-6, 1.5e-5, 3.7e-5.  Replay also needs
nothing the lab cannot record: the torques are what the arm received, noise and
disturbances included, where a closed-loop fit must reproduce the experiment's noise
realisation as well (with the experiment's own seed the residual is zero, and so is
the standard error it would report).  Its price is a narrow basin: open loop, an error
in the arm's inertia or stiffness accumulates (the joints integrate the torque twice,
the vibration drifts out of phase), so a 10 s output error is far from quadratic.
From five starts 20 % to 5× off, a fit of the whole 10 s record converged (all three
within 1 %) in 0 of 5 cases replayed and 2 of 5 in the loop.  The fit therefore *grows
its horizon*: it is solved on the first ``horizon`` seconds (0.1 s: a fraction of the
first vibration period, where the output error is nearly linear in the parameters),
then on twice that, and so on up to the whole record, each stage starting from the last
estimate: 5 of 5 converged either way (744 simulations replayed, 522 in the loop).

**Method.**  SciPy's dogleg with rectangular trust regions (``method="dogbox"``), not its
trust-region reflective method (``"trf"``): both took about as many simulations on a
well-posed fit (EI1, EI2, Mp from three starts up to 5× off: 121, 145, 152 against 127,
135, 118), but where the data cannot see a direction (mh2 and stator_mass, mh1, with
EI1) the reflective method's scaling damped every step: 30 evaluations took its cost
from 3.2e7 to 7.6e3, at a linear rate of 0.8 per step, where dogbox reached the data's
floor (5e-7) in 6.  The directions the Jacobian cannot resolve are removed from it
before each step (`_without_invisible`).

**Jacobians** are forward differences (``fd_step`` relative to the starting values,
1e-3): the simulations of one Jacobian are independent runs, submitted together to the
campaign runner (local worker processes or Dask), stored in the output folder like any
run (sweep ``calibrate``) and read back from it — so an interrupted calibration, rerun,
replays what is stored and continues to the same answer.  A replayed experiment's
torques are a file in the output folder, named in the scenario by path and SHA-256: Dask
workers must see that folder at the same path.

**At the estimate** the fit is refined by Gauss–Newton steps whose Jacobian differences
over a few standard errors of each parameter (`validation.verdicts.calibration.polish`):
where stick–slip makes the outputs jump, the fit's own steps are secants over many of
them.  The verdict on the model, the noise model, the intervals and the physics a
model lacks: `adequacy`, `noise`, `intervals` and `extensions` of
`validation.verdicts.calibration`.

**Failed simulations.**  The optimiser reads a sample a simulation did not reach as a
penalty, so a trial point whose simulation failed (or diverged early) is rejected and the
fit goes on; so does the Jacobian of the fit's steps at the estimate, which only sets the
scale of the refinement's.  The result is not computed from one: where the residual at
the estimate or the Jacobian its intervals rest on (the refinement's) lacks a sample, the
fit is refused with `FitFailed` — every simulation failed (the first's reason), or the
latest that did (`Problem.failure`) — and no verdict is given
(`validation.verdicts.calibration.problem`).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.optimize

from ...batch.store.folder import run_id
from ...run.scenario import scenario_to_mapping
from .adequacy import adequacy, noise_models, physics_missed, residual_blocks, residual_rms
from .comparison import data_fingerprint, model_description
from .differences import STENCILS, jacobian, without_invisible
from .extensions import screen
from .intervals import parameter_uncertainty
from .noise import sandwich_meat
from .plan import Plan
from .polish import polish
from .problem import FitFailed, Problem, together

__all__ = ["fit_plan"]

#: A direction is invisible when its singular value is below this many times the noise
#: the float32 storage of the signals puts into a difference column.
_RESOLUTION_MARGIN = 10.0


# --- the fit -----------------------------------------------------------------------------
def _doubling(first: float, last: float) -> list[float]:
    """first, 2·first, 4·first… below ``last``, then ``last`` (the module docstring's
    growing horizon; a last step shorter than a quarter of the one before is merged)."""
    out, h = [], first
    while h < last * 0.75:
        out.append(h)
        h *= 2
    return out + [last]


def _stages(plan: Plan) -> list[dict]:
    """The horizon [s] of the time series and the band [Hz] of the frequency responses
    fitted at each stage, both doubling until every sample and frequency is in."""
    settings = plan.settings
    longest = max([t.experiment.duration for t in plan.targets], default=0.0)
    Ts = min([t.experiment.Ts for t in plan.targets], default=0.0)
    highest = max([float(r.frequency[-1]) for r in plan.responses], default=0.0)
    horizons = _doubling(max(settings.horizon, 2 * Ts), longest) if plan.targets else [0.0]
    bands = _doubling(settings.frf_band, highest) if plan.responses else [0.0]
    n = max(len(horizons), len(bands))
    pad = lambda v: v + [v[-1]] * (n - len(v))  # noqa: E731
    return [{"horizon": h, "band": b} for h, b in zip(pad(horizons), pad(bands))]


def _solve(problem: Problem, u: np.ndarray, lower, upper, log) -> tuple[np.ndarray, list]:
    """The staged least-squares fit from ``u`` (module docstring): the estimate and a
    record of each stage."""
    plan, settings = problem.plan, problem.settings
    cache: dict[bytes, np.ndarray] = {}

    def fun(v):
        key = v.tobytes()
        if key not in cache:
            cache[key] = problem.penalised([v])[0]
        return cache[key]

    def jac(v):
        J = problem.jacobian(v, fun(v), upper)
        floor = _RESOLUTION_MARGIN * problem.resolution(STENCILS["forward"])
        return without_invisible(J, floor, settings.fd_step)

    stages = []
    for stage in _stages(plan):
        problem.horizon, problem.band = stage["horizon"], stage["band"]
        cache.clear()
        res = scipy.optimize.least_squares(
            fun, np.clip(u, lower, upper), jac=jac, bounds=(lower, upper), method="dogbox",
            x_scale=1.0, max_nfev=settings.max_iterations)
        u = res.x
        stages.append({**stage, "iterations": int(res.njev),
                       "evaluations": int(res.nfev), "cost": float(res.cost),
                       "status": int(res.status), "message": res.message})
        where = ", ".join(f"{k} {stage[k]:g} {unit}" for k, unit, on in (
            ("horizon", "s", plan.targets), ("band", "Hz", plan.responses)) if on)
        values = ", ".join(f"{q.short} = {x:.6g}"
                           for q, x in zip(settings.parameters, u * problem.scale))
        log(f"  {where}: cost {res.cost:.6g} after {res.njev} iterations ({values})")
    problem.horizon = problem.band = math.inf
    return u, stages


def _floor(problem: Problem, steps: list[dict]) -> np.ndarray:
    """Each column's float32 noise, at its own step and formula (norm)."""
    fd = problem.settings.fd_step
    return np.array([_RESOLUTION_MARGIN * problem.resolution(STENCILS[s["formula"]]) * fd
                     / s["step"] for s in steps])


def _complete(problem: Problem, values: np.ndarray, what: str) -> np.ndarray:
    """``values`` (the residual or the Jacobian of the result) if every sample they rest
    on was simulated; else `FitFailed`, saying why (module docstring)."""
    if not np.isfinite(values).all():
        raise FitFailed(problem.failure(what))
    return values


def fit_plan(plan: Plan, problem: Problem, log, start: np.ndarray | None = None, *,
             screened: bool = True) -> dict:
    """Fit ``plan`` on ``problem`` from its starts (or ``start``, in units of the
    scales) and judge the result: what ``calibration.json`` holds, less what the
    results folder adds (the comparison, the extensions' fits).  With ``screened``, a
    model whose residual is correlated has the physics it may lack screened
    (`extensions.screen`: a correlated residual at the stated level is coloured noise
    only if no candidate explains it), the screen kept under ``screen``.  `FitFailed`
    where the result would rest on a failed simulation (module docstring)."""
    settings = plan.settings
    lower = np.array([q.lower for q in settings.parameters]) / problem.scale
    upper = np.array([q.upper for q in settings.parameters]) / problem.scale
    u = np.array([q.start for q in settings.parameters]) / problem.scale if start is None \
        else start
    u, stages = _solve(problem, u, lower, upper, log)
    r = _complete(problem, problem.residuals([u])[0], "the residual at its estimate")
    fd = settings.fd_step
    widest = fd * np.maximum(np.abs(u), 1.0)
    halves_noise = _RESOLUTION_MARGIN * problem.resolution(STENCILS["halves"]) * fd
    # the fit's steps set only the scale of the refinement's: a column whose simulations
    # failed is read penalised there, as the optimiser reads it (its standard error
    # reads tiny: the refinement starts at its narrowest steps)
    J, steps = jacobian(problem.penalised, u, r, widest, lower, upper, halves_noise)
    u, r, J, steps, refined = polish(
        problem.residuals, u, r, J, lower, upper, largest=widest,
        column_noise=problem.resolution(STENCILS["central"]) * fd,
        halves_noise=halves_noise, floor=_floor(problem, steps), collinear=fd)
    _complete(problem, J, "the Jacobian of its intervals")
    if refined:
        log(f"  refined at the scale of the uncertainty: {refined} step(s), cost "
            f"{0.5 * float(r @ r):.6g}")
    floor = _floor(problem, steps)
    estimate = u * problem.scale
    blocks = residual_blocks(plan, r)
    verdict = adequacy(blocks, judged=settings.inputs == "replay")
    rows, models = [b.rows for b in blocks], noise_models(blocks, verdict)
    found = []
    if screened and verdict["model_adequate"] is not None and (
            not verdict["model_adequate"] or verdict["noise_coloured"]):
        found = screen(plan, lambda pairs: together(
            [(Problem(p, problem.evals, problem.inputs), v) for p, v in pairs]),
            u, r, J, rows, models)
        if verdict["model_adequate"] and found and found[0]["significant"]:
            verdict = physics_missed(verdict, found[0])
    effective = verdict["model_adequate"] is not True
    coloured = not effective and verdict["noise_coloured"]
    stats = parameter_uncertainty(
        J, r, settings.names, estimate, problem.scale, floor=floor,
        bounds=[(q.lower, q.upper) for q in settings.parameters],
        model_error=verdict["model_error"] if effective else None,
        noise_variance=verdict["noise_variance"],
        meat=sandwich_meat(J, rows, models) if coloured else None)
    for name, step, x in zip(settings.names, steps, problem.scale):
        stats["parameters"][name]["jacobian"] = {**step, "step": step["step"] * float(x)}
    return {
        "model_adequate": verdict["model_adequate"], "adequacy": verdict,
        "parameters": stats["parameters"], "interval_kind": stats["interval_kind"],
        "correlation": stats["correlation"], "residual_rms": residual_rms(plan, blocks),
        "model": model_description(plan), "data": data_fingerprint(plan),
        "cost": float(0.5 * r @ r), "iterations": sum(s["iterations"] for s in stages),
        "refinements": refined, "screen": found,
        "residual_variance": stats["residual_variance"], "dof": stats["dof"],
        "singular_values": stats["singular_values"], "jacobian_floor": floor.tolist(),
        "inputs": settings.inputs, "stages": stages,
        "experiments": [{"name": t.experiment.name, "source": t.experiment.source,
                         "samples": t.experiment.samples, "Ts": t.experiment.Ts,
                         "signals": list(t.experiment.names),
                         "run": run_id(scenario_to_mapping(problem.scenario(i, u, math.inf)))}
                        for i, t in enumerate(plan.targets)],
        "responses": [{"name": r_.name, "source": r_.source,
                       "pairs": [f"{o}/{i}" for o, i in r_.pairs]} for r_ in plan.responses],
    }
