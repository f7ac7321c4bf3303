"""The sampled-data stability map: the largest control period Ts at which each controller
(+ observer) stays stable, per plant and per arm.

A design made in continuous time (the paper's) meets the real arm through a sampler and
a zero-order hold.  For each case this module runs short closed loops on a grid of Ts
(`GRID`, 0.1–10 ms), finds the largest grid value below which every run was stable, and
refines it by bisection on a log scale between that value and the next (unstable) one.

A run is *stable* if it completes without diverging and still tracks: max |θ − θ_d| over
its second half ≤ `TRACKING_LIMIT` (0.1 rad, five times the paper's 0.02 rad yardstick:
a loop that rings up slowly is caught even if it has not crossed the divergence bounds).
Runs start moving with the reference (no start-up kick) and last `DURATION` seconds.

The *predicted* limit explains what the map finds for the built-in joint-space laws: a
sampled rate feedback −G θ̇ on a plant of instantaneous mobility W (the joint block of
M⁻¹, flexible coupling included) is stable only if Ts·λ_max(W G) < 2, the stability
bound of the explicit Euler step it amounts to.  The joint-2 mobility of the paper's
Table-1 arm is 920 rad/(N m s²) — the motor-2 reaction acts on the link-1 tip, which has
almost no rotary inertia — against 91 with a 0.01 kg m² stator; G is K_d for PD,
M_θθ K_d for computed torque, M_θθ Λ + K_v for the PBC.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..run._config import ConfigError
from ..batch.campaign import PlannedRun, run_campaign, Campaign
from ..batch.executor import Runner
from ..run.laws import nominal_model
from ..run.scenario import (arm_parameters, scenario_from_mapping, scenario_to_mapping,
                            with_plant)
from ..batch.store import ResultStore, run_id

__all__ = ["GRID", "DURATION", "TRACKING_LIMIT", "StabilityCase", "StabilityResult",
           "cases_from_scenarios", "stability_map", "load_stability", "predicted_limit",
           "is_stable", "stability_rows", "write_stability"]

GRID = (1e-4, 2e-4, 5e-4, 1e-3, 2e-3, 5e-3, 1e-2)
DURATION = 2.0
TRACKING_LIMIT = 0.1
BISECTIONS = 3
_MAX_PLANT_STEP = 1e-3


@dataclass(frozen=True)
class StabilityCase:
    label: str  # e.g. "pbc+smo-paper"
    plant: str
    arm: str
    base: dict  # a resolved scenario mapping (Ts and plant step are set per run)


@dataclass
class StabilityResult:
    case: StabilityCase
    tested: dict  # Ts -> (stable, reason)
    largest_stable: float  # NaN if even the smallest Ts failed
    first_unstable: float  # NaN if every Ts was stable
    reason: str  # why the first unstable run was not stable
    predicted: float  # NaN when no prediction exists for the law

    @property
    def controller(self) -> str:
        return self.case.base["controller"]["kind"]

    @property
    def observer(self) -> str:
        return self.case.base["observer"]["kind"]


def _label(config: dict) -> str:
    c, o = config["controller"]["kind"], config["observer"]["kind"]
    return c if o == "none" else f"{c}+{o}"


def cases_from_scenarios(scenarios, *, plants=None, arms=None) -> list[StabilityCase]:
    """One case per distinct (controller + options, observer + options, plant, arm) among
    ``scenarios``; ``plants``/``arms`` (if given) replace the scenarios' own."""
    cases: dict[tuple, StabilityCase] = {}
    for s in scenarios:
        data = scenario_to_mapping(s)
        for plant in plants or (data["plant"]["kind"],):
            for arm in arms or (data["arm"],):
                base = dict(data, disturbances=[], initial_state="reference",
                            duration=DURATION, transient=DURATION / 2)
                base["plant"] = with_plant(base["plant"], plant)
                base["arm"] = arm
                params = scenario_to_mapping(arm_parameters(arm))
                if arm != data["arm"]:  # start the parameter tables from the other arm
                    base["true_params"] = base["nominal_params"] = params
                if plant == "exudyn" and data["controller"]["kind"] == "pbc-idealised":
                    continue  # two actuators: the idealised law cannot run there
                label = _label(base)
                key = (label, _options_key(base), plant, arm)
                base["name"] = f"stability/{label}"
                cases.setdefault(key, StabilityCase(label, plant, arm, base))
    return list(cases.values())


