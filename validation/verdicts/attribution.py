"""Which modelling assumption costs how much: Shapley attribution of the gap between a
real world and the ideal world its controller and observer were designed for.

The given scenario is the *real* world.  Each factor has an *ideal* counterpart — the
assumption of the design (`FACTORS` says exactly what it switches).  Every combination
of real and ideal factors is run (2^k worlds), and each metric's gap
m(real) − m(ideal) is shared among the factors by their Shapley values:

    φ_f = Σ_{S ⊆ F∖{f}} |S|! (k − |S| − 1)! / k! · [m(S ∪ {f}) − m(S)]

where m(S) is the metric of the world whose factors in S are real.  Three properties
hold by construction and are tested: the contributions add up to the gap exactly
(efficiency), a factor that changes nothing gets exactly 0 (null player: both worlds
are the same scenario, hence the same run), and the result does not depend on the order
the factors are listed (symmetry; sums run over subsets in a fixed order).  The
*sequential ladder* switches one factor at a time in the listed order (order-dependent,
shown for contrast), and the largest pairwise interaction
m(F) − m(F∖i) − m(F∖j) + m(F∖{i,j}) says where factors do not add up.

``truncation`` splits the ``plant`` contribution along a sub-ladder: the controller's
reduced model → the reduced model with 4 modes per flexible link → the FE truth plant.  Every term of
the plant's Shapley sum is split the same way, so the two parts — *modes left out* and
*beyond assumed modes* (distributed FE, geometric nonlinearity) — add up to the plant's
contribution exactly.

``kinematics`` names the paper's largest modelling error: its linear kinematics.  Real,
every reduced plant of a world (the plant factor's ideal level, the 4+4 level) has the
exact inextensible kinematics of the real arm (`reduced_model.ArmModel`); ideal, the
paper's linear ones.  A truth plant has its own, exact geometry at both levels, so the
factor acts only where the plant is reduced: with ``plant`` it shares the part of the
plant's gap that the kinematics explain (two factors alone: each gets half of the change
exact kinematics make, m(reduced, exact) − m(reduced, linear)).

Worlds that diverge or fail have no metrics.  Rule: if some worlds have no value, the
smallest set H of factors such that every such world has a factor of H at its real level
is held at its ideal level; the Shapley values are computed over the other factors
(efficiency then holds for m(real with H ideal) − m(ideal)), each factor of H is
reported as *destabilising* with no number, and the diverging combinations are listed.
No diverged run's metric is ever used.
"""
from __future__ import annotations

import copy
import itertools
import math
from dataclasses import dataclass, field

from reduced_model.arm import JOINT_EFFECTS

from ..run.arms import PARAMETER_TABLES, flat_values, params_from_table
from ..run.config import ConfigError, check, did_you_mean
from ..batch.campaign import PlannedRun
from ..batch.queue import run_planned
from ..run.plants import with_plant
from ..run.scenario import Scenario, scenario_from_mapping, scenario_to_mapping
from ..batch.store.folder import ResultStore, run_id

__all__ = ["FACTORS", "METRICS", "METRIC_NAMES", "DIVERGED_RULE", "World", "Attribution",
           "plan", "attribute", "shapley", "attribution_from_store", "parse_factors"]

#: The rule for worlds without a value: the module docstring's paragraph on them, whole.
DIVERGED_RULE = " ".join(next(p for p in __doc__.split("\n\n")
                              if p.startswith("Worlds that diverge")).split())

