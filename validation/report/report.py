"""Reports of a results folder, produced from its stored, verified runs only.

``write_report(results_dir)`` assembles the report as data — tables of values and
figures — and renders it through two templates: ``report/report.html`` (self-contained:
figures embedded, no network; a print stylesheet keeps every table on the page) and
``report/report.md`` (figures in ``report/figures/``), plus ``report/arm.gif``.
Sections: what was run; the summary (each claim, its margin and the truth plant's
difference from the reduced one; the main metrics of every system run on both plants);
the paper's claims (if the folder holds the paper's system); the sampled-data stability
map (if ``stability/`` holds one); attribution; the verdicts over uncertainty and the
calibration (if ``flexarm verify`` or ``flexarm calibrate`` wrote one); estimation
against the measurement;
runs; metrics; the paper's figures; sweeps; the reduced model's validity map (with the
linear analysis of ``validity/`` if `flexarm validity` wrote one); the animation.  Runs whose file fails verification or that were made by other code are
left out and named.

A report is rendered again only when what it shows can have changed: its *content key*
hashes the stored runs it reads (ids, checksums, whether each is fresh), the campaigns'
report settings, the stability map's runs, the code and library versions that draw it,
and the options; an unchanged key leaves the report as it is.
"""
from __future__ import annotations

import base64
import functools
import hashlib
import json
import math
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from reduced_model import ArmParameters

from . import figures as fig
from .sweep_figures import short_value, sweep_figures
from .verdict_figures import stability_chart, validity_map, waterfall
from . import linear_figures
from .drawing import draw_all
from ..batch.fingerprint import fingerprint_of, is_fresh
from ..batch.resimulate import every_signal
from .render import fmt_number, folded, folded_text, render
from .calibration import calibration_section
from .robust import robust_section
from .many import distributions, histograms, is_many, read_metrics, windows_of
from ..run.results import own_folder, write_atomic
from ..run.scenario import ARMS
from ..batch.store import ResultStore, StoreError
from ..verdicts.mesh import MESH_SWEEP, is_check
from ..verdicts.validity import load_validity
from .verdict_tables import gap_rows, stability_rows, study_view, table_rows

__all__ = ["write_report", "report_data", "content_key", "report_is_current", "figure_group",
           "claim_bounds",
           "paper_figure_tasks"]

#: Axes shown in their own columns (not repeated among the swept values); a swept plant
#: table is the plant column and the figures' legend.
_OWN_COLUMNS = {"name", "arm", "plant", "plant.kind", "initial_state", "Ts",
                "controller.kind", "observer.kind"}
_KEY_FILE = ".content-key"


@dataclass
class Figure:
    section: str
    caption: str
    png: bytes
    file: str = ""

    @property
    def data_uri(self) -> str:
        return "data:image/png;base64," + base64.b64encode(self.png).decode()


@dataclass
class ReportData:
    title: str
    description: str
    folder: str
    counts: dict
    scope: list
    warnings: list = field(default_factory=list)
    summary: list | None = None
    pairs: dict | None = None
    claims: list | None = None
    claims_criteria: list = field(default_factory=list)
    claim_notes: list = field(default_factory=list)
    mesh: dict | None = None
    stability: dict | None = None
    estimation: dict | None = None
    runs: dict | None = None
    metrics: dict | None = None
    figures: list = field(default_factory=list)
    notes: dict = field(default_factory=dict)
    animation: dict | None = None
    attribution: list = field(default_factory=list)
    validity: dict | None = None
    robust: dict | None = None
    calibration: dict | None = None
    many: dict | None = None


def _table(head: list[str], rows: list[list], classes: list[str] | None = None) -> dict:
    cells = [[c if isinstance(c, (str, dict)) else fmt_number(c) for c in row] for row in rows]
    return {"head": head, "rows": cells, "classes": classes or [""] * len(rows)}


def _start(config: dict) -> str:
    return "rest" if config.get("initial_state") == "rest" else "moving"


def _swept(run) -> str:
    return ", ".join(f"{k}={short_value(v)}" for k, v in run.axes.items() if k not in _OWN_COLUMNS)


def _identity(run) -> list:
    c = run.config
    return [run.name, c.get("arm", "default"), run.plant, f"{1e3 * c['Ts']:g}", _start(c)]


