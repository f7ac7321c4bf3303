"""The paper's claims (Section 5) as criteria that a perfect system passes and a useless
one fails, checked on every arm of the paper's shape (two flexible links, horizontal:
`validation.run.arms.paper_shaped`), plant, sampling period and initial condition run;
runs on other arms are judged by the requirements a user states.

Each `Claim` (defined with its measure in `validation.run.claim_measures`, so that a
run's worker can compute its robustness) turns a sentence of the paper into a number
measured on stored runs (a pure measurement: value and note) and a bound, with the reason for both and the failure the
row guards against.  The paper's system is the PBC fed by the sign SMO (run name
``pbc+smo-paper``); the disturbance claim uses the same system with a torque pulse
(``pbc+smo-paper+disturbance``).  Runs are grouped into *columns* by what was run: arm,
plant, control period Ts and initial condition.  A column whose run diverged says so with
the reason and time — a result, not a hole.

A verdict is given only after two checks, in this order (README, *Verdicts*):

1. **Convergence** (truth plant only): the claim's value on the run's mesh and in its
   checks — the mesh and the step refined together twice, and the other element
   formulation (`validation.verdicts.mesh`) — must agree within the stated tolerance;
   otherwise the cell is "not converged" with every check's value.  The value carries
   the estimated error of the sequence (Richardson).  A truth-plant run without stored
   checks is "mesh not checked".  A value whose margin to the bound is not larger than
   that error is "undecided at this resolution" (`validation.verdicts.resolution`).
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
from ..run.arms import paper_shaped
from ..run.plants import is_truth, label_of, plant_settings
from ..run.metrics import all_metrics
from ..run.scenario import scenario_from_mapping
from . import mesh as mesh_check
from .resolution import UNDECIDED, judged
from .stability import StabilityResult, cases_from_scenarios

__all__ = ["Claim", "CLAIMS", "Verdict", "Column", "evaluate", "claim_columns", "finer_runs",
           "beyond_every_limit",
           "SYSTEM", "DISTURBED", "CLAIM_RUNS", "WINDOWS", "column_key", "claims_records",
           "mesh_rows", "MeshRow"]

#: The names of the runs the claims are judged on (a campaign's other runs decide none).
CLAIM_RUNS = frozenset(c.run for c in CLAIMS)
#: The family of transients [s] every windowed claim is measured over.
WINDOWS = (1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0)


@dataclass(frozen=True)
class Verdict:
    """A claim on one run.  ``verdict``: "holds" | "fails" | "window-sensitive" |
    "undecided at this resolution" | "not converged" | "mesh not checked" | "diverged" | "failed" | "not run" | "n/a";
    ``value`` at the scenario's transient on the run's own mesh; ``windows``: (transient,
    value, holds/fails) over `WINDOWS`; ``meshes``: (mesh label, value or status)."""

    value: float
    verdict: str
    note: str = ""
    windows: tuple = ()
    meshes: tuple = ()
    error: float = math.nan  # estimated discretisation error of ``value`` (truth plant)
    order: float = math.nan  # observed order of the refined sequence (NaN: not observed)


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
    def plant(self) -> str:
        """The plant, as tables name it: "truth plant (Exudyn)"."""
        return label_of(next(iter(self.runs.values())).config)

    @property
    def condition(self) -> str:
        """The control period and the initial condition: "Ts = 1 ms, from rest"."""
        _, _, Ts, ic = self.key
        start = "from rest" if ic == "rest" else "moving with the reference"
        return f"Ts = {Ts * 1e3:g} ms, {start}"

    @property
    def label(self) -> str:
        return f"{self.plant}, {self.condition}"


class _Measured:
    """One stored run, its signals loaded once (``signals``: (run, names) → those signals,
    every one for no names), its metrics at each transient computed once (`_measured`
    keeps one per run).  A claim that reads signals asks for its own (`Claim.signals`):
    a mesh-check run's file keeps them (`mesh.CHECK_KEEP`) and is read, not re-simulated."""

    def __init__(self, stored, signals) -> None:
        self.stored, self.signals, self._result, self._metrics = stored, signals, None, {}

    @property
    def result(self):
        if self._result is None:
            self._result = self.signals(self.stored, ())
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
        if not claim.signals:
            return claim.measure(self.metrics(transient), None)
        if transient is None and self._result is None:  # the claim's own signals suffice
            return claim.measure(self.metrics(), self.signals(self.stored, claim.signals))
        return claim.measure(self.metrics(transient), self.result)


