"""Stability limits bisected to a stated relative tolerance: a limit's bracket from the
tested control periods, the lattice of periods a map tests, and the next periods a
bracket search asks for.

A limit is bracketed by the largest tested Ts at or below which every run was good and
the first tested Ts that was not (`limit_of`).  A map starts a case at the lattice cell of
its predicted limit (`Lattice.cell`) or at the whole grid, 0.1–10 ms (which, the map
decides: `validation.verdicts.stability`), steps outwards until each limit is bracketed
and then bisects the bracket geometrically until it is within the tolerance.  The periods
bisected to are the points of one *lattice* (`Lattice`): every grid interval cut into
2^d equal ratios, d the smallest depth at which the widest interval's cell (2 → 5 ms) is
within the tolerance — so a bracket within the tolerance is one cell, the brackets of
the levels of a refined sequence are cells of the same lattice (they are the same cell
or they are not: no round-off decides whether they overlap), and a map at 10 % reuses
its runs at 1 % (a coarser lattice's points are points of every finer one, bit for bit).

A refined level starts likewise from the brackets of the level before (`next_points`'
hints): it tests their two ends and, where an outcome changed, steps outwards by 1, 2, 4,
… cells until the limit is bracketed again, then bisects.  A bracket that kept both
outcomes is found in two runs.  A level that a finer one follows leaves a bracket as it
is while the limit *runs off the grid* (`Lattice.runs_off`): it moved from the level
before's bracket by more than its own width, and moving on by as much again would leave
the tested periods — Table 1's arm with a sign SMO on the truth plant, 0.29 → 0.13 ms →
below 0.1 ms.  The finer level is then expected to find no bracket, and bisecting this
one would only sharpen a number no verdict reads (`validation.verdicts.stability`
bisects it after all when the finer level does bracket the limit).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

from ..run.config import ConfigError, check_known, fraction_hint

__all__ = ["TOLERANCE", "MIN_TOLERANCE", "MAX_TOLERANCE", "GOOD", "Limit", "limit_of",
           "Lattice", "next_points", "tolerance_from"]

#: The default relative width a limit's bracket is bisected to (``[stability] tolerance``,
#: ``--tolerance``).
TOLERANCE = 0.01
#: The finest tolerance accepted: runs 0.09 % apart (2.750 and 2.7525 ms, the default
#: arm's PBC on ANCF 8) are still told apart by the growth-rate classifier (0.92 against
#: 1.60 1/s, threshold 1.5); finer separations are not measured.
MIN_TOLERANCE = 1e-3
#: The coarsest: a bracket wider than half its value is no limit worth the name.
MAX_TOLERANCE = 0.5
#: The outcomes that count as good for each limit.
GOOD = {"divergence": ("stable", "lost tracking"), "tracking": ("stable",)}


@dataclass(frozen=True)
class Limit:
    """One limit of a case: the largest Ts at or below which every tested run was good
    (NaN if the smallest was not), the first Ts that was not (NaN if none), its outcome
    and why, and the tested Ts above ``first_bad`` that were good again."""

    largest: float
    first_bad: float
    outcome: str
    reason: str
    non_monotone: tuple[float, ...] = ()

    @property
    def width(self) -> float:
        """The bracket's relative width, first_bad / largest − 1 (NaN if an end is)."""
        return self.first_bad / self.largest - 1.0


def limit_of(tested: dict, good: tuple[str, ...]) -> Limit:
    """Scan the tested Ts ({Ts: (outcome, detail)}) upwards: the last good one before the
    first that is not, and the good ones above it."""
    largest = first_bad = math.nan
    outcome, reason = "", ""
    for Ts in sorted(tested):
        o, detail = tested[Ts]
        if o in good:
            largest = Ts
        else:
            first_bad, outcome, reason = Ts, o, detail
            break
    above = () if math.isnan(first_bad) else tuple(
        Ts for Ts in sorted(tested) if Ts > first_bad and tested[Ts][0] in good)
    return Limit(largest, first_bad, outcome, reason, above)


