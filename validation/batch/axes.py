"""The axes of a campaign's sweeps and of an uncertainty set: a field's values, factors of
the base scenario's value (``scale``), or seeded draws (`RandomAxis`)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..run.config import ConfigError, check
from ..run.arms import parameter_value
from ..run.tomlfiles import flatten

__all__ = ["flatten_axes", "numeric_field", "RandomAxis", "random_axis", "draw_points"]

_SPEC_KEYS = {"scale", "uniform", "loguniform", "choices", "also"}


def flatten_axes(table: dict) -> dict[str, object]:
    """Sweep (or uncertainty) axes by dotted key; a table whose keys are a value spec
    (scale, uniform, …) is one axis."""
    return flatten(table, leaf=lambda value: bool(set(value) & _SPEC_KEYS))

def numeric_field(resolved_base: dict, path: str, where: str):
    """The base scenario's value at ``path``, which a ``scale`` axis multiplies: a number."""
    try:
        value = parameter_value(resolved_base, path)
    except KeyError:
        raise ConfigError(where, f"{path} is not a scenario field") from None
    check(isinstance(value, (int, float)) and not isinstance(value, bool), where,
          f"scale needs a numeric field, {path} is {value!r}")
    return value

@dataclass(frozen=True)
class RandomAxis:
    """A random axis of a sweep or of an uncertainty set (`validation.verdicts.uncertainty`):
    ``{uniform = [lo, hi]}``, ``{loguniform = [lo, hi]}`` or ``{choices = [...]}``; a
    distribution under ``scale`` (``{scale = {uniform = [0.7, 1.3]}}``) draws a factor of
    each field's base value; ``also = ["other.field", ...]`` gives the same draw to
    other fields (one noise level for every sensor).  `sample` draws seeded values,
    `from_unit` maps u ∈ [0, 1] onto the distribution (the searches), `assign` turns
    one draw into field values."""

    path: str
    kind: str  # "uniform" | "loguniform" | "choices"
    arg: tuple  # (low, high), or the choices
    also: tuple[str, ...] = ()
    base: tuple | None = None  # the fields' base values when the draw is a factor

    @property
    def paths(self) -> tuple[str, ...]:
        return (self.path, *self.also)

    def sample(self, rng: np.random.Generator, n: int) -> list:
        """``n`` draws (the campaign's random sweeps have always drawn exactly these)."""
        if self.kind == "choices":
            return [self.arg[i] for i in rng.integers(0, len(self.arg), n)]
        lo, hi = self.arg
        if self.kind == "uniform":
            return [float(v) for v in rng.uniform(lo, hi, n)]
        return [float(v) for v in np.exp(rng.uniform(math.log(lo), math.log(hi), n))]

    def from_unit(self, u: float):
        """The draw at quantile-like position ``u`` ∈ [0, 1] (uniform in the axis's own
        measure: linear, logarithmic, or equal shares of the choices)."""
        u = min(max(float(u), 0.0), 1.0)
        if self.kind == "choices":
            return self.arg[min(int(u * len(self.arg)), len(self.arg) - 1)]
        lo, hi = self.arg
        if self.kind == "uniform":
            return lo + (hi - lo) * u
        return math.exp(math.log(lo) + (math.log(hi) - math.log(lo)) * u)

    def assign(self, draw) -> dict:
        """{field path: value} of one draw."""
        if self.base is None:
            return {p: draw for p in self.paths}
        return {p: b * draw for p, b in zip(self.paths, self.base)}

    def describe(self) -> str:
        dist = (f"one of {list(self.arg)}" if self.kind == "choices" else
                f"{self.kind} [{self.arg[0]:g}, {self.arg[1]:g}]")
        what = ", ".join(self.paths)
        return f"{what}: {'× ' if self.base is not None else ''}{dist}"


def random_axis(path: str, spec, resolved_base: dict, where: str) -> RandomAxis:
    """Parse one random axis (`RandomAxis`); ConfigError naming ``where``."""
    check(isinstance(spec, dict), where, "a random axis is {uniform = [lo, hi]}, "
                                         "{loguniform = [lo, hi]} or {choices = [...]}")
    spec = dict(spec)
    also = spec.pop("also", [])
    check(isinstance(also, list) and all(isinstance(a, str) for a in also), f"{where}.also",
          "must be a list of scenario fields")
    scaled = "scale" in spec
    if scaled:
        check(set(spec) == {"scale"} and isinstance(spec["scale"], dict), where,
              "a scaled random axis is {scale = {uniform = [lo, hi]}} (or loguniform, choices)")
        spec = spec["scale"]
    check(len(spec) == 1 and set(spec) <= {"uniform", "loguniform", "choices"}, where,
          "a random axis is {uniform = [lo, hi]}, {loguniform = [lo, hi]} or {choices = [...]}")
    (kind, arg), = spec.items()
    if kind == "choices":
        check(isinstance(arg, list) and arg, where, "choices must be a non-empty list")
    else:
        check(isinstance(arg, list) and len(arg) == 2 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in arg)
            and arg[0] <= arg[1], where, f"{kind} needs [low, high] with low <= high")
        check(math.isfinite(arg[0]) and math.isfinite(arg[1])
              and math.isfinite(arg[1] - arg[0]), where,
              f"{kind} needs finite bounds less than 1.8e308 apart, got {arg!r}")
        check(kind == "uniform" or arg[0] > 0, where, "loguniform needs low > 0")
    base = None
    if scaled:
        base = []
        for p in (path, *also):
            base.append(numeric_field(resolved_base, p, where))
        check(kind != "choices" or all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                       for v in arg), where, "scale choices must be numbers")
        base = tuple(base)
    return RandomAxis(path, kind, tuple(arg), tuple(also), base)


def draw_points(axes: list[RandomAxis], samples: int, rng: np.random.Generator) -> list[dict]:
    """``samples`` points {field path: value} drawn from ``rng``, axis by axis in order."""
    columns = [axis.sample(rng, samples) for axis in axes]
    points = []
    for i in range(samples):
        point = {}
        for axis, column in zip(axes, columns):
            point |= axis.assign(column[i])
        points.append(point)
    return points
