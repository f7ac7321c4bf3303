"""The paper's claims (Section 5) as criteria that a perfect system passes and a useless
one fails, checked on every arm, plant, sampling period and initial condition run.

Each `Claim` (defined with its measure in `validation.run.claim_measures`, so that a
run's worker can compute its robustness) turns a sentence of the paper into a number
measured on stored runs (a pure measurement: value and note) and a bound, with the reason for both and the failure the
row guards against.  The paper's system is the PBC fed by the sign SMO (run name
``pbc+smo-paper``); the disturbance claim uses the same system with a torque pulse
(``pbc+smo-paper+disturbance``).  Runs are grouped into *columns* by what was run: arm,
plant, control period Ts and initial condition.  A column whose run diverged says so with
the reason and time — a result, not a hole.

A verdict is given only after two checks, in this order (DESIGN.md, "What a verdict is"):

1. **Mesh convergence** (truth plant only): the claim's value on the run's mesh and on
   its check meshes (`validation.verdicts.mesh`) must agree within the stated tolerance;
   otherwise the cell is "not converged" with every mesh's value.  A truth-plant run
   without stored checks is "mesh not checked".
2. **Window family** (claims measured after a transient): the value is measured with the
   transient at each of `WINDOWS` (1–4 s); if the verdict differs within the family the
   cell is "window-sensitive" and says at which transient it flips.

Known-good and known-bad cases (tests/test_claims.py): a perfect tracker passes the
tracking and phase claims and an idle one fails them; a perfect estimator passes every
estimation claim while x̂ ≡ 0 and a pass-through of the noisy measurement fail; a blind
θ̂ = θd passes the angle claim and is caught by the noise-rejection row; the idealised
PBC passes the vibration claim from rest and rigid computed torque fails it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..run.claim_measures import CLAIMS, DISTURBED, SYSTEM, Claim
from ..run.metrics import all_metrics
from . import mesh as mesh_check

__all__ = ["Claim", "CLAIMS", "Verdict", "Column", "evaluate", "claim_columns", "SYSTEM",
           "DISTURBED", "WINDOWS", "column_key", "claims_tables", "claims_records",
           "write_claims", "cell_text", "mesh_rows", "mesh_status", "mesh_row", "arm_notes",
           "MeshRow"]

#: The family of transients [s] every windowed claim is measured over.
WINDOWS = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0)


@dataclass(frozen=True)
class Verdict:
    """A claim on one run.  ``verdict``: "holds" | "fails" | "window-sensitive" |
    "not converged" | "mesh not checked" | "diverged" | "failed" | "not run" | "n/a";
    ``value`` at the scenario's transient on the run's own mesh; ``windows``: (transient,
    value, holds/fails) over `WINDOWS`; ``meshes``: (mesh label, value or status)."""

    value: float
    verdict: str
    note: str = ""
    windows: tuple = ()
    meshes: tuple = ()


def column_key(config: dict) -> tuple:
    """What a claims column is: (arm, plant, Ts, initial condition)."""
    return (config.get("arm", "default"), config["plant"]["kind"], float(config["Ts"]),
            config.get("initial_state", "rest"))


@dataclass
class Column:
    """The runs of one (arm, plant, Ts, initial condition) and their verdicts; ``checks``:
    per run name, its mesh-check runs ({mesh label: stored run or None}, None for the
    reduced plant)."""

    key: tuple
    runs: dict  # run name ("pbc+smo-paper", ...) -> stored run
    verdicts: dict  # claim key -> Verdict
    checks: dict = field(default_factory=dict)

    @property
    def arm(self) -> str:
        return self.key[0]

    @property
    def label(self) -> str:
        _, plant, Ts, ic = self.key
        plant = "truth (Exudyn)" if plant == "exudyn" else "reduced"
        start = "from rest" if ic == "rest" else "moving with the reference"
        return f"{plant} plant, Ts = {Ts * 1e3:g} ms, {start}"


class _Measured:
    """One stored run, its signals loaded once, its metrics at each transient computed
    once (`_measured` keeps one per run)."""

    def __init__(self, stored) -> None:
        self.stored, self._result, self._metrics = stored, None, {}

    @property
    def result(self):
        if self._result is None:
            self._result = self.stored.load()
        return self._result

    def metrics(self, transient: float | None = None) -> dict:
        """The metrics after ``transient`` (None: the scenario's own, as stored — computed
        from the float64 signals; the stored file's float32 copy would differ in the last
        digits, and the family must contain the stored value itself)."""
        if transient is None or transient == float(self.stored.config.get("transient", 2.0)):
            return self.stored.metrics
        if transient not in self._metrics:
            self._metrics[transient] = all_metrics(self.result, transient)
        return self._metrics[transient]

    def value(self, claim: Claim, transient: float | None = None):
        return claim.measure(self.metrics(transient), self.result)


def _measured(stored, cache: dict) -> _Measured:
    key = getattr(stored, "run_id", id(stored))
    if key not in cache:
        cache[key] = _Measured(stored)
    return cache[key]


def _plant(stored) -> str:
    return stored.config["plant"]["kind"]


def _window_family(claim: Claim, run: _Measured) -> tuple:
    """(transient, value, holds/fails) of ``claim`` over `WINDOWS` (those shorter than the
    run)."""
    duration = float(run.stored.config["duration"])
    out = []
    for T in WINDOWS:
        if T < duration:
            value = run.value(claim, T)[0]
            out.append((T, value, claim.judge(value)))
    return tuple(out)


def _flip_note(family: tuple) -> str:
    """"fails for transient 1–2.5 s, holds for transient 3–4 s"."""
    spans: list[list] = []
    for T, _, verdict in family:
        if spans and spans[-1][0] == verdict:
            spans[-1][2] = T
        else:
            spans.append([verdict, T, T])
    return ", ".join(f"{v} for transient {a:g}" + (f"–{b:g} s" if b != a else " s")
                     for v, a, b in spans)


def _mesh_values(claim: Claim, run: _Measured, checks: dict,
                 cache: dict) -> tuple[bool | None, tuple]:
    """(converged?, ((mesh label, value or status text), ...)) of ``claim`` on the run's
    mesh and its check meshes; converged is None when a check has not been run."""
    own = mesh_check.mesh_label(run.stored.config["plant"]["mesh"])
    value = run.value(claim)[0]
    values = [(own, value)]
    converged: bool | None = True
    for label, other in checks.items():
        if other is None:
            values.append((label, "not run"))
            converged = None
            continue
        if other.status != "ok":
            values.append((label, f"{other.status} at {other.end_time:g} s"))
            if converged:
                converged = False
            continue
        other_value = _measured(other, cache).value(claim)[0]
        values.append((label, other_value))
        if converged and not mesh_check.agrees(value, other_value, claim.bound):
            converged = False
    return converged, tuple(values)


def _mesh_text(claim: Claim, values: tuple) -> str:
    from ..report.render import fmt_number
    return ", ".join(f"{label}: " + (v if isinstance(v, str) else
                                      "never" if math.isinf(v) else
                                      f"{fmt_number(v)} {claim.unit}".strip())
                     for label, v in values)


def evaluate(claim: Claim, stored, checks: dict | None = None, *,
             cache: dict | None = None) -> Verdict:
    """The verdict of ``claim`` on one stored run (None: not run).  ``checks``: its
    mesh-check runs ({label: stored run or None}), for a truth-plant run; None for the
    reduced plant.  ``cache`` shares loaded signals and metrics between calls."""
    if stored is None:
        return Verdict(math.nan, "not run")
    if stored.status != "ok":
        return Verdict(math.nan, stored.status, stored.message)
    cache = {} if cache is None else cache
    run = _measured(stored, cache)
    value, note = run.value(claim)
    verdict = claim.judge(value)
    if verdict == "n/a":
        return Verdict(value, verdict, note)
    meshes: tuple = ()
    if _plant(stored) == "exudyn":
        if not checks:
            return Verdict(value, "mesh not checked", note)
        converged, meshes = _mesh_values(claim, run, checks, cache)
        if converged is None:
            return Verdict(value, "mesh not checked", note, meshes=meshes)
        if not converged:
            return Verdict(value, "not converged", _mesh_text(claim, meshes), meshes=meshes)
    windows = _window_family(claim, run) if claim.windowed else ()
    if len({v for _, _, v in windows} | {verdict}) > 1:
        note = f"{_flip_note(windows)}; {note}" if note else _flip_note(windows)
        return Verdict(value, "window-sensitive", note, windows, meshes)
    return Verdict(value, verdict, note, windows, meshes)


def claim_columns(runs) -> list[Column]:
    """Columns of verdicts from stored runs (objects with ``name``, ``config``,
    ``status``, ``message``, ``metrics``, ``sweep``, ``plant``, ``run_id`` and ``load()``),
    sorted by arm, plant, Ts, start.  Mesh-check runs among ``runs`` are used as the
    checks of the runs they refine, never as columns of their own."""
    runs = list(runs)
    by_id = {r.run_id: r for r in runs}
    groups: dict[tuple, dict] = {}
    wanted = {c.run for c in CLAIMS}
    for r in runs:
        short = r.name.split("/")[-1]
        if short in wanted and not mesh_check.is_check(r):
            groups.setdefault(column_key(r.config), {})[short] = r
    columns, cache = [], {}
    order = {"default": 0, "table1": 1, "reduced": 0, "exudyn": 1, "rest": 0, "reference": 1}
    for key in sorted(groups, key=lambda k: (order.get(k[0], 9), order.get(k[1], 9), -k[2],
                                             order.get(k[3], 9))):
        runs_here = groups[key]
        checks = {name: mesh_check.checks_of(r, by_id) for name, r in runs_here.items()}
        columns.append(Column(key, runs_here, {
            c.key: evaluate(c, runs_here.get(c.run), checks.get(c.run), cache=cache)
            for c in CLAIMS},
            checks))
    return columns


# --- mesh convergence of the truth-plant runs -------------------------------------------------
@dataclass(frozen=True)
class MeshRow:
    """One judged value of one truth-plant run on each mesh."""

    run: object  # the stored run on its own mesh
    claim: Claim
    converged: bool | None  # None: a check was not run
    values: tuple  # ((mesh label, value or status text), ...)


def mesh_rows(runs) -> list[MeshRow]:
    """For every truth-plant run among ``runs`` that has checks stored, each claim that
    applies to it (value not NaN), on every mesh; a run that did not complete gives one
    row comparing statuses."""
    runs = list(runs)
    by_id = {r.run_id: r for r in runs}
    out, cache = [], {}
    for r in runs:
        if _plant(r) != "exudyn" or mesh_check.is_check(r):
            continue
        checks = mesh_check.checks_of(r, by_id)
        if not any(checks.values()):
            continue
        if r.status != "ok":
            values = [(mesh_check.mesh_label(r.config["plant"]["mesh"]),
                       f"{r.status} at {r.end_time:g} s")]
            agree = True
            for label, other in checks.items():
                values.append((label, "not run" if other is None else
                               f"{other.status}" + (f" at {other.end_time:g} s"
                                                    if other.status != "ok" else "")))
                agree = agree and other is not None and mesh_check.status_agrees(r, other)
            out.append(MeshRow(r, None, agree, tuple(values)))
            continue
        run = _measured(r, cache)
        for claim in CLAIMS:
            if math.isnan(run.value(claim)[0]):
                continue
            converged, values = _mesh_values(claim, run, checks, cache)
            out.append(MeshRow(r, claim, converged, values))
    return out


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
        return f"{run.status} on every mesh ({labels})"
    moved = [k for k, v in verdicts.items() if v.verdict == "not converged"]
    if moved:
        return f"NOT CONVERGED against {labels}: {', '.join(moved)}"
    if any(v is None for v in checks.values()):
        return f"checks incomplete ({labels})"
    return f"converged against {labels}"


# --- tables ---------------------------------------------------------------------------------
def cell_text(claim: Claim, v: Verdict) -> str:
    """One cell: "0.00963 rad — holds (note)", or what happened instead of a value (the
    reason of a divergence is in the table's "run" row)."""
    if v.verdict in ("diverged", "failed"):
        return f"— ({v.verdict})"
    if v.verdict in ("not run", "n/a"):
        return v.verdict + (f" ({v.note})" if v.note else "")
    if v.verdict == "not converged":
        return f"not converged ({v.note})"
    from ..report.render import fmt_number
    value = "never" if math.isinf(v.value) else f"{fmt_number(v.value)} {claim.unit}".strip()
    return f"{value} — {v.verdict}" + (f" ({v.note})" if v.note else "")


def claims_tables(columns: list[Column]) -> list[dict]:
    """Per arm: column labels, one row of cell texts per claim (with the failure it
    guards), the run row and the mesh row (for the templates)."""
    from ..run.scenario import ARMS
    tables = []
    for arm in dict.fromkeys(c.arm for c in columns):
        cols = [c for c in columns if c.arm == arm]
        rows = [{"claim": "run of the system (" + SYSTEM + ")", "key": "run", "guards": "",
                 "cells": [_run_text(c.runs.get(SYSTEM)) for c in cols],
                 "verdicts": [c.runs[SYSTEM].status if SYSTEM in c.runs else "not run"
                              for c in cols]},
                mesh_row(cols)]
        rows += [{"claim": claim.text, "key": claim.key, "guards": claim.guards,
                  "cells": [cell_text(claim, c.verdicts[claim.key]) for c in cols],
                  "verdicts": [c.verdicts[claim.key].verdict for c in cols]}
                 for claim in CLAIMS]
        rows += _requirement_rows(cols)
        tables.append({"arm": arm, "arm_text": ARMS.get(arm, arm),
                       "columns": [c.label for c in cols], "rows": rows,
                       "notes": arm_notes(cols)})
    return tables


def mesh_row(columns: list[Column]) -> dict:
    """The claims table's row saying, per column, whether the system's truth-plant run
    survived the mesh refinement (cells and their verdicts)."""
    return {"claim": "truth plant under mesh refinement (closed loop)", "key": "mesh",
            "guards": "results of the FE discretisation taken for the arm's",
            "cells": [mesh_status(c.runs[SYSTEM], c.checks.get(SYSTEM), c.verdicts)
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
    from reduced_model import ArmParameters
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
                "(README.md, 'Mesh convergence of the truth plant').")
            break
    return notes


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
                     "guards": "", "cells": cells, "verdicts": verdicts})
    return rows


def _run_text(run) -> str:
    if run is None:
        return "not run"
    if run.status == "ok":
        return f"ok, {run.end_time:g} s"
    return f"{run.status.upper()}: {run.message}"


def claims_records(columns: list[Column]) -> list[dict]:
    """Long-format rows of claims.csv: what was run, the claim, value, verdict, and the
    values over the window family and the meshes."""
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
                            "windows": " ".join(f"{T:g}:{x:.6g}" for T, x, _ in v.windows),
                            "meshes": "; ".join(f"{label}: {x if isinstance(x, str) else f'{x:.6g}'}"
                                                for label, x in v.meshes),
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