class Lattice:
    """The control periods a map at ``tolerance`` tests: ``grid``'s intervals each cut
    into 2^depth equal ratios (module docstring)."""

    def __init__(self, grid, tolerance: float) -> None:
        grid = sorted(float(g) for g in grid)
        self.grid, self.tolerance = tuple(grid), tolerance
        widest = max((b / a for a, b in zip(grid, grid[1:])), default=1.0)
        self.depth = 0
        while widest ** (1.0 / 2 ** self.depth) > 1.0 + tolerance:
            self.depth += 1
        n = 2 ** self.depth
        self.points = [a * (b / a) ** (j / n) for a, b in zip(grid, grid[1:]) for j in range(n)]
        self.points.append(grid[-1])

    def below(self, Ts: float) -> int:
        """The index of the largest point at or below ``Ts`` (−1 if none)."""
        return bisect.bisect_right(self.points, Ts) - 1

    def above(self, Ts: float) -> int:
        """The index of the smallest point at or above ``Ts`` (len(points) if none)."""
        return bisect.bisect_left(self.points, Ts)

    def cell(self, Ts: float) -> set[float]:
        """The two points around ``Ts`` (the nearest end point when ``Ts`` lies beyond the
        lattice); the whole grid when ``Ts`` is not a finite positive period."""
        if not (math.isfinite(Ts) and Ts > 0):
            return set(self.grid)
        i = self.below(Ts)
        return {self.points[j] for j in (i, i + 1) if 0 <= j < len(self.points)}

    def inside(self, low: float, high: float) -> range:
        """The indices of the points strictly inside (low, high)."""
        return range(self.below(low) + 1, self.above(high))

    def within(self, low: float, high: float) -> bool:
        """Whether the bracket (low, high] is resolved: within the tolerance, or no point
        of the lattice inside it."""
        return high / low - 1.0 <= self.tolerance or not self.inside(low, high)

    def runs_off(self, limit: Limit, before: Limit) -> bool:
        """Whether ``limit``'s bracket moved from ``before``'s (the level before's) by a
        ratio larger than its own width, and the whole bracket moved on by that ratio
        once more would lie beyond the grid (module docstring); False where either is
        no bracket."""
        low, high, low0, high0 = limit.largest, limit.first_bad, before.largest, \
            before.first_bad
        if any(math.isnan(v) for v in (low, high, low0, high0)):
            return False
        if high <= low0:  # moved down by at least low0 / high: all of it below the grid
            ratio = low0 / high
            beyond = high / ratio < self.grid[0]
        elif low >= high0:  # moved up by at least low / high0: all of it above the grid
            ratio = low / high0
            beyond = low * ratio > self.grid[-1]
        else:
            return False
        return ratio - 1.0 > limit.width and beyond


def next_points(tested: dict, lattice: Lattice, hints,
                before: dict[str, Limit] | None = None) -> set[float]:
    """The next periods one level of a case tests: ``hints`` while nothing is tested
    (the cell of a predicted limit, the grid, or the ends of the level before's brackets);
    then, per limit, the middle lattice point of an unresolved bracket, or the next step
    outwards — 1, 2, 4, … cells beyond what was tested — for a limit all of whose tested
    runs were good (or bad).  Nothing for a limit that ends at a failed run (a failure
    says nothing about where the limit is), nor beyond the lattice, nor — given
    ``before``, the level before's {limit name: `Limit`}, when a finer level follows this
    one — for a bracket that runs off the grid (`Lattice.runs_off`)."""
    if not tested:
        return set(hints)
    points, out = lattice.points, set()
    lowest, highest = lattice.below(min(tested)), lattice.above(max(tested))
    for name, good in GOOD.items():
        limit = limit_of(tested, good)
        if limit.outcome == "failed":
            continue
        low, high = limit.largest, limit.first_bad
        if not (math.isnan(low) or math.isnan(high)):
            if not (lattice.within(low, high)
                    or before is not None and lattice.runs_off(limit, before[name])):
                inside = lattice.inside(low, high)
                out.add(points[inside[len(inside) // 2]])
        elif math.isnan(high):  # good up to the highest tested: step up
            i = lattice.below(low)
            if i < len(points) - 1:
                out.add(points[min(len(points) - 1, i + max(1, i - lowest))])
        else:  # bad down to the lowest tested: step down
            i = lattice.above(high)
            if i > 0:
                out.add(points[max(0, i - max(1, highest - i))])
    return out - set(tested)


def tolerance_from(table: dict, flag: float | None = None) -> float:
    """The tolerance of a map: ``flag`` (``--tolerance``) if given, else a file's
    ``[stability]`` table's ``tolerance``, else `TOLERANCE`; ConfigError naming the key
    (or the flag) for an unknown key or a value outside [`MIN_TOLERANCE`,
    `MAX_TOLERANCE`] — every value given is checked, whichever one is used."""
    for key in table:
        check_known(key, ("tolerance",), f"stability.{key}")
    given = [("stability.tolerance", table["tolerance"])] if "tolerance" in table else []
    given += [("--tolerance", flag)] if flag is not None else []
    for where, value in given:
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not MIN_TOLERANCE <= value <= MAX_TOLERANCE:
            raise ConfigError(where, f"must be a relative width between {MIN_TOLERANCE:g} "
                                     f"and {MAX_TOLERANCE:g} (0.01 = 1 %), not {value!r}"
                                     f"{fraction_hint(value)}")
    return float(given[-1][1]) if given else TOLERANCE
