"""The residuals a calibration minimises, at any point of parameter space: each
simulation a stored run on the campaign runner (``flexarm calibrate``; the fit is
`validation.verdicts.calibration.fit`).

The weighted output error::

    r = [(y_sim,s(t_k; x) − y_meas,s(t_k)) / σ_s   for every experiment, signal s, sample k]
      + [ln(G(jω; x) / G_meas(jω)) / σ_frf   re and im, for every response and frequency]

x are scenario fields (``true_params.EI1``…) in units of their starting values (u = x /
scale); σ_s is the noise level of signal s (the scenario's sensor noise, or
``[calibrate.noise]``); σ_frf the relative error of a measured response (``frf_noise``,
1 %).

**Failed evaluations are no data.**  A sample a simulation did not reach (the run
failed, or diverged before it) and a response that could not be linearised are NaN in
r, and the reason is kept (`Problem.failure`).  The optimiser's trial points read them
as `PENALTY` (`penalised`): far beyond any fit, so a step there is rejected.  What a
fit's *result* rests on — the residual at its estimate and the Jacobian its intervals
come from — must have every sample: where it does not, the fit is refused
(`FitFailed`, `validation.verdicts.calibration.fit`), never computed from the penalty.
A screen's probe that failed is left out of its candidate's score
(`validation.verdicts.calibration.extensions.screen`).
"""
from __future__ import annotations

import copy
import math

import numpy as np

from ...batch.store.resimulate import every_signal
from ...run.config import ConfigError
from ...run.experiments import Experiment, FrequencyResponse
from ...run.scenario import Scenario, scenario_from_mapping
from ...run.tomlfiles import deep_merge, set_dotted
from ..evaluations import FIT_SWEEP, Evaluations
from .plan import Plan, linear_response

__all__ = ["Problem", "FitFailed", "together", "samples", "penalised", "PENALTY"]

#: Residual, in noise levels, that the optimiser reads at a sample a simulation did not
#: reach (it diverged or failed at a trial point): far beyond any fit, so the step is
#: rejected.
PENALTY = 1e3


class FitFailed(RuntimeError):
    """A fit that could not be computed: what its result rests on failed to simulate
    (the reason in the message)."""


def penalised(r: np.ndarray) -> np.ndarray:
    """The residual ``r`` as the optimiser reads it: a sample without data (NaN) is
    `PENALTY`."""
    return np.where(np.isnan(r), PENALTY, r)


def samples(exp: Experiment, horizon: float) -> int:
    """The samples of ``exp`` within its first ``horizon`` seconds (at least two)."""
    if horizon >= exp.duration:
        return exp.samples
    return max(2, round(horizon / exp.Ts))


