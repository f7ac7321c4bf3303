"""Error-bound regression: named checks of metrics against bounds kept in the repository.

``baselines.toml`` (repository root) holds a margin policy, short named scenarios, and
checks::

    [policy]
    relative = 0.25            # new bound = measured·(1 + relative) + absolute  (for "<=")
    absolute = 1e-4            #            measured·(1 − relative) − absolute  (for ">=")

    [scenarios.pbc-exudyn]     # any scenario keys; ≤ 5 s keeps `make test` short
    duration = 5.0
    plant.kind = "exudyn"

    [[check]]
    name = "pbc-tracking-exudyn"
    scenario = "pbc-exudyn"            # or: campaign = "paper", run = "pbc", plant = "exudyn"
    metric = ["track_max_1", "track_max_2"]   # one key, or several: their maximum
    op = "<="
    bound = 0.02
    measured = 0.0158                  # when the bound was set

A "frequency" check needs no simulation: ``kind = "frequency"`` compares the reduced
model's and the FE model's natural frequencies (``joints``, ``theta2``, ``mode``) and its
metric is the relative gap |f_reduced − f_FE| / f_FE.  Checks that name a shipped
campaign's run are the "full" tier (20 s, `make test-all`); the rest are "short".
"""
from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..run.config import ConfigError, check, check_known, check_label
from ..batch.campaign import expand, load_campaign
from ..batch.worker import execute_run
from ..batch.fingerprint import run_fingerprint
from ..run.results import write_atomic
from ..run.scenario import PLANT_KINDS, scenario_from_mapping, scenario_to_mapping
from ..batch.store.folder import INDEX_NAME, ResultStore, StoreError, run_id
from ..run.tomlfiles import flatten, load_toml, set_dotted, toml_value

__all__ = ["Check", "Baselines", "load_baselines", "measure", "evaluate", "updated_bound",
           "proposed_bounds", "write_baselines", "check_from_run", "parse_margin",
           "DEFAULT_FILE"]

DEFAULT_FILE = Path(__file__).resolve().parents[2] / "baselines.toml"
#: The numerical precision of each kind of metric (glob of its key, first match): two
#: machines' values of the same check may differ by this much (BLAS kernels, compilers,
#: thread counts), so a bound stands at least this far from the value it was set from, and
#: `update` keeps a stored bound whose measured value moved by less.
PRECISION = (
    # Relative FE frequency gap: the FE eigenvalues carry cond(K)·eps ≈ 2e-7 (the axial
    # modes at 0.5-26 kHz over the 0.63 Hz bending mode give cond ≈ 2e9); measured 9.3e-9
    # on one machine and 8.5e-8 on another for the same check.
    ("gap", 1e-6),
    # Everything a run measures (angles [rad], lengths [m], rates, ratios, ρ): the truth
    # plant's Newton tolerance is 1e-6; the reduced plant is far more precise.
    ("*", 1e-6),
)
_CHECK_KEYS = {"name", "kind", "scenario", "campaign", "run", "plant", "arm", "initial_state",
               "metric", "op", "bound", "measured", "joints", "theta2", "mode", "margin", "note"}


@dataclass(frozen=True)
class Check:
    name: str
    metric: tuple[str, ...]
    op: str
    bound: float
    measured: float | None = None
    kind: str = "run"  # "run" | "frequency"
    scenario: str | None = None
    campaign: str | None = None
    run: str | None = None
    plant: str | None = None
    arm: str = "default"  # for campaign checks: which arm and start the run has
    initial_state: str = "rest"
    joints: str = "locked"
    theta2: float = 0.0
    mode: int = 1
    margin: float | None = None  # overrides the policy's relative margin
    note: str = ""

    @property
    def tier(self) -> str:
        return "full" if self.campaign else "short"

    @property
    def precision(self) -> float:
        """The numerical precision of this check's metric (`PRECISION`)."""
        return max(next(p for pattern, p in PRECISION if fnmatch.fnmatch(key, pattern))
                   for key in self.metric)

    def passes(self, value: float) -> bool:
        if not math.isfinite(value):
            return False
        return value <= self.bound if self.op == "<=" else value >= self.bound


@dataclass
class Baselines:
    path: Path
    relative: float
    absolute: float
    scenarios: dict
    checks: list[Check]
    header: str = ""
    extra: dict = field(default_factory=dict)


