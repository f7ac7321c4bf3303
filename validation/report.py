"""Reports of a results folder, produced from the stored results only.

``write_report(results_dir)`` writes ``report/report.html`` (self-contained: PNGs embedded
as base64, no network), ``report/report.md`` (figures in ``report/figures/``) and
``report/arm.gif``.  Sections: runs (scenario table), metrics, the paper's figures
(Figs. 3–8 analogues, truth and reduced plant overlaid), sweeps (metric vs swept axis, one
line per plant), the reduced model's validity map (frequencies vs θ2), the claims table
if `claims.csv` exists, and the animation.
"""
from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from plant_exudyn import Mesh, natural_frequencies  # noqa: E402
from reduced_model import ArmModel, ArmParameters  # noqa: E402

from .results import write_atomic  # noqa: E402
from .store import ResultStore  # noqa: E402

__all__ = ["write_report", "SECTIONS"]

SECTIONS = ("Runs", "Metrics", "Paper figures", "Sweeps", "Validity of the reduced model",
            "Animation")
_PLANT_STYLE = {"reduced": dict(color="C0", ls="-"), "exudyn": dict(color="C3", ls="--")}
_METRIC_COLUMNS = [("track_max_1", "max|e1| [rad]"), ("track_max_2", "max|e2| [rad]"),
                   ("tip_err_max", "tip err [m]"), ("defl_max_1", "defl1 [m]"),
                   ("defl_max_2", "defl2 [m]"), ("tau_max_1", "|τ1| [N m]"),
                   ("tau_tv_1", "TV τ1 [N m/s]"), ("realtime_factor", "RT factor")]


@dataclass
class _Run:
    rid: str
    entry: dict
    metrics: dict

    @property
    def name(self) -> str:
        return self.entry.get("name", "")

    @property
    def plant(self) -> str:
        return self.entry.get("plant", "")


class _Figures:
    """Collects figures as PNG bytes with captions."""

    def __init__(self) -> None:
        self.items: list[tuple[str, str, bytes]] = []  # (section, caption, png)

    def add(self, section: str, caption: str, fig) -> None:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
        plt.close(fig)
        self.items.append((section, caption, buf.getvalue()))


def _load_runs(store: ResultStore) -> list[_Run]:
    manifest = store.manifest()["runs"]
    metrics = {row["run_id"]: row for row in store.metrics()}
    runs = []
    for rid, entry in sorted(manifest.items(), key=lambda kv: (kv[1].get("name", ""), kv[0])):
        result_cfg = None
        try:
            result_cfg = store.load(rid).config
        except (OSError, KeyError, ValueError):
            continue  # a run whose file is missing is not reported
        entry = dict(entry)
        entry["plant"] = result_cfg.get("plant", {}).get("kind", "?")
        entry["controller"] = result_cfg.get("controller", {}).get("kind", "?")
        entry["observer"] = result_cfg.get("observer", {}).get("kind", "?")
        runs.append(_Run(rid, entry, metrics.get(rid, {})))
    return runs