def _runs_table(runs) -> dict:
    head = ["run", "name", "arm", "plant", "Ts [ms]", "start", "controller", "observer",
            "swept values", "status"]
    rows = [[r.run_id, *_identity(r), r.config["controller"]["kind"],
             r.config["observer"]["kind"], _swept(r),
             r.status + (f": {r.message}" if r.message else "")] for r in runs]
    return _table(head, rows, [r.status for r in runs])


#: (metric key, column head, factor from SI to the unit in the head).
_METRICS = [("track_max_1", "max |e₁| [mrad]", 1e3), ("track_max_2", "max |e₂| [mrad]", 1e3),
            ("rate_err_rel", "rate error / peak rate", 1), ("vib_rms_1", "vibration 1 [mm]", 1e3),
            ("vib_rms_2", "vibration 2 [mm]", 1e3), ("defl_max_1", "max deflection 1 [mm]", 1e3),
            ("tau_max_1", "max |τ₁| [N m]", 1), ("tau_tv_1", "τ₁ variation [N m/s]", 1),
            ("tau_tv_2", "τ₂ variation [N m/s]", 1), ("realtime_factor", "real-time factor", 1),
            ("wall_s", "wall [s]", 1), ("startup_s", "first sample [s]", 1)]
#: Of `_METRICS`, what the run's timings hold (the computer's, not the run's).
_TIMINGS = ("realtime_factor", "wall_s", "startup_s")


def _metrics_table(runs) -> dict:
    head = ["name", "arm", "plant", "Ts [ms]", "start", "swept values"] + [h for _, h, _ in _METRICS]
    rows = []
    for r in runs:
        if r.status == "ok":
            measured = r.metrics | {k: r.timings.get(k, math.nan) for k in _TIMINGS}
            values = [measured.get(k, math.nan) * scale if isinstance(measured.get(k), float)
                      else math.nan for k, _, scale in _METRICS]
        else:
            values = [r.status] + [""] * (len(_METRICS) - 1)
        rows.append([*_identity(r), _swept(r), *values])
    return _table(head, rows, [r.status for r in runs])


def _fed(run) -> frozenset:
    """The states the run's observer was fed, as the run recorded them (a report never
    builds a law: that would import and run a plug-in's code)."""
    return frozenset(run.timings.get("observer_measured") or ())


def _estimation_table(runs) -> dict | None:
    """Two tables, one row per observed run: the error / measurement ratio per state
    (flagged), and each state's error, measurement error and signal RMS."""
    observed = [r for r in runs if r.status == "ok" and "est_rms_theta1" in r.metrics]
    if not observed:
        return None
    states = [k.removeprefix("est_rms_") for k in observed[0].metrics
              if k.startswith("est_rms_") and not k.startswith("est_rms_slope")]
    ident = ["name", "arm", "plant", "Ts [ms]", "start", "observer"]
    head = ident + [fig.state_label(s) for s in states] + ["worse than the measurement it is fed",
                                                           "worse than x̂ ≡ 0"]
    detail_head = ident + [f"{fig.state_label(s)} [{fig.state_display(s)[1]}]" for s in states]
    rows, detail = [], []
    for r in observed:
        m, fed = r.metrics, _fed(r)
        cells, values = [], []
        for s in states:
            ratio = m.get(f"est_to_noise_{s}")
            zero = m.get(f"est_to_signal_{s}")
            zero = " ⊘" if isinstance(zero, float) and zero >= 1 else ""
            if not isinstance(ratio, float) or math.isnan(ratio):
                cells.append("—" + zero)
            elif s not in fed:
                cells.append(fmt_number(ratio, 2) + " †" + zero)
            else:
                cells.append(fmt_number(ratio, 2) + (" ⚠" if ratio > 1 else "") + zero)
            scale = fig.state_display(s)[0]
            rms = [m.get(f"{k}_rms_{s}") for k in ("est", "noise", "signal")]
            values.append(" / ".join(fmt_number(scale * v) if isinstance(v, float) else "—"
                                     for v in rms) + ("" if s in fed else " †"))
        worse = " ".join(fig.state_label(s) for s in (m.get("est_worse") or "").split()
                         if s in fed)
        zero = " ".join(fig.state_label(s) for s in (m.get("est_worse_zero") or "").split())
        ident_cells = [*_identity(r), r.config["observer"]["kind"]]
        rows.append([*ident_cells, *cells, worse or "none", zero or "none"])
        detail.append([*ident_cells, *values])
    return {"compact": _table(head, rows), "detail": _table(detail_head, detail)}


