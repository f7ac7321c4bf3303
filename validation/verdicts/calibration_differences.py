"""The Jacobian at a calibration's estimate: second-order differences, each column
checked for a jump of the outputs within its step (``flexarm calibrate``).

A column is the central difference (f(u + h) − f(u − h)) / 2h, or, where a central step
would cross a bound, the one-sided difference of second order into the bounds,
(−3 f(u) + 4 f(u + h) − f(u + 2h)) / 2h: a step across a bound would read the penalty
of an arm that cannot be modelled as a slope.

**Jumps.**  Both formulas are means of two adjacent one-step differences, a and b (the
forward and the backward one, or the first and the second step into the bounds).  Where
the outputs are smooth in the parameter they agree, ‖a − b‖ = h‖f''‖ plus the float32
rounding of the stored signals.  Where they are not, they do not: with dry friction a
stick–slip transition falls on a step of the integrator, and as a parameter moves, the
transition moves by whole steps — the outputs jump.  Measured, the truth plant replaying
2 s of tracking with three velocity reversals (default arm, joint-1 friction): a 1 %
change of ``coulomb1`` crossed five jumps, the one nearest the estimate 11 times the
smooth change over its interval; the central column of step 1e-3 took it in and was 12 %
off the columns of 1e-4 and 1e-5 (which agree to 0.2 %: the slope between jumps, the
one that sets the estimate's scatter there — its standard error was 6e-5 of
``coulomb1``, the jumps 1e-3 apart).  A column whose halves differ by more than
`AGREEMENT` of it (beyond their float32 noise) is therefore computed again with its step
divided by `REFINE`, and the step whose halves agree better is kept; a column that has
not settled is named (``jacobian`` in ``calibration.json``, and the terminal).

Where the jumps are dense — stiction above the Coulomb level (Stribeck), drives with
backlash: the lab arm — no step settles every column (halves differing by up to 200 % at
steps 1e-2 to 1e-5), and the standard errors barely depend on the step (within 20 % over
1e-3 and 1e-2, 20 seeds), but the roughness stops the fit early (on its step tolerance)
along the direction in which the Coulomb and viscous levels trade against each other
(their errors correlated −0.98): on the reduced plant's own data (2 s with reversals, 20
seeds) ``coulomb1`` and ``viscous1`` scattered 2.6 and 2.7 times their standard errors
(rms of the standardised errors; their 95 % intervals covered 13 and 11 of 20; a
Gauss–Newton step of the 1e-2 secant from the estimates still left 1.5 times), where
the stiffnesses and payload covered 19-20 of 20.  On the default arm with friction
(breakaway = Coulomb level) every column settled at the first step and every interval
covered 19-20 of 20 (docs/guide/calibrate.rst).
"""
from __future__ import annotations

import numpy as np

__all__ = ["STENCILS", "AGREEMENT", "REFINE", "REFINEMENTS", "one_sided", "settled_jacobian"]

#: Σ c_i² of the difference formulas: forward (1, −1), central (1, −1)/2, one-sided of
#: second order (−3, 4, −1)/2, and a − b, the difference of the halves (1, −2, 1).
STENCILS = {"forward": 2.0, "central": 0.5, "one-sided": 6.5, "halves": 6.0}
#: The halves of a settled column agree to this fraction of it (a smooth column at the
#: default step: 0.01-1.5 % measured on the arm's stiffnesses, payload and friction).
AGREEMENT = 0.05
#: A column that has not settled is recomputed with its step divided by this…
REFINE = 10.0
#: …at most this many times (1e-3 → 1e-4 of the parameter at the default step; at 1e-5
#: the float32 noise of a friction parameter's column reached 5-100 % of it).
REFINEMENTS = 1


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


def settled_jacobian(residuals, u: np.ndarray, f: np.ndarray, h: np.ndarray, lower, upper,
                     noise: float) -> tuple[np.ndarray, list[dict]]:
    """The Jacobian at ``u`` (``f`` its residual), each column settled (module docstring).

    Parameters
    ----------
    residuals : callable
        A list of points → their residual vectors (one batch of simulations).
    u, f : ndarray
        The estimate (in units of the parameters' scales) and its residual.
    h : ndarray
        The first steps (in the same units).
    lower, upper : ndarray
        The bounds.
    noise : float
        What the float32 noise of a − b may reach at a unit step (norm): a − b within
        ``noise`` / h_j at step h_j is agreement.

    Returns
    -------
    (ndarray, list of dict)
        The Jacobian, and per parameter ``step`` (the step used, in units of the scale),
        ``halves`` (‖a − b‖ over the column's norm there), ``steps_tried``, ``settled``
        and ``formula`` ("central" or "one-sided").
    """
    p = len(u)
    J = np.zeros((f.size, p))
    best: dict[int, tuple] = {}
    tried = [0] * p
    pending, h = list(range(p)), np.array(h, dtype=float)
    for _ in range(REFINEMENTS + 1):
        side = one_sided(u, h, lower, upper)
        for j, (column, halves) in _columns(residuals, u, f, h, side, pending).items():
            tried[j] += 1
            norm = float(np.linalg.norm(column))
            gap = float(np.linalg.norm(halves))
            relative = gap / norm if norm > 0 else 0.0
            settled = gap <= max(AGREEMENT * norm, noise / h[j])
            if j not in best or relative < best[j][1] or settled:
                best[j] = (column, relative, float(h[j]), settled, side[j])
        pending = [j for j in pending if not best[j][3]]
        if not pending:
            break
        h[pending] /= REFINE
    report = []
    for j in range(p):
        column, relative, step, settled, side = best[j]
        J[:, j] = column
        report.append({"step": step, "halves": relative, "steps_tried": tried[j],
                       "settled": bool(settled),
                       "formula": "central" if side == 0 else "one-sided"})
    return J, report
