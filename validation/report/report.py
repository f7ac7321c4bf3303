"""Reports of a results folder, produced from its stored, verified runs only.

``write_report(results_dir)`` assembles the report as data — tables of values and
figures — and renders it through two templates: ``report/report.html`` (self-contained:
figures embedded, no network; a print stylesheet keeps every table on the page) and
``report/report.md`` (figures in ``report/figures/``), plus ``report/arm.gif`` and the
report's sentences and tables as data, ``report/report.json`` (`record`: the docs'
findings page reads it).
Sections: what was run and its bottom line (`bottom_line`: sentences a reviewer can
quote, computed from the results); the summary (each claim, its margin and the truth
plant's difference from the reduced one; the main metrics of every system run on both
plants); the paper's claims (if the folder holds the paper's system); the sampled-data
stability map (if ``stability/`` holds one); attribution; the verdicts over uncertainty
and the calibration (if ``flexarm verify`` or ``flexarm calibrate`` wrote one);
estimation against the measurement; runs; metrics (`run_tables`); the paper's figures
(`groups`); sweeps; the reduced model's validity map (with the linear analysis of
``validity/`` if `flexarm validity` wrote one); the animation.  Runs whose file fails
verification or that were made by other code are left out and named.

A report is rendered again only when what it shows can have changed (`content_key`).
"""
from __future__ import annotations

import base64
import functools
import json
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from reduced_model import ArmParameters

from . import figures as fig
from .sweep_figures import sweep_figures
from .verdict_figures import stability_chart, validity_map, waterfall
from . import linear_figures
from ..batch.beside import beside, out_of_collection
from ..batch.fingerprint import fingerprint_of, fmu_of
from ..batch.store.resimulate import every_signal
from .render import fmt_number, folded_text, render
from .bottom_line import bottom_line, claims_sentences
from .arms import arms_answers, arms_table
from .calibration import calibration_section
from .content_key import content_key, paths, report_is_current
from .record import report_record
from .groups import animation, claim_bounds, figure_groups, paper_figure_tasks
from .many import completed, distributions, histograms, is_many, read_metrics, windows_of
from .robust import robust_section
from .run_tables import estimation_table, mesh_table, metrics_table, runs_table, table
from ..run.results import own_folder, write_atomic
from ..run.arms import arm_description
from ..batch.store.folder import ResultStore, StoreError
from ..verdicts.evaluations import FIT_SWEEP, ROBUST_SWEEPS
from ..verdicts.mesh import MESH_SWEEP, is_check
from ..verdicts.validity_file import load_validity
from .verdict_tables import gap_rows, stability_rows, study_view, table_rows

__all__ = ["write_report", "report_data", "contents", "file_stem", "SECTIONS"]


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
    scope: list
    answers: list = field(default_factory=list)  # the bottom line's claims sentences
    bottom_line: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    arms_answers: list = field(default_factory=list)
    arms: dict | None = None
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
    content_key: str = ""  # what it shows, hashed (`content_key`): the report's own key
    attribution: list = field(default_factory=list)
    validity: dict | None = None
    robust: dict | None = None
    calibration: dict | None = None
    many: dict | None = None



def report_rows(store: ResultStore) -> list:
    """Every row of ``store``, with the metrics the report reads (`many.read_metrics`)."""
    return store.rows(metrics=read_metrics(store))


def _role(row) -> str:
    """What a stored row is to the report: a "run" it reports, a mesh/step "check" of
    them, an "evaluation" of a verdict over uncertainty (`robust_section`), or "apart"
    (a stability-map run, a calibration's simulation: their own sections)."""
    if is_check(row):
        return "check"
    if row.sweep in ROBUST_SWEEPS:
        return "evaluation"
    return "apart" if row.sweep in ("stability", FIT_SWEEP) else "run"


def _first_of_each_arm(runs) -> dict:
    """arm → the first of ``runs`` of that arm (the run whose arm its validity map draws),
    in the order of the arms."""
    first: dict = {}
    for r in runs:
        first.setdefault(r.arm, r)
    return {arm: first[arm] for arm in sorted(first, key=str)}  # a stale row's arm: any