def _mesh_table(runs, signals) -> dict | None:
    """Closed-loop mesh convergence of the truth-plant runs that have checks: per run, its
    verdict and the values that moved (compact); each judged value (a claim's measure) on
    every mesh (detail)."""
    from ..verdicts.claims import mesh_rows
    from ..verdicts.mesh import MESH_ATOL, MESH_RTOL
    rows = sorted(mesh_rows(runs, signals), key=lambda r: (r.run.name, _swept(r.run),
                                                  r.run.config["Ts"]))
    if not rows:
        return None
    labels = list(dict.fromkeys(label for r in rows for label, _ in r.values))

    def text(v, unit):
        if isinstance(v, str):
            return v
        return "never" if math.isinf(v) else f"{fmt_number(v)} {unit}".strip()
    detail, detail_classes, per_run = [], [], {}
    for r in rows:
        by_label = dict(r.values)
        unit = r.claim.unit if r.claim else ""
        values = [text(by_label[label], unit) if label in by_label else "" for label in labels]
        verdict = {True: "converged" if r.claim else "same outcome in every check",
                   False: "not converged", None: "check not run"}[r.converged]
        estimate = "" if not math.isfinite(r.error) else \
            f"± {fmt_number(r.error, 2)} {unit}".strip() + (
                f" (order {r.order:.2g})" if math.isfinite(r.order) else " (order not observed)")
        detail.append([*_identity(r.run)[:2], *_identity(r.run)[3:], _swept(r.run),
                       r.claim.key if r.claim else "run status", *values, estimate, verdict])
        detail_classes.append({True: "holds", False: "fails", None: ""}[r.converged])
        per_run.setdefault(r.run.run_id, (r.run, []))[1].append((r, values))
    compact, classes = [], []
    for run, items in per_run.values():
        moved = [f"{r.claim.key if r.claim else 'status'} ({', '.join(v)})"
                 for r, v in items if r.converged is False]
        missing = any(r.converged is None for r, _ in items)
        verdict = ("not converged" if moved else "check not run" if missing else
                   "converged" if run.status == "ok" else f"{run.status} in every check")
        compact.append([*_identity(run)[:2], *_identity(run)[3:], _swept(run), verdict,
                        folded(f"{len(moved)} value(s)", "; ".join(moved)) if moved else "—"])
        classes.append("fails" if moved else "" if missing else "holds")
    head = ["name", "arm", "Ts [ms]", "start", "swept values"]
    return {"compact": _table(head + ["verdict", f"moved ({', '.join(labels)})"], compact,
                              classes),
            "detail": _table(head + ["judged value", *labels, "estimated error", "verdict"],
                             detail, detail_classes),
            "tolerance": f"|a − b| ≤ {MESH_RTOL:.0%} of the larger value + {MESH_ATOL:.0%} "
                         "of the claim's bound"}


def _scenario_key(r) -> str:
    """What a run is, but its plant and its name: runs of one key are the same scenario
    on different plants (their default names differ: "pbc@reduced", "pbc@exudyn")."""
    return _key({k: v for k, v in r.config.items() if k not in ("plant", "name")})


def _order(rs) -> list:
    return sorted(rs, key=lambda r: r.role != "truth")


def plant_groups(runs) -> list[list]:
    """``runs`` in groups drawn together: the same scenario but the plant, one run per
    plant role (by name where a role has several), truth plant first."""
    by_key: dict[str, dict[str, list]] = {}
    for r in sorted(runs, key=lambda r: (r.name, r.run_id)):
        by_key.setdefault(_scenario_key(r), {}).setdefault(r.role, []).append(r)
    groups = []
    for roles in by_key.values():
        for i in range(max(len(rs) for rs in roles.values())):
            groups.append(_order([rs[i] for rs in roles.values() if i < len(rs)]))
    return groups


def figure_group(row, rows) -> list:
    """The runs among ``rows`` drawn with ``row``: itself and, for each other plant role,
    the same scenario on that plant when the folder holds it (the one of the same name if
    there are several), whatever the names; truth plant first."""
    key = _scenario_key(row)
    others: dict[str, object] = {}
    for r in sorted(rows, key=lambda r: (r.name != row.name, r.name, r.run_id)):
        if r.role != row.role and _scenario_key(r) == key and not is_check(r):
            others.setdefault(r.role, r)
    return _order([row, *others.values()])


