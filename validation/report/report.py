"""Reports of a results folder, produced from its stored, verified runs only.

``write_report(results_dir)`` assembles the report as data — tables of values and
figures — and renders it through two templates: ``report/report.html`` (self-contained:
figures embedded, no network) and ``report/report.md`` (figures in ``report/figures/``),
plus ``report/arm.gif``.  Sections: what was run; the paper's claims (if the folder holds
the paper's system); the sampled-data stability map (if ``stability/`` holds one);
estimation against the measurement; runs; metrics; the paper's figures; sweeps; the
reduced model's validity map; the animation.  Runs whose file fails verification or that
were made by other code are left out and named.
"""
from __future__ import annotations

import base64
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from reduced_model import ArmParameters

from . import figures as fig
from ..batch.fingerprint import run_fingerprint
from .render import fmt_number, render
from ..run.results import write_atomic
from ..run.scenario import ARMS
from ..batch.store import ResultStore, StoreError

__all__ = ["write_report", "report_data"]

#: Axes shown in their own columns (not repeated among the swept values).
_OWN_COLUMNS = {"name", "arm", "plant.kind", "initial_state", "Ts", "controller.kind",
                "observer.kind"}


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
    claims: list | None = None
    claims_criteria: list = field(default_factory=list)
    stability: dict | None = None
    estimation: dict | None = None
    runs: dict | None = None
    metrics: dict | None = None
    figures: list = field(default_factory=list)
    notes: dict = field(default_factory=dict)
    animation: dict | None = None
    attribution: list = field(default_factory=list)
    robust: dict | None = None


def _table(head: list[str], rows: list[list], classes: list[str] | None = None) -> dict:
    cells = [[c if isinstance(c, str) else fmt_number(c) for c in row] for row in rows]
    return {"head": head, "rows": cells, "classes": classes or [""] * len(rows)}


def _start(config: dict) -> str:
    return "rest" if config.get("initial_state") == "rest" else "moving"


def _swept(run) -> str:
    return ", ".join(f"{k}={fig._short(v)}" for k, v in run.axes.items() if k not in _OWN_COLUMNS)


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


_METRICS = [("track_max_1", "max |e₁| [rad]", 1), ("track_max_2", "max |e₂| [rad]", 1),
            ("rate_err_rel", "rate error / peak", 1), ("vib_rms_1", "vibration 1 [mm]", 1e3),
            ("vib_rms_2", "vibration 2 [mm]", 1e3), ("defl_max_1", "max defl. 1 [mm]", 1e3),
            ("tau_max_1", "max |τ₁| [N m]", 1), ("tau_tv_1", "TV τ₁ [N m/s]", 1),
            ("tau_tv_2", "TV τ₂ [N m/s]", 1), ("realtime_factor", "real-time factor", 1),
            ("wall_s", "wall [s]", 1), ("startup_s", "first sample [s]", 1)]


def _metrics_table(runs) -> dict:
    head = ["name", "arm", "plant", "Ts [ms]", "start", "swept values"] + [h for _, h, _ in _METRICS]
    rows = []
    for r in runs:
        if r.status == "ok":
            values = [r.metrics.get(k, math.nan) * scale if isinstance(r.metrics.get(k), float)
                      else math.nan for k, _, scale in _METRICS]
        else:
            values = [r.status] + [""] * (len(_METRICS) - 1)
        rows.append([*_identity(r), _swept(r), *values])
    return _table(head, rows, [r.status for r in runs])


