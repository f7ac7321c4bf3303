"""Requirements of a run and their quantitative robustness ρ (ρ > 0 holds, ρ < 0 fails).

A scenario's ``[[requirement]]`` entries name either a built-in claim of the paper
(``claim = "tracking"``: ρ = bound − value, in the claim's unit, see
`validation.run.claim_measures`) or a Signal Temporal Logic formula over the run's named
signals (``formula = "always[2,20](abs(theta1 - theta1_ref) <= 0.02)"``: ρ is the
formula's robustness at t = 0 in the signals' unit).  The worker computes every
requirement's ρ with the metrics (`requirement_metrics`: the metric ``rho_<name>``), so
that campaigns, verdicts over uncertainty, reports and regression bounds all read the
same number from the results store.

Formulas are RTAMT's discrete-time offline STL (Ničković & Yamaguchi, RTAMT, 2020): the
field's reference monitor, with the standard quantitative semantics (``x <= c`` has
robustness c − x, ``and``/``always`` take the minimum, ``or``/``eventually`` the
maximum, time bounds in seconds and whole multiples of Ts; a window that reaches past
the end of the run sees only the samples it has — ``always`` of nothing is +∞).  RTAMT
evaluates a bounded ``always``/``eventually`` (and the past ``historically``/``once``)
by a minimum over each window in Python, O(n·w): 3.0 s for ``always[2,20]`` on a 20 s
run at 1 kHz; and a bounded ``until``/``since`` in O(n·w²): a 4 s run's
``until[0.2,2.5]`` exceeded its run's time limit.  `_SlidingWindowVisitor` computes the
same values in O(n) — windows with SciPy's sliding-window filter (0.045 s), ``until``
and ``since`` by blocks of the window's length (0.02 s) — identical, as they only take
minima and maxima of the same numbers (tests/test_requirements.py and
tests/reliability/test_verdicts.py compare them with RTAMT's own on random signals).

Every check happens before anything runs: an unknown claim, a formula that does not
parse, a signal the run will not record and a time bound that is not a multiple of Ts
are `ConfigError`\\ s naming the requirement's key.
"""
from __future__ import annotations

import contextlib
import functools
import logging
import math
from dataclasses import dataclass

import numpy as np

from .config import ConfigError, check, check_label, did_you_mean, short_repr
from .claim_measures import CLAIMS, claim_by_key

__all__ = ["Requirement", "check_requirements", "requirement_metrics", "robustness",
           "signal_names", "RHO_PREFIX"]

#: The metric holding a requirement's robustness is ``RHO_PREFIX + name``.
RHO_PREFIX = "rho_"


@dataclass(frozen=True)
class Requirement:
    """One ``[[requirement]]``: what must hold, with its robustness ρ as a metric.

    Parameters
    ----------
    name : str
        A plain name; the run's metric ``rho_<name>`` holds its robustness.
    claim : str
        A built-in claim's key (ρ = bound − value, in the claim's unit); give either this
        or ``formula``.
    formula : str
        A Signal Temporal Logic formula over the run's signal names, time bounds in
        seconds (ρ in the signals' unit); give either this or ``claim``.
    """

    name: str
    claim: str = ""
    formula: str = ""

    def __post_init__(self):
        check_label(self.name, "name")
        check(bool(self.claim) != bool(self.formula), "name",
              f"requirement {self.name!r} needs either claim = \"<claim>\" or formula = "
              "\"<STL>\" (exactly one)")
        if self.claim:
            keys = [c.key for c in CLAIMS]
            check(self.claim in keys, "claim", f"unknown claim {self.claim!r} (claims: "
                                               f"{', '.join(keys)})"
                                               f"{did_you_mean(self.claim, keys, quote=True)}")
        else:
            _parse(self.formula, ())  # syntax only: the signals are checked per scenario

    @property
    def metric(self) -> str:
        return RHO_PREFIX + self.name

    @property
    def unit(self) -> str:
        return claim_by_key(self.claim).unit if self.claim else "(signal unit)"

    @property
    def text(self) -> str:
        return f"claim {self.claim}" if self.claim else self.formula

    def rho_text(self, rho: float | None) -> str:
        """ρ with its unit, 4 significant digits: "0.006923 rad", "−inf (diverged)" for a
        run that left the bounds, "— (no run)" for None."""
        if rho is None:
            return "— (no run)"
        if math.isinf(rho):
            return ("inf" if rho > 0 else "−inf (diverged)")
        unit = "in the signals' units" if self.formula else self.unit
        return f"{rho:.4g} {unit}" if not self.formula else f"{rho:.4g} ({unit})"