def load_baselines(path: str | Path = DEFAULT_FILE) -> Baselines:
    path = Path(path)
    data = load_toml(path)
    for key in data:
        check_known(key, ("policy", "scenarios", "check"), key)
    policy = data.get("policy", {})
    rel, absolute = policy.get("relative", 0.25), policy.get("absolute", 0.0)
    check(isinstance(rel, (int, float)) and rel >= 0, "policy.relative", "must be >= 0")
    check(isinstance(absolute, (int, float)) and absolute >= 0, "policy.absolute", "must be >= 0")
    scenarios = data.get("scenarios", {})
    for name, spec in scenarios.items():
        try:
            scenario_from_mapping(spec)
        except ConfigError as exc:
            raise exc.under(f"scenarios.{name}") from None
    checks, names = [], set()
    for i, raw in enumerate(data.get("check", [])):
        where = f"check[{i}]"
        check(isinstance(raw, dict), where, "must be a table ([[check]])")
        for key in raw:
            check_known(key, _CHECK_KEYS, f"{where}.{key}")
        for key in ("name", "op", "bound"):
            check(key in raw, f"{where}.{key}", "missing (a check needs name, op and bound)")
        check(isinstance(raw["bound"], (int, float)) and not isinstance(raw["bound"], bool),
              f"{where}.bound", f"must be a number, got {raw['bound']!r}")
        metric = raw.get("metric", "gap")
        metric = (metric,) if isinstance(metric, str) else tuple(metric)
        c = Check(**{**raw, "metric": metric, "bound": float(raw.get("bound", math.nan))})
        check(c.name not in names, f"{where}.name", f"duplicate check name {c.name!r}")
        names.add(c.name)
        check(c.op in ("<=", ">="), f"{where}.op", f"must be '<=' or '>=', got {c.op!r}")
        check(math.isfinite(c.bound), f"{where}.bound", "must be a finite number")
        check(c.kind in ("run", "frequency"), f"{where}.kind", "must be 'run' or 'frequency'")
        if c.kind == "run":
            check(bool(c.scenario) != bool(c.campaign), where,
                  "needs either scenario = NAME or campaign + run + plant")
            if c.scenario:
                check(c.scenario in scenarios, f"{where}.scenario",
                      f"no scenario {c.scenario!r} in [scenarios]")
            else:
                check(bool(c.run) and c.plant in PLANT_KINDS, where,
                      f"a campaign check needs run = NAME and plant = one of "
                      f"{', '.join(map(repr, PLANT_KINDS))}")
        checks.append(c)
    header = "".join(line + "\n" for line in path.read_text().splitlines()
                     if line.startswith("#")) if path.exists() else ""
    return Baselines(path, float(rel), float(absolute), scenarios, checks, header)


# --- measuring ---------------------------------------------------------------------------------
class _Runner:
    """Runs each distinct scenario once and stores it (the failure message names the file)."""

    def __init__(self, baselines: Baselines, out: str | Path, results: str | Path | None) -> None:
        self.b, self.store = baselines, ResultStore(out)
        # Verified runs made by this code are reused: the given folder's, then our own.
        self.reuse = [ResultStore(results)] if results else []
        if results and not self.reuse[0].exists():
            raise StoreError(f"--results {results}: not a results folder (no {INDEX_NAME})")
        self.reuse.append(self.store)
        self.cache: dict[str, tuple[dict, Path | None]] = {}

    def scenario_data(self, c: Check) -> dict:
        if c.scenario:
            return scenario_to_mapping(scenario_from_mapping(self.b.scenarios[c.scenario]))
        campaign = load_campaign(self.b.path.parent / "campaigns" / f"{c.campaign}.toml")
        wanted = f"{campaign.name}/{c.run}"
        for planned in expand(campaign):
            s = planned.scenario
            if (s.name, s.plant.kind, s.arm, s.initial_state, s.Ts) == (
                    wanted, c.plant, c.arm, c.initial_state, 1e-3):
                return scenario_to_mapping(s)
        raise ConfigError(f"check {c.name}", f"campaign {c.campaign!r} has no run {wanted!r} "
                                             f"on the {c.plant} plant, {c.arm} arm, from "
                                             f"{c.initial_state}, Ts = 1 ms")

    def _reusable(self, rid: str):
        """(store, row) of ``rid`` where it can be trusted: present, its file verified,
        made by this code; None if nowhere."""
        for store in self.reuse:
            if not store.exists():
                continue
            row = store.row(rid)
            if row is not None and row.fingerprint == run_fingerprint(row.config) \
                    and not store.verify([row]):
                return store, row
        return None

    def metrics(self, c: Check) -> tuple[dict, Path | None]:
        data = self.scenario_data(c)
        rid = run_id(data)
        if rid not in self.cache:
            found = self._reusable(rid)
            if found is not None:
                store, row = found
                self.cache[rid] = (row.metrics | {"status": row.status}, store.out / row.file)
            else:
                result, metrics = execute_run(data)
                path = self.store.add(rid, result, metrics)
                self.cache[rid] = (metrics, path)
        return self.cache[rid]


