"""The paper's claims (Section 5) checked on the reduced and the truth plant.

Each claim is turned into a number measured on stored runs of the paper campaign and a
threshold stated here; the verdict is "holds" or "fails" per plant.  The paper's system
is the PBC fed by the sign SMO (`pbc+smo-paper`); the disturbance claim uses the same
system with a torque pulse (`pbc+smo-paper+disturbance`).
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass

import numpy as np

from .results import write_atomic
from .store import ResultStore

__all__ = ["CLAIMS", "evaluate_claims", "write_claims"]

SYSTEM, DISTURBED = "pbc+smo-paper", "pbc+smo-paper+disturbance"


@dataclass(frozen=True)
class Claim:
    key: str
    text: str  # the paper's words, shortened
    criterion: str  # how we measure it
    run: str
    bound: float
    unit: str


CLAIMS = (
    Claim("tracking", "Fig. 3: precise tracking of eq. (37), minimal error",
          "max |θ − θd| after 2 s ≤ 0.02 (the paper's own 0.02 rad yardstick)", SYSTEM, 0.02, "rad"),
    Claim("vibration", "Fig. 4: tip vibration managed, acceptable residual vibration",
          "max tip deflection after 2 s ≤ 1 cm (2 % of a link)", SYSTEM, 0.01, "m"),
    Claim("estimation", "Fig. 7: estimation error bounded within 0.02 rad",
          "max |θ̂ − θ| after 2 s ≤ 0.02", SYSTEM, 0.02, "rad"),
    Claim("flexible_rates", "Fig. 7: flexible-mode estimation errors ~2e-3 rad/s",
          "max |q̂̇ − q̇| after 2 s ≤ 2e-3 (modal rates, m/s here)", SYSTEM, 2e-3, "m/s"),
    Claim("convergence", "errors converge rapidly to near zero",
          "every estimate within its tolerance from ≤ 1 s on", SYSTEM, 1.0, "s"),
    Claim("phase_angle", "Fig. 8: phase portrait within ±2 rad",
          "max |θ| after 2 s ≤ 2 rad (+1 %)", SYSTEM, 2.02, "rad"),
    Claim("phase_rate", "Fig. 8: phase portrait within ±1.2 rad/s",
          "max |θ̇| after 2 s ≤ 1.2 rad/s (+1 %); the reference itself peaks at 0.4π = 1.257",
          SYSTEM, 1.212, "rad/s"),
    Claim("disturbance", "effective rejection of external perturbations",
          "max |θ − θd| during and after a 1 N m, 0.2 s pulse on joint 1 ≤ 0.02", DISTURBED,
          0.02, "rad"),
)


def _value(claim: Claim, result, metrics: dict) -> float:
    t = result.time
    late = t >= 2.0
    if claim.key == "tracking":
        return max(metrics["track_max_1"], metrics["track_max_2"])
    if claim.key == "vibration":
        return float(np.abs(result.select(["tip_defl1", "tip_defl2"])[:, late]).max())
    if claim.key == "estimation":
        return max(metrics["est_max_theta1"], metrics["est_max_theta2"])
    if claim.key == "flexible_rates":
        return max(v for k, v in metrics.items() if k.startswith("est_max_q") and k.endswith("_dot"))
    if claim.key == "convergence":
        return max(v for k, v in metrics.items() if k.startswith("est_conv_"))
    if claim.key == "phase_angle":
        return float(np.abs(result.select(["theta1", "theta2"])[:, late]).max())
    if claim.key == "phase_rate":
        return float(np.abs(result.select(["theta1_dot", "theta2_dot"])[:, late]).max())
    if claim.key == "disturbance":
        start = min(d["start"] for d in result.config["disturbances"])
        after = t >= start
        err = result.select(["theta1", "theta2"]) - result.select(["theta1_ref", "theta2_ref"])
        return float(np.abs(err[:, after]).max())
    raise KeyError(claim.key)


def evaluate_claims(results_dir) -> list[dict]:
    """One row per claim: values and verdicts on the reduced and the truth plant."""
    store = ResultStore(results_dir)
    manifest = store.manifest()["runs"]
    metrics = {row["run_id"]: row for row in store.metrics()}
    rows = []
    for claim in CLAIMS:
        row = {"claim": claim.text, "criterion": claim.criterion, "unit": claim.unit}
        for plant, label in (("reduced", "reduced"), ("exudyn", "truth")):
            rid = next((rid for rid, e in manifest.items()
                        if e.get("name", "").split("/")[-1] == claim.run
                        and store.load(rid).config["plant"]["kind"] == plant), None)
            if rid is None:
                row[label], row[f"{label}_verdict"] = math.nan, "not run"
                continue
            result = store.load(rid)
            if result.status != "ok":
                row[label], row[f"{label}_verdict"] = math.nan, f"fails ({result.status})"
                continue
            value = _value(claim, result, metrics[rid])
            row[label] = value
            row[f"{label}_verdict"] = "holds" if value <= claim.bound else "fails"
        rows.append(row)
    return rows


def write_claims(results_dir) -> str:
    """Write claims.md and claims.csv in ``results_dir``; return the markdown table."""
    rows = evaluate_claims(results_dir)
    store = ResultStore(results_dir)
    lines = ["| claim (paper, Section 5) | criterion | reduced plant | truth plant (Exudyn) |",
             "|---|---|---|---|"]
    for r in rows:
        cells = [f"{r[p]:.3g} {r['unit']} — {r[p + '_verdict']}" if isinstance(r[p], float)
                 and not math.isnan(r[p]) else r[p + "_verdict"] for p in ("reduced", "truth")]
        lines.append(f"| {r['claim']} | {r['criterion']} | {cells[0]} | {cells[1]} |")
    table = "\n".join(lines)
    write_atomic(store.out / "claims.md", lambda fh: fh.write(table + "\n"))
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(store.out / "claims.csv", lambda fh: fh.write(buf.getvalue()))
    return table
