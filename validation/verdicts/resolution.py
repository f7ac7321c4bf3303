"""The one rule for a verdict's resolution, and the estimates it rests on: a limit's
brackets and a robustness ρ on the refined sequence of the truth plant.

A verdict that rests on a number — a stability limit, a ρ, a metric against a claim's
threshold — states the number's resolution and error, and a verdict whose *margin* (the
distance from the number to what it is judged against) is not larger than them reads
`UNDECIDED`, never holds or fails (`judged`).  The rule is written once, here; the docs'
theory page *What a verdict is* states it for the reader.

On the refined sequence (level k: 2^k times the elements per link and 1/2^k of the step):

- a **limit** bisected to a tolerance at every level (`resolve_limit`) is *converged* when
  the finest level's bracket overlaps the one before (it moved by less than its width);
  its error is then the span of the two brackets (the change left beyond the finest
  level, for a sequence of order ≥ 1, is at most the last change).  Else, at the finest
  level, a Richardson estimate of the converged limit from the brackets' midpoints
  (*extrapolated*), if the sequence is in its asymptotic range and the estimate's error is
  small against it (`SMALL`); else *not converged*, the levels' brackets side by side.
  A limit outside the tested periods is no bracket: on every level of two or more, above
  the largest period tested it is *beyond the grid* (`BEYOND`), below the smallest *below
  the grid* (`BELOW`) — the refined sequence keeps it there, as an overlap keeps a
  bracket; *not converged* when it is bracketed on some levels, or above on one and below
  on another.  A truth plant's first level alone is *not checked*, outside the grid or
  not (a limit beyond a coarse mesh's grid may come inside it on a finer mesh).
- a **ρ** on levels 0, 1, 2 (`resolve_rho`) is *undecided* when it changes sign under
  refinement or its margin |ρ| is inside its error; *converged* when the error of the
  Richardson ρ is small against |ρ| (`SMALL`); else *not converged* (the sign stands, the
  value does not).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .mesh import MESH_RTOL

__all__ = ["UNDECIDED", "SMALL", "BEYOND", "BELOW", "judged", "extrapolate", "ResolvedLimit",
           "resolve_limit", "resolve_rho"]

#: What a verdict whose margin lies inside its number's resolution and error reads.
UNDECIDED = "undecided at this resolution"
#: An error is small against a value when it is at most this fraction of it: the
#: tolerance a claim's value is held to between meshes (`mesh.MESH_RTOL`, 10 %).
SMALL = MESH_RTOL
#: What a limit above the largest period tested on every level reads (no bad run there).
BEYOND = "beyond the grid"
#: What a limit below the smallest period tested on every level reads (no good run there).
BELOW = "below the grid"


def judged(verdict: str, margin: float, error: float) -> str:
    """``verdict`` if the margin is larger than the error, else `UNDECIDED`; a NaN
    error (none stated: a plant without a refined sequence) decides nothing."""
    return UNDECIDED if math.isfinite(error) and not abs(margin) > error else verdict


def extrapolate(values) -> tuple[float, float, float]:
    """(observed order, Richardson estimate of the converged value, its error) of values
    on levels 0, 1, 2 of a sequence refined by 2 at each level.  In the asymptotic range
    (the two differences of one sign, shrinking) p = log2((f0 − f1)/(f1 − f2)), the
    estimate f2 + (f2 − f1)/(2^p − 1) and its error the size of that correction (the
    extrapolation trusted no further than its own step).  Otherwise no order, the finest
    value, and the largest difference from it."""
    values = [float(v) for v in values]
    finest = values[-1]
    if len(values) == 3 and all(map(math.isfinite, values)):
        d1, d2 = values[0] - values[1], values[1] - values[2]
        if d1 * d2 > 0 and abs(d2) < abs(d1):
            p = math.log2(d1 / d2)
            estimate = finest + (finest - values[1]) / (2.0 ** p - 1.0)
            return p, estimate, abs(estimate - finest)
    spread = max((abs(v - finest) for v in values), default=math.nan)
    return math.nan, finest, spread


@dataclass(frozen=True)
class ResolvedLimit:
    """A limit judged on the refined sequence.  ``low``/``high``: the finest level's
    bracket [s] (``high`` NaN: no bad run, the limit above the largest period tested;
    ``low`` NaN: no good run, below the smallest); ``verdict``: "converged" |
    "extrapolated" | "not converged" | `BEYOND` | `BELOW` (outside the grid on every
    level: no bracket) | "not checked" (a truth plant's first level alone) | "" (no
    refined sequence: the reduced plant); ``error`` [s] of the converged limit (NaN: none
    stated); ``estimate``: the Richardson estimate of the converged limit (extrapolated
    only); ``order``; ``levels``: (discretisation, low, high) per level."""

    low: float
    high: float
    verdict: str
    error: float = math.nan
    estimate: float = math.nan
    order: float = math.nan
    levels: tuple = ()
    #: [s] How far below the bracket the period at which the loop turns unstable may lie
    #: (the resolution of the outcome test, `validation.verdicts.stability`; NaN: none).
    band: float = math.nan

    @property
    def width(self) -> float:
        """The bracket's relative width (NaN where an end is beyond the grid)."""
        return self.high / self.low - 1.0

    def interval(self) -> tuple[float, float]:
        """Where the converged limit lies: the estimate ± its error (extrapolated), else
        the bracket widened by the error (if one is stated), its low end lowered by the
        band; (NaN, NaN) if not converged."""
        if self.verdict == "not converged":
            return math.nan, math.nan
        band = self.band if math.isfinite(self.band) else 0.0
        if self.verdict == "extrapolated":
            return self.estimate - self.error - band, self.estimate + self.error
        error = self.error if math.isfinite(self.error) else 0.0
        low = 0.0 if math.isnan(self.low) else self.low
        high = math.inf if math.isnan(self.high) else self.high
        return low - error - band, high + error

    def text(self) -> str:
        """"converged ±0.02 ms", "extrapolated 2.742 ± 0.003 ms", "beyond the grid: above
        10 ms, the largest period tested, on every level (ANCF 4 el/link, …)", or the
        levels' brackets side by side."""
        ms = lambda v: f"{1e3 * v:.4g}"  # noqa: E731
        if self.verdict == "converged":
            return f"converged (error ≤ {ms(self.error)} ms)"
        if self.verdict == "extrapolated":
            order = f", order {self.order:.2g}" if math.isfinite(self.order) else ""
            return f"extrapolated {ms(self.estimate)} ± {ms(self.error)} ms{order}"
        if self.verdict in (BEYOND, BELOW):
            where = f"above {ms(self.low)} ms, the largest" if self.verdict == BEYOND else \
                f"below {ms(self.high)} ms, the smallest"
            return (f"{self.verdict}: {where} period tested, on every level ("
                    + "; ".join(label for label, _, _ in self.levels) + ")")
        if self.verdict == "not converged":
            return "not converged: " + "; ".join(
                f"{label}: ({'—' if math.isnan(lo) else ms(lo)}, "
                f"{'—' if math.isnan(hi) else ms(hi)}]" for label, lo, hi in self.levels)
        return ""