#: What each factor switches from its real level (the scenario's) to its ideal one.
FACTORS = {
    "plant": "truth plant → the controller's own reduced model as plant (same modes per "
             "link and kinematics as the controller's model)",
    "truncation": "splits 'plant' along reduced (controller's order) → reduced 4+4 modes → "
                  "FE: modes left out vs beyond assumed modes",
    "parameters": "true parameters → the nominal parameters (no parameter error; the "
                  "joints' fields of friction, drive and bandwidth stay theirs where those "
                  "are factors too)",
    "sensing": "the scenario's sensors (noise, quantisation, gauges, delay) → exact "
               "measurements of the same quantities",
    "estimation": "the observer's estimate → the true state fed to the controller",
    "sampling": "the scenario's Ts → Ts / 10 (closer to the continuous-time design)",
    "actuation": "torque limits and disturbances → none",
    "friction": "the arm's joint friction (Coulomb, stiction, Stribeck, viscous) → none, "
                "in the true and the nominal arm",
    "drive": "the arm's drives (gear compliance and damping, rotor inertia, backlash) → "
             "rigid joints, in the true and the nominal arm (the encoders then read θ)",
    "bandwidth": "the current loops' lag → an ideal torque, in the true and the nominal arm",
    "kinematics": "the reduced plant's exact inextensible kinematics → the paper's linear "
                  "kinematics (on every reduced plant of a world; none on a truth plant)",
    "gravity": "the arm's gravity → a horizontal arm (none), in the true and the nominal "
               "arm",
}
#: Attributed metrics: name → (how it is made from a run's metrics, unit).
METRICS = {
    "track_max": (lambda m: max(_per_joint(m, "track_max_")), "rad"),
    "track_rms": (lambda m: _quadratic_mean(_per_joint(m, "track_rms_")), "rad"),
    "vib_rms": (lambda m: _quadratic_mean(_per_joint(m, "vib_rms_")), "m"),
    "est_rms_theta": (lambda m: _group(m, "theta", False), "rad"),
    "est_rms_q": (lambda m: _group(m, "q", False), "m"),
    "est_rms_theta_dot": (lambda m: _group(m, "theta", True), "rad/s"),
    "est_rms_q_dot": (lambda m: _group(m, "q", True), "m/s"),
    "tau_tv": (lambda m: sum(_per_joint(m, "tau_tv_")), "N m/s"),
}
#: What a reader calls each metric (tables, waterfalls, attribution.md).
METRIC_NAMES = {
    "track_max": "tracking error, max", "track_rms": "tracking error, RMS",
    "vib_rms": "vibration RMS", "est_rms_theta": "angle estimation error, RMS",
    "est_rms_q": "modal-position estimation error, RMS",
    "est_rms_theta_dot": "angle-rate estimation error, RMS",
    "est_rms_q_dot": "modal-rate estimation error, RMS", "tau_tv": "torque variation",
}
MAX_FACTORS = 7
_SUB_LADDER = ("plant: modes left out", "plant: beyond assumed modes")


def _per_joint(m: dict, prefix: str) -> list[float]:
    """The values of a metric per joint or link (``prefix`` then 1, 2, …)."""
    out, i = [], 1
    while f"{prefix}{i}" in m:
        out.append(m[f"{prefix}{i}"])
        i += 1
    return out


def _quadratic_mean(values: list[float]) -> float:
    """√(Σ v²/k): the paper's two-link hypot(v1, v2)/√2 for any number of joints."""
    if len(values) == 2:  # as it has always been computed (the same rounding)
        return math.hypot(*values) / math.sqrt(2)
    return math.sqrt(sum(v * v for v in values) / len(values)) if values else math.nan


def _group(m: dict, kind: str, rate: bool) -> float:
    """RMS over the states of a group (angles, modal positions, their rates)."""
    vals = [v for k, v in m.items() if k.startswith("est_rms_") and not k.startswith("est_rms_slope")
            and k.removeprefix("est_rms_").startswith(kind) and k.endswith("_dot") == rate
            and (kind != "q" or not k.removeprefix("est_rms_").startswith("theta"))]
    return math.sqrt(sum(v * v for v in vals) / len(vals)) if vals else math.nan


# --- the worlds ---------------------------------------------------------------------------------
def parse_factors(names, scenario: Scenario) -> tuple[str, ...]:
    """Validated factor names (``truncation`` only with ``plant``); errors name the factor."""
    names = list(dict.fromkeys(names))
    check(len(names) > 0, "--factors", "needs at least one factor")
    for f in names:
        check(f in FACTORS, "--factors", f"unknown factor {f!r} (factors: {', '.join(FACTORS)})"
                                         f"{did_you_mean(f, FACTORS, quote=True)}")
    check("truncation" not in names or "plant" in names, "--factors",
          "'truncation' splits the 'plant' factor: list 'plant' too")
    shapley_factors = [f for f in names if f != "truncation"]
    check(len(shapley_factors) <= MAX_FACTORS, "--factors",
          f"at most {MAX_FACTORS} factors (2^{MAX_FACTORS} runs)")
    if "estimation" in names:
        check(scenario.uses_estimate, "--factors", "'estimation' cannot be idealised: the "
              "scenario feeds the controller no estimate (no observer, or feedback = 'true')")
    if "gravity" in names:
        check(any(scenario.true_params.gravity), "--factors", "'gravity' cannot be "
              "idealised: the arm is horizontal (no gravity in its plane)")
    if "truncation" in names:
        check(scenario.plant.role == "truth", "--factors",
              "'truncation' needs a truth plant (the scenario's plant is the reduced one)")
    if "kinematics" in names:
        check(scenario.model.kinematics == "linear", "--factors", "'kinematics' idealises "
              "the plant to the paper's linear kinematics, but the controller's model has "
              "the exact ones (model.kinematics = \"exact\")")
        if scenario.plant.role == "truth":
            check("plant" in names, "--factors", "'kinematics' acts on the reduced plant: "
                  "list 'plant' too (the scenario's plant is the truth plant)")
        else:
            check(getattr(scenario.plant, "kinematics", None) == "exact", "--factors",
                  "'kinematics' cannot be idealised: the scenario's reduced plant does not "
                  "have the exact kinematics (set plant.kinematics = \"exact\")")
    return tuple(names)