def _drawn_or_none(draw):
    """``draw()``, or None if it fails: drawn before its run is checked, a map of a run
    then left out must not stop the report (`report_data` draws the map again from the
    first run that is fresh and verifies, where a failure is the report's)."""
    try:
        return draw()
    except Exception:  # noqa: BLE001 - any failure: the map is drawn again after the check
        return None


def _validity_task(example):
    """The task drawing the validity map of the arm of the run ``example``."""
    config = example.config
    return functools.partial(validity_map, ArmParameters.from_mapping(config["true_params"]),
                             tuple(config["model"]["modes_per_link"]), f"{example.arm} arm")


@dataclass
class _Included:
    """What `_included` finds of a folder's rows."""
    runs: list  # to report: fresh, verified, neither checks, evaluations nor apart
    evaluations: list  # of `flexarm verify`
    checks: list  # fresh, verified mesh/step checks of the runs
    warnings: list
    content_key: str
    drawn: dict  # arm → (its example, its validity map's PNG): drawn beside the checks
    meanwhile: object  # what ``meanwhile`` returned


def _included(store: ResultStore, all_rows: list, *, animate: bool,
              meanwhile=lambda: None) -> _Included:
    """Which of ``all_rows``, every row of ``store``, the report shows: the rows whose
    file verifies and that this code made.  The rows are verified in a worker (0.5 s at
    40,000 runs) while this process asks which are fresh, computes the content key and
    calls ``meanwhile``, and another draws the validity map of each arm (1.2 s): its
    example is then the first run of that arm, if that one verifies (`report_data` draws
    it otherwise)."""
    if not all_rows:
        raise StoreError(f"{store.out}: no stored runs")
    roles = [_role(r) for r in all_rows]
    maps = {}
    for arm, example in _first_of_each_arm(
            r for r, role in zip(all_rows, roles) if role == "run").items():
        try:
            maps[arm] = (example, functools.partial(_drawn_or_none, _validity_task(example)))
        except (ValueError, KeyError, TypeError):  # damaged, or another code's scenario:
            continue  # left out below, the map drawn after the check from a run that is not
    with beside([functools.partial(store.verify, all_rows),
                 *(draw for _, draw in maps.values())], stores=[store],
                progress=False) as done:
        made = [(r.controller, r.observer, r.plant, fmu_of(r)) for r in all_rows]
        now = {k: fingerprint_of(*k) for k in set(made)}  # once per kind of run
        key = content_key(store.out, animate=animate, rows=all_rows)
        result = meanwhile()
        damaged, *pngs = done()
    found = _Included([], [], [], [], key, {arm: (example, png) for (arm, (example, _)), png
                                            in zip(maps.items(), pngs)}, result)
    stale = []
    lists = {"run": found.runs, "evaluation": found.evaluations, "check": found.checks}
    for r, role, kinds in zip(all_rows, roles, made):  # one pass (10^5 rows: ~20 ms)
        if r.fingerprint != now[kinds]:
            stale.append(r)
        elif r.run_id not in damaged and role in lists:
            lists[role].append(r)
    found.warnings = [f"run {rid} left out: {why} (rerun the campaign to redo it)"
                      for rid, why in damaged.items()]
    if stale:
        found.warnings.append(
            f"{len(stale)} run(s) left out: made by other code than this installation "
            f"({', '.join(r.run_id for r in stale[:8])}{', …' if len(stale) > 8 else ''}); "
            "rerun the campaign to refresh them")
    return found


def _stability_results(folder: Path) -> list:
    """The fresh results of the stability map in ``folder``, if it holds one."""
    if not ResultStore(folder).exists():
        return []
    from ..verdicts.stability import load_stability
    return load_stability(folder, fresh_only=True)


