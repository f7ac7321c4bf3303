"""A sweep's figures: each judged metric against the swept axis, one line per
combination of the other axes, diverged and failed runs in a strip of their own
(the conventions of `validation.report.figures`)."""
from __future__ import annotations

import json
import math
import re

from .figures import BOUND_STYLE, figure_title, plt, png

__all__ = ["sweep_figures", "SWEEP_METRICS", "AXIS_UNITS", "axis_label", "short_value",
           "fit_tick_labels"]

#: Units of the scenario keys a sweep may vary (shown on the x axes).
AXIS_UNITS = {
    "Ts": "s", "plant.step": "s", "duration": "s", "transient": "s", "torque_limit": "N m",
    "sensors.encoder_noise": "rad", "sensors.modal_noise": "m", "sensors.rate_noise": "rad/s",
    "sensors.encoder_resolution": "rad", "sensors.delay": "samples",
    "Mp": "kg", "Jp": "kg m²", "mh1": "kg", "mh2": "kg", "Jh1": "kg m²", "Jh2": "kg m²",
    "EI1": "N m²", "EI2": "N m²", "rho1": "kg/m", "rho2": "kg/m", "L1": "m", "L2": "m",
    "stator_inertia": "kg m²", "stator_mass": "kg", "bending_damping1": "N m² s",
    "bending_damping2": "N m² s",
}


def axis_label(axis: str) -> str:
    """A sweep axis as an axis label with its unit, e.g. "true_params.Mp [kg]"."""
    unit = AXIS_UNITS.get(axis) or AXIS_UNITS.get(axis.split(".")[-1])
    if axis in ("Ts", "plant.step"):
        return f"{axis} [ms]"
    return f"{axis} [{unit}]" if unit else axis


#: (key, title, metrics whose largest value is drawn, display factor, display unit).
SWEEP_METRICS = [
    ("track_max", "tracking error, max after the transient", ("track_max_1", "track_max_2"),
     1e3, "mrad"),
    ("vib_rms", "vibration RMS after the transient", ("vib_rms_1", "vib_rms_2"), 1e3, "mm"),
    ("est_theta", "angle estimation error, max", ("est_max_theta1", "est_max_theta2"),
     1e3, "mrad"),
    ("tau_tv", "torque variation", ("tau_tv_1", "tau_tv_2"), 1.0, "N m/s"),
]


def _key(value) -> str:
    return json.dumps(value, sort_keys=True)


def _groups_of_axes(runs, axes: list[str]) -> list[list[str]]:
    """Varying axes grouped where one determines the others (a zip: ``name`` with the
    controller and observer kinds it pairs with) — one x axis per group."""
    distinct = {a: len({_key(r.axes.get(a)) for r in runs}) for a in axes}
    order = sorted(axes, key=lambda a: (-distinct[a], a != "name", a))
    groups: list[list[str]] = []
    for a in order:
        for g in groups:
            pairs = {(_key(r.axes.get(g[0])), _key(r.axes.get(a))) for r in runs}
            if len(pairs) == distinct[g[0]]:  # g's leader determines a
                g.append(a)
                break
        else:
            groups.append([a])
    return groups


def sweep_figures(sweep: str, runs, bounds: dict | None = None) -> list[tuple[str, bytes]]:
    """Each metric of a sweep against its swept values, with its claim's bound
    (``bounds``: metric key of `SWEEP_METRICS` → bound in SI units).

    Axes that vary together (a zip) form one group and one x axis, labelled by the run
    names if ``name`` is among them.  A figure is drawn for every numeric group and every
    group of three or more values (the other groups become series, one per combination
    and plant); with no such group, the largest group is the x axis.  Constant axes are
    not drawn; list-valued axes are categories labelled by their value; diverged and
    failed runs are a crimson × in a strip above the panels, never a data point, on a row
    naming their series (plant and the other axes).  The plant (``plant.kind``, or whole
    plant tables, one per plant) is a series, not an axis.

    The metrics are panels one above the other, sharing the x axis: its labels are
    written once, under the last, at the report's type size, horizontal where they fit
    (`fit_tick_labels`)."""
    axes = sorted({a for r in runs for a in r.axes})
    plants = len({r.plant_label for r in runs})
    varying = [a for a in axes if a != "plant.kind"
               and not (a == "plant" and len({_key(r.axes.get(a)) for r in runs}) == plants)
               and len({_key(r.axes.get(a)) for r in runs}) > 1]
    groups = _groups_of_axes(runs, varying)
    values = {tuple(g): sorted({_key([r.axes.get(a) for a in g]) for r in runs},
                               key=lambda k: _sort_key(json.loads(k))) for g in groups}

    def numeric(g):  # the group's leading axis is a number: a numeric x axis
        return all(isinstance(json.loads(x)[0], (int, float)) and
                   not isinstance(json.loads(x)[0], bool) for x in values[tuple(g)])
    primary = [g for g in groups if numeric(g) or len(values[tuple(g)]) >= 3] or \
        sorted(groups, key=lambda g: -len(values[tuple(g)]))[:1]
    metrics = [m for m in SWEEP_METRICS if any(isinstance(r.metrics.get(k), float) and
                                               not math.isnan(r.metrics.get(k)) for r in runs
                                               for k in m[2])]
    return [_sweep_figure(sweep, runs, g, [a for h in groups if h != g for a in h], values[tuple(g)],
                          numeric(g), metrics, bounds or {}) for g in primary]


