"""Calibration's uncertainty: standard errors, intervals, correlations and
identifiability from the Jacobian at the estimate (``flexarm calibrate``).

**Uncertainty.**  At the estimate the Jacobian is recomputed by differences of second
order over a few standard errors of each parameter (central, or one-sided into the bounds
for a parameter on or near one: truncation error O(h²), so an exact degeneracy shows as
one; `validation.verdicts.calibration.polish`), and it is decomposed J = U S Vᵀ.  A
direction v_k of parameter space is *not identifiable* when the data cannot see it: its
singular value is within the Jacobian's own error (the float32 resolution of stored
signals over the difference step, ×10), or the data determine it only to more than
±100 % of the starting values.  Every parameter with a weight |v_k,i| ≥ 0.1 on such a
direction is reported *not identifiable*, with the direction (e.g. +0.45 mh2 − 0.89
stator_mass: two masses at the same point, which the arm sees only as their sum) and no
interval; the others get their intervals and correlations from every direction the data
see.  A parameter whose estimate sits on a bound has no valid interval either; that the
data ask for a value beyond it is said only when they determine it (a degenerate
partner could take up the change instead).

What the interval is depends on the verdict on the model
(`validation.verdicts.calibration.adequacy`):

* **An adequate model** (the residual is white noise, independent of the inputs): with
  the residual variance s² = rᵀr / (m − p), the covariance s²(JᵀJ)⁻¹ and a 95 % interval
  (Student t, m − p degrees of freedom).  A misstated noise level changes s², not the
  interval's truth.  Measured: 17-20 of 20 noise seeds cover (tests/test_calibration.py;
  bench/bench_calibration_coverage.py).
* **Coloured noise** (an adequate model whose residual is correlated measurement noise):
  the least-squares estimate's covariance is the sandwich (JᵀJ)⁻¹ JᵀΣJ (JᵀJ)⁻¹, Σ each
  signal's noise model (`validation.verdicts.calibration.noise`; white signals at their
  own mean square), and the interval a normal one of it.
* **An inadequate model** (or one not judged): the estimate is an *effective* parameter of
  that model, and no 95 % interval of a physical value exists.  Linearised, the model
  error d (the outputs' difference at the physical parameters) moves the estimate by
  J⁺d: the part of d along J's columns (P d) is absorbed as a parameter change, the rest
  is the residual the fit leaves.  For any d, |(J⁺d)_i| ≤ ‖P d‖ √((JᵀJ)⁻¹_ii)
  (Cauchy–Schwarz, no assumption on the error's correlation), and the data show only
  the rest, ‖e‖ = √(rᵀr − Σ n σ̂²) (the residual beyond its white part).  The interval is
  the noise's 95 % interval (the white part's level) widened by κ ‖e‖ √((JᵀJ)⁻¹_ii),
  `MODEL_ERROR_FACTOR` κ = 5: it holds the physical value whenever the absorbed part
  is at most κ times the part left.  Measured ‖P d‖/‖e‖ (the reduced model and the
  truth plant's default mesh on data of the geometrically exact arm, 16 el/link, at
  three arms, 1-8 s, with and without observer and pulse), fitting EI1, EI2, Mp: 0.15
  (ANCF 4 el/link, 8 s), 0.9-1.3 (reduced model, 2-8 s), 2.1-2.15 (reduced model, 1 s:
  a short record shows less of the error).  Fitting coulomb1 and viscous1 as well, on
  data with joint-1 friction (25 fits, 1-4 s, most tracking with velocity reversals):
  0.2-1.2 (ANCF 4 el/link), 1.0-2.6 (reduced model, 2-4 s), 3.5 (reduced model, 1 s) and 4.4
  (the lab arm, 1 s): more parameters absorb more of the error.  κ = 3, chosen on the
  first set (the issue's 8 s case: EI1 8.32..9.10, EI2 9.47..13.31, Mp 0.317..0.454
  around 8.6, 11.3, 0.37), missed on the second: EI1 of the reduced model on 1 s of the
  ANCF arm by 1 % of its half-width, and coulomb1 of the ANCF arm (+1.8 %, 2 s, seed 0)
  at 1.23 half-widths — beyond the linearised bound, whose ratio there was 1.18: the
  friction level absorbs the model error through the timing of stick–slip transitions,
  a change no linearisation sees.  The largest κ these fits needed to hold every hidden
  value was 3.7 (that coulomb1; next EI1 of 1 s records, 2.9-3.0); κ = 5 leaves a third
  more.  The block-bootstrap (cluster) sandwich covariance of correlated residuals, 4-64
  blocks, missed all three of the first set (EI1 ±0.04-0.10 around a bias of 0.11): the
  bias of a model error is not a random effect the residual's correlation reveals.  A
  direction the model error leaves undetermined to more than ±100 % (by the same
  measure) is not identifiable.
"""
from __future__ import annotations

