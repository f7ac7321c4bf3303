"""The verdicts as a reader sees them: claims.md/.csv, stability.md/.csv,
attribution.md/.csv and validity.md/.csv, and the table rows the report shows — the text
and layout of what `validation.verdicts` computes (values in the units a reader
expects, notes, the mesh and run rows)."""
from __future__ import annotations

import csv
import functools
import io
import json
import math
from pathlib import Path

from reduced_model import ArmParameters

from ..batch.store.resimulate import every_signal
from ..batch.store.folder import ResultStore
from ..run.requirements import Requirement
from ..run.results import own_folder, write_atomic
from ..run.arms import arm_description
from ..verdicts import mesh as mesh_check
from ..verdicts.attribution import (DIVERGED_RULE, FACTORS, METRIC_NAMES, METRICS,
                                    Attribution, records)
from ..verdicts.claims import (CLAIMS, SYSTEM, WINDOWS, Column, claim_columns,
                               claims_records)
from ..verdicts.stability import (DURATION, GRID, GROWTH_LIMIT, MAX_LEVEL, TRACKING_LIMIT,
                                  Limit, StabilityResult)
from ..verdicts.validity_file import GAP_VIEWS
from .linear_figures import validity_figures
from .render import display_unit, fmt_number, folded, folded_text, render
from .summary import value_text, verdict_parts

__all__ = ["write_claims", "claims_tables", "mesh_row", "mesh_status",
           "arm_notes", "run_text", "stability_rows", "write_stability", "write_attribution",
           "study_view", "table_rows", "gap_rows", "write_validity"]


# --- from claims --------------------------------------------------------------------------------
def mesh_status(run, checks: dict | None, verdicts: dict) -> str:
    """The claims table's mesh row for one column (``run``: the system's stored run)."""
    if checks is None:
        return "— (reduced plant)"
    if not checks or not any(checks.values()):
        return "not checked"
    labels = ", ".join(checks)
    if run.status != "ok":
        others = {label: other.status for label, other in checks.items() if other is not None}
        if any(status != run.status for status in others.values()):
            return f"NOT CONVERGED: {run.status} on its mesh, " + ", ".join(
                f"{status} on {label}" for label, status in others.items())
        return f"{run.status} in every check ({labels})"
    moved = [k for k, v in verdicts.items() if v.verdict == "not converged"]
    if moved:
        return f"NOT CONVERGED against {labels}: {', '.join(moved)}"
    if any(v.verdict == "mesh not checked" for v in verdicts.values()):
        return f"checks incomplete ({labels})"
    return "converged against " + mesh_check.checked_against(
        [(label, mesh_check.NOT_NEEDED if other is None else "")
         for label, other in checks.items()])


def claims_tables(columns: list[Column]) -> list[dict]:
    """Per arm: column labels (and each column's plant and condition apart), the run row
    and the mesh row, one row per claim (its bound and cells in the units a reader
    expects, with the margin: `summary.verdict_parts`, a long note `folded`; the
    failure it guards against) and one per requirement — for claims.md and the report."""
    tables = []
    for arm in dict.fromkeys(c.arm for c in columns):
        cols = [c for c in columns if c.arm == arm]
        rows = [{"claim": "run of the system (" + SYSTEM + ")", "key": "run", "bound": "",
                 "guards": "", "cells": [run_text(c.runs.get(SYSTEM)) for c in cols],
                 "verdicts": [c.runs[SYSTEM].status if SYSTEM in c.runs else "not run"
                              for c in cols]},
                dict(mesh_row(cols), bound="")]
        rows += [{"claim": claim.text, "key": claim.key, "bound": value_text(claim, claim.bound),
                  "guards": claim.guards,
                  "cells": [folded(*verdict_parts(claim, c.verdicts[claim.key]))
                            for c in cols],
                  "verdicts": [c.verdicts[claim.key].verdict for c in cols]}
                 for claim in CLAIMS]
        rows += _requirement_rows(cols)
        tables.append({"arm": arm, "arm_text": arm_description(arm),
                       "columns": [c.label for c in cols],
                       "plants": [c.plant for c in cols],
                       "conditions": [c.condition for c in cols], "rows": rows,
                       "notes": arm_notes(cols)})
    return tables