def _options_key(config: dict) -> str:
    import json
    return json.dumps([config["controller"], config["observer"]], sort_keys=True)


def _scenario_at(case: StabilityCase, Ts: float) -> dict:
    data = dict(case.base, Ts=Ts)
    data["plant"] = dict(case.base["plant"], step=Ts / math.ceil(Ts / _MAX_PLANT_STEP - 1e-9))
    return data


def is_stable(row) -> tuple[bool, str]:
    """(stable?, why not) of a stored stability run (module docstring)."""
    if row.status != "ok":
        return False, row.message or row.status
    worst = max(row.metrics.get("track_max_1", math.inf), row.metrics.get("track_max_2", math.inf))
    if not worst <= TRACKING_LIMIT:
        return False, f"max |θ − θd| = {worst:.3g} rad over the second half"
    return True, ""


def _planned(case: StabilityCase, Ts: float) -> PlannedRun:
    scenario = scenario_from_mapping(_scenario_at(case, Ts))
    rid = run_id(scenario_to_mapping(scenario))
    return PlannedRun(rid, scenario, "stability", {"Ts": Ts, "plant.kind": case.plant,
                                                   "arm": case.arm})


def stability_map(cases: list[StabilityCase], out, *, runner: Runner | None = None,
                  progress: bool = True) -> tuple[list[StabilityResult], object]:
    """Run the grid and the bisections for every case into the results folder ``out``
    (resumable like any campaign); returns the results and the last campaign summary."""
    campaign = Campaign(name="stability", base={}, sweeps=(),
                        description="sampled-data stability map")
    tested: dict[int, dict[float, tuple[bool, str]]] = {i: {} for i in range(len(cases))}
    store = ResultStore(out)

    def run(points: list[tuple[int, float]]):
        planned = {(i, Ts): _planned(cases[i], Ts) for i, Ts in points}
        summary = run_campaign(campaign, out, runner=runner, progress=progress,
                               only=list(planned.values()))
        if summary.interrupted:
            return summary
        rows = {r.run_id: r for r in store.rows()}
        for (i, Ts), p in planned.items():
            tested[i][Ts] = is_stable(rows[p.run_id])
        return summary

    summary = run([(i, Ts) for i in range(len(cases)) for Ts in GRID])
    for _ in range(BISECTIONS):
        if summary.interrupted:
            break
        points = []
        for i in range(len(cases)):
            lo, hi = _bracket(tested[i])
            if not (math.isnan(lo) or math.isnan(hi)):
                points.append((i, float(np.sqrt(lo * hi))))
        if not points:
            break
        summary = run(points)
    return [_result(case, tested[i]) for i, case in enumerate(cases)], summary


def _result(case: StabilityCase, tested: dict) -> StabilityResult:
    lo, hi = _bracket(tested)
    reason = tested[hi][1] if not math.isnan(hi) else ""
    return StabilityResult(case, dict(sorted(tested.items())), lo, hi, reason,
                           predicted_limit(case.base))


def load_stability(out, *, fresh_only: bool = False) -> list[StabilityResult]:
    """The stability map of a results folder, rebuilt from its stored runs (with
    ``fresh_only``, from the runs made by this code only)."""
    from ..batch.fingerprint import run_fingerprint
    groups: dict[tuple, tuple[StabilityCase, dict]] = {}
    for row in ResultStore(out).rows(where="sweep = 'stability'"):
        if fresh_only and row.fingerprint != run_fingerprint(row.config):
            continue
        c = row.config
        key = (_label(c), _options_key(c), c["plant"]["kind"], c["arm"])
        case = StabilityCase(key[0], key[2], key[3], c)
        groups.setdefault(key, (case, {}))[1][float(c["Ts"])] = is_stable(row)
    order = {"default": 0, "table1": 1, "reduced": 0, "exudyn": 1}
    keys = sorted(groups, key=lambda k: (k[0], order.get(k[2], 9), order.get(k[3], 9)))
    return [_result(*groups[k]) for k in keys]


