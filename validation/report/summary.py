"""The report's summary and claims tables, from the reader's side: each claim with its
margin to the bound and the truth plant's difference from the reduced one (the
toolkit's central question), values in the units a reader expects (mrad, mm).

The verdicts themselves come from `validation.verdicts.claims`; this module only says
them.  Margin = 1 − value/bound: positive when the claim holds (the share of the bound
left), negative when it fails; a value at twice the bound or more is said as a multiple of
it ("3.4× the bound").  Δ = (truth − reduced)/|reduced|; beyond ±1000 %, the ratio
("truth = 1700× reduced").
"""
from __future__ import annotations

import json
import math

from .render import display_unit, fmt_number

__all__ = ["verdict_text", "value_text", "summary_view", "pairs_table", "NOTE_MEANING",
           "margin"]

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


def verdict_text(claim, v) -> str:
    """"9.63 mrad — holds, margin +52 % (link 2)", or what happened instead.  A value
    without a verdict (window-sensitive, mesh not checked) has no margin; a truth-plant
    value that moved with the mesh is not given at all, only every mesh's."""
    if v.verdict in ("diverged", "failed"):
        return f"— ({v.verdict})"
    if v.verdict in ("not run", "n/a"):
        return v.verdict + (f" ({v.note})" if v.note else "")
    if v.verdict == "not converged":
        return f"not converged ({v.note})"
    text = f"{value_text(claim, v.value, v.error)} — {v.verdict}"
    if v.verdict in ("holds", "fails") and _margin_text(claim, v.value):
        text += f", {_margin_text(claim, v.value)}"
    return text + (f" ({v.note})" if v.note else "")


def summary_view(columns) -> list[dict]:
    """Per arm, one column per (Ts, initial condition), one row per claim.  A cell says
    the truth plant's verdict with its margin (the reduced plant's where there is no
    truth run), then the other plant's value and Δ = (truth − reduced)/|reduced|."""
    from ..verdicts.claims import CLAIMS
    tables = []
    for arm in dict.fromkeys(c.arm for c in columns):
        pairs: dict[tuple, dict] = {}
        for c in columns:
            if c.arm == arm:
                _, _, Ts, start = c.key
                role = next(iter(c.runs.values())).role
                pairs.setdefault((Ts, start), {})[role] = c
        heads = [f"Ts = {1e3 * Ts:g} ms, {'from rest' if start == 'rest' else 'moving'}"
                 for Ts, start in pairs]
        rows = []
        for claim in CLAIMS:
            cells, classes = [], []
            for plants in pairs.values():
                lines, verdict = _summary_cell(claim, plants)
                cells.append(lines)
                classes.append(verdict)
            rows.append({"claim": claim.text, "bound": value_text(claim, claim.bound),
                         "cells": cells, "verdicts": classes})
        tables.append({"arm": arm, "columns": heads, "rows": rows})
    return tables


def _summary_cell(claim, plants: dict) -> tuple[list[str], str]:
    first = "truth" if "truth" in plants else next(iter(plants))
    v = plants[first].verdicts[claim.key]
    lines = [f"{first}: {_short_verdict(claim, v)}"]
    other = next((p for p in plants if p != first), None)
    if other is not None:
        w = plants[other].verdicts[claim.key]
        line = f"{other}: {_short_verdict(claim, w)}"
        truth, reduced = (v, w) if first == "truth" else (w, v)
        if _finite(truth.value) and _finite(reduced.value) and reduced.value != 0:
            line += f"; {_delta(truth.value, reduced.value)}"
        lines.append(line)
    return lines, v.verdict


def _delta(truth: float, reduced: float) -> str:
    """"Δ +3 %"; beyond ±1000 %, the ratio: "truth = 1700× reduced"."""
    delta = (truth - reduced) / abs(reduced)
    if abs(delta) < 10:
        return f"Δ {_percent(delta)}"
    return f"truth = {_times(truth / reduced)} reduced"


def _finite(x) -> bool:
    return isinstance(x, float) and math.isfinite(x)


def _short_verdict(claim, v) -> str:
    if v.verdict in ("diverged", "failed"):
        return v.verdict.upper()
    return verdict_text(claim, v)


#: (metric keys whose largest value is shown, name, SI unit) of the reduced-vs-truth table.
PAIR_METRICS = [(("track_max_1", "track_max_2"), "tracking error, max", "rad"),
                (("vib_rms_1", "vib_rms_2"), "vibration RMS", "m"),
                (("est_max_theta1", "est_max_theta2"), "angle estimation error, max", "rad"),
                (("tau_tv_1",), "τ₁ variation", "N m/s")]


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
        vals = [run.metrics.get(k) for k in keys]
        vals = [v for v in vals if isinstance(v, float) and math.isfinite(v)]
        return (max(vals), fmt_number(scale * max(vals))) if vals else (math.nan, "—")
    (a, ta), (b, tb) = value(red), value(tru)
    if ta == tb == "—":
        return "—"
    delta = f" ({_delta(b, a)})" if math.isfinite(a) and math.isfinite(b) and a else ""
    return f"{ta} / {tb}{delta}"