def _figure_groups(runs, wanted: list[str] | None):
    groups = plant_groups([r for r in runs if r.status != "failed"])
    if wanted:
        groups = [g for g in groups if any(r.name == w or r.name.endswith("/" + w)
                                           for r in g for w in wanted)]
    else:
        both = [g for g in groups if len({r.plant for r in g}) > 1]
        groups = (both or groups)[:1]
    order = {"default": 0, "table1": 1, "rest": 0, "reference": 1}
    groups.sort(key=lambda g: (g[0].name, order.get(g[0].config.get("arm"), 9),
                               -g[0].config["Ts"], order.get(g[0].config.get("initial_state"), 9),
                               _swept(g[0])))
    drawable = [g for g in groups if any(r.status == "ok" for r in g)]
    return drawable, [g[0] for g in groups if g not in drawable]


def _key(value) -> str:
    return json.dumps(value, sort_keys=True)


def claim_bounds() -> dict:
    """The claims' bounds, by claim key (SI units)."""
    from ..verdicts.claims import CLAIMS
    return {c.key: c.bound for c in CLAIMS}


def _included(store: ResultStore):
    """(rows, runs to report, warnings, evaluations of `flexarm verify`): runs whose file
    verifies and that this code made (mesh-check runs are in ``rows``: they check the
    runs, they are not reported as runs; the evaluations of a verdict over uncertainty
    have their own section, `robust_section`, not a row each; so do a calibration's
    simulations, `calibration_section`)."""
    from ..verdicts.calibration import FIT_SWEEP
    from ..verdicts.verify import ROBUST_SWEEPS
    all_rows = store.rows(metrics=read_metrics(store))
    if not all_rows:
        raise StoreError(f"{store.out}: no stored runs")
    damaged = store.verify(all_rows)
    now = {k: fingerprint_of(*k) for k in {(r.controller, r.observer, r.plant)
                                           for r in all_rows}}  # once per kind of run
    stale = [r for r in all_rows if r.fingerprint != now[r.controller, r.observer, r.plant]]
    left_out = set(damaged) | {r.run_id for r in stale}  # a set: a list was quadratic
    fresh = [r for r in all_rows if r.run_id not in left_out]
    runs = [r for r in fresh if r.sweep != "stability" and not is_check(r)
            and r.sweep not in (*ROBUST_SWEEPS, FIT_SWEEP)]
    evaluations = [r for r in fresh if r.sweep in ROBUST_SWEEPS]
    warnings = [f"run {rid} left out: {why} (rerun the campaign to redo it)"
                for rid, why in damaged.items()]
    if stale:
        warnings.append(f"{len(stale)} run(s) left out: made by other code than this "
                        f"installation ({', '.join(r.run_id for r in stale[:8])}"
                        f"{', …' if len(stale) > 8 else ''}); rerun the campaign to refresh them")
    return all_rows, runs, warnings, evaluations


def _scope(runs) -> list[str]:
    arms = sorted({r.arm for r in runs})
    scope = [f"arm: {a} — {ARMS.get(a, a)}" for a in arms]
    kinds = {(r.plant, r.role): r for r in runs}  # a label per kind, not per run
    scope.append("plants: " + ", ".join(sorted({r.plant_label for r in kinds.values()})))
    scope.append("control periods Ts: " + ", ".join(f"{1e3 * t:g} ms" for t in
                                                     sorted({r.Ts for r in runs})))
    scope.append("initial conditions: " + ", ".join(sorted(
        {"at rest" if r.initial_state == "rest" else "moving with the reference"
         for r in runs})))
    windows = sorted(windows_of(runs))
    scope.append("metrics after the transient: " + ", ".join(
        f"{t:g} s of {d:g} s runs" for t, d in windows[:6]) + (", …" if len(windows) > 6 else "")
        + " (maxima of deflection and torque, torque variation: the whole run)")
    return scope