# --- STL through RTAMT ------------------------------------------------------------------------
@functools.cache
def _spec_factory():
    """A function making an empty RTAMT offline specification whose bounded temporal
    operators use SciPy's sliding-window extremes (module docstring); RTAMT is imported
    on first use."""
    from rtamt.antlr.parser.stl.error.parser_error_listener import STLParserErrorListener
    from rtamt.antlr.parser.stl.LtlLexer import LtlLexer
    from rtamt.antlr.parser.stl.StlParser import StlParser
    from rtamt.exception.exception import RTAMTException
    from rtamt.semantics.abstract_discrete_time_offline_interpreter import \
        discrete_time_offline_interpreter_factory
    from rtamt.semantics.stl.discrete_time.offline.ast_visitor import \
        StlDiscreteTimeOfflineAstVisitor
    from rtamt.spec.abstract_specification import AbstractOfflineSpecification
    from rtamt.syntax.ast.parser.abstract_ast_parser import ast_factory
    from rtamt.syntax.ast.parser.stl.parser_visitor import StlAstParserVisitor
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    def window(sample, first: int, last: int, fill: float, extreme) -> list:
        """out[i] = extreme of sample[i + first .. i + last], ``fill`` outside the run."""
        x = np.asarray(sample, dtype=float)
        # Bounds beyond the run's length see nothing more: clipped to ±n, exactly the same
        # (a window held outside the run holds ``fill``, which is neutral or the answer).
        first, last = (min(max(b, -x.size), x.size) for b in (first, last))
        n, width = x.size, last - first + 1
        front, back = max(0, -first), max(0, last)
        padded = np.concatenate([np.full(front, fill), x, np.full(back, fill)])
        centred = extreme(padded, size=width, mode="constant", cval=fill)
        return centred[np.arange(n) + front + first + width // 2].tolist()

    def until(left, right, first: int, last: int) -> list:
        """out[i] = max over j in [i + first, i + last] of min(right[j], left[i .. j − 1])
        (RTAMT's timed until; left is +∞ and right −∞ past the run), exactly — only
        minima and maxima of the inputs — in O(n):

        - the left operand over [i, i + first − 1] is a sliding minimum A[i], and
          ρ[i] = min(A[i], U[i + first]) with U the until over the window [0, w], w =
          last − first (a minimum distributes over the maximum);
        - U[k] with blocks of w + 1 samples: for j in k's own block, the untimed until
          run backwards through the block, P[k] = max(right[k], min(left[k], P[k + 1]));
          for j in the next block, min(left over the rest of k's block, the running
          maximum from the next block's start to k + w of min(right[j], left from the
          block's start to j − 1))."""
        left, right = np.asarray(left, dtype=float), np.asarray(right, dtype=float)
        n = left.size
        if first >= n:  # no right operand within the run
            return [-math.inf] * n
        last = min(last, n - 1)  # j past the run contributes −∞: the same maximum
        w = last - first
        size = w + 1
        blocks = -(-(n + first) // size) + 1  # every k up to n + first, and the next block
        m = blocks * size
        L = np.concatenate([left, np.full(m - n, math.inf)]).reshape(blocks, size)
        R = np.concatenate([right, np.full(m - n, -math.inf)]).reshape(blocks, size)
        # in each block: P by the backward recursion, the suffix minimum of left, and the
        # running maximum of min(right[j], prefix minimum of left before j)
        P = np.empty_like(R)
        P[:, -1] = R[:, -1]
        for c in range(size - 2, -1, -1):
            P[:, c] = np.maximum(R[:, c], np.minimum(L[:, c], P[:, c + 1]))
        suffix = np.minimum.accumulate(L[:, ::-1], axis=1)[:, ::-1]
        before = np.concatenate([np.full((blocks, 1), math.inf),
                                 np.minimum.accumulate(L[:, :-1], axis=1)], axis=1)
        reach = np.maximum.accumulate(np.minimum(R, before), axis=1)
        # j in the next block up to k + w: column c + w − size = c − 1 of the next block
        nxt = np.full_like(R, -math.inf)
        nxt[:-1, 1:] = np.minimum(suffix[:-1, 1:], reach[1:, :-1])
        U = np.maximum(P, nxt).ravel()
        A = window(left, 0, first - 1, math.inf, minimum_filter1d) if first else \
            np.full(n, math.inf)
        return np.minimum(A, U[first:first + n]).tolist()

    class _SlidingWindowVisitor(StlDiscreteTimeOfflineAstVisitor):
        def _samples(self, node) -> tuple[int, int]:
            begin, end = self.time_unit_transformer(node)  # checked multiples of Ts
            if begin > end:
                raise RTAMTException(f"the interval [{float(node.begin):g}"
                                     f"{node.begin_unit}, {float(node.end):g}"
                                     f"{node.end_unit}] ends before it begins")
            return int(begin), int(end)

        def visitTimedAlways(self, node, *args, **kwargs):
            b, e = self._samples(node)
            return window(self.visit(node.children[0], *args, **kwargs), b, e, math.inf,
                          minimum_filter1d)

        def visitTimedEventually(self, node, *args, **kwargs):
            b, e = self._samples(node)
            return window(self.visit(node.children[0], *args, **kwargs), b, e, -math.inf,
                          maximum_filter1d)

        def visitTimedHistorically(self, node, *args, **kwargs):
            b, e = self._samples(node)
            return window(self.visit(node.children[0], *args, **kwargs), -e, -b, math.inf,
                          minimum_filter1d)

        def visitTimedUntil(self, node, *args, **kwargs):
            b, e = self._samples(node)
            return until(self.visit(node.children[0], *args, **kwargs),
                         self.visit(node.children[1], *args, **kwargs), b, e)

        def visitTimedSince(self, node, *args, **kwargs):  # the until of the reversed run
            b, e = self._samples(node)
            return until(self.visit(node.children[0], *args, **kwargs)[::-1],
                         self.visit(node.children[1], *args, **kwargs)[::-1], b, e)[::-1]

        def visitTimedOnce(self, node, *args, **kwargs):
            b, e = self._samples(node)
            return window(self.visit(node.children[0], *args, **kwargs), -e, -b, -math.inf,
                          maximum_filter1d)

    class _Interpreter(discrete_time_offline_interpreter_factory(_SlidingWindowVisitor)):
        def evaluate(self, dataset):
            """RTAMT's, for a run of one sample too: RTAMT's own reads the period between
            the last two samples (for a counter of irregular sampling, which a run's
            regular samples never raise) and raises UnboundLocalError without them."""
            if len(dataset["time"]) > 1:
                return super().evaluate(dataset)
            self.exist_ast()
            self.set_variable_to_ast_from_dataset(dataset)
            self.ast.offline_results["time"] = dataset["time"]
            return [[dataset["time"][0], self.visitAst(self.ast, 1)[-1][0]]]

    class _Lexer(LtlLexer):
        """RTAMT's STL lexer raising its errors as its parser does: ANTLR's default prints
        each character it cannot read to stderr ("line 1:22 token recognition error at:
        '#'") and goes on without it."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self._listeners = [STLParserErrorListener()]

    def make_spec():
        ast = ast_factory(StlAstParserVisitor)(_Lexer, StlParser, STLParserErrorListener)
        return AbstractOfflineSpecification(ast, _Interpreter())

    return make_spec


@contextlib.contextmanager
def _quiet():
    """RTAMT logs a warning through the root logger for every undeclared variable; the
    error that follows is ours to word (one line)."""
    previous = logging.root.manager.disable
    logging.disable(logging.WARNING)
    try:
        yield
    finally:
        logging.disable(previous)


@functools.lru_cache(maxsize=256)
def _parse(formula: str, variables: tuple[str, ...], Ts: float = 1e-3):
    """A parsed RTAMT specification of ``formula`` over ``variables`` sampled every
    ``Ts`` seconds, and the variables it uses.  ConfigError ("formula") for a syntax
    error, KeyError(name) for a variable not among ``variables``."""
    check(isinstance(formula, str) and formula.strip() != "", "formula",
          "must be a non-empty STL formula")
    from rtamt.exception.exception import RTAMTException
    spec = _spec_factory()()
    for name in variables:
        spec.declare_var(name, "float")
    spec.spec = formula
    # The period in whole nanoseconds: RTAMT checks time bounds as exact fractions of it.
    spec.set_sampling_period(int(round(Ts * 1e9)), "ns", 0.1)
    with _quiet():
        try:
            spec.parse()
        except RTAMTException as exc:
            text = " ".join(str(exc).replace("RTAMT Exception:", "").split())
            raise ConfigError("formula", f"{formula!r} does not parse: {text}") from None
        except KeyError:
            if not variables:
                return None, ()  # a syntax check only: names are checked per scenario
            raise
        except RecursionError:  # ANTLR and RTAMT's visitors recurse once per operator
            raise ConfigError("formula", f"{short_repr(formula)}: nested too deeply to "
                                         "parse") from None
    used = tuple(sorted(_variables(spec.ast.specs[0])))
    for name in used:
        if name not in variables:  # a field of a signal (``theta1.real``): no signal
            raise KeyError(name)
    return spec, used


def _variables(node) -> set[str]:
    """The signals a formula reads; RTAMT reads ``x.f`` as the attribute ``f`` of each
    sample of ``x`` (for structured inputs), named here ``"x.f"``, which is no signal."""
    if type(node).__name__ == "Variable":
        return {f"{node.var}.{node.field}" if node.field else node.var}
    return set().union(*(_variables(c) for c in getattr(node, "children", ())))


def signal_names(scenario) -> tuple[str, ...]:
    """The signals a run of ``scenario`` records (`validation.run.sample.signal_layout`): the
    model's states, tips, reference, estimates (with an observer), measurements,
    torques, the PBC's unrealisable forces (laws that have them) and disturbances."""
    from reduced_model import truth_extras

    from .sample import signal_layout
    from .laws import measurement_names, nominal_model
    model = nominal_model(scenario.nominal_params, scenario.model.modes_per_link)
    N = model.n_joints
    names, _ = signal_layout(model.state_names, truth_extras(N),
                             measurement_names(scenario, model),
                             scenario.observer.kind != "none", model.coordinate_names[N:], N)
    return names


def check_requirements(scenario) -> None:
    """Names unique, every formula's signals recorded by the run, its time bounds whole
    multiples of Ts and within the run (ConfigError naming ``requirement[i]``)."""
    names = set()
    for i, req in enumerate(scenario.requirement):
        where = f"requirement[{i}]"
        check(req.name not in names, f"{where}.name", f"duplicate requirement {req.name!r}")
        names.add(req.name)
        if not req.formula:
            continue
        signals = signal_names(scenario)
        try:
            spec, used = _parse(req.formula, signals, scenario.Ts)
        except KeyError as exc:
            raise ConfigError(f"{where}.formula", f"unknown signal {exc.args[0]!r} in "
                                                  f"{req.formula!r} (signals: "
                                                  f"{', '.join(signals)})"
                                                  f"{did_you_mean(exc.args[0], signals)}") \
                from None
        except ConfigError as exc:
            raise exc.under(where) from None
        for begin, end in _time_bounds(spec.ast.specs[0]):
            check(end <= scenario.duration * (1 + 1e-9), f"{where}.formula",
                  f"{req.formula!r}: its time bound [{begin:g}, {end:g}] s reaches beyond the "
                  f"{scenario.duration:g} s run, which could judge only the part of it within "
                  "the run: shorten the bound or lengthen the run")
        _evaluate(req.formula, signals, scenario.Ts, np.array([0.0, scenario.Ts]),
                  {v: np.zeros(2) for v in used}, where)


#: RTAMT's time units, in seconds ("": the specification's default, seconds).
_UNITS = {"": 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


def _time_bounds(node) -> list[tuple[float, float]]:
    """Every [begin, end] time bound of a parsed formula [s]."""
    out = []
    if hasattr(node, "begin") and hasattr(node, "end"):
        out.append((float(node.begin) * _UNITS.get(node.begin_unit, 1.0),
                    float(node.end) * _UNITS.get(node.end_unit, 1.0)))
    for child in getattr(node, "children", ()):
        out += _time_bounds(child)
    return out


def _evaluate(formula: str, signals: tuple[str, ...], Ts: float, time: np.ndarray,
              values: dict, where: str = "formula") -> float:
    from rtamt.exception.exception import RTAMTException
    spec, used = _parse(formula, signals, Ts)
    data = {"time": time.tolist()} | {v: np.asarray(values[v], float).tolist() for v in used}
    try:
        with _quiet():
            out = spec.evaluate(data)
    except RTAMTException as exc:
        text = " ".join(str(exc).replace("RTAMT Exception:", "").split())
        raise ConfigError(f"{where}.formula" if where != "formula" else where,
                          f"{formula!r}: {text} (Ts = {Ts:g} s)") from None
    except RecursionError:
        raise ConfigError(f"{where}.formula" if where != "formula" else where,
                          f"{short_repr(formula)}: nested too deeply to evaluate") from None
    return float(out[0][1])


def robustness(requirement: Requirement, result, metrics: dict) -> tuple[float, str]:
    """(ρ, note) of one requirement on one run: NaN with the reason when it does not
    apply (a claim that needs an observer the run has not, a run that did not complete)."""
    if result.status != "ok" or result.time.size == 0:
        return math.nan, f"the run {result.status}"
    if requirement.claim:
        claim = claim_by_key(requirement.claim)
        value, note = claim.measure(metrics, result)
        return float(claim.bound - value), note
    config = result.config
    signals = tuple(result.names)
    try:
        spec, used = _parse(requirement.formula, signals, float(config["Ts"]))
    except KeyError as exc:
        return math.nan, f"no signal {exc.args[0]!r} in this run"
    return _evaluate(requirement.formula, signals, float(config["Ts"]), result.time,
                     {v: result[v] for v in used}), ""


def requirement_metrics(result, metrics: dict) -> dict[str, float]:
    """The robustness of every requirement in the run's scenario.

    Parameters
    ----------
    result : RunResult
        The run; its ``config`` holds the ``[[requirement]]`` entries.
    metrics : dict
        Its metrics (`validation.run.metrics.all_metrics`): a claim's ρ is computed from them.

    Returns
    -------
    rho_<name> : float
        Robustness ρ of requirement ``name`` [the claim's or the signals' unit]: ≥ 0 holds,
        < 0 fails, NaN if it does not apply.
    """
    out = {}
    for data in result.config.get("requirement", ()):
        req = Requirement(**data)
        out[req.metric] = robustness(req, result, metrics)[0]
    return out