def mesh_row(columns: list[Column]) -> dict:
    """The claims table's row saying, per column, whether the system's truth-plant run
    survived the mesh refinement (cells and their verdicts)."""
    return {"claim": "truth plant under mesh and time-step refinement (closed loop)", "key": "mesh",
            "guards": "results of the FE discretisation taken for the arm's",
            "cells": [folded_text(mesh_status(c.runs[SYSTEM], c.checks.get(SYSTEM), c.verdicts))
                      if SYSTEM in c.runs else "not run" for c in columns],
            "verdicts": [_mesh_verdict(c) if SYSTEM in c.runs else "not run"
                         for c in columns]}


def _mesh_verdict(column: Column) -> str:
    checks = column.checks.get(SYSTEM)
    if checks is None:
        return "n/a"
    if mesh_status(column.runs[SYSTEM], checks, column.verdicts).startswith("NOT CONVERGED"):
        return "not converged"
    return "converged" if checks and all(checks.values()) else "mesh not checked"


def arm_notes(columns: list[Column]) -> list[str]:
    """What is true of an arm's truth plant when its columns did not converge."""
    notes = []
    for c in columns:
        run = c.runs.get(SYSTEM)
        if run is None or _mesh_verdict(c) != "not converged":
            continue
        params = ArmParameters.from_mapping(run.config["true_params"])
        if params.stator_inertia == 0:
            notes.append(
                "With no stator inertia at the link-1 tip the motor-2 reaction torque acts "
                "on an FE node whose only rotary inertia is the elements' consistent mass: "
                "the FE model has no mesh limit (its joint-2 mobility grows as elements³), "
                "so its truth-plant columns describe the mesh, not the arm.  Give the arm "
                "a stator inertia (true_params.stator_inertia): campaigns/stator.toml "
                "measures the smallest at which the truth plant converges in closed loop "
                "(documentation: 'The truth plant and its convergence').")
            break
    return notes


def _requirement_rows(cols: list[Column]) -> list[dict]:
    """A row per ``[[requirement]]`` of the system's runs: its robustness ρ (≥ 0 holds)."""
    texts: dict[str, str] = {}
    requirements: dict[str, Requirement] = {}
    for c in cols:
        for r in (c.runs[SYSTEM].config.get("requirement", []) if SYSTEM in c.runs else []):
            texts.setdefault(r["name"], r["formula"] or f"claim {r['claim']}")
            requirements.setdefault(r["name"], Requirement(**r))
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
                cell = f"ρ = {requirements[name].rho_text(rho)} — {verdict}"
            cells.append(cell)
            verdicts.append(verdict)
        rows.append({"claim": f"requirement {name}: {text}", "key": f"rho_{name}",
                     "bound": "ρ ≥ 0", "guards": "", "cells": cells, "verdicts": verdicts})
    return rows


def run_text(run) -> str:
    if run is None:
        return "not run"
    if run.status == "ok":
        return f"ok, {run.end_time:g} s"
    return f"{run.status.upper()}: {run.message}"