def default_factors(scenario: Scenario) -> tuple[str, ...]:
    names = ["plant", "truncation", "parameters", "sensing", "estimation", "sampling", "actuation"]
    if scenario.plant.role != "truth":
        names.remove("truncation")
    if not scenario.uses_estimate:
        names.remove("estimation")
    if any(scenario.true_params.gravity):
        names.insert(1, "gravity")
        names.remove("actuation")  # at most MAX_FACTORS: an arm in gravity names its own
    return tuple(names)


def _flat(table: dict) -> dict:
    """A resolved parameter table by flat key (``EI1``, ``coulomb2``, ``gravity``)."""
    return flat_values(params_from_table(table, lambda: None, "params"))


def _step_for(Ts: float, step: float) -> float:
    """The largest plant step ≤ ``step`` that divides ``Ts``."""
    return Ts / math.ceil(Ts / step - 1e-9)


def _idealise(data: dict, factor: str, players) -> None:
    """Switch ``factor`` of the resolved scenario mapping ``data`` to its ideal level
    (``players``: every factor of the attribution)."""
    if factor in JOINT_EFFECTS:
        for table in PARAMETER_TABLES:
            joints = len(data[table]["links"])
            data[table] = {**data[table], **{f"{name}{i}": 0.0 for name in JOINT_EFFECTS[factor]
                                             for i in range(1, joints + 1)}}
    elif factor == "gravity":
        for table in PARAMETER_TABLES:
            data[table] = {**data[table], "gravity": [0.0, 0.0]}
    elif factor == "plant":
        data["plant"] = with_plant(data["plant"], "reduced",
                                   modes_per_link=list(data["model"]["modes_per_link"]),
                                   kinematics=data["model"].get("kinematics", "linear"),
                                   step=_step_for(data["Ts"], min(data["plant"]["step"], 1e-3)))
    elif factor == "parameters":
        true, nominal = _flat(data["true_params"]), _flat(data["nominal_params"])
        joints = len(data["true_params"]["links"])
        own = {f"{name}{i}" for effect in JOINT_EFFECTS if effect in players
               for name in JOINT_EFFECTS[effect] for i in range(1, joints + 1)}
        if "gravity" in players:
            own.add("gravity")
        data["true_params"] = {**data["true_params"],
                               **{key: true[key] if key in own else value
                                  for key, value in nominal.items()}}
    elif factor == "sensing":
        s = data["sensors"]
        data["sensors"] = dict(s, modal="direct" if s["modal"] == "gauges" else s["modal"],
                               gauges_link1=None, gauges_link2=None, strain_quantity=None,
                               encoder_resolution=0.0, encoder_noise=0.0, modal_noise=0.0,
                               rate_noise=0.0, delay=0)
    elif factor == "estimation":
        data["feedback"] = "true"
    elif factor == "sampling":
        Ts = data["Ts"] / 10
        data["Ts"] = Ts
        data["plant"] = dict(data["plant"], step=_step_for(Ts, data["plant"]["step"]))
    elif factor == "actuation":
        data["torque_limit"] = 0.0
        data["disturbances"] = []
    elif factor == "kinematics":
        _set_kinematics(data, "linear")
    else:
        raise KeyError(factor)


def _set_kinematics(data: dict, kinematics: str) -> None:
    """The kinematics of the world's reduced plant (a truth plant keeps its own)."""
    if data["plant"].get("kind", "reduced") == "reduced":
        data["plant"] = dict(data["plant"], kinematics=kinematics)


def _truncation_level(data: dict) -> None:
    """The middle of the plant sub-ladder: the reduced plant with 4 modes per flexible link
    (RK4 needs a step ≤ 0.25 ms for its ~250 Hz top mode)."""
    modes = [4 if link["modes"] else 0 for link in data["true_params"]["links"]]
    data["plant"] = with_plant(data["plant"], "reduced", modes_per_link=modes,
                               step=_step_for(data["Ts"], min(data["plant"]["step"], 2.5e-4)))