def _sweep_figure(sweep, runs, group, others, xs, numeric, metrics, bounds) -> tuple[str, bytes]:
    label_axis = "name" if "name" in group else group[0]
    scale = 1e3 if group[0] in ("Ts", "plant.step") else 1.0
    series: dict[tuple, list] = {}
    for r in runs:
        other = ", ".join(f"{a.split('.')[-1]}={short_value(r.axes.get(a))}" for a in others)
        series.setdefault((other, r.plant_label, r.role), []).append(r)
    keys = sorted(series)
    others_order = sorted({k[0] for k in keys})
    # A row of the strip per series with a run that diverged or failed, named: a run's
    # status is the same for every metric, so one strip heads the column of panels.
    bad_rows = [k for k in keys if any(r.status != "ok" for r in series[k])]
    any_bad = bool(bad_rows)
    # As wide as the report's page (11 in at the saved 110 dpi: ~1200 px) for many
    # categories, their labels side by side; narrower for a few or a number line.
    width = 9.0 if numeric else min(11.0, 6.0 + 0.5 * len(xs))
    fig = plt.figure(figsize=(width, 1.45 * len(metrics) + 1.9 + 0.3 * len(bad_rows)),
                     layout="constrained")
    grid = fig.add_gridspec(len(metrics) + any_bad, 1, height_ratios=(
        [0.25 + 0.2 * len(bad_rows)] if any_bad else []) + [1] * len(metrics))
    panels = []
    for row in range(len(metrics)):
        panels.append(fig.add_subplot(grid[row + any_bad, 0],
                                      sharex=panels[0] if panels else None))
    strip = fig.add_subplot(grid[0, 0], sharex=panels[0]) if any_bad else None
    for ax, (key, title, names, factor, unit) in zip(panels, metrics):
        for n, (other, plant, role) in enumerate(keys):
            color = f"C{others_order.index(other) % 10}"
            pts, bad = [], []
            for r in series[(other, plant, role)]:
                xk = _key([r.axes.get(a) for a in group])
                if numeric:
                    x = json.loads(xk)[0] * scale
                else:
                    x = xs.index(xk) + (n - (len(keys) - 1) / 2) * 0.6 / max(len(keys), 1)
                if r.status != "ok":
                    bad.append(x)
                    continue
                vals = [r.metrics.get(k) for k in names]
                vals = [v for v in vals if isinstance(v, float) and not math.isnan(v)]
                if vals:
                    pts.append((x, factor * max(vals)))
            label = _series_label((other, plant, role))
            truth = role == "truth"
            style = dict(color=color, marker="o" if truth else "s", ms=5,
                         mfc=color if truth else "white", label=label)
            if pts:
                pts.sort()
                ax.plot(*zip(*pts), ls=("--" if truth else "-") if numeric
                        else "none", lw=1, **style)
            if bad and ax is panels[0]:
                row = bad_rows.index((other, plant, role))
                strip.plot(bad, [row] * len(bad), "x", color="crimson", ms=7, mew=2)
        bound = bounds.get(key)
        if bound is not None:
            ax.axhline(factor * bound, label="claim bound", **BOUND_STYLE)
            lo, hi = ax.get_ylim()
            if factor * bound > 4 * hi:  # far above the data: name it, keep the data's scale
                ax.axhline(factor * bound, alpha=0)
                ax.set_ylim(lo, hi)
                ax.text(0.99, 0.97, f"bound {factor * bound:g} {unit}: above", ha="right",
                        va="top", transform=ax.transAxes, fontsize=7, color="crimson")
        ax.set_title(f"{title} [{unit}]", fontsize=9, loc="left")
        ax.tick_params(labelsize=8, labelbottom=ax is panels[-1])
    if numeric:
        lo = min(json.loads(x)[0] for x in xs) * scale
        hi = max(json.loads(x)[0] for x in xs) * scale
        if lo > 0 and hi / lo > 20:
            panels[0].set_xscale("log")
    else:
        panels[0].set_xticks(range(len(xs)))
    if strip is not None:
        strip.set_ylim(len(bad_rows) - 0.4, -0.6)
        strip.set_yticks(range(len(bad_rows)))
        # names in lines of a legend entry's width at most: the strip's margin is
        # every panel's, its width taken from the categories' slots
        strip.set_yticklabels([_wrapped(_series_label(k), 36) for k in bad_rows], fontsize=8,
                              color="crimson", linespacing=1.0)
        strip.tick_params(labelbottom=False, left=False)
        strip.set_title("diverged / failed: no value", fontsize=9, loc="left")
    zipped = [a for a in group if a != label_axis]
    panels[-1].set_xlabel(axis_label(label_axis) + (f" (zipped with {', '.join(zipped)})"
                                                    if zipped else ""), fontsize=9)
    handles, labels = panels[0].get_legend_handles_labels()
    if any_bad:
        handles.append(plt.Line2D([], [], ls="none", marker="x", color="crimson", mew=2))
        labels.append("diverged / failed (no value; top strip, a row per series)")
    fig.legend(handles, labels, loc="outside lower center", fontsize=8, ncol=2,
               title="filled: truth plant; hollow: reduced", title_fontsize=8)
    caption = f"sweep '{sweep}': metrics vs {' / '.join(group)}"
    figure_title(fig, caption)
    if not numeric:  # measured in the figure's final layout: last
        idx = group.index(label_axis)
        fit_tick_labels(panels[-1], [short_value(json.loads(x)[idx]).split("/")[-1]
                                     for x in xs])
    return caption, png(fig)