def _bracket(tested: dict[float, tuple[bool, str]]) -> tuple[float, float]:
    """(largest Ts below which everything tested was stable, the smallest unstable Ts)."""
    lo, hi = math.nan, math.nan
    for Ts in sorted(tested):
        if tested[Ts][0]:
            lo = Ts
        else:
            hi = Ts
            break
    return lo, hi


def predicted_limit(config: dict) -> float:
    """2 / λ_max(W G) for the built-in joint-space laws (module docstring); NaN else."""
    from reduced_model import ArmParameters
    kind, opts = config["controller"]["kind"], config["controller"].get("options", {})
    params = ArmParameters.from_mapping(config["nominal_params"])
    model = nominal_model(params, tuple(config["model"]["modes_per_link"]))
    M = model.mass_matrix(np.zeros(model.n))
    W = np.linalg.inv(M)[:2, :2]
    Mtt = M[:2, :2]
    try:
        from controllers import CONTROLLERS, accepted_options
        defaults = accepted_options(CONTROLLERS[kind]) if kind in CONTROLLERS else {}
        get = lambda k: np.broadcast_to(np.asarray(opts.get(k, defaults[k]), float), (2,))  # noqa: E731
        if kind == "pd":
            G = np.diag(get("kd"))
        elif kind == "ct":
            G = Mtt @ np.diag(get("kd"))
        elif kind in ("pbc", "pbc-idealised"):
            G = Mtt @ np.diag(get("lambda_joint")) + np.diag(get("kv_joint"))
        else:
            return math.nan
    except (KeyError, ValueError, ConfigError):
        return math.nan
    lam = np.max(np.abs(np.linalg.eigvals(W @ G)))
    return float(2.0 / lam) if lam > 0 else math.inf


def stability_rows(results: list[StabilityResult]) -> list[dict]:
    """Table rows (values in ms as text) for the templates and stability.csv."""
    from ..report.render import fmt_number

    def ms(v):
        return "—" if math.isnan(v) else fmt_number(1e3 * v)
    rows = []
    for r in results:
        largest = ms(r.largest_stable) if not math.isnan(r.largest_stable) else \
            f"< {fmt_number(1e3 * GRID[0])}"
        unstable = ms(r.first_unstable) if not math.isnan(r.first_unstable) else \
            f"> {fmt_number(1e3 * GRID[-1])}"
        rows.append({"case": r.case.label, "plant": r.case.plant, "arm": r.case.arm,
                     "largest": largest, "unstable": unstable, "predicted": ms(r.predicted),
                     "reason": r.reason, "largest_s": r.largest_stable,
                     "first_unstable_s": r.first_unstable, "predicted_s": r.predicted})
    return rows


def write_stability(results: list[StabilityResult], out) -> str:
    """Write stability.md and stability.csv into ``out``; return the markdown."""
    import csv
    import io
    from pathlib import Path

    from ..report.render import render
    from ..run.results import write_atomic
    rows = stability_rows(results)
    text = render("stability.md.j2", rows=rows, duration=f"{DURATION:g}",
                  grid=", ".join(f"{1e3 * t:g}" for t in GRID), bisections=BISECTIONS,
                  limit=f"{TRACKING_LIMIT:g}")
    out = Path(out)
    write_atomic(out / "stability.md", lambda fh: fh.write(text))
    keys = ["case", "plant", "arm", "largest_s", "first_unstable_s", "predicted_s", "reason"]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=keys, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    write_atomic(out / "stability.csv", lambda fh: fh.write(buf.getvalue()))
    return text