def _estimation_table(runs) -> dict | None:
    observed = [r for r in runs if r.status == "ok" and "est_rms_theta1" in r.metrics]
    if not observed:
        return None
    states = [k.removeprefix("est_rms_") for k in observed[0].metrics
              if k.startswith("est_rms_") and not k.startswith("est_rms_slope")]
    head = ["name", "arm", "plant", "Ts [ms]", "start", "observer"] + \
        [fig.state_label(s) for s in states] + ["worse than the measurement"]
    rows, detail = [], []
    for r in observed:
        m = r.metrics
        cells = []
        for s in states:
            ratio = m.get(f"est_to_noise_{s}")
            cells.append("—" if not isinstance(ratio, float) or math.isnan(ratio) else
                         fmt_number(ratio, 2) + (" ⚠" if ratio > 1 else ""))
            detail.append([*_identity(r), r.config["observer"]["kind"], fig.state_label(s),
                           fig.state_unit(s), m.get(f"est_rms_{s}"), m.get(f"noise_rms_{s}"),
                           m.get(f"signal_rms_{s}"), m.get(f"est_to_noise_{s}"),
                           m.get(f"est_to_signal_{s}")])
        worse = " ".join(fig.state_label(s) for s in (m.get("est_worse") or "").split())
        rows.append([*_identity(r), r.config["observer"]["kind"], *cells, worse or "none"])
    detail_head = ["name", "arm", "plant", "Ts [ms]", "start", "observer", "state", "unit",
                   "error RMS", "measurement error RMS", "signal RMS", "error / measurement",
                   "error / signal"]
    return {"compact": _table(head, rows), "detail": _table(detail_head, detail)}


def _figure_groups(runs, wanted: list[str] | None):
    """Runs drawn together as the paper's figures: the same name and the same swept
    values except the plant (truth and reduced overlaid)."""
    groups: dict[tuple, list] = {}
    for r in runs:
        if r.status == "failed":
            continue
        key = (r.name, _key(r.config.get("arm")), r.config["Ts"], r.config.get("initial_state"),
               _key({k: v for k, v in r.axes.items() if k not in ("plant.kind",)}))
        groups.setdefault(key, []).append(r)
    if wanted:
        chosen = [k for k in groups if any(k[0] == w or k[0].endswith("/" + w) for w in wanted)]
    else:
        both = [k for k, rs in groups.items() if len({r.plant for r in rs}) > 1]
        chosen = (both or list(groups))[:1]
    order = {"default": 0, "table1": 1, "rest": 0, "reference": 1}
    chosen.sort(key=lambda k: (k[0], order.get(json.loads(k[1]), 9), -k[2], order.get(k[3], 9), k[4]))
    drawable = [k for k in chosen if any(r.status == "ok" for r in groups[k])]
    skipped = [k for k in chosen if k not in drawable]
    plants = {"exudyn": 0, "reduced": 1}
    return ([sorted(groups[k], key=lambda r: plants.get(r.plant, 2)) for k in drawable],
            [groups[k][0] for k in skipped])


def _key(value) -> str:
    return json.dumps(value, sort_keys=True)


