"""The report of a campaign of many runs: distributions, worst cases and the runs that
decide a verdict, instead of a table row and a figure per run.

A campaign of more than `MANY` reported runs (a sweep over uncertainty, a falsification
budget: 10^4–10^6 runs) is summarised: for each main metric and each requirement's
robustness ρ, over the runs that completed, its quantiles and histogram, the runs where
it is worst, and for a requirement how many runs fail it and the runs nearest its
boundary (ρ closest to 0: those a slightly different arm or code would turn).  The
values are read from the rows' metric columns (`validation.batch.store.records.metric_matrix`:
no run's scenario decoded), so the section's time grows linearly with the runs, a few
seconds at 10^5; every run's values are in ``metrics.csv``."""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from ..batch.store.records import metric_matrix
from .render import fmt_number

__all__ = ["MANY", "is_many", "Completed", "completed", "distributions", "histograms",
           "read_metrics", "windows_of"]

#: More reported runs than this are summarised (a table row per run is no longer read).
MANY = 2000
#: (metric, what it is, factor to the unit shown, unit, "max" if larger is worse).
_HEADLINE = [("track_max_1", "max |e₁|", 1e3, "mrad", "max"),
             ("track_max_2", "max |e₂|", 1e3, "mrad", "max"),
             ("vib_rms_1", "vibration 1", 1e3, "mm", "max"),
             ("vib_rms_2", "vibration 2", 1e3, "mm", "max"),
             ("defl_max_1", "max deflection 1", 1e3, "mm", "max"),
             ("tau_max_1", "max |τ₁|", 1, "N m", "max"),
             ("rate_err_rel", "rate error / peak rate", 1, "", "max"),
             ("est_rms_theta1", "θ₁ estimation error", 1e3, "mrad", "max")]
#: How many worst runs and runs nearest a boundary are named.
_NAMED = 5
_QUANTILES = (0.0, 0.05, 0.5, 0.95, 1.0)


def is_many(runs) -> bool:
    """Whether ``runs`` are summarised rather than listed."""
    return len(runs) > MANY


@dataclass(frozen=True)
class Completed:
    """The runs that completed and their metrics, read once from the rows' columns
    (`validation.batch.store.records.metric_matrix`) for the summary's tables, its figure and
    the windows of the report's scope."""

    ok: list
    #: (key, label, scale, unit, worse) of each metric shown (`_metrics`).
    shown: list
    #: (len(ok), len(shown) + 2): the metrics shown, then the transient and end time.
    values: np.ndarray


def completed(runs) -> Completed:
    """`Completed` of ``runs``."""
    ok = [r for r in runs if r.status == "ok"]
    shown = _metrics(ok)
    return Completed(ok, shown, metric_matrix(ok, [*(m[0] for m in shown),
                                                   "transient_s", "end_time"]))


def windows_of(runs, done: Completed | None = None) -> set:
    """(transient, duration) of ``runs``: from each run's scenario, or for many runs from
    the metrics that say them (the transient applied; the end time of a run that
    completed: ``done``, `completed` of ``runs``) and the scenarios of the others."""
    if not is_many(runs):
        return {(r.config["transient"], r.config["duration"]) for r in runs}
    done = done or completed(runs)
    pairs = {tuple(p) for p in np.unique(done.values[:, -2:], axis=0).tolist()}
    return pairs | {(r.config["transient"], r.config["duration"])
                    for r in runs if r.status != "ok"}


def read_metrics(store) -> tuple[str, ...] | None:
    """The metrics a report of ``store`` reads of every run: all of them (None) for a
    few runs; for many, those this summary shows, the requirements' ρ and the windows
    (transient, end time) — reading every metric is most of reading 10^5 rows."""
    if len(store.columns(["run_id"])) <= MANY:
        return None
    names = [c[2:] for c in store.column_names() if c.startswith("m:")]
    return ("status", "end_time", "transient_s", *(m[0] for m in _HEADLINE),
            *(n for n in names if n.startswith("rho_")))


def _metrics(runs) -> list[tuple]:
    """The headline metrics and requirements' ρ that ``runs`` have: (key, label, scale,
    unit, worse)."""
    layouts = {id(r.metric_names): r.metric_names for r in runs}  # shared tuples: no hash
    names = {n for layout in layouts.values() for n in layout}
    rhos = sorted(n for n in names if n.startswith("rho_"))
    return [m for m in _HEADLINE if m[0] in names] + \
        [(n, f"ρ of {n[4:]}", 1, "", "min") for n in rhos]