def _fmt(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


# --- paper figures ------------------------------------------------------------------------
def _figure_groups(runs: list[_Run], wanted: list[str] | None) -> list[list[_Run]]:
    """Runs to draw as the paper's figures: same scenario name, one per plant."""
    by_name: dict[str, list[_Run]] = {}
    for r in runs:
        if r.entry.get("status") != "failed":
            by_name.setdefault(r.name, []).append(r)
    if wanted:
        names = [n for n in by_name if any(n == w or n.endswith("/" + w) for w in wanted)]
    else:
        both = [n for n, rs in by_name.items() if len({r.plant for r in rs}) > 1]
        names = (both or list(by_name))[:1]
    return [sorted(by_name[n], key=lambda r: r.plant, reverse=True) for n in names]


def _paper_figures(store: ResultStore, group: list[_Run], figs: _Figures) -> None:
    results = [(r, store.load(r.rid)) for r in group]
    name = group[0].name
    label = lambda r: f"{r.plant} plant"  # noqa: E731

    fig, axes = plt.subplots(2, 2, figsize=(10, 5.5), sharex=True)
    for r, res in results:
        st = _PLANT_STYLE.get(r.plant, {})
        for j in (0, 1):
            axes[0, j].plot(res.time, res[f"theta{j + 1}"], label=label(r), **st)
            axes[1, j].plot(res.time, res[f"theta{j + 1}"] - res[f"theta{j + 1}_ref"], **st)
    for j in (0, 1):
        axes[0, j].plot(results[0][1].time, results[0][1][f"theta{j + 1}_ref"], color="k",
                        lw=0.8, label="reference (eq. 37)")
        axes[0, j].set_ylabel(f"θ{j + 1} [rad]")
        axes[1, j].set_ylabel(f"θ{j + 1} − θ{j + 1}d [rad]")
        axes[1, j].set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"{name}: joint tracking (cf. the paper's Fig. 3)")
    figs.add("Paper figures", f"{name}: joint tracking (Fig. 3)", fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 3))
    for r, res in results:
        for j in (0, 1):
            axes[j].plot(res.time, 1e3 * res[f"tip_defl{j + 1}"], label=label(r),
                         **_PLANT_STYLE.get(r.plant, {}))
    for j in (0, 1):
        axes[j].set_ylabel(f"tip deflection link {j + 1} [mm]")
        axes[j].set_xlabel("t [s]")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{name}: tip deflections (cf. Fig. 4)")
    figs.add("Paper figures", f"{name}: tip deflections (Fig. 4)", fig)

    observed = [(r, res) for r, res in results if "xhat_theta1" in res]
    if observed:
        rates = [n.removeprefix("xhat_") for n in observed[0][1].names_with("xhat_")
                 if n.endswith("_dot")]
        fig, axes = plt.subplots(2, math.ceil(len(rates) / 2), figsize=(12, 5), sharex=True)
        for ax, s in zip(axes.ravel(), rates):
            for r, res in observed:
                st = _PLANT_STYLE.get(r.plant, {})
                ax.plot(res.time, res[s], lw=0.8, label=f"{label(r)}: true", **st)
                ax.plot(res.time, res[f"xhat_{s}"], lw=0.6, alpha=0.8,
                        label=f"{label(r)}: estimate", color=st.get("color"), ls=":")
            ax.set_title(s, fontsize=9)
        axes.ravel()[0].legend(fontsize=7)
        fig.suptitle(f"{name}: measured vs estimated rates (cf. Figs. 5–6)")
        figs.add("Paper figures", f"{name}: true vs estimated states (Figs. 5–6)", fig)

        states = observed[0][1].names_with("xhat_")
        fig, axes = plt.subplots(2, math.ceil(len(states) / 2), figsize=(14, 5), sharex=True)
        for ax, xs in zip(axes.ravel(), states):
            s = xs.removeprefix("xhat_")
            for r, res in observed:
                ax.plot(res.time, res[xs] - res[s], lw=0.7, label=label(r),
                        **_PLANT_STYLE.get(r.plant, {}))
            ax.set_title(f"{s} error", fontsize=9)
        axes.ravel()[0].legend(fontsize=7)
        fig.suptitle(f"{name}: estimation errors (cf. Fig. 7)")
        figs.add("Paper figures", f"{name}: estimation errors (Fig. 7)", fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for r, res in results:
        for j in (0, 1):
            axes[j].plot(res[f"theta{j + 1}"], res[f"theta{j + 1}_dot"], lw=0.8, label=label(r),
                         **_PLANT_STYLE.get(r.plant, {}))
    for j in (0, 1):
        axes[j].set_xlabel(f"θ{j + 1} [rad]")
        axes[j].set_ylabel(f"θ̇{j + 1} [rad/s]")
        axes[j].axhline(1.2, color="grey", lw=0.5)
        axes[j].axhline(-1.2, color="grey", lw=0.5)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{name}: phase portrait (cf. Fig. 8; grey: the paper's ±1.2 rad/s)")
    figs.add("Paper figures", f"{name}: phase portrait (Fig. 8)", fig)


# --- sweeps ---------------------------------------------------------------------------------
_SWEEP_METRICS = [("track_max", "max |θ − θd| after transient [rad]"),
                  ("defl_max", "max tip deflection [m]"),
                  ("est_max_theta", "max angle estimation error [rad]")]


def _metric(run: _Run, key: str) -> float:
    m = run.metrics
    vals = [m.get(k) for k in m if k.startswith(key) and (key != "est_max_theta" or
                                                           not k.endswith("_dot"))]
    vals = [v for v in vals if isinstance(v, float) and not math.isnan(v)]
    return max(vals) if vals else math.nan


def _sweep_figures(runs: list[_Run], figs: _Figures) -> None:
    by_sweep: dict[str, list[_Run]] = {}
    for r in runs:
        if r.entry.get("sweep") and r.entry.get("axes"):
            by_sweep.setdefault(r.entry["sweep"], []).append(r)
    for sweep, rs in by_sweep.items():
        axes_names = sorted({a for r in rs for a in r.entry["axes"]})
        numeric = [a for a in axes_names if a != "plant.kind" and all(
            isinstance(r.entry["axes"].get(a), (int, float)) and not isinstance(
                r.entry["axes"].get(a), bool) for r in rs)]
        for axis in numeric:
            metrics = [(k, t) for k, t in _SWEEP_METRICS if any(
                not math.isnan(_metric(r, k)) for r in rs)]
            fig, axs = plt.subplots(1, len(metrics), figsize=(4.5 * len(metrics), 3.3),
                                    squeeze=False)
            others = [a for a in axes_names if a not in (axis,)]
            for ax, (key, title) in zip(axs[0], metrics):
                lines: dict[str, list[tuple[float, float]]] = {}
                for r in rs:
                    lab = ", ".join(f"{a.split('.')[-1]}={r.entry['axes'].get(a)}" for a in others)
                    lines.setdefault(lab or r.plant, []).append(
                        (r.entry["axes"][axis], _metric(r, key)))
                for lab, pts in sorted(lines.items()):
                    pts.sort()
                    style = _PLANT_STYLE.get("exudyn" if "exudyn" in lab else "reduced", {})
                    ax.plot(*zip(*pts), marker="o", label=lab, color=style.get("color"),
                            ls=style.get("ls"))
                ax.set_xlabel(axis)
                ax.set_title(title, fontsize=9)
            axs[0, 0].legend(fontsize=7)
            fig.suptitle(f"sweep '{sweep}': metrics vs {axis}")
            figs.add("Sweeps", f"sweep '{sweep}': metrics vs {axis}", fig)


# --- validity map ---------------------------------------------------------------------------------
def _validity_figure(params: ArmParameters, modes: tuple[int, int], figs: _Figures) -> None:
    theta2 = np.linspace(0.0, np.pi, 13)
    model = ArmModel(params, modes)
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    for col, joints in enumerate(("locked", "free")):
        red, fe = [], []
        for t2 in theta2:
            Q = np.zeros(model.n)
            Q[1] = t2
            red.append(model.natural_frequencies(Q, joints)[:4])
            fe.append(natural_frequencies(params, Mesh(), theta=(0.0, t2), joints=joints,
                                          n=len(red[-1])))
        red, fe = np.array(red), np.array(fe)
        for k in range(red.shape[1]):
            axes[0, col].plot(theta2, red[:, k], color=f"C{k}", label=f"mode {k + 1} reduced")
            axes[0, col].plot(theta2, fe[:, k], color=f"C{k}", ls="--", marker=".",
                              label=f"mode {k + 1} FE")
            axes[1, col].plot(theta2, 100 * (red[:, k] - fe[:, k]) / fe[:, k], color=f"C{k}",
                              marker=".", label=f"mode {k + 1}")
        axes[0, col].set_yscale("log")
        axes[0, col].set_ylabel("frequency [Hz]")
        axes[0, col].set_title(f"joints {joints}")
        axes[1, col].set_ylabel("(reduced − FE)/FE [%]")
        axes[1, col].set_xlabel("θ2 [rad]")
        axes[1, col].axhline(0, color="k", lw=0.5)
    axes[0, 0].legend(fontsize=7, ncol=2)
    axes[1, 0].legend(fontsize=7)
    fig.suptitle(f"validity map: reduced model ({modes[0]}+{modes[1]} modes, solid) vs "
                 "FE (ANCF 4 el, dashed)")
    figs.add("Validity of the reduced model", "frequencies vs θ2: reduced model vs FE, and "
                                               "their relative gap", fig)


# --- animation --------------------------------------------------------------------------------------
def _arm_shape(params: ArmParameters, model: ArmModel, Q: np.ndarray, magnify: float):
    """Points along both links for the state Q with deflection × ``magnify``."""
    n1 = model.modes_per_link[0]
    x1 = np.linspace(0, params.L1, 15)
    x2 = np.linspace(0, params.L2, 15)
    (m1, m2) = model.mode_shapes
    w1 = magnify * (m1.phi(x1).T @ Q[2:2 + n1])
    w2 = magnify * (m2.phi(x2).T @ Q[2 + n1:])
    slope1 = magnify * (m1.tip_values[1] @ Q[2:2 + n1])
    z1 = np.exp(1j * Q[0]) * (x1 + 1j * w1)
    z2 = z1[-1] + np.exp(1j * (Q[0] + Q[1] + slope1)) * (x2 + 1j * w2)
    return np.concatenate([[0], z1, z2])


def _animation(store: ResultStore, group: list[_Run], path: Path, *, seconds: float = 10.0,
               fps: int = 12) -> str:
    from matplotlib.animation import FuncAnimation, PillowWriter
    results = [(r, store.load(r.rid)) for r in group]
    cfg = results[0][1].config
    params = ArmParameters.from_mapping(cfg["nominal_params"])
    model = ArmModel(params, tuple(cfg["model"]["modes_per_link"]))
    coords = model.coordinate_names
    # Scale the deflection after the transient (the start-up bend is much larger) to
    # ~10 % of link 1 on screen.
    typical = max(np.percentile(np.abs(res.select(["tip_defl1", "tip_defl2"])[:, res.time >= 2.0]
                                       if res.time[-1] > 2.0 else res.select(["tip_defl1"])), 95)
                  for _, res in results)
    magnify = float(max(1, round(0.1 * params.L1 / max(typical, 1e-9))))
    t_end = min(seconds, min(res.time[-1] for _, res in results))
    frames = np.arange(0.0, t_end, 1.0 / fps)
    fig, ax = plt.subplots(figsize=(5, 5))
    reach = params.L1 + params.L2
    ax.set_xlim(-1.1 * reach, 1.1 * reach)
    ax.set_ylim(-1.1 * reach, 1.1 * reach)
    ax.set_aspect("equal")
    lines = [ax.plot([], [], lw=2, label=f"{r.plant} plant", **_PLANT_STYLE.get(r.plant, {}))[0]
             for r, _ in results]
    ref_line, = ax.plot([], [], color="k", lw=0.8, alpha=0.5, label="rigid reference")
    title = ax.set_title("")
    ax.legend(loc="lower left", fontsize=8)

    def draw(t):
        for line, (_, res) in zip(lines, results):
            k = min(int(round(t / (res.time[1] - res.time[0]))), len(res.time) - 1)
            Q = res.select(coords)[:, k].astype(float)
            z = _arm_shape(params, model, Q, magnify)
            line.set_data(z.real, z.imag)
        res = results[0][1]
        k = min(int(round(t / (res.time[1] - res.time[0]))), len(res.time) - 1)
        th = res.select(["theta1_ref", "theta2_ref"])[:, k].astype(float)
        zr = np.cumsum([0, params.L1 * np.exp(1j * th[0]), params.L2 * np.exp(1j * th.sum())])
        ref_line.set_data(zr.real, zr.imag)
        title.set_text(f"{group[0].name}  t = {t:4.1f} s  (deflection ×{magnify:g})")
        return (*lines, ref_line, title)

    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    tmp = path.with_suffix(".tmp.gif")
    anim.save(tmp, writer=PillowWriter(fps=fps))
    plt.close(fig)
    tmp.replace(path)
    return f"{group[0].name}: arm motion, truth and reduced plant, deflection ×{magnify:g}"


# --- writing ------------------------------------------------------------------------------------------
def write_report(results_dir: str | Path, *, animate: bool = True,
                 figures: list[str] | None = None) -> tuple[Path, Path]:
    """Write report.html and report.md for ``results_dir``; returns their paths."""
    store = ResultStore(results_dir)
    if not store.manifest_path.exists():
        raise ValueError(f"{results_dir}: no manifest.json (not a results folder)")
    runs = _load_runs(store)
    if not runs:
        raise ValueError(f"{results_dir}: no stored runs")
    manifest = store.manifest()
    wanted = figures or manifest.get("campaign", {}).get("report", {}).get("figures")
    out = store.out / "report"
    (out / "figures").mkdir(parents=True, exist_ok=True)
    figs = _Figures()
    groups = _figure_groups(runs, wanted)
    for group in groups:
        _paper_figures(store, group, figs)
    _sweep_figures(runs, figs)
    first = store.load(runs[0].rid).config
    _validity_figure(ArmParameters.from_mapping(first["true_params"]),
                     tuple(first["model"]["modes_per_link"]), figs)
    animation_caption = None
    if animate and groups:
        animation_caption = _animation(store, groups[0], out / "arm.gif")

    claims = store.out / "claims.md"
    claims_text = claims.read_text() if claims.exists() else None
    md_path, html_path = out / "report.md", out / "report.html"
    md = _markdown(store, runs, figs, out, claims_text, animation_caption)
    write_atomic(md_path, lambda fh: fh.write(md))
    page = _html(store, runs, figs, claims_text, animation_caption, out)
    write_atomic(html_path, lambda fh: fh.write(page))
    return html_path, md_path


def _run_rows(runs: list[_Run]) -> tuple[list[str], list[list[str]]]:
    head = ["run", "name", "plant", "controller", "observer", "swept values", "status"]
    rows = [[r.rid, r.name, r.plant, r.entry["controller"], r.entry["observer"],
             ", ".join(f"{k}={v}" for k, v in r.entry.get("axes", {}).items()
                       if k not in ("plant.kind", "name")),
             r.entry.get("status", "") + (f" ({r.entry['message']})" if r.entry.get("message") else "")]
            for r in runs]
    return head, rows


def _metric_rows(runs: list[_Run]) -> tuple[list[str], list[list[str]]]:
    head = ["run", "name", "plant"] + [label for _, label in _METRIC_COLUMNS] + \
        ["max est. θ [rad]", "max est. q̇ [m/s]"]
    rows = []
    for r in runs:
        m = r.metrics
        est_q = [v for k, v in m.items() if k.startswith("est_max_q") and k.endswith("_dot")
                 and isinstance(v, float)]
        rows.append([r.rid, r.name, r.plant] + [_fmt(m.get(k)) for k, _ in _METRIC_COLUMNS]
                    + [_fmt(_metric(r, "est_max_theta")), _fmt(max(est_q) if est_q else None)])
    return head, rows


def _md_table(head, rows) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _markdown(store, runs, figs, out, claims_text, animation_caption) -> str:
    parts = [f"# Report: {store.out.name}", "",
             f"{len(runs)} runs; statuses: " + ", ".join(
                 f"{s} {sum(r.entry.get('status') == s for r in runs)}"
                 for s in ("ok", "diverged", "failed")), ""]
    if claims_text:
        parts += ["## Claims of the paper", "", claims_text, ""]
    parts += ["## Runs", "", _md_table(*_run_rows(runs)), "", "## Metrics", "",
              _md_table(*_metric_rows(runs)), ""]
    for section in SECTIONS[2:5]:
        parts += [f"## {section}", ""]
        for i, (sec, caption, png) in enumerate(figs.items):
            if sec == section:
                name = f"fig{i:02d}.png"
                (out / "figures" / name).write_bytes(png)
                parts += [f"![{caption}](figures/{name})", "", f"*{caption}*", ""]
    if animation_caption:
        parts += ["## Animation", "", f"![{animation_caption}](arm.gif)", "",
                  f"*{animation_caption}*", ""]
    return "\n".join(parts)


def _html_table(head, rows) -> str:
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>"
                   for row in rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"


def _html(store, runs, figs, claims_text, animation_caption, out) -> str:
    parts = [f"<h1>Report: {html.escape(store.out.name)}</h1>",
             f"<p>{len(runs)} runs</p>"]
    if claims_text:
        rows = [line.strip("|").split("|") for line in claims_text.splitlines()
                if line.startswith("|") and not line.startswith("|---")]
        parts += ["<h2>Claims of the paper</h2>",
                  _html_table([c.strip() for c in rows[0]], [[c.strip() for c in r] for r in rows[1:]])]
    parts += ["<h2>Runs</h2>", _html_table(*_run_rows(runs)),
              "<h2>Metrics</h2>", _html_table(*_metric_rows(runs))]
    for section in SECTIONS[2:5]:
        parts.append(f"<h2>{html.escape(section)}</h2>")
        for sec, caption, png in figs.items:
            if sec == section:
                data = base64.b64encode(png).decode()
                parts.append(f'<figure><img src="data:image/png;base64,{data}" '
                             f'alt="{html.escape(caption)}"><figcaption>{html.escape(caption)}'
                             "</figcaption></figure>")
    if animation_caption:
        data = base64.b64encode((out / "arm.gif").read_bytes()).decode()
        parts += ["<h2>Animation</h2>", f'<figure><img src="data:image/gif;base64,{data}" '
                  f'alt="animation"><figcaption>{html.escape(animation_caption)}</figcaption></figure>']
    style = ("body{font-family:sans-serif;max-width:1200px;margin:auto}"
             "table{border-collapse:collapse;font-size:12px}"
             "td,th{border:1px solid #ccc;padding:2px 6px}img{max-width:100%}")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(store.out.name)}"
            f"</title><style>{style}</style></head><body>{''.join(parts)}</body></html>")
