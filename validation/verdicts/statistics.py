"""How likely a requirement holds: exact binomial intervals and Wald's sequential test.

Statistical model checking (Younes & Simmons 2006; UPPAAL SMC, PLASMA) treats each
seeded draw from the uncertainty set as a Bernoulli trial "the requirement holds".
`clopper_pearson` is the exact two-sided interval of the success probability at a
stated level (SciPy's ``binomtest(...).proportion_ci(method="exact")``); with no
failure in n draws its lower end is ((1 − level)/2)^(1/n) — 59 successes give 0.939
at level 0.95 (two-sided), 0.950 at level 0.90 (the one-sided 95 % bound).

`sprt` is Wald's sequential probability ratio test of H0: p ≥ p0 + δ ("holds") against
H1: p ≤ p0 − δ ("fails") with error probabilities α (rejecting a true H0) and β
(accepting a false one); between p0 − δ and p0 + δ (the indifference region) either
answer is acceptable.  It decides after as few draws as the evidence allows, or says
"inconclusive" when the draws run out first.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.stats import binomtest

from ..run.config import check

__all__ = ["clopper_pearson", "SequentialTest", "sprt"]


def clopper_pearson(successes: int, n: int, level: float) -> tuple[float, float]:
    """Exact two-sided interval of a binomial proportion at confidence ``level``."""
    if n == 0:
        return 0.0, 1.0
    ci = binomtest(successes, n).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)


@dataclass(frozen=True)
class SequentialTest:
    """Wald's test of p ≥ p0 + δ against p ≤ p0 − δ (module docstring)."""

    p0: float = 0.95
    indifference: float = 0.025
    alpha: float = 0.05
    beta: float = 0.05

    def __post_init__(self):
        check(0 < self.indifference and 0 < self.p0 - self.indifference
              and self.p0 + self.indifference < 1, "verify.indifference",
              f"p0 ± indifference must lie inside (0, 1), got {self.p0} ± {self.indifference}")
        for name in ("alpha", "beta"):
            value = getattr(self, name)
            check(0 < value < 0.5, f"verify.{name}", f"must be in (0, 0.5), got {value!r}")

    @property
    def thresholds(self) -> tuple[float, float]:
        """(accept "holds" at or below, accept "fails" at or above) the log-likelihood
        ratio of H1 to H0."""
        return math.log(self.beta / (1 - self.alpha)), math.log((1 - self.beta) / self.alpha)

    def step(self, holds: bool) -> float:
        """The log-likelihood ratio increment of one draw."""
        p_h0, p_h1 = self.p0 + self.indifference, self.p0 - self.indifference
        return math.log(p_h1 / p_h0) if holds else math.log((1 - p_h1) / (1 - p_h0))


def sprt(outcomes, test: SequentialTest) -> tuple[str, int]:
    """("holds" | "fails" | "inconclusive", draws used) for ``outcomes`` (True = the
    requirement held) taken in order."""
    low, high = test.thresholds
    llr, n = 0.0, 0
    for n, holds in enumerate(outcomes, start=1):
        llr += test.step(holds)
        if llr <= low:
            return "holds", n
        if llr >= high:
            return "fails", n
    return "inconclusive", n