def report_data(results_dir, *, animate: bool = True, progress: bool = True,
                animation_path: Path | None = None) -> ReportData:
    """Everything the report shows, as data (figures as PNG bytes)."""
    from ..verdicts.claims import CLAIMS, claim_columns
    from .summary import NOTE_MEANING, pairs_table, verdict_counts
    from .verdict_tables import claims_tables
    store = ResultStore(results_dir)
    all_rows, runs, warnings, evaluations = _included(store)
    fresh_ids = {r.run_id for r in runs}
    checks = [r for r in all_rows if is_check(r) and r.run_id not in fresh_ids
              and is_fresh(r)]
    damaged_checks = store.verify(checks)
    checks = [r for r in checks if r.run_id not in damaged_checks]
    campaigns = store.campaigns()
    names = [n for n in campaigns if n not in ("stability", MESH_SWEEP)] or ["(single runs)"]
    info = [campaigns.get(n, {}) for n in names]
    wanted = [w for i in info for w in i.get("report", {}).get("figures", [])] or None
    counted = runs + evaluations
    counts = {s: sum(r.status == s for r in counted) for s in ("ok", "diverged", "failed")}
    data = ReportData(title=", ".join(names), folder=str(store.out),
                      description="; ".join(i["description"] for i in info
                                            if i.get("description")),
                      counts=counts, scope=_scope(counted), warnings=warnings)
    bounds = claim_bounds()

    signals = functools.partial(every_signal, store)
    columns = claim_columns(runs + checks, signals)
    data.mesh = _mesh_table(runs + checks, signals)
    if columns:
        data.summary = verdict_counts(columns)
        data.claims = claims_tables(columns)
        data.claims_criteria = [{"text": c.text, "criterion": c.criterion,
                                 "bound": f"{fmt_number(c.bound)} {c.unit}",
                                 "rationale": c.rationale} for c in CLAIMS]
        data.claim_notes = [f"{c.text.split(':')[0]} ({c.key.replace('_', ' ')}): "
                            f"{NOTE_MEANING[c.key]}" for c in CLAIMS if c.key in NOTE_MEANING]
    data.pairs = pairs_table(runs, fig.describe_run) if len({r.role for r in runs}) > 1 \
        else None
    stability_dir = store.out / "stability"
    tasks = []
    if ResultStore(stability_dir).exists():
        from ..verdicts.stability import load_stability
        results = load_stability(stability_dir, fresh_only=True)
        if results:
            rows = stability_rows(results)
            data.stability = {"table": _table(
                ["case", "plant", "arm", "no divergence up to [ms]", "first divergence [ms]",
                 "keeps tracking up to [ms]", "first loss [ms]", "predicted [ms]",
                 "monotone?", "mesh and step", "why the first bad one is"],
                [[r["case"], r["plant"], r["arm"], r["no_divergence"], r["first_divergence"],
                  r["tracking"], r["first_loss"], r["predicted"], folded_text(r["notes"]),
                  folded_text(r["mesh"]), folded_text(r["reason"])] for r in rows],
                ["failed" if "FAILED" in r["notes"] else "" for r in rows])}
            tasks.append(("Stability map", "sampled-data stability map: tested control periods "
                          "per case, plant and arm", lambda: stability_chart(results)))
    for study, spec in campaigns.get("attribution", {}).get("studies", {}).items():
        from ..verdicts.attribution import attribution_from_store
        a = attribution_from_store(store.out, study, tuple(spec["factors"]))
        view = study_view(a)
        data.attribution.append(view)
        for m in view["metrics"]:
            key, scale = m["key"], m["scale"]
            contributions = {f: scale * v for f, v in a.contributions[key].items()}
            tasks.append(("Attribution", f"{study}: {m['metric']}, from the ideal to the real "
                          "world", lambda a=a, m=m, c=contributions, s=scale: waterfall(
                              a.name, m["metric"], m["unit"], s * a.ideal_value[m["key"]], c,
                              s * a.totals[m["key"]])))
    data.robust, robust_tasks = robust_section(store, evaluations)
    tasks += robust_tasks
    data.calibration, calibration_tasks = calibration_section(store)
    tasks += calibration_tasks
    many = is_many(runs)
    if many:  # summarised: no table row and no figure per run
        data.many = distributions(runs)
        tasks.append(("Distributions", "distributions over the runs that completed",
                      lambda: histograms(runs)))
    else:
        data.estimation = _estimation_table(runs)
    if runs and not many:  # a folder of `flexarm verify` alone has its section instead
        data.runs, data.metrics = _runs_table(runs), _metrics_table(runs)

    groups, skipped = _figure_groups(runs, wanted) if not many else ([], [])
    if many and data.many:  # a run's figures: `flexarm show`, e.g. of a worst run
        data.many["stopped"].append(f"no run's figures are drawn here: 'flexarm show "
                                    f"{store.out}/RUN' draws any run's")
    data.notes["paper_figures"] = [f"{r.name}, {fig.describe_run(r.config)}: not drawn, every "
                                   f"run of it {r.status} ({r.message})" for r in skipped]
    for group in groups:
        tasks += paper_figure_tasks(store, group, bounds)
    by_sweep: dict[str, list] = {}
    for r in runs if not many else ():  # many runs: their distributions instead
        if r.sweep and r.axes:
            by_sweep.setdefault(r.sweep, []).append(r)
    sweep_bounds = {"track_max": bounds["tracking"], "vib_rms": bounds["vibration"],
                    "est_theta": bounds["estimation"]}
    for sweep, rs in by_sweep.items():
        tasks.append(("Sweeps", None, lambda sweep=sweep, rs=rs: sweep_figures(
            sweep, rs, sweep_bounds)))
    validity = load_validity(store.out / "validity")
    if validity:
        data.validity = {"cases": _table(*table_rows(validity)),
                         "gaps": _table(*gap_rows(validity))}
        tasks.append(("Validity of the reduced model", None,
                      lambda: linear_figures.validity_figures(validity)))
    for arm in sorted({r.arm for r in runs}):
        example = next(r for r in runs if r.arm == arm)
        params = ArmParameters.from_mapping(example.config["true_params"])
        modes = tuple(example.config["model"]["modes_per_link"])
        tasks.append(("Validity of the reduced model",
                      f"validity map, {arm} arm: reduced model vs FE frequencies over θ₂ and "
                      "their relative gap",
                      lambda p=params, m=modes, a=arm: validity_map(p, m, f"{a} arm")))
    makes = [make for _, _, make in tasks]
    if animate and groups and animation_path is not None:
        makes.append(lambda: _animation(store, groups[0], animation_path))
    drawn = draw_all(makes, stores=[store], progress=progress)
    for (section, caption, _), made in zip(tasks, drawn):
        items = made if isinstance(made, list) else [(caption, made)]
        data.figures += [Figure(section, c, p) for c, p in items]
    if len(drawn) > len(tasks) and drawn[-1] is not None:
        caption, poster = drawn[-1]
        data.animation = {"caption": caption, "file": animation_path.name,
                          "poster": Figure("Animation", caption, poster)}
    return data