def _scope(runs, done=None) -> list[str]:
    """What ``runs`` cover (arms, plants, control periods, initial states, metric
    windows); ``done``: `many.completed` of them, if read."""
    kinds = {}  # a run per kind, in one pass over the runs (10^5 of them: ~20 ms a pass)
    for r in runs:
        kinds.setdefault((r.arm, r.plant, r.role, r.Ts, r.initial_state), r)
    scope = [f"arm: {a} — {arm_description(a)}" for a in sorted({k[0] for k in kinds})]
    scope.append("plants: " + ", ".join(sorted({r.plant_label for r in kinds.values()})))
    scope.append("control periods Ts: " + ", ".join(
        f"{1e3 * t:g} ms" if t is not None else "not given"  # a scenario without Ts
        for t in sorted({k[3] for k in kinds}, key=lambda t: (t is None, t or 0))))
    scope.append("initial conditions: " + ", ".join(sorted(
        {"at rest" if k[4] == "rest" else "moving with the reference" for k in kinds})))
    windows = list(dict.fromkeys(f"{t:g} s of {d:g} s runs"  # each as it reads, once
                                 for t, d in sorted(windows_of(runs, done))))
    scope.append("metrics after the transient: " + ", ".join(windows[:6])
                 + (", …" if len(windows) > 6 else "")
                 + " (maxima of deflection and torque, torque variation: the whole run)")
    return scope