import math

import numpy as np
import scipy.stats

__all__ = ["parameter_uncertainty", "MODEL_ERROR_FACTOR"]

#: A direction is not identifiable when the data determine it only to more than this
#: (relative to the starts).
_MAX_RELATIVE_STD = 1.0
#: κ: an inadequate model's intervals allow a parameter error κ times the largest that a
#: model error of the residual's size could hide (module docstring).
MODEL_ERROR_FACTOR = 5.0
#: A parameter whose weight on an unidentifiable direction is at least this is named.
_NAMED_WEIGHT = 0.1


def _direction(v: np.ndarray, names, scale) -> str:
    """A direction of parameter space in words: its components relative to the starts,
    then in the parameters' own units (largest 1), e.g. +0.24 mh2 −0.97 stator_mass
    (ΔSI: +1 mh2 −1 stator_mass: only their sum is seen)."""
    relative = " ".join(f"{x:+.3g} {n}" for x, n in zip(v, names) if abs(x) >= 1e-3)
    si = v * scale
    si = si / np.abs(si).max()
    own = " ".join(f"{x:+.3g} {n.rsplit('.', 1)[-1]}" for x, n in zip(si, names)
                   if abs(x) >= 1e-3)
    return f"{relative} (relative to the starts; in their own units {own})"


def _short(v: np.ndarray, names) -> str:
    """A direction by its largest components, relative to the starts (+0.45 mh2 −0.89
    stator_mass)."""
    order = np.argsort(-np.abs(v))[:3]
    return " ".join(f"{v[i]:+.2g} {names[i].rsplit('.', 1)[-1]}" for i in order
                    if abs(v[i]) >= _NAMED_WEIGHT)