def write_claims(results_dir, columns: list[Column] | None = None) -> str:
    """Write claims.md and claims.csv in ``results_dir`` from its stored runs (their
    ``columns``, if the caller has them: `claim_columns`); return the markdown."""
    if columns is None:
        store = ResultStore(results_dir)
        columns = claim_columns(store.rows(), functools.partial(every_signal, store))
    if not columns:
        raise ValueError(f"{results_dir}: no run named {SYSTEM!r}; the claims need the paper "
                         "campaign (flexarm reproduce-paper)")
    example = next(iter(columns[0].runs.values())).config
    sensors = example["sensors"]
    text = render("claims.md.j2", tables=claims_tables(columns), claims=CLAIMS,
                  duration=f"{example['duration']:g} s",
                  windows=", ".join(f"{T:g}" for T in WINDOWS),
                  rtol=f"{mesh_check.MESH_RTOL:.0%}", atol=f"{mesh_check.MESH_ATOL:.0%}",
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


# --- from stability --------------------------------------------------------------------------------
def stability_rows(results: list[StabilityResult]) -> list[dict]:
    """Table rows (values in ms as text) for the templates and stability.csv: each limit's
    bracket at the finest level mapped, its width and its verdict on the refined sequence
    (with the error it states), the runs the case took."""

    def ms(v):
        return "—" if math.isnan(v) else fmt_number(1e3 * v)

    def largest(limit: Limit) -> str:
        return ms(limit.largest) if not math.isnan(limit.largest) else \
            f"< {fmt_number(1e3 * GRID[0])}"

    def first(limit: Limit) -> str:
        if math.isnan(limit.first_bad):
            return f"> {fmt_number(1e3 * GRID[-1])}"
        return f"{ms(limit.first_bad)} ({limit.outcome})"

    def width(limit: Limit) -> str:
        return "—" if math.isnan(limit.width) else f"{100 * limit.width:.2g} %"
    rows = []
    for r in results:
        notes = r.non_monotone + [f"FAILED at {1e3 * Ts:.3g} ms: {r.tested[Ts][1]}"
                                  for Ts in r.failed]
        row = {"case": r.case.label, "plant": r.case.plant, "arm": r.case.arm,
               "no_divergence": largest(r.divergence), "first_divergence": first(r.divergence),
               "tracking": largest(r.tracking), "first_loss": first(r.tracking),
               "width_text": width(r.divergence), "tracking_width_text": width(r.tracking),
               "predicted": ms(r.predicted), "runs": r.runs,
               "reason": r.divergence.reason if r.divergence.reason == r.tracking.reason
               else "; ".join(x for x in (r.tracking.reason, r.divergence.reason) if x),
               "mesh": "; ".join(f"{name}: {v.text()}" for name, v in r.resolved.items()
                                 if v.text()) or "— (reduced plant)",
               "discretisation": r.discretisation or "— (reduced plant)",
               "notes": "; ".join(notes) or "monotone",
               "no_divergence_s": r.divergence.largest,
               "first_divergence_s": r.divergence.first_bad,
               "tracking_s": r.tracking.largest, "first_loss_s": r.tracking.first_bad,
               "predicted_s": r.predicted, "failed_s": " ".join(f"{Ts:g}" for Ts in r.failed)}
        for name, limit in (("divergence", r.divergence), ("tracking", r.tracking)):
            v = r.resolved[name]
            row |= {f"{name}_width": limit.width, f"{name}_convergence": v.verdict or "n/a",
                    f"{name}_error_s": v.error, f"{name}_estimate_s": v.estimate}
        row["divergence_band_s"] = r.resolved["divergence"].band
        rows.append(row)
    return rows


#: The columns of stability.csv.
_STABILITY_COLUMNS = ("case", "plant", "arm", "no_divergence_s", "first_divergence_s",
                     "divergence_width", "divergence_convergence", "divergence_error_s",
                     "divergence_estimate_s", "divergence_band_s", "tracking_s",
                     "first_loss_s", "tracking_width", "tracking_convergence",
                     "tracking_error_s", "tracking_estimate_s", "predicted_s", "runs",
                     "discretisation", "failed_s", "mesh", "notes", "reason")


def write_stability(results: list[StabilityResult], out, *, tolerance: float) -> str:
    """Write stability.md and stability.csv into ``out`` (a map bisected to
    ``tolerance``); return the markdown."""
    rows = stability_rows(results)
    text = render("stability.md.j2", rows=rows, duration=f"{DURATION:g}",
                  grid=", ".join(f"{1e3 * t:g}" for t in GRID), tolerance=f"{tolerance:.2%}",
                  limit=f"{TRACKING_LIMIT:g}", growth=f"{GROWTH_LIMIT:g}",
                  max_level=MAX_LEVEL, runs=sum(r.runs for r in results))
    out = Path(out)
    write_atomic(out / "stability.md", lambda fh: fh.write(text))
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=_STABILITY_COLUMNS, extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(out / "stability.csv", lambda fh: fh.write(buf.getvalue()))
    return text


# --- from attribution --------------------------------------------------------------------------------
def write_attribution(atts: list[Attribution], out) -> str:
    """attribution.csv and attribution.md in ``out``; returns the markdown."""
    rows = [r for a in atts for r in records(a)]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=["study", "metric", "factor", "contribution",
                                             "share"], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    out = Path(out)
    write_atomic(out / "attribution.csv", lambda fh: fh.write(buf.getvalue()))
    text = render("attribution.md.j2", studies=[study_view(a) for a in atts], factors=FACTORS,
                  rule=DIVERGED_RULE)
    write_atomic(out / "attribution.md", lambda fh: fh.write(text))
    return text


def study_view(att: Attribution) -> dict:
    """Data for the templates: per metric (by its human name, in the unit a reader
    expects: mrad, mm), one row per factor (and the sub-ladder)."""
    metrics = []
    for metric, contributions in att.contributions.items():
        total = att.totals[metric]
        scale, unit = display_unit(METRICS[metric][1])
        num = lambda v: fmt_number(None if v is None else scale * v)  # noqa: E731
        rows = [[f, num(v), f"{100 * v / total:.1f}" if total and math.isfinite(v)
                 else "—"] for f, v in contributions.items()]
        ladder = " → ".join(f"{f}: {num(v)}" for f, v in att.ladder.get(metric, []))
        pair, value = att.interaction.get(metric, (None, math.nan))
        metrics.append({"metric": METRIC_NAMES.get(metric, metric), "key": metric, "unit": unit,
                        "scale": scale, "rows": rows,
                        "real": num(att.real_value.get(metric)),
                        "ideal": num(att.ideal_value.get(metric)),
                        "total": num(total), "ladder": ladder,
                        "interaction": f"{pair[0]} × {pair[1]}: {num(value)}" if pair else ""})
    return {"name": att.name, "factors": [f for f in att.factors],
            "destabilising": att.destabilising, "diverging": att.diverging, "metrics": metrics}


# --- from validity --------------------------------------------------------------------------------
def _ms(value: float) -> str:
    if isinstance(value, float) and math.isinf(value):
        return "> 100" if value > 0 else "−∞"
    return "—" if value is None or math.isnan(value) else fmt_number(1e3 * value)


def table_rows(data: dict) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the case table (values as text, periods in ms)."""
    head = ["case", "plant", "arm", "predicted [ms]", "FE mesh", "predicted, mesh ×2 [ms]",
            "certified [ms]", "measured: no divergence up to [ms]", "first divergence [ms]",
            "measured limit lies in [ms]", "prediction in it", "certificate sound",
            "certified / measured", "notes"]
    rows = []
    for r in data["cases"]:
        notes = "; ".join(n for n in (r["note"], r["evidence"]) if n)
        rows.append([r["case"], r["plant"], r["arm"], _ms(r["predicted_s"]), r["mesh"],
                     _ms(r["predicted_fine_s"]) if r["mesh_fine"] else "",
                     _ms(r["certified_s"]) if r["certificate"] else "n/a",
                     _ms(r["largest_stable_s"]), _ms(r["first_unstable_s"]),
                     f"({_ms(r['limit_low_s'])}, {_ms(r['limit_high_s'])}] {r['limit_verdict']}",
                     r["in_bracket"],
                     r["sound"], fmt_number(r["conservatism"]), notes])
    return head, rows


def gap_rows(data: dict) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the ν-gap over θ2 table."""
    laws = " / ".join(dict.fromkeys(arm["law"] for arm in data["arms"]))
    head = ["arm", "θ₂ [rad]", "δν τ→θ", "peak [Hz]", "δν τ→tip", "peak [Hz]",
            f"δν {laws} loop at Ts", "peak [Hz]"]
    rows = []
    for arm in data["arms"]:
        for g in arm["gaps"]:
            rows.append([arm["arm"], fmt_number(g["theta2"])] +
                        [fmt_number(g[k]) for v in GAP_VIEWS for k in (v, f"{v}_peak_hz")])
    return head, rows


def write_validity(data: dict, out) -> str:
    """Write ``out``/validity.json (the data), validity.md, validity.csv (the cases),
    nugap.csv (ν-gap over θ2) and the figures (figures/*.png); return the markdown."""
    out = Path(out)
    own_folder(out, "figures")
    write_atomic(out / "validity.json", lambda fh: json.dump(data, fh, indent=1))
    head, rows = table_rows(data)
    ghead, grows = gap_rows(data)
    figures = validity_figures(data)
    files = []
    for i, (caption, png) in enumerate(figures):
        name = f"figures/validity{i:02d}.png"
        write_atomic(out / name, lambda fh, png=png: fh.write(png), binary=True)
        files.append({"caption": caption, "file": name})
    text = render("validity.md.j2", head=head, rows=rows, ghead=ghead, grows=grows,
                  left_out={arm["arm"]: arm["left_out"] for arm in data["arms"]
                            if arm["left_out"]},
                  figures=files, timings=data["timings"], points=data["points"],
                  periods=", ".join(f"{1e3 * t:g}" for t in data["certify_periods"]))
    write_atomic(out / "validity.md", lambda fh: fh.write(text))
    for name, (h, r) in (("validity.csv", (head, rows)), ("nugap.csv", (ghead, grows))):
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(h)
        writer.writerows(r)
        write_atomic(out / name, lambda fh, text=buf.getvalue(): fh.write(text))
    return text
