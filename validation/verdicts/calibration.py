"""Calibration: the plant's physical parameters fitted to measured experiments, with
honest uncertainty (``flexarm calibrate``).

The fit minimises the weighted output error, a bounded nonlinear least-squares problem
solved by SciPy's ``least_squares``::

    r = [(y_sim,s(t_k; x) − y_meas,s(t_k)) / σ_s   for every experiment, signal s, sample k]
      + [ln(G(jω; x) / G_meas(jω)) / σ_frf   re and im, for every response and frequency]

x are scenario fields (``true_params.EI1``…) in units of their starting values; σ_s is
the noise level of signal s (the scenario's sensor noise, or ``[calibrate.noise]``);
σ_frf the relative error of a measured response (``frf_noise``, 1 %).  A response is
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

**Uncertainty** rests on a Jacobian of second order at the estimate, each column checked
for a jump of the outputs within its step (stick–slip: `validation.verdicts.
calibration_differences`); the intervals and the verdict on the model:
`validation.verdicts.calibration_intervals` and `validation.verdicts.calibration_adequacy`.
"""
from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import scipy.optimize

from ..batch.store import run_id
from ..run.config import ConfigError
from ..run.experiments import Experiment, FrequencyResponse
from ..run.scenario import Scenario, scenario_from_mapping, scenario_to_mapping
from ..run.tomlfiles import deep_merge, set_dotted
from .calibration_adequacy import adequacy, residual_blocks, residual_rms
from .calibration_comparison import comparison, data_fingerprint, model_description
from .calibration_differences import STENCILS, settled_jacobian
from .calibration_intervals import parameter_uncertainty
from .calibration_outputs import write_inputs, write_results
from .calibration_plan import Plan, linear_response
from ..batch.resimulate import every_signal
from .evaluations import FIT_SWEEP, Evaluations

__all__ = ["calibrate"]

#: Residual, in noise levels, of a sample a simulation did not reach (it diverged or
#: failed at a trial point): far beyond any fit, so the step is rejected.
_PENALTY = 1e3
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


def _samples(exp: Experiment, horizon: float) -> int:
    """The samples of ``exp`` within its first ``horizon`` seconds (at least two)."""
    if horizon >= exp.duration:
        return exp.samples
    return max(2, round(horizon / exp.Ts))