def _loaded(store, group):
    """(row, every signal) of each run of a figure group (re-simulated where a run's file
    keeps less: `validation.batch.resimulate.every_signal`)."""
    return [(r, every_signal(store, r)) for r in group]


def _title(group) -> str:
    """What a group of runs is: its name(s), arm, Ts, start and swept values, then the
    runs of it that did not complete, after " — " (a figure's file name stops there)."""
    head = next(r for r in group if r.status == "ok")
    swept = _swept(head)
    names = " / ".join(dict.fromkeys(r.name for r in group))
    stopped = "; ".join(f"{r.plant_label} {r.status.upper()}: {r.message}"
                        for r in group if r.status != "ok")
    return f"{names} ({fig.describe_run(head.config)}{'; ' + swept if swept else ''})" + (
        f" — {stopped}" if stopped else "")


def paper_figure_tasks(store, group, bounds: dict | None = None) -> list:
    """The paper's figures of one group as (section, caption, draw) tasks; runs that
    diverged or failed are named in the title, not drawn (their last samples before
    leaving the bounds are not data).  ``bounds``: the claims' bounds by claim key."""
    from ..run.vibration import vibration_cutoff
    bounds = bounds or {}
    title = _title(group)
    group = [r for r in group if r.status == "ok"]
    head = group[0]
    transient = float(head.config["transient"])
    cutoff = vibration_cutoff(ArmParameters.from_mapping(head.config["true_params"]))
    cache = {}

    def results():
        if "r" not in cache:
            cache["r"] = _loaded(store, group)
        return cache["r"]
    what, _, stopped = title.partition(" — ")

    def caption(figure: str) -> str:  # what was run, the figure, then what did not complete
        return f"{what}: {figure}" + (f" — {stopped}" if stopped else "")
    tasks = [("Paper figures", caption("joint tracking (Fig. 3)"),
              lambda: fig.tracking(results(), title, transient, bounds.get("tracking"))),
             ("Paper figures", caption("tip deflections and vibration (Fig. 4)"),
              lambda: fig.deflections(results(), title, transient, cutoff,
                                      bounds.get("vibration")))]
    if head.config["observer"]["kind"] != "none":
        tasks += [("Paper figures", caption("true vs estimated rates (Figs. 5–6)"),
                   lambda: fig.rates(results(), title, transient)),
                  ("Paper figures", caption("estimation errors (Fig. 7)"),
                   lambda: fig.estimation_errors(results(), title, transient,
                                                 bounds.get("estimation")))]
    tasks.append(("Paper figures", caption("phase portrait (Fig. 8)"),
                  lambda: fig.phase_portrait(results(), title, transient,
                                             bounds.get("phase_portrait"))))
    return tasks


