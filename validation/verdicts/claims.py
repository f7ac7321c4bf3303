"""The paper's claims (Section 5) as criteria that a perfect system passes and a useless
one fails, checked on every arm, plant, sampling period and initial condition run.

Each `Claim` (defined with its measure in `validation.run.claim_measures`, so that a
run's worker can compute its robustness) turns a sentence of the paper into a number
measured on stored runs and a bound, with the reason for both.  The paper's system is the PBC fed by the sign SMO
(run name ``pbc+smo-paper``); the disturbance claim uses the same system with a torque
pulse (``pbc+smo-paper+disturbance``).  Runs are grouped into *columns* by what was run:
arm, plant, control period Ts and initial condition.  A column whose run diverged says so
with the reason and time — a result, not a hole.

Known-good and known-bad cases (tests/test_claims.py): a perfect tracker passes the
tracking and phase claims and an idle one fails them; a perfect estimator passes every
estimation claim while x̂ ≡ 0 and a pass-through of the noisy measurement fail; the
idealised PBC passes the vibration claim from rest and rigid computed torque (no
vibration damping) fails it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..run.claim_measures import CLAIMS, DISTURBED, SYSTEM, Claim

__all__ = ["Claim", "CLAIMS", "Verdict", "Column", "evaluate", "claim_columns", "SYSTEM",
           "DISTURBED", "column_key", "claims_tables", "claims_records", "write_claims",
           "cell_text"]


@dataclass(frozen=True)
class Verdict:
    value: float
    verdict: str  # "holds" | "fails" | "diverged" | "failed" | "not run" | "n/a"
    note: str = ""


def column_key(config: dict) -> tuple:
    """What a claims column is: (arm, plant, Ts, initial condition)."""
    return (config.get("arm", "default"), config["plant"]["kind"], float(config["Ts"]),
            config.get("initial_state", "rest"))


@dataclass
class Column:
    """The runs of one (arm, plant, Ts, initial condition) and their verdicts."""

    key: tuple
    runs: dict  # run name ("pbc+smo-paper", ...) -> stored run
    verdicts: dict  # claim key -> Verdict

    @property
    def arm(self) -> str:
        return self.key[0]

    @property
    def label(self) -> str:
        _, plant, Ts, ic = self.key
        plant = "truth (Exudyn)" if plant == "exudyn" else "reduced"
        start = "from rest" if ic == "rest" else "moving with the reference"
        return f"{plant} plant, Ts = {Ts * 1e3:g} ms, {start}"


def evaluate(claim: Claim, stored) -> Verdict:
    """The verdict of ``claim`` on one stored run (None: not run)."""
    if stored is None:
        return Verdict(math.nan, "not run")
    if stored.status != "ok":
        return Verdict(math.nan, stored.status, stored.message)
    value, note = claim.measure(stored.metrics, stored.load())
    return Verdict(value, claim.judge(value), note)


def claim_columns(runs) -> list[Column]:
    """Columns of verdicts from stored runs (objects with ``name``, ``config``,
    ``status``, ``message``, ``metrics`` and ``load()``), sorted by arm, plant, Ts, start."""
    groups: dict[tuple, dict] = {}
    wanted = {c.run for c in CLAIMS}
    for r in runs:
        short = r.name.split("/")[-1]
        if short in wanted:
            groups.setdefault(column_key(r.config), {})[short] = r
    columns = []
    order = {"default": 0, "table1": 1, "reduced": 0, "exudyn": 1, "rest": 0, "reference": 1}
    for key in sorted(groups, key=lambda k: (order.get(k[0], 9), order.get(k[1], 9), -k[2],
                                             order.get(k[3], 9))):
        runs_here = groups[key]
        columns.append(Column(key, runs_here, {c.key: evaluate(c, runs_here.get(c.run))
                                               for c in CLAIMS}))
    return columns


# --- tables ---------------------------------------------------------------------------------
def cell_text(claim: Claim, v: Verdict) -> str:
    """One cell: "0.00963 rad — holds (note)", or what happened instead of a value (the
    reason of a divergence is in the table's "run" row)."""
    if v.verdict in ("diverged", "failed"):
        return f"— ({v.verdict})"
    if v.verdict in ("not run", "n/a"):
        return v.verdict + (f" ({v.note})" if v.note else "")
    from ..report.render import fmt_number
    value = "never" if math.isinf(v.value) else f"{fmt_number(v.value)} {claim.unit}".strip()
    return f"{value} — {v.verdict}" + (f" ({v.note})" if v.note else "")


def claims_tables(columns: list[Column]) -> list[dict]:
    """Per arm: column labels and one row of cell texts per claim (for the templates)."""
    from ..run.scenario import ARMS
    tables = []
    for arm in dict.fromkeys(c.arm for c in columns):
        cols = [c for c in columns if c.arm == arm]
        rows = [{"claim": "run of the system (" + SYSTEM + ")", "key": "run",
                 "cells": [_run_text(c.runs.get(SYSTEM)) for c in cols],
                 "verdicts": [c.runs[SYSTEM].status if SYSTEM in c.runs else "not run"
                              for c in cols]}]
        rows += [{"claim": claim.text, "key": claim.key,
                  "cells": [cell_text(claim, c.verdicts[claim.key]) for c in cols],
                  "verdicts": [c.verdicts[claim.key].verdict for c in cols]}
                 for claim in CLAIMS]
        rows += _requirement_rows(cols)
        tables.append({"arm": arm, "arm_text": ARMS.get(arm, arm),
                       "columns": [c.label for c in cols], "rows": rows})
    return tables


def _requirement_rows(cols: list[Column]) -> list[dict]:
    """A row per ``[[requirement]]`` of the system's runs: its robustness ρ (≥ 0 holds)."""
    from ..report.render import fmt_number
    texts: dict[str, str] = {}
    for c in cols:
        for r in (c.runs[SYSTEM].config.get("requirement", []) if SYSTEM in c.runs else []):
            texts.setdefault(r["name"], r["formula"] or f"claim {r['claim']}")
    rows = []
    for name, text in texts.items():
        cells, verdicts = [], []
        for c in cols:
            run = c.runs.get(SYSTEM)
            rho = run.metrics.get(f"rho_{name}") if run is not None else None
            if run is not None and run.status != "ok":
                verdict, cell = run.status, f"— ({run.status})"
            elif not isinstance(rho, float) or math.isnan(rho):
                verdict = cell = "not run" if rho is None else "n/a"
            else:
                verdict = "holds" if rho >= 0 else "fails"
                cell = f"ρ = {fmt_number(rho)} — {verdict}"
            cells.append(cell)
            verdicts.append(verdict)
        rows.append({"claim": f"requirement {name}: {text}", "key": f"rho_{name}",
                     "cells": cells, "verdicts": verdicts})
    return rows


def _run_text(run) -> str:
    if run is None:
        return "not run"
    if run.status == "ok":
        return f"ok, {run.end_time:g} s"
    return f"{run.status.upper()}: {run.message}"


def claims_records(columns: list[Column]) -> list[dict]:
    """Long-format rows of claims.csv: what was run, the claim, value, verdict."""
    records = []
    for col in columns:
        arm, plant, Ts, start = col.key
        for claim in CLAIMS:
            v = col.verdicts[claim.key]
            run = col.runs.get(claim.run)
            records.append({"arm": arm, "plant": plant, "Ts": Ts, "initial_state": start,
                            "claim": claim.key, "criterion": claim.criterion,
                            "bound": claim.bound, "unit": claim.unit, "value": v.value,
                            "verdict": v.verdict, "note": v.note,
                            "run_id": run.run_id if run else ""})
    return records


def write_claims(results_dir) -> str:
    """Write claims.md and claims.csv in ``results_dir`` from its stored runs; return the
    markdown."""
    import csv
    import io
    from pathlib import Path

    from ..report.render import render
    from ..run.results import write_atomic
    from ..batch.store import ResultStore
    store = ResultStore(results_dir)
    rows = store.rows()
    columns = claim_columns(rows)
    if not columns:
        raise ValueError(f"{results_dir}: no run named {SYSTEM!r}; the claims need the paper "
                         "campaign (flexarm reproduce-paper)")
    example = next(iter(columns[0].runs.values())).config
    sensors = example["sensors"]
    text = render("claims.md.j2", tables=claims_tables(columns), claims=CLAIMS,
                  duration=f"{example['duration']:g} s",
                  initial_error=", ".join(f"{v:g}" for v in example["observer"]["initial_error"])
                  + " (rad, m, rad/s, m/s)",
                  noise=f"{sensors['encoder_noise']:g} rad, {sensors['modal_noise']:g} m, "
                        f"{sensors['rate_noise']:g} rad/s and m/s")
    out = Path(results_dir)
    write_atomic(out / "claims.md", lambda fh: fh.write(text))
    records = claims_records(columns)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(records[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(records)
    write_atomic(out / "claims.csv", lambda fh: fh.write(buf.getvalue()))
    return text