def resolve_limit(levels, *, final: bool, refined: bool = True) -> ResolvedLimit:
    """A limit's verdict on the refined sequence (module docstring) from its brackets per
    level, coarsest first: ``levels`` = [(discretisation, low, high), ...].  Without a
    refined sequence (``refined`` false: the reduced plant) the bracket alone, verdict "";
    a truth plant's single level is "not checked" (mapped one level finer, inside the
    grid or not).  A limit above the largest period tested on every level is `BEYOND`,
    below the smallest on every level `BELOW`; one that is outside the grid on some
    levels only (or on both sides), "not converged".  ``final``: no finer level will be
    mapped (a sequence that has not converged by then is extrapolated or not converged;
    before, it is "not converged" and mapped one level finer)."""
    levels = tuple(levels)
    _, low, high = levels[-1]
    if len(levels) == 1:
        return ResolvedLimit(low, high, "not checked" if refined else "", levels=levels)
    sides = {_side(a, b) for _, a, b in levels}
    if sides in ({BEYOND}, {BELOW}):
        return ResolvedLimit(low, high, sides.pop(), levels=levels)
    if len(sides) > 1:  # the levels disagree about where the limit lies
        return ResolvedLimit(low, high, "not converged", levels=levels)
    _, low0, high0 = levels[-2]
    if low0 < high and low < high0:  # the brackets overlap
        return ResolvedLimit(low, high, "converged", max(high0, high) - min(low0, low),
                             levels=levels)
    if final and len(levels) == 3:
        order, estimate, error = extrapolate(math.sqrt(a * b) for _, a, b in levels)
        error += high - low  # each midpoint is known to half its bracket
        if math.isfinite(order) and error <= SMALL * estimate:
            return ResolvedLimit(low, high, "extrapolated", error, estimate, order, levels)
    return ResolvedLimit(low, high, "not converged", levels=levels)


def _side(low: float, high: float) -> str:
    """Where one level puts a limit: `BEYOND` the grid (no bad run), `BELOW` it (no good
    run), or "" (bracketed)."""
    return BEYOND if math.isnan(high) else BELOW if math.isnan(low) else ""


def resolve_rho(values: dict, others: dict | None = None) -> dict:
    """The verdict of a robustness ρ on the refined sequence (module docstring).
    ``values``: {discretisation: ρ} on levels 0, 1, 2 in order (−∞: the run diverged,
    None: it failed); ``others``: ρ on other checks (another element formulation), whose
    sign must agree too.  Returns {"verdict", "rho" (Richardson), "error", "order",
    "rule"}; "check failed" if a run failed."""
    rule = (f"converged: the error of the Richardson ρ ≤ {SMALL:.0%} of |ρ|; {UNDECIDED}: "
            "ρ changes sign under refinement (or in another formulation), or |ρ| ≤ its "
            "error; not converged: the sign stands, the value does not")
    every = list(values.values()) + list((others or {}).values())
    out = {"rho": None, "error": None, "order": None, "rule": rule}
    if any(v is None for v in every):
        return out | {"verdict": "check failed"}
    if len({v < 0 for v in every}) > 1:
        return out | {"verdict": UNDECIDED}
    numbers = list(values.values())
    if all(math.isinf(v) for v in numbers):  # diverged on every level
        return out | {"verdict": "converged"}
    if not all(math.isfinite(v) for v in numbers):
        return out | {"verdict": "not converged"}
    order, rho, error = extrapolate(numbers)
    out |= {"rho": rho, "error": error, "order": order if math.isfinite(order) else None}
    if judged("decided", rho, error) == UNDECIDED:
        return out | {"verdict": UNDECIDED}
    return out | {"verdict": "converged" if error <= SMALL * abs(rho) else "not converged"}