class _Problem:
    """The residuals of a plan at points u (the parameters over their scales), each
    simulation a stored run on the campaign runner."""

    def __init__(self, plan: Plan, out, runner, inputs: list[dict]) -> None:
        self.plan, self.settings = plan, plan.settings
        self.scale = np.array([p.scale for p in plan.settings.parameters])
        self.inputs = inputs  # per target: the scenario keys that reproduce its input
        self.evals = Evaluations(out, runner, FIT_SWEEP, description=(
            "the plant's parameters fitted to measured experiments (flexarm calibrate)"))
        self.horizon = self.band = math.inf

    # scenarios
    def scenario(self, i: int, u: np.ndarray, horizon: float) -> Scenario | None:
        """Target ``i``'s scenario at ``u`` over its first ``horizon`` seconds (None if the
        arm there cannot be modelled: a trial point the fit must reject)."""
        target = self.plan.targets[i]
        data = deep_merge(target.scenario, self.inputs[i])
        for p, x in zip(self.settings.parameters, u * self.scale):
            set_dotted(data, p.name, float(x))
        exp = target.experiment
        data["duration"] = _samples(exp, horizon) * exp.Ts
        data.pop("transient", None)
        data["name"] = f"{FIT_SWEEP}/{exp.name}"
        try:
            return scenario_from_mapping(data)
        except ConfigError:
            return None

    def _axes(self, i: int, u: np.ndarray, horizon: float) -> dict:
        exp = self.plan.targets[i].experiment
        return {"experiment": exp.name, "horizon": _samples(exp, horizon) * exp.Ts,
                **{p.name: float(x) for p, x in zip(self.settings.parameters, u * self.scale)}}

    # residuals
    def residuals(self, points: list[np.ndarray]) -> list[np.ndarray]:
        """The weighted residual vector at each of ``points`` (their simulations run as
        one batch)."""
        items, where = [], {}
        for n, u in enumerate(points):
            for i in range(len(self.plan.targets)):
                s = self.scenario(i, u, self.horizon)
                if s is not None:
                    where[n, i] = len(items)
                    items.append((s, FIT_SWEEP, self._axes(i, u, self.horizon)))
        rows = self.evals.run(items) if items else []
        out = []
        for n, u in enumerate(points):
            parts = [self._time_residual(i, rows[where[n, i]] if (n, i) in where else None)
                     for i in range(len(self.plan.targets))]
            parts += [self._frf_residual(r, u) for r in self.plan.responses]
            out.append(np.concatenate(parts) if parts else np.zeros(0))
        return out

    def samples(self, i: int) -> int:
        return _samples(self.plan.targets[i].experiment, self.horizon)

    def _time_residual(self, i: int, row) -> np.ndarray:
        target, k = self.plan.targets[i], self.samples(i)
        exp = target.experiment
        measured = exp.signals[:, :k]
        r = np.full(measured.shape, _PENALTY)
        if row is not None and row.status != "failed":
            result = every_signal(self.evals.store, row)
            done = min(k, len(result.time))
            sim = result.select([f"y_{n}" for n in exp.names])[:, :done].astype(np.float64)
            r[:, :done] = (sim - measured[:, :done]) / target.sigma[:, None]
        return r.ravel()

    def _frf_residual(self, response: FrequencyResponse, u: np.ndarray) -> np.ndarray:
        data = copy.deepcopy(self.plan.base)
        for p, x in zip(self.settings.parameters, u * self.scale):
            set_dotted(data, p.name, float(x))
        try:
            s = scenario_from_mapping(data)
            G = linear_response(s, self.settings.frf_theta, response.frequency, response.pairs)
        except (ConfigError, ArithmeticError, np.linalg.LinAlgError):
            return np.full(2 * response.values.size, _PENALTY)
        e = np.log(G / response.values) / self.settings.frf_noise
        e = e[:, :self.frequencies(response)]
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    def frequencies(self, response: FrequencyResponse) -> int:
        """How many of the response's frequencies the current band holds (at least 2)."""
        return max(2, int(np.searchsorted(response.frequency, self.band, side="right")))

    # the fit's callables
    def jacobian(self, u: np.ndarray, f: np.ndarray, upper) -> np.ndarray:
        """Forward differences at ``u`` (``f`` its residual), one batch of simulations (a
        step that would cross the upper bound goes down); the fit's steps.  The Jacobian
        the uncertainty rests on is `settled_jacobian`'s."""
        p = len(u)
        h = self.settings.fd_step * np.maximum(np.abs(u), 1.0)
        h = np.where(u + h > upper, -h, h)
        unit = np.eye(p)
        values = self.residuals([u + h[j] * unit[j] for j in range(p)])
        return np.column_stack([(values[j] - f) / h[j] for j in range(p)])

    def resolution(self, stencil: float) -> float:
        """The noise the float32 storage of the simulated signals puts into one column of
        the difference Jacobian (norm, in the residual's units per unit of u): a rounding
        error of spacing δ is uniform, variance δ²/12, and a difference formula Σ c_i f_i / h
        has variance ``stencil`` δ²/(12 h²), ``stencil`` = Σ c_i² (`calibration_differences.STENCILS`)."""
        total = 0.0
        for i, target in enumerate(self.plan.targets):
            k = self.samples(i)
            spacing = np.spacing(np.abs(target.experiment.signals[:, :k]).astype(np.float32))
            total += float(np.sum((spacing.astype(np.float64) / target.sigma[:, None]) ** 2))
        return math.sqrt(total * stencil / 12.0) / self.settings.fd_step