def _animation(store, group, path: Path) -> tuple[str, bytes] | None:
    """The GIF of a group written to ``path`` and its still for print: (caption, PNG);
    None when no run moves (one sample)."""
    from ..run.laws import nominal_model
    head = group[0]
    params = ArmParameters.from_mapping(head.config["nominal_params"])
    model = nominal_model(params, tuple(head.config["model"]["modes_per_link"]))
    loaded = _loaded(store, [r for r in group if r.status == "ok"])
    caption = fig.animation(loaded, params, model, _title(group), path)
    if caption is None:
        return None
    return caption, fig.arm_snapshots(loaded, params, model, _title(group))


# --- the pages ------------------------------------------------------------------------------
#: The figure sections, in the order the report shows them.
SECTIONS = ["Stability map", "Attribution", "Distributions", "Paper figures", "Sweeps",
            "Validity of the reduced model"]


def file_stem(caption: str, taken: set[str]) -> str:
    """A figure's file name from what it shows (its caption up to " — ", where what did not
    complete starts), e.g. "pbc+smo-paper-default-arm-ts-1-ms-from-rest-joint-tracking-
    fig-3": ASCII, at most 140 characters, unique among ``taken``, which it joins."""
    what = caption.partition(" — ")[0].lower().replace("paper/", "", 1)
    text = re.sub(r"\.(?!\d)", " ", what)  # "fig. 3" → "fig 3", "0.2" kept
    stem = re.sub(r"-+", "-", re.sub(r"[^a-z0-9+.]+", "-", text)).strip("-.")
    stem = (stem[:140].rsplit("-", 1)[0] if len(stem) > 140 else stem) or "figure"
    name, k = stem, 2
    while name in taken:
        name, k = f"{stem}-{k}", k + 1
    taken.add(name)
    return name


def contents(data: ReportData) -> list[tuple[str, str]]:
    """(anchor, title) of each section the report has, for its table of contents."""
    has = {s: any(f.section == s for f in data.figures) for s in SECTIONS}
    present = [("summary", "Summary", data.summary or data.pairs),
               ("claims", "The paper's claims", data.claims),
               ("mesh", "Mesh and time-step convergence", data.mesh),
               ("stability", "Stability map", data.stability),
               ("attribution", "Attribution", data.attribution),
               ("robust", "Robust verdicts", data.robust),
               ("calibration", "Calibration", data.calibration),
               ("estimation", "Estimation against the measurement", data.estimation),
               ("runs", "Runs and metrics", data.runs),
               ("many", "Distributions and worst cases", data.many),
               ("paper-figures", "Paper figures", has["Paper figures"]),
               ("sweeps", "Sweeps", has["Sweeps"]),
               ("validity", "Validity of the reduced model",
                has["Validity of the reduced model"]),
               ("animation", "Animation", data.animation)]
    return [(anchor, title) for anchor, title, shown in present if shown]


# --- the content key -------------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def _drawing_code() -> str:
    """A hash of the code and libraries that turn stored runs into a report."""
    from importlib.metadata import version

    from ..run.plants import ENGINE_PACKAGES
    h = hashlib.sha256()
    root = Path(__file__).resolve().parents[2]
    for package in ("validation", "reduced_model", "plant_exudyn", "controllers"):
        for path in sorted((root / package).rglob("*")):
            if path.suffix in (".py", ".j2") and "__pycache__" not in path.parts:
                h.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    for name in ("matplotlib", "jinja2", "numpy", "scipy", *ENGINE_PACKAGES):
        h.update(f"{name}={version(name)}".encode())
    return h.hexdigest()