@dataclass(frozen=True)
class World:
    real: frozenset  # the Shapley factors at their real level
    level: str  # the plant level: "real", "truncated" (4+4 reduced) or "ideal"
    run: PlannedRun


def plan(scenario: Scenario, factors: tuple[str, ...], name: str) -> list[World]:
    """Every world: 2^k combinations (+ 2^(k−1) with the 4+4 plant for ``truncation``)."""
    players = [f for f in factors if f != "truncation"]
    base = scenario_to_mapping(scenario)
    worlds = []
    for mask in itertools.product((True, False), repeat=len(players)):
        real = frozenset(f for f, r in zip(players, mask) if r)
        levels = ["real"] if "plant" in real else ["ideal"]
        if "truncation" in factors and "plant" not in real:
            levels.append("truncated")
        for level in levels:
            data = copy.deepcopy(base)
            for f in players:
                if f not in real:
                    _idealise(data, f, players)
            if "kinematics" in real:  # a reduced plant made by idealising 'plant' too
                _set_kinematics(data, "exact")
            if level == "truncated":
                _truncation_level(data)
            label = "+".join(sorted(real)) or "ideal"
            data["name"] = f"{name}/{label}" + ("/4+4 modes" if level == "truncated" else "")
            try:
                s = scenario_from_mapping(data)
            except ConfigError as exc:
                raise ConfigError(exc.path, f"{exc.message} (in the world with real factors: "
                                            f"{label})") from None
            axes = {f: ("real" if f in real else "ideal") for f in players}
            if "truncation" in factors:
                axes["plant_level"] = level
            rid = run_id(scenario_to_mapping(s))
            worlds.append(World(real, level, PlannedRun(rid, s, name, axes)))
    return worlds


# --- Shapley --------------------------------------------------------------------------------------
def shapley(players: list[str], value) -> dict[str, float]:
    """Shapley values of ``value(frozenset)`` over ``players``; the sum over subsets runs in
    a fixed (sorted) order, so listing the players differently gives identical numbers."""
    players = sorted(players)
    k = len(players)
    weights = [math.factorial(s) * math.factorial(k - s - 1) / math.factorial(k) for s in range(k)]
    out = {}
    for f in players:
        others = [p for p in players if p != f]
        total = 0.0
        for size in range(k):
            for subset in itertools.combinations(others, size):
                S = frozenset(subset)
                total += weights[size] * (value(S | {f}) - value(S))
        out[f] = total
    return out


@dataclass
class Attribution:
    """One system's attribution: per metric, contributions per factor and the gap."""

    name: str
    factors: tuple[str, ...]  # as listed (the ladder's order)
    real_value: dict  # metric -> m(real) (NaN if the real world diverged)
    ideal_value: dict
    contributions: dict  # metric -> {factor or sub-ladder part: value}
    totals: dict  # metric -> the attributed gap
    ladder: dict  # metric -> [(factor switched to ideal, metric after)]
    interaction: dict  # metric -> (pair, value)
    destabilising: list = field(default_factory=list)  # held at their ideal level
    diverging: list = field(default_factory=list)  # labels of worlds with no metrics


def _hitting_set(missing: list[frozenset], players: list[str]) -> list[str]:
    """The smallest set of players meeting every set in ``missing`` (ties: first in order)."""
    for size in range(len(players) + 1):
        for combo in itertools.combinations(players, size):
            if all(set(combo) & m for m in missing):
                return list(combo)
    return list(players)


