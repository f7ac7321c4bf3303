"""Difference Jacobians of a calibration's residual: second order at a given step, each
column checked for a jump of the outputs within it (``flexarm calibrate``; the step is
chosen by `validation.verdicts.calibration.polish`).

A column is the central difference (f(u + h) − f(u − h)) / 2h, or, where a central step
would cross a bound, the one-sided difference of second order into the bounds,
(−3 f(u) + 4 f(u + h) − f(u + 2h)) / 2h: a step across a bound would read the penalty
of an arm that cannot be modelled as a slope.

**Jumps.**  Both formulas are means of two adjacent one-step differences, a and b (the
forward and the backward one, or the first and the second step into the bounds).  Where
the outputs are smooth in the parameter they agree, ‖a − b‖ = h‖f''‖ plus the float32
rounding of the stored signals.  Where they are not, they do not: with dry friction a
stick–slip transition falls on a step of the integrator, and as a parameter moves, the
transition moves by whole steps — the outputs jump.  A column whose halves differ by
more than `AGREEMENT` of it (beyond their float32 noise) has not *settled*: the outputs
are rough at the scale of its step, and it is named (``jacobian`` in
``calibration.json``, and the terminal).  Given a narrowest step, such a column is
differenced again at half its step until it settles or would go below it: a secant across
a jump is not a slope at the estimate, and a standard error from it is too narrow
(`validation.verdicts.calibration.polish`: 4.5x for a friction level on the truth plant).
"""
from __future__ import annotations

import numpy as np

__all__ = ["STENCILS", "AGREEMENT", "one_sided", "jacobian", "without_invisible"]

#: Σ c_i² of the difference formulas: forward (1, −1), central (1, −1)/2, one-sided of
#: second order (−3, 4, −1)/2, and a − b, the difference of the halves (1, −2, 1).
STENCILS = {"forward": 2.0, "central": 0.5, "one-sided": 6.5, "halves": 6.0}
#: The halves of a settled column agree to this fraction of it (a smooth column at the
#: default step: 0.01-1.5 % measured on the arm's stiffnesses, payload and friction).
AGREEMENT = 0.05


def one_sided(u: np.ndarray, h: np.ndarray, lower, upper) -> np.ndarray:
    """Per parameter: 0 where a central step of ``h`` stays within the bounds, else the
    direction (+1, −1) of a one-sided second-order difference that does."""
    central = (u - h >= lower) & (u + h <= upper)
    return np.where(central, 0.0, np.where(u + 2 * h <= upper, 1.0, -1.0))


def _columns(residuals, u, f, h, side, which) -> dict:
    """For the parameters ``which``: (column, its halves' difference a − b) at steps
    ``h`` (module docstring), their simulations as one batch."""
    unit = np.eye(len(u))
    near = np.where(side == 0, h, side * h)
    far = np.where(side == 0, -h, 2 * side * h)
    values = residuals([u + near[j] * unit[j] for j in which] +
                       [u + far[j] * unit[j] for j in which])
    out = {}
    for k, j in enumerate(which):
        first, second = values[k], values[len(which) + k]
        if side[j] == 0:
            a, b = (first - f) / h[j], (f - second) / h[j]
            out[j] = ((a + b) / 2, a - b)
        else:
            a, b = (first - f) / h[j], (second - first) / h[j]
            out[j] = (side[j] * (3 * a - b) / 2, a - b)
    return out


def jacobian(residuals, u: np.ndarray, f: np.ndarray, h: np.ndarray, lower, upper,
             noise: float, narrowest: np.ndarray | None = None
             ) -> tuple[np.ndarray, list[dict]]:
    """The Jacobian at ``u`` (``f`` its residual) by second-order differences of steps
    ``h``, each column checked for a jump and, down to ``narrowest``, differenced again at
    half its step while it has not settled (module docstring); one batch of simulations
    per halving.

    Parameters
    ----------
    residuals : callable
        A list of points → their residual vectors (one batch of simulations).
    u, f : ndarray
        The point (in units of the parameters' scales) and its residual.
    h : ndarray
        The steps (in the same units).
    lower, upper : ndarray
        The bounds.
    noise : float
        What the float32 noise of a − b may reach at a unit step (norm): a − b within
        ``noise`` / h_j at step h_j is agreement.
    narrowest : ndarray, optional
        Per parameter, the narrowest step a column that has not settled is halved to
        (default ``h``: no halving).

    Returns
    -------
    (ndarray, list of dict)
        The Jacobian, and per parameter ``step`` (the last, in units of the scale),
        ``halves`` (‖a − b‖ over the column's norm), ``settled`` and ``formula``
        ("central" or "one-sided").
    """
    h = np.array(h, dtype=float)
    narrowest = h if narrowest is None else np.asarray(narrowest, dtype=float)
    J = np.zeros((f.size, len(u)))
    report: list[dict] = [{} for _ in u]
    which = list(range(len(u)))
    while which:
        side = one_sided(u, h, lower, upper)
        for j, (column, halves) in _columns(residuals, u, f, h, side, which).items():
            norm, gap = float(np.linalg.norm(column)), float(np.linalg.norm(halves))
            J[:, j] = column
            report[j] = {"step": float(h[j]), "halves": gap / norm if norm > 0 else 0.0,
                         "settled": bool(gap <= max(AGREEMENT * norm, noise / h[j])),
                         "formula": "central" if side[j] == 0 else "one-sided"}
        which = [j for j in which if not report[j]["settled"] and h[j] / 2 >= narrowest[j]]
        h[which] /= 2
    return J, report


def without_invisible(J: np.ndarray, floor: float, collinear: float) -> np.ndarray:
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