def _rows_digest(store: ResultStore) -> str:
    """A hash of what the report reads of each stored run (its detail whole: swept values
    included, never decoded)."""
    if not store.exists():
        return ""
    store.rows(where="0")  # refuses an index it cannot read
    h, now = hashlib.sha256(), {}
    for *values, controller, observer, plant, detail in store.columns(
            ["run_id", "sha256", "size", "status", "name", "sweep", "fingerprint",
             "controller", "observer", "plant", "detail"], where="1 ORDER BY run_id"):
        kinds = (controller, observer, plant)
        if kinds not in now:  # the fingerprint each kind of run gets from this code
            now[kinds] = fingerprint_of(*kinds)
        h.update(f"{values}{values[-1] == now[kinds]}".encode() + detail)
    return h.hexdigest()


def content_key(results_dir, *, animate: bool) -> str:
    """The hash of everything a report of ``results_dir`` shows (module docstring)."""
    store = ResultStore(results_dir)
    validity = store.out / "validity" / "validity.json"
    calibration = store.out / "calibration.json"
    parts = {"runs": _rows_digest(store), "campaigns": store.campaigns(),
             "calibration": hashlib.sha256(calibration.read_bytes()).hexdigest()
             if calibration.is_file() else "",
             "stability": _rows_digest(ResultStore(store.out / "stability")),
             "validity": hashlib.sha256(validity.read_bytes()).hexdigest()
             if validity.is_file() else "",
             "code": _drawing_code(), "animate": animate}
    text = json.dumps(parts, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _paths(results_dir) -> tuple[Path, Path, Path]:
    out = ResultStore(results_dir).out / "report"
    return out / "report.html", out / "report.md", out / _KEY_FILE


def report_is_current(results_dir, *, animate: bool = True) -> bool:
    """Whether the report of ``results_dir`` exists and shows what the folder holds now
    (the same content key)."""
    html_path, md_path, key_path = _paths(results_dir)
    return (html_path.is_file() and md_path.is_file() and key_path.is_file()
            and key_path.read_text().strip() == content_key(results_dir, animate=animate))


def write_report(results_dir, *, animate: bool = True, progress: bool = True,
                 force: bool = False) -> tuple[Path, Path]:
    """Write report.html and report.md for ``results_dir``, unless they are current
    (`report_is_current`; ``force`` renders anyway); returns their paths."""
    store = ResultStore(results_dir)
    store.check()
    html_path, md_path, key_path = _paths(results_dir)
    if not force and report_is_current(results_dir, animate=animate):
        return html_path, md_path
    out = html_path.parent
    key = content_key(results_dir, animate=animate)
    created = not out.exists()
    try:
        own_folder(store.out, "report", "figures")
    except OSError as exc:
        raise StoreError(f"{out}: cannot write the report ({exc.strerror or exc})") from None
    try:
        data = report_data(results_dir, animate=animate, progress=progress,
                           animation_path=out / "arm.gif")
    except BaseException:
        if created:  # refused (no runs, a damaged verdict) or stopped: no report folder
            shutil.rmtree(out, ignore_errors=True)
        raise
    try:
        key_path.unlink(missing_ok=True)  # written last: a report cut short is redone
    except OSError as exc:
        raise StoreError(f"{out}: cannot write the report ({exc.strerror or exc})") from None
    for old in (out / "figures").glob("*.png"):  # the report's own folder (own_folder)
        old.unlink()
    poster = [data.animation["poster"]] if data.animation else []
    names: set[str] = set()
    for f in data.figures + poster:
        f.file = f"figures/{file_stem(f.caption, names)}.png"
        (out / f.file).write_bytes(f.png)
    gif = None
    if data.animation:
        gif = "data:image/gif;base64," + base64.b64encode((out / "arm.gif").read_bytes()).decode()
    page = render("report.html.j2", d=data, sections=SECTIONS, toc=contents(data), gif=gif)
    write_atomic(html_path, lambda fh: fh.write(page))
    text = render("report.md.j2", d=data, sections=SECTIONS)
    write_atomic(md_path, lambda fh: fh.write(text))
    write_atomic(key_path, lambda fh: fh.write(key + "\n"))
    return html_path, md_path