def report_data(results_dir, *, animate: bool = True, progress: bool = True,
                animation_path: Path | None = None) -> ReportData:
    """Everything the report shows, as data (figures as PNG bytes)."""
    from tqdm import tqdm

    from ..verdicts.claims import CLAIMS, claim_columns, claims_tables
    store = ResultStore(results_dir)
    all_rows = store.rows()
    if not all_rows:
        raise StoreError(f"{results_dir}: no stored runs")
    damaged = store.verify(all_rows)
    stale = [r for r in all_rows if r.fingerprint != run_fingerprint(r.config)]
    from ..verdicts.verify import ROBUST_SWEEPS
    fresh = [r for r in all_rows if r.run_id not in damaged and r not in stale]
    # The evaluations of `flexarm verify` have their own section (robust.py), not a row each.
    runs = [r for r in fresh if r.sweep != "stability" and r.sweep not in ROBUST_SWEEPS]
    warnings = [f"run {rid} left out: {why} (rerun the campaign to redo it)"
                for rid, why in damaged.items()]
    if stale:
        warnings.append(f"{len(stale)} run(s) left out: made by other code than this "
                        f"installation ({', '.join(r.run_id for r in stale[:8])}"
                        f"{', …' if len(stale) > 8 else ''}); rerun the campaign to refresh them")
    campaigns = store.campaigns()
    names = [n for n in campaigns if n not in ("stability",)] or ["(single runs)"]
    info = [campaigns.get(n, {}) for n in names]
    wanted = [w for i in info for w in i.get("report", {}).get("figures", [])] or None
    counted = [r for r in fresh if r.sweep != "stability"]
    counts = {s: sum(r.status == s for r in counted) for s in ("ok", "diverged", "failed")}
    arms = sorted({r.config.get("arm", "default") for r in runs})
    scope = [f"arm: {a} — {ARMS.get(a, a)}" for a in
             sorted({r.config.get("arm", "default") for r in counted})]
    scope.append("plants: " + ", ".join(sorted({fig.PLANT_NAME.get(r.plant, r.plant)
                                                for r in counted})))
    scope.append("control periods Ts: " + ", ".join(f"{1e3 * t:g} ms" for t in
                                                     sorted({r.config["Ts"] for r in counted})))
    scope.append("initial conditions: " + ", ".join(sorted(
        {"at rest" if _start(r.config) == "rest" else "moving with the reference"
         for r in counted})))
    data = ReportData(title=", ".join(names), folder=str(store.out),
                      description=" ".join(i.get("description", "") for i in info).strip(),
                      counts=counts, scope=scope, warnings=warnings)

    columns = claim_columns(runs)
    if columns:
        data.claims = claims_tables(columns)
        data.claims_criteria = [{"text": c.text, "criterion": c.criterion,
                                 "bound": f"{fmt_number(c.bound)} {c.unit}",
                                 "rationale": c.rationale} for c in CLAIMS]
    stability_dir = store.out / "stability"
    tasks = []
    if ResultStore(stability_dir).exists():
        from ..verdicts.stability import load_stability, stability_rows
        results = load_stability(stability_dir, fresh_only=True)
        if results:
            rows = stability_rows(results)
            data.stability = {"table": _table(
                ["case", "plant", "arm", "largest stable Ts [ms]", "first unstable Ts [ms]",
                 "predicted [ms]", "why the first unstable one is"],
                [[r["case"], r["plant"], r["arm"], r["largest"], r["unstable"], r["predicted"],
                  r["reason"]] for r in rows])}
            tasks.append(("Stability map", "sampled-data stability map: tested control periods "
                          "per case, plant and arm", lambda: fig.stability_chart(results)))
    for study, spec in campaigns.get("attribution", {}).get("studies", {}).items():
        from ..verdicts.attribution import METRICS, attribution_from_store, study_view
        a = attribution_from_store(store.out, study, tuple(spec["factors"]))
        data.attribution.append(study_view(a))
        for metric, contributions in a.contributions.items():
            tasks.append(("Attribution", f"{study}: {metric}, from the ideal to the real world",
                          lambda a=a, m=metric, c=contributions: fig.waterfall(
                              a.name, m, METRICS[m][1], a.ideal_value[m], c, a.totals[m])))
    from .robust import robust_section
    data.robust, robust_tasks = robust_section(store, fresh)
    tasks += robust_tasks
    data.estimation = _estimation_table(runs)
    if runs:  # a folder of `flexarm verify` alone has its section instead
        data.runs, data.metrics = _runs_table(runs), _metrics_table(runs)

    groups, skipped = _figure_groups(runs, wanted)
    data.notes["paper_figures"] = [f"{r.name}, {fig.describe_run(r.config)}: not drawn, every "
                                   f"run of it {r.status} ({r.message})" for r in skipped]
    for group in groups:
        tasks += _paper_figure_tasks(group)
    by_sweep: dict[str, list] = {}
    for r in runs:
        if r.sweep and r.axes:
            by_sweep.setdefault(r.sweep, []).append(r)
    for sweep, rs in by_sweep.items():
        tasks.append(("Sweeps", None, lambda sweep=sweep, rs=rs: fig.sweep_figures(sweep, rs)))
    for arm in arms:
        example = next(r for r in runs if r.config.get("arm", "default") == arm)
        params = ArmParameters.from_mapping(example.config["true_params"])
        modes = tuple(example.config["model"]["modes_per_link"])
        tasks.append(("Validity of the reduced model",
                      f"validity map, {arm} arm: reduced model vs FE frequencies over θ₂ and "
                      "their relative gap",
                      lambda p=params, m=modes, a=arm: fig.validity_map(p, m, f"{a} arm")))
    for section, caption, make in tqdm(tasks, desc="report figures", unit="fig",
                                       disable=not progress):
        made = make()
        items = made if isinstance(made, list) else [(caption, made)]
        data.figures += [Figure(section, c, p) for c, p in items]
    if animate and groups and animation_path is not None:
        data.animation = {"caption": _animation(groups[0], animation_path),
                          "file": animation_path.name}
    return data


