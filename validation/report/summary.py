"""The report's summary and claims cells, from the reader's side: each claim with its
margin to the bound, the verdicts counted at a glance, and the truth plant's difference
from the reduced one (the toolkit's central question), values in the units a reader
expects (mrad, mm).

The verdicts themselves come from `validation.verdicts.claims`; this module only says
them.  Margin = 1 − value/bound: positive when the claim holds (the share of the bound
left), negative when it fails; a value at twice the bound or more is said as a multiple of
it ("3.4× the bound").  Δ = (truth − reduced)/|reduced|; beyond ±1000 %, the ratio
("truth = 1700× reduced").
"""
from __future__ import annotations

import json
import math
from collections import Counter

from .render import display_unit, fmt_number
from ..verdicts.resolution import UNDECIDED

__all__ = ["verdict_parts", "value_text", "verdict_counts", "counted",
           "pairs_table", "NOTE_MEANING", "margin", "VERDICT_ORDER", "numbered"]

#: What the note in brackets after a verdict says, per claim.
NOTE_MEANING = {
    "vibration": "the link with the larger value (the one shown), its RMS per 2 s window, "
                 "its decay after the transient and what stays over the run's second half",
    "beats_zero": "the states whose estimate is worse than x̂ ≡ 0 (else the worst state)",
    "flexible_rates": "the link with the larger value (the one shown)",
    "noise_rejection": "the state with the largest ratio",
    "convergence": "the state that converged last (or never)",
    "disturbance": "when the pulse starts",
}


def margin(claim, value: float) -> float:
    """1 − value/bound (NaN without a finite value)."""
    if not isinstance(value, float) or not math.isfinite(value) or claim.bound == 0:
        return math.nan
    return 1.0 - value / claim.bound


def value_text(claim, value: float, error: float = math.nan) -> str:
    """A value in the unit a reader expects, with its estimated discretisation error where
    one is known: "9.63 mrad", "9.63 ± 0.02 mrad", "never"."""
    if math.isinf(value):
        return "never"
    scale, unit = display_unit(claim.unit)
    unit = "" if unit == "(ratio)" else f" {unit}"
    plus = f" ± {fmt_number(scale * error, 2)}" if math.isfinite(error) else ""
    return f"{fmt_number(scale * value)}{plus}{unit}"


def _percent(x: float) -> str:
    return "" if not math.isfinite(x) else f"{100 * x:+.0f} %".replace("-", "−")


def _margin_text(claim, value: float) -> str:
    """"margin +52 %"; a value at twice the bound or more: "3.4× the bound"."""
    m = margin(claim, value)
    if not math.isfinite(m):
        return ""
    return f"{_times(value / claim.bound)} the bound" if m <= -1 else f"margin {_percent(m)}"


def _times(ratio: float) -> str:
    """A ratio of 2 or more as a multiple: "2.9×", "34×", "570×"."""
    return f"{ratio:.2g}×" if ratio < 10 else f"{ratio:.0f}×"


def verdict_parts(claim, v) -> tuple[str, str]:
    """(verdict, note): "9.63 mrad — holds, margin +52 %" and "link 2", or what happened
    instead.  A value without a verdict (window-sensitive, mesh not checked) has no
    margin; a truth-plant value that moved with the mesh is not given at all, only every
    mesh's (the note)."""
    if v.verdict in ("diverged", "failed"):
        return f"— ({v.verdict})", ""
    if v.verdict in ("not run", "n/a", "not converged"):
        return v.verdict, v.note
    text = f"{value_text(claim, v.value, v.error)} — {v.verdict}"
    if v.verdict in ("holds", "fails") and _margin_text(claim, v.value):
        text += f", {_margin_text(claim, v.value)}"
    return text, v.note


#: Verdicts in the order a count lists them.
VERDICT_ORDER = ("holds", "fails", UNDECIDED, "window-sensitive", "not converged",
                 "mesh not checked",
                 "diverged", "failed", "not run", "n/a")


