"""What a verdict command says on the terminal: the verdicts counted, what is missing and
why, and where the tables are — never the tables, which go to files (claims.md,
stability.md, validity.md, attribution.md and the report).

Each function returns the lines to print and the number of verdicts that are missing
because a run that decides one failed (the command's exit status 1); a failed run that
decides nothing (a stability run above a limit already found) is counted, not missing.
"""
from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

from ..report.summary import counted

__all__ = ["claims_summary", "stability_summary", "validity_summary",
           "attribution_summary"]


def claims_summary(columns, path: Path) -> tuple[list[str], int]:
    """One line per claim: its verdicts over the columns of each arm; the claims a failed
    run left without a verdict are missing."""
    from ..verdicts.claims import CLAIMS, SYSTEM
    arms = list(dict.fromkeys(c.arm for c in columns))
    n = Counter(c.arm for c in columns)
    lines = [f"the paper's claims ({SYSTEM}; columns per arm: "
             + ", ".join(f"{arm} {n[arm]}" for arm in arms) + f") -> {path}"]
    width = max(len(c.key) for c in CLAIMS)
    missing = 0
    for claim in CLAIMS:
        verdicts = {arm: [c.verdicts[claim.key].verdict for c in columns if c.arm == arm]
                    for arm in arms}
        missing += sum(v == "failed" for vs in verdicts.values() for v in vs)
        lines.append(f"  {claim.key:<{width}}  " + "; ".join(
            f"{arm}: {counted(vs)}" for arm, vs in verdicts.items()))
    if missing:
        lines.append(f"  {missing} verdict(s) missing: the run of the system failed there "
                     f"(the run row of {path.name})")
    return lines, missing


def _ms(seconds: float) -> str:
    return f"{1e3 * seconds:.3g} ms"


def stability_summary(results, path: Path, *, tolerance: float) -> tuple[list[str], int]:
    """The range of each limit over the cases, the runs it took and the widest bracket,
    what is not converged (or extrapolated) or not monotone, and the failed runs: a limit
    that ends at one is missing; one above a limit already found decides nothing and is
    counted."""
    widths = [w for r in results for w in (r.divergence.width, r.tracking.width)
              if not math.isnan(w)]
    lines = [f"stability map: {len(results)} cases, {sum(r.runs for r in results)} runs, "
             f"bisected to {tolerance:.2%}"
             + (f" (widest bracket {max(widths):.2%})" if widths else "") + f" -> {path}"]
    for name, attr in (("no divergence up to", "divergence"), ("keeps tracking up to",
                                                                 "tracking")):
        values = [getattr(r, attr).largest for r in results]
        found = [v for v in values if not math.isnan(v)]
        text = f"{_ms(min(found))} to {_ms(max(found))}" if found else "—"
        below = len(values) - len(found)
        lines.append(f"  {name}: {text}" + (f"; below the smallest tested Ts in {below} "
                                            "case(s)" if below else ""))
    for verdict, meaning in (("extrapolated", "a Richardson estimate of the converged limit "
                                              "stated with its error"),
                             ("not converged", "their limits describe the FE mesh")):
        moved = [r for r in results if any(v.verdict == verdict for v in r.resolved.values())]
        if moved:
            lines.append(f"  {verdict} on the refined sequence: {len(moved)} case(s) "
                         f"({meaning})")
    bends = sum(bool(r.non_monotone) for r in results)
    if bends:
        lines.append(f"  not monotone: {bends} case(s)")
    undecided = [r for r in results if "failed" in (r.divergence.outcome, r.tracking.outcome)]
    decided = [(r, Ts) for r in results if r not in undecided for Ts in r.failed]
    where = lambda r: f"{r.case.label} ({r.case.plant}, {r.case.arm})"  # noqa: E731
    if undecided:
        lines.append(f"  {len(undecided)} limit(s) missing: a run failed where the limit "
                     "is (no verdict on stability there): "
                     + "; ".join(f"{where(r)} at {_ms(min(r.failed))}" for r in undecided))
    if decided:
        lines.append(f"  {len(decided)} run(s) failed above a limit already found (they "
                     "decide nothing): " + "; ".join(f"{where(r)} at {_ms(Ts)}"
                                                     for r, Ts in decided))
    return lines, len(undecided)


def validity_summary(data: dict, folder: Path) -> list[str]:
    """Per case: the predicted, certified and measured limit in one line; where the files
    are."""
    lines = [f"linear validity: {len(data['cases'])} cases -> {folder / 'validity.md'}"]
    for arm in data["arms"]:
        if arm["left_out"]:
            lines.append(f"  {arm['arm']} arm: not in the linear models (nonlinear): "
                         + "; ".join(arm["left_out"]))
    for r in data["cases"]:
        lines.append(f"  {r['case']} · {r['plant']} · {r['arm']}: predicted "
                     f"{_period(r['predicted_s'])}, certified "
                     f"{_period(r['certified_s']) if r['certificate'] else 'n/a'}, measured "
                     f"{_period(r['largest_stable_s'])}")
    lines.append(f"  figures and tables: {folder} (validity.csv, nugap.csv, validity.json, "
                 "figures/)")
    return lines


def _period(seconds) -> str:
    if seconds is None or (isinstance(seconds, float) and math.isnan(seconds)):
        return "—"
    if math.isinf(seconds):
        return "> 100 ms" if seconds > 0 else "none"
    return _ms(seconds)


def attribution_summary(views: list[dict], path: Path) -> list[str]:
    """Per study and metric: the gap and the factor that contributes most."""
    lines = [f"attribution -> {path}"]
    for study in views:
        for m in study["metrics"]:
            top = max(m["rows"], key=lambda row: abs(_number(row[1])), default=None)
            lead = f"; largest: {top[0]} {top[1]} {m['unit']}" if top else ""
            lines.append(f"  {study['name']}: {m['metric']}: gap {m['total'] or '—'} "
                         f"{m['unit']}{lead}")
    return lines


def _number(text: str) -> float:
    try:
        return float(text.replace("−", "-"))
    except (ValueError, AttributeError):
        return 0.0
