"""The evaluations of ``flexarm verify``'s searches: scenarios run on the campaign runner,
stored in the results folder and read back, counted per plant; the robustness ρ a stored
run counts for; the verdict file and the replayable scenario files a search writes.

Every evaluation is a run on the campaign runner (`run_campaign` on a local pool or
Dask), stored in the results folder as it finishes.  A search is a deterministic
function of its seed and of the stored values (the optimiser's randomness is seeded,
values are read back from the store), so after an interruption the same command replays
the stored evaluations without simulating them and continues to the same answer.
Simulations are counted per plant as the distinct scenarios a search asked for.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..batch.campaign import PlannedRun
from ..batch.queue import Batch, answer_all
from ..batch.store.folder import ResultStore, run_id
from ..run.config import ConfigError
from ..run.requirements import Requirement
from ..run.results import write_atomic
from ..run.scenario import scenario_to_mapping
from ..run.tomlfiles import toml_text

__all__ = ["ROBUST_SWEEPS", "FIT_SWEEP", "effective_rho", "Evaluations", "ask", "asked",
           "point_axes", "number", "write_verdict", "write_scenario"]

#: The sweep names the evaluations are stored under (reports keep them apart).
ROBUST_SWEEPS = ("estimate", "falsify", "conform")
#: The sweep the calibration's simulations are stored under (reports keep them apart too).
FIT_SWEEP = "calibrate"


def effective_rho(row, requirement: Requirement) -> float | None:
    """ρ of a stored run as the verdicts count it: −∞ for a run that diverged (it failed
    every requirement), None for a run that failed (no data); ConfigError if the
    requirement does not apply to the run (e.g. an estimation claim without observer)."""
    if row.status == "diverged":
        return -math.inf
    if row.status != "ok":
        return None
    value = row.metrics.get(requirement.metric, math.nan)
    if not isinstance(value, float) or math.isnan(value):
        raise ConfigError(f"--requirement {requirement.name}",
                          f"{requirement.text} has no value on run {row.run_id} (it does not "
                          "apply to this system)")
    return value


@dataclass
class Evaluations:
    """Scenarios run on the campaign runner into ``out`` (a folder, or a `BaseStore`: an
    in-memory one) and read back; simulations counted per plant role (distinct scenarios
    asked for).  A search asks with `run`; a question answered beside others (`queue`)
    yields `batch` and hands the rows it is sent to `record`."""

    out: object
    runner: object
    name: str
    seen: set = field(default_factory=set)
    count: dict = field(default_factory=lambda: {"reduced": 0, "truth": 0})
    failed: list = field(default_factory=list)
    description: str = "verdicts over uncertainty (flexarm verify)"  # the campaign's

    def __post_init__(self):
        self.store = ResultStore(self.out) if isinstance(self.out, (str, Path)) else self.out

    def batch(self, items: list[tuple]) -> Batch:
        """The batch of ``items`` = [(scenario, sweep, axes)]."""
        planned = [PlannedRun(run_id(scenario_to_mapping(scenario)), scenario, sweep, axes)
                   for scenario, sweep, axes in items]
        return Batch(self.out, self.name, planned, description=self.description)

    def record(self, batch: Batch, rows: list) -> list:
        """``rows`` (a batch's, in order), counted: simulations per plant, failed runs."""
        for p, row in zip(batch.runs, rows):
            if p.run_id not in self.seen:
                self.seen.add(p.run_id)
                self.count[p.scenario.plant.role] += 1
                if row.status == "failed":
                    self.failed.append(p.run_id)
        return rows

    def run(self, items: list[tuple]) -> list:
        """Rows of ``items`` = [(scenario, sweep, axes)], in order (run if not stored)."""
        batch = self.batch(items)
        return self.record(batch, answer_all([ask(batch)], self.runner)[0])

    def finish(self) -> None:
        """Export metrics.csv and manifest.json once (not after every batch)."""
        self.store.export()
        self.store.close()

    @property
    def simulations(self) -> dict:
        return dict(self.count)


def ask(batch: Batch):
    """A question of one batch: its answer is the batch's rows."""
    return (yield batch)


def point_axes(point: dict, **extra) -> dict:
    """The axes a point is stored under (plain floats)."""
    return {**extra, **{k: (float(v) if isinstance(v, (float, np.floating)) else v)
                        for k, v in point.items()}}


def number(value):
    """A JSON-safe number: None for NaN and ±∞ (the verdict says why elsewhere)."""
    return float(value) if value is not None and math.isfinite(value) else None


def write_verdict(out: Path, verdict: dict) -> Path:
    """Write ``verdict`` as OUT/verdict.json (strict JSON: no NaN)."""
    path = Path(out) / "verdict.json"
    write_atomic(path, lambda fh: json.dump(verdict, fh, indent=1, allow_nan=False))
    return path


def write_scenario(out: Path, name: str, mapping: dict, comment: str) -> str:
    """Write a stored run's scenario ``mapping`` as the scenario file ``out/name`` that
    ``flexarm run --config`` replays: its run named by its label, as a scenario file
    names its one run (a plain name; "<campaign>/<label>" is a campaign's run)."""
    mapping = dict(mapping, name=mapping["name"].split("/")[-1])
    text = "".join(f"# {line}\n" for line in comment.splitlines()) + toml_text(mapping)
    write_atomic(Path(out) / name, lambda fh: fh.write(text))
    return name


def asked(ev: Evaluations, items: list[tuple]):
    """Ask for ``items``' rows (a question's step: ``rows = yield from asked(...)``)."""
    batch = ev.batch(items)
    return ev.record(batch, (yield batch))