def counted(verdicts) -> str:
    """"3 holds, 1 fails, 2 diverged": each verdict with how often it occurs."""
    counts = Counter(verdicts)
    order = [v for v in VERDICT_ORDER if v in counts] + sorted(set(counts) - set(VERDICT_ORDER))
    return ", ".join(f"{counts[v]} {v}" for v in order)


def verdict_counts(columns) -> dict:
    """The claims at a glance: per claim, arm and plant (the truth plant first), its
    verdicts over those columns counted ("3 holds, 1 diverged"), and how many columns
    each has."""
    from ..run.plants import is_truth
    from ..verdicts.claims import CLAIMS

    def where(c):
        return c.arm, "truth plant" if is_truth(next(iter(c.runs.values())).config) \
            else "reduced model"
    found = {where(c) for c in columns}
    places = [(arm, plant) for plant in ("truth plant", "reduced model")
              for arm in dict.fromkeys(c.arm for c in columns) if (arm, plant) in found]
    rows = [{"claim": claim.text,
             "cells": [counted(c.verdicts[claim.key].verdict for c in columns
                               if where(c) == place) for place in places]} for claim in CLAIMS]
    sizes = Counter(map(where, columns))
    return {"arms": [f"{arm} arm, {plant} ({sizes[arm, plant]} column"
                     f"{'' if sizes[arm, plant] == 1 else 's'})" for arm, plant in places],
            "rows": rows}


def _delta(truth: float, reduced: float) -> str:
    """"Δ +3 %"; beyond ±1000 %, the ratio: "truth = 1700× reduced"."""
    delta = (truth - reduced) / abs(reduced)
    if abs(delta) < 10:
        return f"Δ {_percent(delta)}"
    return f"truth = {_times(truth / reduced)} reduced"


#: (metric key prefix: the largest value over the joints or links numbered after it is
#: shown, name, SI unit) of the reduced-vs-truth table.
PAIR_METRICS = [("track_max_", "tracking error, max", "rad"),
                ("vib_rms_", "vibration RMS", "m"),
                ("est_max_theta", "angle estimation error, max", "rad"),
                ("tau_tv_", "τ variation, max", "N m/s")]


def numbered(metrics: dict, prefix: str) -> list[float]:
    """The finite values of ``metrics`` named ``prefix`` and a joint's or link's number."""
    return [v for k, v in metrics.items() if k.startswith(prefix)
            and k[len(prefix):].isdigit() and isinstance(v, float) and math.isfinite(v)]


def pairs_table(runs, describe) -> dict | None:
    """Every system run on both plants with otherwise the same scenario: reduced, truth
    and Δ for the main metrics (None if there is no such pair).  ``describe(config)``
    says what was run."""
    groups: dict[str, dict] = {}
    for r in runs:
        config = {k: v for k, v in r.config.items() if k != "plant"}
        groups.setdefault(json.dumps(config, sort_keys=True), {})[r.role] = r
    pairs = [g for g in groups.values() if {"reduced", "truth"} <= set(g)]
    if not pairs:
        return None
    head = ["system", "what was run"] + [f"{name} [{display_unit(unit)[1]}]: reduced / truth (Δ)"
                                         for _, name, unit in PAIR_METRICS]
    rows, classes = [], []
    for g in sorted(pairs, key=lambda g: (g["reduced"].name, describe(g["reduced"].config))):
        red, tru = g["reduced"], g["truth"]
        cells = [red.name, describe(red.config)]
        for keys, _, unit in PAIR_METRICS:
            cells.append(_pair_cell(red, tru, keys, display_unit(unit)[0]))
        rows.append(cells)
        classes.append("" if red.status == tru.status == "ok" else "diverged")
    return {"head": head, "rows": rows, "classes": classes}


def _pair_cell(red, tru, keys, scale) -> str:
    def value(run):
        if run.status != "ok":
            return math.nan, run.status.upper()
        vals = numbered(run.metrics, keys)
        return (max(vals), fmt_number(scale * max(vals))) if vals else (math.nan, "—")
    (a, ta), (b, tb) = value(red), value(tru)
    if ta == tb == "—":
        return "—"
    delta = f" ({_delta(b, a)})" if math.isfinite(a) and math.isfinite(b) and a else ""
    return f"{ta} / {tb}{delta}"
