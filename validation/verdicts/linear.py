"""Linear analysis of the sampled closed loop: the reduced model as a `control.StateSpace`
(the paper's eq. 1–3 linearised), any law linearised from its own object, and the exact
zero-order-hold loop of the two — its spectral radius and the largest stable period.

A law is linearised numerically, by central differences of the torque it returns with
respect to the state it is fed (``controller(t, x, ref)``), at a point (t, x) — so every
gain it applies is in it (for the PBC of eq. 20 also the flexible-rate feedback
M_θq Λ_f q̇ and the Coriolis terms), and a plug-in is linearised like a built-in law.
Each evaluation runs on a deep copy of the law, so a law that keeps state (an integrator)
is linearised with that state frozen: its static part.  A law that is not differentiable
at the point (a sign, a switch) is refused: the gains from two step sizes must agree.

The sampled loop of a law fed the state at t_k and holding its torque over [t_k, t_k+1):
x_{k+1} = (A_d − B_d K C_x) x_k, with (A_d, B_d) the exact ZOH discretisation of the
plant and C_x the plant outputs the law reads (the reduced model's state, or the FE
plant's projected θ, q, θ̇, q̇).  It is called stable if no mode grows faster than
`STABLE_GROWTH` = 0.01 s⁻¹ (ln|z|/Ts; an e-folding time of 100 s, 50 times the stability
map's runs): on an undamped arm a frozen-time linearisation can leave a mode no torque
reaches at |z| = 1 + 1e-9 (measured: +1.4e-5 s⁻¹ on a 32 Hz mode of Table 1's arm), which
no run can see; a sampled-data instability crosses that threshold steeply, so the limit
moves by far less than the bisection's tolerance.
"""
from __future__ import annotations

import copy
import math
from collections.abc import Callable

import control
import numpy as np
from numba.core.dispatcher import Dispatcher

from reduced_model import reduced_linear_model

__all__ = ["reduced_linear_model", "law_gain", "closed_loop_matrix", "growth_rate",
           "largest_stable_period", "feedback_rows", "NotLinearisable", "STABLE_GROWTH"]

_FD_STEP = 1e-6  # relative step of the law's central differences
_FD_AGREEMENT = 1e-4  # gains from steps h and 10 h must agree to this (relative)
STABLE_GROWTH = 0.01  # 1/s: a mode growing faster is unstable (module docstring)


class NotLinearisable(ValueError):
    """The law is not differentiable at the point asked for."""


def law_gain(controller, x, t: float, reference, *, shared=()) -> np.ndarray:
    """The state-feedback gain K of a law at (t, x): δτ = −K δx (module docstring).

    Parameters
    ----------
    controller : callable
        A controller of the plug-in interface, ``tau = controller(t, x, ref)``.
    x : array (2n,)
        The state it is fed, [Q, Q̇] in its model's coordinates.
    t : float
        The time [s] (the reference's phase).
    reference : callable
        ``reference(t) -> (θ_d, θ̇_d, θ̈_d)``.
    shared : objects
        Objects the law holds that are not copied for each evaluation (the nominal model,
        which laws must not mutate: copying it costs 20× the law itself).

    Returns
    -------
    ndarray (k, 2n)
        K, in the sign convention of `control.feedback(P, K)` (negative feedback); k is
        the number of torques the law returns (2, or n for the idealised PBC).

    Raises
    ------
    NotLinearisable
        If the torque is not differentiable at x (gains from two step sizes differ).
    """
    x = np.asarray(x, dtype=float)
    keep = {id(obj): obj for obj in (*shared, *_compiled_parts(controller))}

    def torque(xs):
        law = copy.deepcopy(controller, memo=dict(keep))
        return np.asarray(law(t, xs, reference), dtype=float)

    def gain(scale):
        K = np.empty((len(torque(x)), len(x)))
        for j in range(len(x)):
            h = scale * _FD_STEP * max(1.0, abs(x[j]))
            up, down = x.copy(), x.copy()
            up[j] += h
            down[j] -= h
            K[:, j] = -(torque(up) - torque(down)) / (2 * h)
        return K

    K, K10 = gain(1.0), gain(10.0)
    if not np.all(np.isfinite(K)):
        raise NotLinearisable("the torque is not finite near the point")
    worst = np.abs(K - K10).max() / max(np.abs(K).max(), 1e-300)
    if worst > _FD_AGREEMENT:
        raise NotLinearisable(f"the torque is not differentiable at the point (gains from "
                              f"two step sizes differ by {worst:.2g} relative)")
    return K


def _compiled_parts(obj, depth: int = 3) -> list:
    """The compiled functions (numba dispatchers) a law holds, ``depth`` attributes deep:
    stateless, and copying one pickles its compiler (10 ms each: 95 % of a gain)."""
    found = []
    for value in vars(obj).values() if hasattr(obj, "__dict__") else ():
        if isinstance(value, Dispatcher):
            found.append(value)
        elif depth > 1 and hasattr(value, "__dict__") and not isinstance(value, type):
            found.extend(_compiled_parts(value, depth - 1))
    return found


def feedback_rows(plant: control.StateSpace, names) -> np.ndarray:
    """Rows of ``plant``'s C matrix for the outputs ``names`` (what the law reads), in
    that order; ValueError if one is missing."""
    labels = list(plant.output_labels)
    missing = [n for n in names if n not in labels]
    if missing:
        raise ValueError(f"the plant has no output(s) {', '.join(missing)}")
    return np.asarray(plant.C)[[labels.index(n) for n in names]]


def closed_loop_matrix(plant_d: control.StateSpace, K: np.ndarray, names) -> np.ndarray:
    """A_d − B_d K C_x: the sampled loop of the discrete plant ``plant_d`` with the static
    law u = −K y, y = the outputs ``names``."""
    return np.asarray(plant_d.A) - np.asarray(plant_d.B) @ K @ feedback_rows(plant_d, names)


def growth_rate(matrix: np.ndarray, Ts: float) -> float:
    """Fastest growth rate max ln|z| / Ts [1/s] of the sampled loop ``matrix`` at period
    ``Ts`` (negative: every mode decays)."""
    if not matrix.size:
        return -math.inf
    radius = float(np.abs(np.linalg.eigvals(matrix)).max())
    return math.log(radius) / Ts if radius > 0 else -math.inf


def largest_stable_period(growth: Callable[[float], float], *, low: float = 1e-5,
                          high: float = 0.1, points: int = 41, rtol: float = 1e-4) -> float:
    """The largest Ts below which the sampled loop is stable at every period: the first
    crossing of ``growth(Ts)`` (`growth_rate`) above `STABLE_GROWTH` on a log scan of
    [low, high], refined by bisection on a log scale to ``rtol``.  inf if stable on the
    whole scan, 0 if not even at ``low``."""
    grid = np.geomspace(low, high, points)
    last_stable = None
    for Ts in grid:
        if growth(float(Ts)) > STABLE_GROWTH:
            break
        last_stable = float(Ts)
    else:
        return math.inf
    if last_stable is None:
        return 0.0
    lo, hi = last_stable, float(Ts)
    while hi / lo > 1.0 + rtol:
        mid = math.sqrt(lo * hi)
        if growth(mid) > STABLE_GROWTH:
            hi = mid
        else:
            lo = mid
    return lo