def compute(name: str, factors: tuple[str, ...], metrics_of: dict) -> Attribution:
    """The attribution from each world's run metrics: ``metrics_of[(real, level)]`` is the
    run's metric dict, or None if it diverged or failed."""
    players = [f for f in factors if f != "truncation"]
    full = frozenset(players)
    missing = [real for (real, level), m in metrics_of.items() if m is None and level != "truncated"]
    truncated_missing = [real for (real, level), m in metrics_of.items()
                         if m is None and level == "truncated"]
    held = _hitting_set(missing, players) if missing else []
    free = [p for p in players if p not in held]
    att = Attribution(name, factors, {}, {}, {}, {}, {}, {}, destabilising=held,
                      diverging=sorted("+".join(sorted(r)) or "ideal" for r in missing))
    if frozenset() in missing:  # the ideal world itself diverged: nothing to attribute
        return att
    for metric, (make, _) in METRICS.items():
        def m(real: frozenset, level: str = "") -> float:
            row = metrics_of.get((real, level or ("real" if "plant" in real else "ideal")))
            if row is None:
                return math.nan
            try:
                return float(make(row))
            except (KeyError, TypeError, ZeroDivisionError):
                return math.nan
        if math.isnan(m(frozenset())):
            continue
        att.real_value[metric] = m(full) if not missing else math.nan
        att.ideal_value[metric] = m(frozenset())
        values = {S: m(S) for S in _subsets(free)}
        if any(math.isnan(v) for v in values.values()):
            continue
        phi = shapley(free, lambda S: values[S])
        top = frozenset(free)
        att.totals[metric] = values[top] - values[frozenset()]
        contributions = {f: phi.get(f, math.nan) for f in players}
        if "truncation" in factors and "plant" in free and not truncated_missing:
            contributions.update(_split_plant(free, lambda S, lv: m(S, lv)))
        att.contributions[metric] = contributions
        ladder, current = [], set(free)
        for f in [f for f in factors if f in free]:
            current.discard(f)
            ladder.append((f, values[frozenset(current)]))
        att.ladder[metric] = ladder
        best = max(((i, j) for i, j in itertools.combinations(free, 2)),
                   key=lambda ij: abs(_interaction(values, top, *ij)), default=None)
        if best:
            att.interaction[metric] = (best, _interaction(values, top, *best))
    return att


def _interaction(values, top, i, j) -> float:
    return values[top] - values[top - {i}] - values[top - {j}] + values[top - {i, j}]


def _subsets(players):
    return [frozenset(c) for size in range(len(players) + 1)
            for c in itertools.combinations(sorted(players), size)]


def _split_plant(players, m) -> dict:
    """The plant's Shapley sum, each term split along reduced → 4+4 → FE."""
    players = sorted(players)
    k = len(players)
    others = [p for p in players if p != "plant"]
    left_out = beyond = 0.0
    for size in range(k):
        w = math.factorial(size) * math.factorial(k - size - 1) / math.factorial(k)
        for subset in itertools.combinations(others, size):
            S = frozenset(subset)
            left_out += w * (m(S, "truncated") - m(S, "ideal"))
            beyond += w * (m(S | {"plant"}, "real") - m(S, "truncated"))
    return {_SUB_LADDER[0]: left_out, _SUB_LADDER[1]: beyond}


# --- running and reading back ------------------------------------------------------------------
def attribute(scenario: Scenario, factors: tuple[str, ...], out, *, name: str | None = None,
              runner=None, progress: bool = True):
    """Run every world of ``scenario`` into ``out`` (resumable) and attribute; returns
    (attribution, campaign summary)."""
    name = name or scenario.name.replace("/", "-")
    worlds = plan(scenario, factors, name)
    store = ResultStore(out)
    store.prepare()
    info = store.campaigns().get("attribution", {"studies": {}})
    info.setdefault("studies", {})[name] = {"factors": list(factors)}
    store.set_campaign("attribution", info)
    summary = run_planned([w.run for w in worlds], out, name="attribution",
                          description="Shapley attribution of the truth-vs-design gap",
                          runner=runner, progress=progress)
    if summary.interrupted:
        return None, summary
    return attribution_from_store(out, name, factors), summary


def attribution_from_store(out, name: str, factors: tuple[str, ...]) -> Attribution:
    """Recompute an attribution from the stored runs of study ``name``."""
    store = ResultStore(out)
    players = [f for f in factors if f != "truncation"]
    metrics_of = {}
    for row in store.rows(where="sweep = ?", params=(name,)):
        real = frozenset(f for f in players if row.axes.get(f) == "real")
        level = row.axes.get("plant_level", "real" if "plant" in real else "ideal")
        metrics_of[(real, level)] = row.metrics if row.status == "ok" else None
    return compute(name, factors, metrics_of)


def records(att: Attribution) -> list[dict]:
    """Rows of attribution.csv: metric, factor, contribution, share (of the total)."""
    out = []
    for metric, contributions in att.contributions.items():
        total = att.totals[metric]
        for factor, value in contributions.items():
            out.append({"study": att.name, "metric": metric, "factor": factor,
                        "contribution": value,
                        "share": value / total if total and math.isfinite(value) else math.nan})
        out.append({"study": att.name, "metric": metric, "factor": "total",
                    "contribution": total, "share": 1.0 if total else math.nan})
    return out