class _Cache(dict):
    """Measured runs by id, and how their signals are had ((a run, names) → those
    signals, every one for no names; default: the run object's own ``load()``, a run held
    in memory)."""

    def __init__(self, signals=None) -> None:
        super().__init__()
        self.signals = signals or (lambda run, names=(): run.load())


def _may_apply(claim: Claim, run) -> bool:
    """Whether ``claim`` is worth measuring on stored ``run`` when every run is scanned: a
    claim that reads signals only on its own runs (`Claim.run`), so that a run keeping only
    its metrics is never re-simulated to find that the claim does not apply."""
    return not claim.signals or run.name.split("/")[-1] == claim.run


def _measured(stored, cache: _Cache) -> _Measured:
    key = getattr(stored, "run_id", id(stored))
    if key not in cache:
        cache[key] = _Measured(stored, cache.signals)
    return cache[key]


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
    mesh and its check meshes; converged is None when a check that could change the
    verdict has not been run (a second level the first decides is "not needed":
    `mesh.second_level_needed`)."""
    own = plant_settings(run.stored.config["plant"]).discretisation()
    value = run.value(claim)[0]
    values = [(own, value)]
    converged: bool | None = True
    levels = {r.label: r.level for r in mesh_check.refinements(run.stored.config)}
    first = None  # the value on level 1, where it completed
    for label, other in checks.items():
        if other is None:
            needed = levels.get(label) != 2 or (
                first is not None and mesh_check.second_level_needed(value, first, claim.bound))
            values.append((label, "not run" if needed else mesh_check.NOT_NEEDED))
            if needed and converged:
                converged = None
            continue
        if other.status != "ok":
            values.append((label, f"{other.status} at {other.end_time:g} s"))
            if converged:
                converged = False
            continue
        other_value = _measured(other, cache).value(claim)[0]
        if levels.get(label) == 1:
            first = other_value
        values.append((label, other_value))
        if converged and not mesh_check.agrees(value, other_value, claim.bound):
            converged = False
    return converged, tuple(values)


def finer_runs(rows, signals=None) -> list:
    """The truth-plant runs among stored ``rows`` whose level-1 check leaves a judged
    value's verdict open (`mesh.second_level_needed`, for any claim that applies to the
    run): their level 2 is worth running.  ``signals``: as `claim_columns`'."""
    rows = list(rows)
    by_id = {r.run_id: r for r in rows}
    out, cache = [], _Cache(signals)
    for r in rows:
        if not is_truth(r.config) or mesh_check.is_check(r) or r.status != "ok":
            continue
        label = next((c.label for c in mesh_check.refinements(r.config) if c.level == 1), None)
        first = mesh_check.checks_of(r, by_id).get(label)
        if first is None or first.status != "ok":
            continue
        run = _measured(r, cache)
        for claim in (c for c in CLAIMS if _may_apply(c, r)):
            value = run.value(claim)[0]
            if not math.isnan(value) and mesh_check.second_level_needed(
                    value, _measured(first, cache).value(claim)[0], claim.bound):
                out.append(r)
                break
    return out


def beyond_every_limit(results: list[StabilityResult], rows) -> set[str]:
    """The ids of the stored runs among ``rows`` that diverged at a control period at or
    beyond their case's first divergence on every level of the stability map
    (``results``): a divergence the map explains (their mesh checks would decide
    nothing)."""
    first = {}
    for r in results:
        highs = [high for _, _, high in r.resolved["divergence"].levels]
        if highs and not any(math.isnan(h) for h in highs):
            first[r.case.key] = max(highs)
    out = set()
    for row in rows:
        if row.status != "diverged":
            continue
        (case,) = cases_from_scenarios([scenario_from_mapping(row.config)]) or (None,)
        if case is not None and float(row.config["Ts"]) >= first.get(case.key, math.inf):
            out.add(row.run_id)
    return out


def _mesh_text(claim: Claim, values: tuple) -> str:
    """"ANCF 4: 0.0075 rad, ANCF 8: 0.0049 rad, …" (a status text as it is)."""
    return ", ".join(f"{label}: " + (v if isinstance(v, str) else "never" if math.isinf(v)
                                      else "n/a" if math.isnan(v)
                                      else f"{v:.3g} {claim.unit}".strip())
                     for label, v in values)