def _frequency_gap(c: Check, params) -> float:
    from plant_exudyn import Mesh, natural_frequencies
    from reduced_model import ArmModel
    model = ArmModel(params)
    Q = np.zeros(model.n)
    Q[1] = c.theta2
    reduced = model.natural_frequencies(Q, c.joints)[c.mode - 1]
    fe = natural_frequencies(params, Mesh(), theta=(0.0, c.theta2), joints=c.joints,
                             n=c.mode)[c.mode - 1]
    return abs(reduced - fe) / fe


def measure(c: Check, runner: _Runner) -> tuple[float, Path | None]:
    """The check's current value and the stored result it came from (if any)."""
    if c.kind == "frequency":
        from reduced_model import ArmParameters
        return _frequency_gap(c, ArmParameters()), None
    metrics, path = runner.metrics(c)
    if metrics.get("status") != "ok":
        return math.nan, path
    values = [metrics.get(k) for k in c.metric]
    missing = [k for k, v in zip(c.metric, values) if v is None]
    if missing:
        raise ConfigError(f"check {c.name}", f"the run has no metric {missing}")
    return float(max(values)), path


def evaluate(baselines: Baselines, *, out: str | Path, tier: str = "short",
             only: str | None = None, campaign: str | None = None,
             results: str | Path | None = None) -> list[dict]:
    """Measure the selected checks: rows of name, metric, op, bound, value, ok, path."""
    runner = _Runner(baselines, out, results)
    rows = []
    for c in baselines.checks:
        if tier != "all" and c.tier != tier and not (tier == "full" and c.kind == "frequency"):
            continue
        if only and not fnmatch.fnmatch(c.name, only):
            continue
        if campaign and c.campaign != campaign:
            continue
        value, path = measure(c, runner)
        rows.append({"check": c, "value": value, "ok": c.passes(value), "path": path})
    return rows


def updated_bound(c: Check, value: float, baselines: Baselines) -> float:
    """The margin policy: headroom relative to the measured value plus an absolute one, and
    never less than the metric's numerical precision (`Check.precision`), rounded to the 4
    significant digits the file stores."""
    rel = baselines.relative if c.margin is None else c.margin
    if c.op == "<=":
        return _stored(max(value * (1 + rel) + baselines.absolute, value + c.precision))
    return _stored(min(value * (1 - rel) - baselines.absolute, value - c.precision))


def _within_precision(c: Check, value: float) -> bool:
    """Whether ``value`` is the stored measurement again, up to the metric's precision,
    and the stored bound keeps that precision clear of it."""
    if c.measured is None or abs(value - c.measured) > c.precision:
        return False
    headroom = c.bound - c.measured if c.op == "<=" else c.measured - c.bound
    return headroom >= c.precision * (1 - 1e-3)  # the 4 stored digits round the bound


def _stored(value: float) -> float:
    """``value`` at the precision written to baselines.toml (4 significant digits)."""
    return float(f"{value:.4g}")


def proposed_bounds(rows: list[dict], baselines: Baselines) -> dict[str, dict]:
    """Per measurable check: the policy's bound and measured value at stored precision,
    whether it differs from the stored bound and whether it is looser.  A value within the
    metric's precision of the stored measurement keeps its bound (another machine's
    round-off is no change), and comparing at stored precision makes `update` idempotent:
    a second update changes nothing."""
    out = {}
    for r in rows:
        c, value = r["check"], r["value"]
        if not math.isfinite(value):
            continue
        if _within_precision(c, value):
            out[c.name] = {"bound": c.bound, "measured": c.measured, "looser": False,
                           "changed": False}
            continue
        bound = updated_bound(c, value, baselines)
        looser = bound > c.bound if c.op == "<=" else bound < c.bound
        out[c.name] = {"bound": bound, "measured": _stored(value), "looser": looser,
                       "changed": bound != c.bound}
    return out


# --- a check from a measured run ---------------------------------------------------------------
def parse_margin(text: str) -> float:
    """"25%" or "0.25" → 0.25; ConfigError naming ``--margin`` otherwise."""
    number = text.strip().removesuffix("%")
    try:
        value = float(number) / (100 if text.strip().endswith("%") else 1)
    except ValueError:
        raise ConfigError("--margin", f"expected a share such as 25% or 0.25, got {text!r}") \
            from None
    check(math.isfinite(value) and 0 <= value < 10, "--margin",
          f"must be between 0 % and 1000 %, got {text!r}")
    return value