class Problem:
    """The residuals of a plan at points u (the parameters over their scales), each
    simulation a stored run of ``evals`` (its store and runner); ``inputs`` per target:
    the scenario keys that reproduce its input (`outputs.write_inputs`)."""

    def __init__(self, plan: Plan, evals: Evaluations, inputs: list[dict]) -> None:
        self.plan, self.settings, self.evals = plan, plan.settings, evals
        self.scale = np.array([p.scale for p in plan.settings.parameters])
        self.inputs = inputs  # per target: the scenario keys that reproduce its input
        self.horizon = self.band = math.inf
        # what gave no data and why, latest last (run id or response name → reason), and
        # the simulations and responses that gave every sample asked of them
        self.missing: dict[str, str] = {}
        self.reached: set[str] = set()

    # scenarios
    def scenario(self, i: int, u: np.ndarray, horizon: float) -> Scenario | None:
        """Target ``i``'s scenario at ``u`` over its first ``horizon`` seconds (None if the
        arm there cannot be modelled: a trial point the fit must reject)."""
        target = self.plan.targets[i]
        data = deep_merge(target.scenario, self.inputs[i])
        for p, x in zip(self.settings.parameters, u * self.scale):
            set_dotted(data, p.name, float(x))
        exp = target.experiment
        data["duration"] = samples(exp, horizon) * exp.Ts
        data.pop("transient", None)
        data["name"] = f"{FIT_SWEEP}/{exp.name}"
        try:
            return scenario_from_mapping(data)
        except ConfigError:
            return None

    def _axes(self, i: int, u: np.ndarray, horizon: float) -> dict:
        exp = self.plan.targets[i].experiment
        return {"experiment": exp.name, "horizon": samples(exp, horizon) * exp.Ts,
                **{p.name: float(x) for p, x in zip(self.settings.parameters, u * self.scale)}}

    # residuals
    def residuals(self, points: list[np.ndarray]) -> list[np.ndarray]:
        """The weighted residual vector at each of ``points`` (their simulations run as
        one batch); NaN where a simulation gave no data (module docstring)."""
        return together([(self, u) for u in points])

    def penalised(self, points: list[np.ndarray]) -> list[np.ndarray]:
        """The residuals of ``points`` as the optimiser reads them (`penalised`)."""
        return [penalised(r) for r in self.residuals(points)]

    def requests(self, points: list[np.ndarray]) -> tuple[list, dict]:
        """The simulations of ``points``: (scenario, sweep, axes) items and where each
        (point, target) is among them (a target whose arm cannot be modelled: absent)."""
        items, where = [], {}
        for n, u in enumerate(points):
            for i in range(len(self.plan.targets)):
                s = self.scenario(i, u, self.horizon)
                if s is not None:
                    where[n, i] = len(items)
                    items.append((s, FIT_SWEEP, self._axes(i, u, self.horizon)))
        return items, where

    def answers(self, rows: list, points: list[np.ndarray], where: dict) -> list[np.ndarray]:
        """The residual vectors of ``points`` from the rows of their `requests`."""
        out = []
        for n, u in enumerate(points):
            parts = [self._time_residual(i, rows[where[n, i]] if (n, i) in where else None)
                     for i in range(len(self.plan.targets))]
            parts += [self._frf_residual(r, u) for r in self.plan.responses]
            out.append(np.concatenate(parts) if parts else np.zeros(0))
        return out

    def samples(self, i: int) -> int:
        """The samples of target ``i`` in the current horizon."""
        return samples(self.plan.targets[i].experiment, self.horizon)

    def _time_residual(self, i: int, row) -> np.ndarray:
        target, k = self.plan.targets[i], self.samples(i)
        exp = target.experiment
        measured = exp.signals[:, :k]
        r = np.full(measured.shape, np.nan)
        done = 0
        if row is not None and row.status != "failed":
            result = every_signal(self.evals.store, row)
            done = min(k, len(result.time))
            sim = result.select([f"y_{n}" for n in exp.names])[:, :done].astype(np.float64)
            r[:, :done] = (sim - measured[:, :done]) / target.sigma[:, None]
        if row is None:
            self._record(exp.name, f"experiment {exp.name}: the arm at this point cannot be "
                                   "modelled")
        elif done < k:
            self._record(row.run_id, f"run {row.run_id} {row.status} after {row.end_time:g} "
                                     f"of {row.config['duration']:g} s"
                                     + (f": {row.message}" if row.message else ""))
        else:
            self.reached.add(row.run_id)
        return r.ravel()

    def _record(self, key: str, reason: str) -> None:
        self.missing.pop(key, None)  # read again: the latest
        self.missing[key] = reason

    def failure(self, what: str) -> str:
        """Why the fit could not be computed, ``what`` (the part of its result that
        lacks data: "the residual at its estimate", …) lacking data: every simulation
        failed (the first's reason), or the latest failure (the one ``what`` read)."""
        noun = "simulation" if self.plan.targets else "linearisation"
        reasons = list(self.missing.values())
        total = len(reasons) + len(self.reached)
        if not self.reached:
            return (f"the fit could not be computed: every {noun} failed ({total} of "
                    f"{total}; the first: {reasons[0]})")
        return (f"the fit could not be computed: {what} rests on {noun}s that failed "
                f"({len(reasons)} of {total}; the latest: {reasons[-1]})")

    def _frf_residual(self, response: FrequencyResponse, u: np.ndarray) -> np.ndarray:
        data = copy.deepcopy(self.plan.base)
        for p, x in zip(self.settings.parameters, u * self.scale):
            set_dotted(data, p.name, float(x))
        try:
            s = scenario_from_mapping(data)
            G = linear_response(s, self.settings.frf_theta, response.frequency, response.pairs)
        except (ConfigError, ArithmeticError, np.linalg.LinAlgError) as exc:
            self._record(response.name, f"frequency response {response.name}: {exc}")
            return np.full(2 * response.values.size, np.nan)
        self.reached.add(response.name)
        e = np.log(G / response.values) / self.settings.frf_noise
        e = e[:, :self.frequencies(response)]
        return np.concatenate([e.real.ravel(), e.imag.ravel()])

    def frequencies(self, response: FrequencyResponse) -> int:
        """How many of the response's frequencies the current band holds (at least 2)."""
        return max(2, int(np.searchsorted(response.frequency, self.band, side="right")))

    # the fit's callables
    def jacobian(self, u: np.ndarray, f: np.ndarray, upper) -> np.ndarray:
        """Forward differences at ``u`` (``f`` its residual as the optimiser reads it,
        `penalised`: so are the steps'), one batch of simulations (a step that would
        cross the upper bound goes down); the fit's steps.  The Jacobian the uncertainty
        rests on is `polish`'s."""
        p = len(u)
        h = self.settings.fd_step * np.maximum(np.abs(u), 1.0)
        h = np.where(u + h > upper, -h, h)
        unit = np.eye(p)
        values = self.penalised([u + h[j] * unit[j] for j in range(p)])
        return np.column_stack([(values[j] - f) / h[j] for j in range(p)])

    def resolution(self, stencil: float) -> float:
        """The noise the float32 storage of the simulated signals puts into one column of
        the difference Jacobian (norm, in the residual's units per unit of u): a rounding
        error of spacing δ is uniform, variance δ²/12, and a difference formula Σ c_i f_i / h
        has variance ``stencil`` δ²/(12 h²), ``stencil`` = Σ c_i² (`differences.STENCILS`)."""
        total = 0.0
        for i, target in enumerate(self.plan.targets):
            k = self.samples(i)
            spacing = np.spacing(np.abs(target.experiment.signals[:, :k]).astype(np.float32))
            total += float(np.sum((spacing.astype(np.float64) / target.sigma[:, None]) ** 2))
        return math.sqrt(total * stencil / 12.0) / self.settings.fd_step


def together(pairs: list[tuple[Problem, np.ndarray]]) -> list[np.ndarray]:
    """The residual vectors of (problem, point) pairs — problems of one store, such as a
    plan and its extensions — their simulations run as one batch."""
    if not pairs:
        return []
    asked = [problem.requests([u]) for problem, u in pairs]
    items = [item for its, _ in asked for item in its]
    rows = pairs[0][0].evals.run(items) if items else []
    out, offset = [], 0
    for (problem, u), (its, where) in zip(pairs, asked):
        out += problem.answers(rows[offset:offset + len(its)], [u], where)
        offset += len(its)
    return out