def _loaded(group):
    return [(r, r.load()) for r in group]


def _paper_figure_tasks(group) -> list:
    """The paper's figures of one group; runs that diverged or failed are named in the
    title, not drawn (their last samples before leaving the bounds are not data)."""
    gone = [r for r in group if r.status != "ok"]
    group = [r for r in group if r.status == "ok"]
    head = group[0]
    swept = _swept(head)
    title = f"{head.name} ({fig.describe_run(head.config)}{'; ' + swept if swept else ''})" + "".join(
        f"; {fig.PLANT_NAME.get(r.plant, r.plant)} {r.status.upper()}: {r.message}" for r in gone)
    transient = float(head.config.get("transient", 2.0))
    from ..run.metrics import vibration_cutoff
    cutoff = vibration_cutoff(ArmParameters.from_mapping(head.config["true_params"]))
    cache = {}

    def results():
        if "r" not in cache:
            cache["r"] = _loaded(group)
        return cache["r"]
    tasks = [("Paper figures", f"{title}: joint tracking (Fig. 3)",
              lambda: fig.tracking(results(), title, transient)),
             ("Paper figures", f"{title}: tip deflections and vibration (Fig. 4)",
              lambda: fig.deflections(results(), title, transient, cutoff))]
    if head.config["observer"]["kind"] != "none":
        tasks += [("Paper figures", f"{title}: true vs estimated rates (Figs. 5–6)",
                   lambda: fig.rates(results(), title, transient)),
                  ("Paper figures", f"{title}: estimation errors (Fig. 7)",
                   lambda: fig.estimation_errors(results(), title, transient))]
    tasks.append(("Paper figures", f"{title}: phase portrait (Fig. 8)",
                  lambda: fig.phase_portrait(results(), title)))
    return tasks


def _animation(group, path: Path) -> str:
    from ..run.laws import nominal_model
    head = group[0]
    params = ArmParameters.from_mapping(head.config["nominal_params"])
    model = nominal_model(params, tuple(head.config["model"]["modes_per_link"]))
    swept = _swept(head)
    title = f"{head.name} ({fig.describe_run(head.config)}{'; ' + swept if swept else ''})"
    return fig.animation(_loaded(group), params, model, title, path)


def write_report(results_dir, *, animate: bool = True, progress: bool = True) -> tuple[Path, Path]:
    """Write report.html and report.md for ``results_dir``; returns their paths."""
    store = ResultStore(results_dir)
    if not store.exists():
        raise StoreError(f"{results_dir}: not a results folder (no index.sqlite)")
    out = store.out / "report"
    try:
        (out / "figures").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StoreError(f"{out}: cannot write the report ({exc.strerror or exc})") from None
    data = report_data(results_dir, animate=animate, progress=progress,
                       animation_path=out / "arm.gif")
    for i, f in enumerate(data.figures):
        f.file = f"figures/fig{i:02d}.png"
        (out / f.file).write_bytes(f.png)
    sections = ["Stability map", "Attribution", "Paper figures", "Sweeps",
                "Validity of the reduced model"]
    gif = None
    if data.animation:
        gif = "data:image/gif;base64," + base64.b64encode((out / "arm.gif").read_bytes()).decode()
    html_path, md_path = out / "report.html", out / "report.md"
    page = render("report.html.j2", d=data, sections=sections, gif=gif)
    write_atomic(html_path, lambda fh: fh.write(page))
    text = render("report.md.j2", d=data, sections=sections)
    write_atomic(md_path, lambda fh: fh.write(text))
    return html_path, md_path