def _scenario_name(run_name: str) -> str:
    """A run's name as a bare TOML key: "pbc+smo-paper@exudyn" → "pbc-smo-paper-exudyn"."""
    return "".join(c if c.isascii() and (c.isalnum() or c in "_-") else "-"
                   for c in run_name.split("/")[-1]).strip("-") or "run"


def check_from_run(baselines: Baselines, store, row, metric: tuple[str, ...], *, margin: float,
                   op: str = "<=", name: str | None = None) -> tuple[Baselines, Check]:
    """A new check of a stored run's ``metric`` (several: their maximum) at the value it
    measured, its bound set by ``margin`` (`updated_bound`); the run's scenario joins
    ``[scenarios]`` as the keys that differ from the defaults.  Returns the baselines with
    both added (not yet written: `write_baselines`) and the check.

    Parameters
    ----------
    baselines : Baselines
        The file to add to (`load_baselines`).
    row : StoredRun
        A run that completed, made by this code (its numbers are what a check measures).
    metric : tuple of str
        Metric keys of the run.
    margin : float
        Relative headroom of the bound (0.25: 25 %).
    op : {"<=", ">="}
        Which side of the bound holds.
    name : str, optional
        The check's name (default: the scenario's name and the metric).

    Returns
    -------
    (Baselines, Check)
    """
    where = f"{store.out}/{row.run_id}"
    check(row.status == "ok", "RESULTS/RUN", f"{where} {row.status}: a check needs a run that "
                                             "completed")
    check(row.fingerprint == run_fingerprint(row.config), "RESULTS/RUN",
          f"{where} was made by other code: its numbers are not what a check would measure "
          f"now (rerun it: flexarm run --like {where})")
    values = []
    for key in metric:
        value = row.metrics.get(key)
        check(isinstance(value, float) and math.isfinite(value), "--metric",
              f"{where} has no finite metric {key!r}" + ("" if key in row.metrics else
                                                         " (metric keys: docs/reference/metrics)"))
        values.append(value)
    # The defaults of a run as long (the transient's follows the duration).
    duration = {"duration": row.config["duration"]}
    defaults = flatten(scenario_to_mapping(scenario_from_mapping(duration)))
    spec = {k: v for k, v in flatten(row.config).items()
            if k != "name" and v is not None and defaults.get(k) != v}
    if scenario_from_mapping({}).duration != duration["duration"]:
        spec = duration | spec
    scenarios = dict(baselines.scenarios)
    label = next((n for n, s in scenarios.items() if flatten(s) == spec), None)
    if label is None:
        label = _scenario_name(row.name)
        label = next(f"{label}-{k}" if k else label for k in range(1000)
                     if (f"{label}-{k}" if k else label) not in scenarios)
        scenarios[label] = {}
        for key, value in spec.items():
            set_dotted(scenarios[label], key, value)
    name = name or f"{label}-{'-'.join(k.replace('_', '-') for k in metric)}"
    check_label(name, "--name")
    check(name not in {c.name for c in baselines.checks}, "--name",
          f"{baselines.path} already has a check named {name!r}")
    new = Check(name=name, metric=tuple(metric), op=op, bound=math.nan, scenario=label,
                margin=margin)
    measured = max(values)
    new = replace(new, bound=updated_bound(new, measured, baselines), measured=_stored(measured))
    return replace(baselines, scenarios=scenarios, checks=[*baselines.checks, new]), new


# --- writing --------------------------------------------------------------------------------
def write_baselines(b: Baselines, checks: list[Check]) -> None:
    """Rewrite the baselines file (atomically) with ``checks``."""
    lines = [b.header.rstrip("\n"), "", "[policy]", f"relative = {b.relative!r}",
             f"absolute = {b.absolute!r}", ""]
    for name, spec in b.scenarios.items():
        lines.append(f"[scenarios.{name}]")
        lines += [f"{k} = {toml_value(v)}" for k, v in flatten(spec).items()]
        lines.append("")
    for c in checks:
        lines.append("[[check]]")
        for key in ("name", "kind", "scenario", "campaign", "run", "plant", "arm",
                    "initial_state", "metric", "op", "bound", "measured", "joints", "theta2",
                    "mode", "margin", "note"):
            value = getattr(c, key)
            default = Check.__dataclass_fields__[key].default
            if value is None or (key not in ("name", "metric", "op", "bound") and value == default):
                continue
            if key == "metric":
                value = value[0] if len(value) == 1 else list(value)
            lines.append(f"{key} = {toml_value(value)}")
        lines.append("")
    text = "\n".join(lines).lstrip("\n")
    write_atomic(b.path, lambda fh: fh.write(text))