def parameter_uncertainty(J: np.ndarray, r: np.ndarray, names, estimate, scale, *,
                          floor=0.0, bounds=None, level: float = 0.95,
                          model_error: float | None = None,
                          noise_variance: float | None = None,
                          meat: np.ndarray | None = None) -> dict:
    """Standard errors, intervals, correlations and identifiability (module docstring).

    Parameters
    ----------
    J : ndarray (m, p)
        Jacobian of the weighted residual with respect to u = x / ``scale``.
    r : ndarray (m,)
        The weighted residual at the estimate.
    names : sequence of str
        The parameters.
    estimate, scale : ndarray (p,)
        The estimate x and the scale of each parameter.
    floor : float or ndarray (p,)
        The Jacobian's own error (norm of one column's noise, or of each column's where
        their steps differ): a direction whose singular value is not above its error
        (√Σ (v_j floor_j)², v the direction) is invisible to the data.
    bounds : list of (lower, upper), optional
        An estimate on a bound has no valid interval.
    level : float
        Of the noise's interval (Student t with m − p degrees of freedom).
    model_error : float or None
        None for an adequate model: 95 % intervals from the residual variance.  Else the
        norm of the model error the fit leaves (the residual beyond its white part, in
        units of the weights): intervals of effective parameters, the noise's interval
        widened by `MODEL_ERROR_FACTOR` times the parameter change that error can hide.
    noise_variance : float, optional
        With ``model_error``: the variance of the residual's white part (in units of the
        weights), the noise's share of the interval.
    meat : ndarray (p, p), optional
        JᵀΣJ for correlated noise of covariance Σ (`noise.NoiseModel.backwards`): the
        covariance is the sandwich; the interval a normal one.

    Returns
    -------
    dict
        ``parameters`` (name → estimate, std, ci95 (None for an inadequate model),
        interval, model_error, identifiable, reason (in full), why (in a few words)),
        ``interval_kind``, ``correlation`` (names, matrix), ``residual_variance``,
        ``dof``, ``singular_values`` (relative to the largest).
    """
    m, p = J.shape
    dof = max(m - p, 1)
    s2 = float(r @ r) / dof
    effective, coloured = model_error is not None, meat is not None
    quantile = float(scipy.stats.norm.ppf(0.5 + level / 2) if coloured else
                     scipy.stats.t.ppf(0.5 + level / 2, dof))
    noise2 = noise_variance if effective else s2
    U, S, Vt = np.linalg.svd(J, full_matrices=False)
    if meat is None:
        meat = noise2 * (J.T @ J)
    reasons: dict[int, list[tuple[str, str]]] = {i: [] for i in range(p)}
    visible, determined = [], []
    top = S[0] if S.size and S[0] > 0 else 1.0
    for k in range(p):
        error = float(np.sqrt(np.sum((Vt[k] * floor) ** 2)))
        if S[k] <= error or S[k] <= 1e-12 * top:
            why = (f"J is singular along {_direction(Vt[k], names, scale)}: its singular "
                   f"value, {S[k] / top:.2g} of the largest, is within the Jacobian's own error "
                   f"({error / top:.2g}): the data do not see this change")
            short = f"the data do not see {_short(Vt[k], names)}"
        else:
            visible.append(k)
            # the size of the residual this direction's singular value turns into a step
            spread = math.sqrt(max(float(Vt[k] @ meat @ Vt[k]), 0.0)) / S[k] + (
                MODEL_ERROR_FACTOR * model_error / quantile if effective else 0.0)
            if spread / S[k] <= _MAX_RELATIVE_STD:
                determined.append(k)
                continue
            why = (f"the data {'and the model error ' if effective else ''}determine "
                   f"{_direction(Vt[k], names, scale)} only to ±{100 * spread / S[k]:.3g} % "
                   "of the starts")
            short = f"{_short(Vt[k], names)} determined only to ±{100 * spread / S[k]:.3g} %"
        for i in np.flatnonzero(np.abs(Vt[k]) >= _NAMED_WEIGHT):
            reasons[int(i)].append((short, why))
    # A parameter's interval takes every direction the data see, the poorly determined
    # ones too (its small weight on them still moves it); not those within the error.
    unit = sum(np.outer(Vt[k], Vt[k]) / S[k] ** 2 for k in visible) if visible \
        else np.zeros((p, p))
    covariance = unit @ meat @ unit
    per_unit = scale * np.sqrt(np.clip(np.diag(unit), 0.0, None))  # per unit of residual norm
    std = scale * np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    hidden = MODEL_ERROR_FACTOR * model_error * per_unit if effective else np.zeros(p)
    half = quantile * std + hidden
    # the Gauss-Newton step along the directions the data determine; a parameter on a
    # direction they do not (two masses at one point) can be relieved by the others: the
    # data ask nothing of it alone
    step = -sum(Vt[k] * (U[:, k] @ r) / S[k] for k in determined) * scale if determined \
        else np.zeros(p)
    limits = bounds or [(-math.inf, math.inf)] * p
    for i, (lo, hi) in enumerate(limits):
        near = 1e-6 * scale[i]
        at_lower, at_upper = estimate[i] - lo <= near, hi - estimate[i] <= near
        if not (at_lower or at_upper):
            continue
        beyond = not reasons[i] and ((step[i] < -half[i]) if at_lower else (step[i] > half[i]))
        text = (f"the estimate is at its bound [{lo:g}, {hi:g}]"
                + (" and the data ask for a value beyond it" if beyond else ""))
        reasons[i].append((f"at its bound {lo if at_lower else hi:g}", text
                           + " (no valid interval)"))
    parameters = {}
    for i, name in enumerate(names):
        ok = not reasons[i]
        interval = [float(max(estimate[i] - half[i], limits[i][0])),
                    float(min(estimate[i] + half[i], limits[i][1]))] if ok else None
        more = len(reasons[i]) - 1
        parameters[name] = {
            "estimate": float(estimate[i]), "std": float(std[i]) if ok else None,
            "ci95": interval if ok and not effective else None, "interval": interval,
            "model_error": float(hidden[i]) if ok and effective else None,
            "identifiable": ok, "reason": "; ".join(full for _, full in reasons[i]),
            "why": "" if ok else reasons[i][0][0] + (
                f" (and {more} more: calibration.json)" if more > 0 else "")}
    ident = [i for i in range(p) if parameters[names[i]]["identifiable"]]
    d = np.sqrt(np.diag(covariance))
    matrix = [[float(covariance[i, j] / (d[i] * d[j]))
               if i in ident and j in ident and d[i] * d[j] > 0 else None
               for j in range(p)] for i in range(p)]
    kind = (f"effective parameters of an inadequate model: the noise's {100 * level:g} % "
            f"interval ± {MODEL_ERROR_FACTOR:g}× the change the model error can hide"
            if effective else f"{100 * level:g} % (the noise"
            + (", coloured: its correlation counted)" if coloured else ")"))
    return {"parameters": parameters, "interval_kind": kind,
            "correlation": {"names": list(names), "matrix": matrix},
            "residual_variance": s2, "dof": dof,
            "singular_values": [float(v / top) for v in S]}