def _who(run) -> str:
    swept = ", ".join(f"{k}={v}" for k, v in run.axes.items())
    return f"{run.run_id} ({swept})" if swept else f"{run.run_id} ({run.name})"


def distributions(runs, done: Completed) -> dict | None:
    """The summary of ``runs`` (rows that completed or not; ``done``: `completed` of
    them): counts, per metric its quantiles over the runs that completed and the worst
    runs, per requirement the runs that fail it and those nearest its boundary; None if
    no run completed."""
    ok, values = done.ok, done.values
    if not ok or not done.shown:
        return None
    rows, worst, deciding = [], [], []
    for j, (key, label, scale, unit, worse) in enumerate(done.shown):
        column = values[:, j]
        finite = np.isfinite(column)
        if not finite.any():
            continue
        shown = np.quantile(column[finite], _QUANTILES) * scale
        rows.append([f"{label} [{unit}]" if unit else label, str(int(finite.sum())),
                     *(fmt_number(v) for v in shown)])
        order = np.argsort(column if worse == "min" else -column, kind="stable")
        # NaN sorts last either way; ±∞ first where it is worst
        named = [i for i in order[:_NAMED] if not np.isnan(column[i])]
        worst.append([label, "; ".join(f"{fmt_number(scale * column[i])} in {_who(ok[i])}"
                                       for i in named)])
        if key.startswith("rho_"):
            fails = int((column < 0).sum())
            near = np.argsort(np.abs(np.where(np.isnan(column), np.inf, column)),
                              kind="stable")[:_NAMED]
            deciding.append([label, f"{fails} of {int(finite.sum())}",
                             "; ".join(f"ρ = {fmt_number(column[i])} in {_who(ok[i])}"
                                       for i in near if np.isfinite(column[i]))])
    statuses = Counter(r.status for r in runs)
    counts = {s: statuses[s] for s in ("ok", "diverged", "failed")}
    return {"count": len(runs), "counts": counts,
            "quantiles": {"head": ["metric", "runs", "min", "5 %", "median", "95 %", "max"],
                          "rows": rows, "classes": [""] * len(rows)},
            "worst": {"head": ["metric", f"the {_NAMED} worst runs"], "rows": worst,
                      "classes": [""] * len(worst)},
            "deciding": {"head": ["requirement", "runs that fail it",
                                  f"the {_NAMED} runs nearest its boundary (ρ = 0)"],
                         "rows": deciding, "classes": [""] * len(deciding)} if deciding else None,
            "stopped": _stopped(runs)}


def _stopped(runs) -> list[str]:
    """The first runs that diverged or failed, named with why."""
    bad = [r for r in runs if r.status != "ok"][:_NAMED]
    return [f"{r.run_id} {r.status}: {r.message}" for r in bad]


def histograms(done: Completed) -> bytes | None:
    """One figure: a histogram of each headline metric and ρ over the runs that
    completed (``done``, `completed`) (PNG); None if none."""
    from . import figures as fig
    import matplotlib.pyplot as plt
    wanted, values = done.shown, done.values
    if not done.ok or not wanted:
        return None
    columns = min(4, len(wanted))
    lines = -(-len(wanted) // columns)
    width, height = 3.2 * columns, 2.4 * lines
    # margins fixed in inches (room for 7-pt tick labels, an axis offset and a 9-pt
    # title): a layout engine's passes over every tick label were half the figure's time
    figure, axes = plt.subplots(lines, columns, figsize=(width, height), squeeze=False,
                                gridspec_kw={"left": 0.5 / width, "right": 1 - 0.15 / width,
                                             "bottom": 0.45 / height, "top": 1 - 0.3 / height,
                                             "wspace": 0.55 / (3.2 - 0.55),
                                             "hspace": 0.8 / (2.4 - 0.8)})
    for ax, (j, (key, label, scale, unit, _)) in zip(axes.flat, enumerate(wanted)):
        column = values[:, j]
        column = column[np.isfinite(column)] * scale
        if column.size:  # stairs of np.histogram: a third of hist's time (50 patches)
            ax.stairs(*np.histogram(column, bins=50), fill=True, color="#4477aa")
        if key.startswith("rho_"):
            ax.axvline(0.0, color="#cc3311", lw=1)
        ax.set_title(f"{label} [{unit}]" if unit else label, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.locator_params(axis="x", nbins=4)
    for ax in list(axes.flat)[len(wanted):]:
        ax.set_visible(False)
    return fig.png(figure)