def calibrate(plan: Plan, out, *, runner, log=print, compare=(), store=None) -> dict:
    """Fit the plan's parameters with scipy's ``least_squares`` (module docstring).

    Parameters
    ----------
    plan : Plan
        From `plan_calibration`.
    out : path-like
        The results folder: the experiments (``experiments/NAME.csv`` and the torques
        replayed, ``.npy``), the simulations (``runs/``, index), ``calibration.json``,
        ``calibrated.toml`` and ``uncertainty.toml`` are written there.
    runner : callable
        Runs a list of planned scenarios (`make_runner`).
    log : callable
        Receives one line per iteration.
    compare : list of (str, dict)
        Other fits of the same data (`calibration_comparison.read_fits`): the result gets
        a ``comparison`` of them and this one.
    store : BaseStore, optional
        Where the simulations are kept (default: the folder ``out``, which a calibration
        stopped and started again resumes from); an in-memory store
        (`validation.batch.memory.MemoryStore`) keeps them in this process, every signal
        in float64, nothing written to ``runs/``.

    Returns
    -------
    dict
        What ``calibration.json`` holds: estimates, standard errors, correlations,
        residuals and the verdict on the fit.
    """
    out = Path(out)
    settings = plan.settings
    inputs = write_inputs(plan, out)
    problem = _Problem(plan, store or out, runner, inputs)
    lower = np.array([q.lower for q in settings.parameters]) / problem.scale
    upper = np.array([q.upper for q in settings.parameters]) / problem.scale
    u = np.array([q.start for q in settings.parameters]) / problem.scale
    cache: dict[bytes, np.ndarray] = {}

    def fun(v):
        key = v.tobytes()
        if key not in cache:
            cache[key] = problem.residuals([v])[0]
        return cache[key]

    def jac(v):
        J = problem.jacobian(v, fun(v), upper)
        floor = _RESOLUTION_MARGIN * problem.resolution(STENCILS["forward"])
        return _without_invisible(J, floor, settings.fd_step)

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
    cache.clear()
    r = fun(u)
    J, steps = settled_jacobian(problem.residuals, u, r,
                                settings.fd_step * np.maximum(np.abs(u), 1.0), lower, upper,
                                _RESOLUTION_MARGIN * problem.resolution(STENCILS["halves"])
                                * settings.fd_step)
    # each column's float32 noise, at its own step and formula
    floor = np.array([_RESOLUTION_MARGIN * problem.resolution(STENCILS[s["formula"]])
                      * settings.fd_step / s["step"] for s in steps])
    estimate = u * problem.scale
    blocks = residual_blocks(plan, r)
    verdict = adequacy(blocks, judged=settings.inputs == "replay")
    effective = verdict["model_adequate"] is not True
    stats = parameter_uncertainty(
        J, r, settings.names, estimate, problem.scale, floor=floor,
        bounds=[(q.lower, q.upper) for q in settings.parameters],
        model_error=verdict["model_error"] if effective else None,
        noise_variance=verdict["noise_variance"])
    for name, step, x in zip(settings.names, steps, problem.scale):  # its column, settled
        stats["parameters"][name]["jacobian"] = {**step, "step": step["step"] * float(x)}
    result = {
        "model_adequate": verdict["model_adequate"], "adequacy": verdict,
        "parameters": stats["parameters"], "interval_kind": stats["interval_kind"],
        "correlation": stats["correlation"], "residual_rms": residual_rms(plan, blocks),
        "model": model_description(plan), "data": data_fingerprint(plan),
        "cost": float(0.5 * r @ r), "iterations": sum(s["iterations"] for s in stages),
        "simulations": len(problem.evals.seen),
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
        "failed_runs": problem.evals.failed,
    }
    if compare:
        result["comparison"] = comparison([(str(out), result), *compare])
    if plan.targets:  # a fit of frequency responses alone simulates nothing: no store
        problem.evals.finish()
    write_results(out, plan, result)
    return result


def _without_invisible(J: np.ndarray, floor: float, collinear: float) -> np.ndarray:
    """J without the directions it cannot resolve, so that a Gauss-Newton step does not
    move along them: those whose singular value is within ``floor`` (the float32
    resolution of the signals), and combinations of columns that are parallel to within
    ``collinear`` (singular values of J with unit columns: a forward difference is wrong
    by O(step) relative to its column).  Without this, the difference error along an
    exact degeneracy (mh2 and stator_mass: 5.7e-5 of the largest singular value, forward
    steps 1e-3) reads as a slope: the step it suggests (mh2 +160 %, stator_mass
    −1800 %) is rejected or cut, and the pair drifts to a bound (measured with dogbox,
    mh2, stator_mass, mh1, EI1 from 0.1 s to 0.5 s: 31 evaluations, stator_mass ending at
    1.5e-4 kg; with it, 10 evaluations, the pair where it started along the invisible
    direction)."""
    norms = np.linalg.norm(J, axis=0)
    unit = J / np.where(norms > 0, norms, 1.0)
    U, S, Vt = np.linalg.svd(unit, full_matrices=False)
    if not S.size:
        return J
    J = ((U * np.where(S <= collinear * S[0], 0.0, S)) @ Vt) * norms
    U, S, Vt = np.linalg.svd(J, full_matrices=False)
    return (U * np.where((S <= floor) | (S <= 1e-12 * S[0]), 0.0, S)) @ Vt