def report_data(results_dir, *, animate: bool = True, progress: bool = True,
                animation_path: Path | None = None, rows: list | None = None) -> ReportData:
    """Everything the report shows, as data (figures as PNG bytes); ``rows``: every row
    of the folder with the metrics the report reads (`report_rows`), if already read.
    Nothing waits that need not: the rows are checked and the arms' validity maps drawn
    while the content key is computed and the stability map read (`_included`); the
    other figures are drawn while the tables are computed (`beside.beside`)."""
    from ..verdicts.claims import CLAIMS, claim_columns
    from .summary import NOTE_MEANING, pairs_table, verdict_counts
    from .verdict_tables import claims_tables
    store = ResultStore(results_dir)
    stability_dir = store.out / "stability"
    found = _included(store, report_rows(store) if rows is None else rows, animate=animate,
                      meanwhile=functools.partial(_stability_results, stability_dir))
    runs, evaluations, checks, warnings = found.runs, found.evaluations, found.checks, \
        found.warnings
    campaigns = store.campaigns()
    names = [n for n in campaigns if n not in ("stability", MESH_SWEEP)] or ["(single runs)"]
    info = [campaigns.get(n, {}) for n in names]
    wanted = [w for i in info for w in i.get("report", {}).get("figures", [])] or None
    counted = runs + evaluations
    data = ReportData(title=", ".join(names), folder=str(store.out),
                      content_key=found.content_key,
                      description="; ".join(i["description"] for i in info
                                            if i.get("description")),
                      scope=[], warnings=warnings)
    bounds = claim_bounds()

    tasks = []
    results = found.meanwhile
    expected = frozenset()
    if results:
        from ..verdicts.claims import beyond_every_limit
        expected = frozenset(beyond_every_limit(results, runs))
        rows = stability_rows(results)
        data.stability = {"table": table(
            ["case", "plant", "arm", "no divergence up to [ms]", "first divergence [ms]",
             "width", "keeps tracking up to [ms]", "first loss [ms]", "predicted [ms]",
             "runs", "monotone?", "refined sequence", "why the first bad one is"],
            [[r["case"], r["plant"], r["arm"], r["no_divergence"], r["first_divergence"],
              r["width_text"], r["tracking"], r["first_loss"], r["predicted"],
              str(r["runs"]), folded_text(r["notes"]),
              folded_text(f"at {r['discretisation']}: {r['mesh']}"),
              folded_text(r["reason"])] for r in rows],
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
    done = completed(runs) if many else None
    if many:  # summarised: no table row and no figure per run
        tasks.append(("Distributions", "distributions over the runs that completed",
                      lambda: histograms(done)))

    groups, skipped = figure_groups(runs, wanted) if not many else ([], [])
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
        data.validity = {"cases": table(*table_rows(validity)),
                         "gaps": table(*gap_rows(validity))}
        tasks.append(("Validity of the reduced model", None,
                      lambda: linear_figures.validity_figures(validity)))
    for arm, example in _first_of_each_arm(runs).items():
        early, png = found.drawn.get(arm, (None, None))
        tasks.append(("Validity of the reduced model",
                      f"validity map, {arm} arm: reduced model vs FE frequencies over a joint "
                      "angle and their relative gap",
                      (lambda png=png: png) if early is example and png is not None
                      else _validity_task(example)))
    makes = [make for _, _, make in tasks]
    animated = bool(animate and groups and animation_path is not None)
    if animated:  # the longest task (1.5 s): begun first, no core waits for it at the end
        makes.insert(0, lambda: animation(store, groups[0], animation_path))

    with beside(makes, stores=[store], progress=progress) as drawn:  # the tables meanwhile
        signals = functools.partial(every_signal, store)  # the claims: 3.5 s of the paper's
        columns = claim_columns(runs + checks, signals)
        data.mesh = mesh_table(runs + checks, signals)
        data.scope = _scope(counted, None if evaluations else done) if counted else []
        if columns:
            data.summary = verdict_counts(columns)
            data.claims = claims_tables(columns)
            data.claims_criteria = [{"text": c.text, "criterion": c.criterion,
                                     "bound": f"{fmt_number(c.bound)} {c.unit}",
                                     "rationale": c.rationale} for c in CLAIMS]
            data.claim_notes = [f"{c.text.split(':')[0]} ({c.key.replace('_', ' ')}): "
                                f"{NOTE_MEANING[c.key]}" for c in CLAIMS
                                if c.key in NOTE_MEANING]
        data.pairs = pairs_table(runs, fig.describe_run) if len({r.role for r in runs}) > 1 \
            else None
        data.arms_answers, data.arms = arms_answers(runs), arms_table(runs)
        data.answers = claims_sentences(columns) if columns else []
        data.bottom_line = bottom_line(counted, checks, columns, data.calibration,
                                       expected=expected)
        if many:
            data.many = distributions(runs, done)
        else:
            data.estimation = estimation_table(runs)
        if runs and not many:  # a folder of `flexarm verify` alone has its section instead
            data.runs, data.metrics = runs_table(runs), metrics_table(runs)
        if many and data.many:  # a run's figures: `flexarm show`, e.g. of a worst run
            data.many["stopped"].append(f"no run's figures are drawn here: 'flexarm show "
                                        f"{store.out}/RUN' draws any run's")
        figures = drawn()
    drawn_animation = figures.pop(0) if animated else None
    for (section, caption, _), made in zip(tasks, figures):
        items = made if isinstance(made, list) else [(caption, made)]
        data.figures += [Figure(section, c, p) for c, p in items if p is not None]
    if drawn_animation is not None:
        caption, poster = drawn_animation
        data.animation = {"caption": caption, "file": animation_path.name,
                          "poster": Figure("Animation", caption, poster)}
    return data



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
    present = [("arms", "The arms side by side", data.arms),
               ("summary", "Summary", data.summary or data.pairs),
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



def write_report(results_dir, *, animate: bool = True, progress: bool = True,
                 force: bool = False) -> tuple[Path, Path]:
    """Write report.html, report.md and report.json (`record`) for ``results_dir``,
    unless they are current (`report_is_current`; ``force`` renders anyway); returns the
    paths of the first two."""
    store = ResultStore(results_dir)
    store.check()
    html_path, md_path, _, key_path = paths(results_dir)
    if not force and report_is_current(results_dir, animate=animate):
        return html_path, md_path
    rows = report_rows(store)
    with out_of_collection():  # the rows read: no collector pass over them from here on
        return _write(store, rows, animate=animate, progress=progress)


def _write(store: ResultStore, rows: list, *, animate: bool, progress: bool
           ) -> tuple[Path, Path]:
    """`write_report` of the folder of ``store`` from its ``rows`` (`report_rows`)."""
    results_dir = store.out
    html_path, md_path, json_path, key_path = paths(results_dir)
    out = html_path.parent
    created = not out.exists()
    try:
        own_folder(store.out, "report", "figures")
    except OSError as exc:
        raise StoreError(f"{out}: cannot write the report ({exc.strerror or exc})") from None
    try:
        data = report_data(results_dir, animate=animate, progress=progress,
                           animation_path=out / "arm.gif", rows=rows)
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
    write_atomic(json_path, lambda fh: json.dump(report_record(data), fh, ensure_ascii=False,
                                                 indent=1))
    write_atomic(key_path, lambda fh: fh.write(data.content_key + "\n"))
    return html_path, md_path
