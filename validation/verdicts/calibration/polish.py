"""The estimate refined at the scale of its own uncertainty, and the Jacobian its
intervals rest on (``flexarm calibrate``).

The fit's Jacobians are differences over ``fd_step`` (1e-3 of each parameter).  Where
the outputs are smooth in a parameter that is its slope.  Where they are not — dry
friction decides a stick–slip switch at an integration step, so as a friction level
moves the switches move by whole steps — a difference over 1e-3 of the parameter is a
secant across many of those jumps, and it can span many times the parameter's own
uncertainty: the scatter of an estimate is set by the cost's shape within a few of its
standard errors, and no other scale.  Measured on the truth plant replaying 2 s of
tracking with three reversals (joint-1 friction, EI1, EI2, Mp, coulomb1, viscous1 fitted,
seed 10 of bench/bench_calibration_coverage.py): the standard error of ``coulomb1`` was
3.8e-5 of its value, the fit's step 27 of them; the fit stopped where the cost, scanned
along ``coulomb1`` with the others re-fitted, was still 8.3 noise variances above its
minimum 3.5 standard errors away, and the 95 % interval missed the true value by 3.85
standard errors.  One Gauss–Newton step with the Jacobian of steps ±2 standard errors
reached that minimum (the cost fell by 8.31) and the true value was then 0.14 standard
errors from the estimate.

So after the fit, the estimate is refined by Gauss–Newton steps whose Jacobian is the
second-order difference over ±`SCALE` standard errors of each parameter (no wider than
the fit's step; no narrower than the step at which the float32 rounding of the stored
signals reaches `ROUNDING` of the column, nor than `NARROWEST` of the fit's step): a
step is taken when it lowers the cost, until every parameter moves less than `SETTLED`
of its standard error, at most `STEPS` times.  A column that has not settled at a step
the rounding widened is differenced again at half its step, down to ±`SCALE` standard
errors (`differences.jacobian`): the rounding's floor is worth less than a slope.
Measured on the truth plant's own mesh (geometrically exact, 16 el/link) fitted to 2 s
of its EKF-observed tracking with reversals and a torque pulse (joint-1 friction, EI1,
EI2, Mp, coulomb1, viscous1 fitted; tests/test_calibration_friction.py, seed 1): the
rounding put coulomb1's step at 38 of the standard errors it gave (2.1e-6 N m), across
a stick–slip jump 16-19 of them above the estimate: at the true arm the weighted outputs
move by 0.23 noise variances (squared norm) at +1 of them, 32 at +12 and 13,900 at +16.
That column, its halves 165 % apart, was 3.8 times the slope, the standard error 4.5
times too narrow and the true value 3.06 of them away (the data alone, noise-free, put
the estimate 2e-8 from it: the simulator's own error is not what moved it).  Halved to
3.6e-5 N m the column settles (halves 1.4 %), one more step is taken (the cost falls by
0.68 noise variances) and the estimate is 0.3000015 ± 9.6e-6, 0.16 standard errors
from the true value, every column settled.

The uncertainty rests on the last Jacobian (`validation.verdicts.calibration.intervals`).
A Jacobian with a sample no simulation reached (NaN) ends the refinement there, for the
fit to refuse; a trial point with one is not taken.
"""
from __future__ import annotations

import numpy as np

from .differences import jacobian, without_invisible

__all__ = ["polish", "SCALE", "STEPS"]

#: The difference step, in standard errors of each parameter.
SCALE = 2.0
#: Gauss–Newton steps at most.
STEPS = 4
#: A step smaller than this fraction of every standard error ends the refinement.
SETTLED = 0.1
#: The narrowest step, relative to the fit's.
NARROWEST = 0.01
#: The float32 rounding of a column may reach this fraction of it, no more: a column
#: differenced over a few of its standard errors — 2e-6 of EI1 on the truth plant — is
#: otherwise noisy enough (1 % of it, ×10 the Jacobian's error margin) to hide a weak
#: direction it barely takes part in (a Stribeck velocity against its breakaway).
ROUNDING = 1e-3


def _standard_errors(J: np.ndarray, r: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Each parameter's standard error (units of u) from the directions J resolves
    (an unresolved one: inf)."""
    m, p = J.shape
    s2 = float(r @ r) / max(m - p, 1)
    U, S, Vt = np.linalg.svd(J, full_matrices=False)
    top = S[0] if S.size and S[0] > 0 else 1.0
    seen = [k for k in range(p) if S[k] > max(float(np.sqrt(np.sum((Vt[k] * floor) ** 2))),
                                              1e-12 * top)]
    var = sum(np.outer(Vt[k], Vt[k]) / S[k] ** 2 for k in seen) if seen else np.zeros((p, p))
    std = np.sqrt(s2 * np.clip(np.diag(var), 0.0, None))
    blind = np.array([any(abs(Vt[k, i]) >= 0.1 for k in range(p) if k not in seen)
                      for i in range(p)])
    return np.where(blind | (std == 0), np.inf, std)


def polish(residuals, u: np.ndarray, r: np.ndarray, J: np.ndarray, lower, upper, *,
           largest: np.ndarray, column_noise, halves_noise: float,
           floor: np.ndarray, collinear: float):
    """Refine ``u`` (residual ``r``, a Jacobian ``J`` of the fit's steps) as the module
    docstring says.

    Parameters
    ----------
    residuals : callable
        A list of points → their residual vectors (one batch of simulations).
    u, r, J : ndarray
        The fit's estimate (units of the scales), its residual and a Jacobian there.
    lower, upper : ndarray
        The bounds.
    largest : ndarray
        The widest step per parameter (the fit's).
    column_noise : float
        The float32 noise of a central column at a unit step (norm): at step h, /h.
    halves_noise : float
        The same for the difference of a column's halves (`differences.jacobian`).
    floor : ndarray
        Per parameter, the Jacobian's own error at the fit's step (a direction within it
        is not resolved).
    collinear : float
        Columns parallel to within this are one direction (`without_invisible`).

    Returns
    -------
    (ndarray, ndarray, ndarray, list of dict, int)
        The refined point, its residual, the Jacobian there (steps of ±`SCALE` standard
        errors), its columns' report (`differences.jacobian`) and the steps taken.
    """
    taken = 0
    while True:
        std = _standard_errors(J, r, floor)
        norms = np.linalg.norm(J, axis=0)
        smallest = column_noise / (ROUNDING * np.where(norms > 0, norms, np.inf))
        wanted = np.clip(SCALE * std, NARROWEST * largest, largest)
        h = np.minimum(np.maximum(wanted, smallest), largest)
        J, report = jacobian(residuals, u, r, h, lower, upper, halves_noise, narrowest=wanted)
        if taken == STEPS or not np.isfinite(J).all():
            return u, r, J, report, taken
        std = _standard_errors(J, r, floor)
        free = (u > lower + 1e-9 * np.abs(u)) & (u < upper - 1e-9 * np.abs(u))
        step = np.zeros_like(u)
        if free.any():
            clean = without_invisible(J[:, free], float(np.max(floor)), collinear)
            step[free] = -np.linalg.lstsq(clean, r, rcond=None)[0]
        visible = np.isfinite(std)
        if not np.any(np.abs(step[visible]) > SETTLED * std[visible]):
            return u, r, J, report, taken
        trial = np.clip(u + step, lower, upper)
        r_trial = residuals([trial])[0]
        if not np.isfinite(r_trial).all() or float(r_trial @ r_trial) >= float(r @ r):
            return u, r, J, report, taken
        u, r, taken = trial, r_trial, taken + 1