def evaluate(claim: Claim, stored, checks: dict | None = None, *,
             cache: _Cache | None = None) -> Verdict:
    """The verdict of ``claim`` on one stored run (None: not run).  ``checks``: its
    mesh-check runs ({label: stored run or None}), for a truth-plant run; None for the
    reduced plant.  ``cache`` shares loaded signals and metrics between calls, and says
    how signals are had (`_Cache`)."""
    if stored is None:
        return Verdict(math.nan, "not run")
    if stored.status != "ok":
        return Verdict(math.nan, stored.status, stored.message)
    cache = _Cache() if cache is None else cache
    run = _measured(stored, cache)
    value, note = run.value(claim)
    verdict = claim.judge(value)
    if verdict == "n/a":
        return Verdict(value, verdict, note)
    meshes, estimate = (), {}
    if is_truth(stored.config):
        if not checks:
            return Verdict(value, "mesh not checked", note)
        converged, meshes = _mesh_values(claim, run, checks, cache)
        order, error = mesh_check.sequence_estimate(stored.config, value, dict(meshes))
        estimate = {"error": error, "order": order}
        if converged is None:
            return Verdict(value, "mesh not checked", note, meshes=meshes, **estimate)
        if not converged:
            return Verdict(value, "not converged", _mesh_text(claim, meshes), meshes=meshes,
                           **estimate)
        if judged(verdict, value - claim.bound, estimate["error"]) == UNDECIDED:
            return Verdict(value, UNDECIDED, f"the margin to the bound is inside the value's "
                           f"estimated error, ±{estimate['error']:.2g} {claim.unit}".strip(),
                           meshes=meshes, **estimate)
    windows = _window_family(claim, run) if claim.windowed else ()
    if len({v for _, _, v in windows} | {verdict}) > 1:
        note = f"{_flip_note(windows)}; {note}" if note else _flip_note(windows)
        return Verdict(value, "window-sensitive", note, windows, meshes, **estimate)
    return Verdict(value, verdict, note, windows, meshes, **estimate)


def claim_columns(runs, signals=None) -> list[Column]:
    """Columns of verdicts from stored runs (objects with ``name``, ``config``,
    ``status``, ``message``, ``metrics``, ``sweep``, ``plant``, ``run_id``), sorted by
    arm, plant, Ts, start; ``signals``: (a run, names) → those signals, every one for no
    names (e.g. `every_signal` of its store; default: the run object's own ``load()``).
    Mesh-check runs among ``runs`` are used as the checks of the runs they refine, never
    as columns of their own; runs on arms not of the paper's shape are no column."""
    runs = list(runs)
    by_id = {r.run_id: r for r in runs}
    groups: dict[tuple, dict] = {}
    for r in runs:
        short = r.name.split("/")[-1]
        if (short in CLAIM_RUNS and not mesh_check.is_check(r)
                and paper_shaped(r.config["true_params"])):
            groups.setdefault(column_key(r.config), {})[short] = r
    columns, cache = [], _Cache(signals)
    order = {"default": 0, "table1": 1, "rest": 0, "reference": 1}
    truth = {k: is_truth(next(iter(g.values())).config) for k, g in groups.items()}
    for key in sorted(groups, key=lambda k: (order.get(k[0], 9), truth[k], k[1], -k[2],
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
    order: float = math.nan  # observed order of the refined sequence (`mesh.richardson`)
    error: float = math.nan  # estimated error of the nominal value


def mesh_rows(runs, signals=None) -> list[MeshRow]:
    """For every truth-plant run among ``runs`` that has checks stored, each claim that
    applies to it (value not NaN), on every mesh; a run that did not complete gives one
    row comparing statuses.  ``signals``: as `claim_columns`'."""
    runs = list(runs)
    by_id = {r.run_id: r for r in runs}
    out, cache = [], _Cache(signals)
    for r in runs:
        if r.role != "truth" or mesh_check.is_check(r):
            continue
        checks = mesh_check.checks_of(r, by_id)
        if not any(checks.values()):
            continue
        if r.status != "ok":
            values = [(plant_settings(r.config["plant"]).discretisation(),
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
            if not _may_apply(claim, r) or math.isnan(run.value(claim)[0]):
                continue
            converged, values = _mesh_values(claim, run, checks, cache)
            order, error = mesh_check.sequence_estimate(r.config, values[0][1], dict(values))
            out.append(MeshRow(r, claim, converged, values, order, error))
    return out


# --- tables ---------------------------------------------------------------------------------
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
                            "error": v.error, "order": v.order,
                            "verdict": v.verdict, "note": v.note,
                            "windows": " ".join(f"{T:g}:{x:.6g}" for T, x, _ in v.windows),
                            "meshes": "; ".join(f"{label}: {x if isinstance(x, str) else f'{x:.6g}'}"
                                                for label, x in v.meshes),
                            "run_id": run.run_id if run else ""})
    return records