def fit_tick_labels(ax, labels: list[str], gap: float = 4.0) -> None:
    """Category labels on ``ax``'s ticks, horizontal: each on one line where they all fit
    side by side, else broken into lines at each "+", ",", ";" or space, and tilted only
    where even those overlap (measured in the figure's layout, with ``gap`` points
    between neighbours: call it once the figure is complete)."""
    def overlap() -> bool:
        fig = ax.figure
        fig.canvas.draw()
        boxes = sorted((t.get_window_extent() for t in ax.get_xticklabels()
                        if t.get_text()), key=lambda b: b.x0)
        pixels = gap * fig.dpi / 72
        return any(b.x0 < a.x1 + pixels for a, b in zip(boxes, boxes[1:]))
    ticks = ax.get_xticks()
    ax.set_xticks(ticks, labels, fontsize=8)
    if len(labels) < 2 or not overlap():
        return
    ax.set_xticks(ticks, [_wrapped(label, 0) for label in labels], fontsize=8)
    if overlap():
        ax.set_xticks(ticks, labels, fontsize=8, rotation=40, ha="right",
                      rotation_mode="anchor")


def _wrapped(label: str, chars: int) -> str:
    """``label`` in lines of at most ``chars`` characters where it can break: after a
    ", " or ";", before a "+", at a space (a word longer than a line stays whole; 0:
    a line per word)."""
    words = re.split(r"(?<=[,;])\s*|\s+|(?=\+)", label)
    lines: list[str] = []
    for word in filter(None, words):
        joint = "" if word.startswith("+") or not lines else " "
        if lines and len(lines[-1]) + len(joint) + len(word) <= chars:
            lines[-1] += joint + word
        else:
            lines.append(word)
    return "\n".join(lines)


def _series_label(key: tuple) -> str:
    """"truth plant (Exudyn), arm=table1": a series of a sweep figure, in words."""
    other, plant, _ = key
    return plant + (f", {other}" if other else "")


def _sort_key(values):
    return [(0, v) if isinstance(v, (int, float)) else (1, _key(v)) for v in values]


def short_value(value) -> str:
    """A swept value in a few words: numbers as %g, disturbances by kind, a plant table by
    its kind and what it sets ("exudyn, step=0.00025"), other lists and tables as JSON."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, dict) and isinstance(value.get("kind"), str):
        return ", ".join([value["kind"], *(f"{k}={short_value(v)}" for k, v in
                                           sorted(value.items()) if k != "kind")])
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return "; ".join(f"{d.get('kind', '?')} {d.get('target', '')} {d.get('amplitude', '')}"
                         .strip() for d in value)
    if value == []:
        return "none"
    return json.dumps(value) if isinstance(value, (list, dict)) else str(value)


# --- the reduced model's validity, the stability map --------------------------------------------
