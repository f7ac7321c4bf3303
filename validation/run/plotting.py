"""Drawing runs' signals (matplotlib), shared by `RunResult.plot` and the reports
(`validation.report.figures`, whose docstring states the conventions): the plants' styles,
a dense series as its envelope, y-ranges after the transient, the claims' bounds, and the
panels of the paper's Figs. 3 and 4.

pyplot is imported where a figure is made, and the backend is never chosen here: a
notebook keeps its own (the reports choose Agg).
"""
from __future__ import annotations

import textwrap

import numpy as np

__all__ = ["PLANT_STYLE", "BOUND_STYLE", "SUB", "DPI", "NOTE_PT", "ENVELOPE_LABEL",
           "figure_title", "figure_legend", "pixel_columns", "envelope", "trace", "plant_trace",
           "fit_ylim", "bound_lines", "draw_tracking", "draw_deflections", "plot_results"]

#: Reduced plant wide and light underneath, truth plant thin and dark on top.
PLANT_STYLE = {"reduced": dict(color="tab:blue", lw=2.4, alpha=0.45, zorder=2),
               "truth": dict(color="darkred", lw=0.8, alpha=1.0, zorder=3)}
BOUND_STYLE = dict(color="crimson", lw=0.9, ls=(0, (5, 3)), zorder=4)
SUB = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")
#: Resolution of the saved figures [dots per inch]: a dense series is binned to its
#: pixel columns at it.
DPI = 110
#: Type size of a note in a panel [pt], and its margin to the frame [pt].
NOTE_PT = 6.5
_NOTE_MARGIN = 2.0
#: The legend's entry for the envelopes of dense series (`trace`), drawn as a neutral patch.
ENVELOPE_LABEL = "shaded: min–max per pixel column"


def figure_title(fig, text: str, fontsize: float = 10) -> None:
    """A figure title wrapped to the figure's width (never wider than the plots)."""
    chars = max(40, int(fig.get_figwidth() * 72 / (0.55 * fontsize)))
    fig.suptitle(textwrap.fill(text, chars), fontsize=fontsize)


def figure_legend(fig, axes) -> None:
    """One legend for a grid of panels, below them (never over the data); entries of
    every panel, each label once."""
    from matplotlib.patches import Patch
    seen = {}
    for ax in np.ravel(axes):
        for h, label in zip(*ax.get_legend_handles_labels()):
            seen.setdefault(label, h)
    if ENVELOPE_LABEL in seen:  # one entry for the bands of every colour, at the end
        del seen[ENVELOPE_LABEL]
        seen[ENVELOPE_LABEL] = Patch(facecolor=(0.5, 0.5, 0.5, 0.15), edgecolor="0.3", lw=0.5)
    if seen:  # as many columns as the figure's width holds (8 pt: ~0.06 in a character)
        fits = int(fig.get_figwidth() / (0.06 * (max(map(len, seen)) + 6)))
        fig.legend(list(seen.values()), list(seen), loc="outside lower center",
                   ncol=max(1, min(len(seen), 4, fits)), fontsize=8)


# --- drawing a series -----------------------------------------------------------------------
def pixel_columns(ax) -> int:
    """Pixel columns of a panel at the saved resolution (`DPI`)."""
    return max(60, int(ax.get_position().width * ax.figure.get_figwidth() * DPI))


def envelope(t: np.ndarray, y: np.ndarray, columns: int):
    """(column centres, min, max, mean) of ``y`` over ``columns`` equal bins of samples."""
    n = t.size
    starts = np.linspace(0, n, columns + 1).astype(int)[:-1]
    counts = np.diff(np.append(starts, n))
    tc = np.add.reduceat(t, starts) / counts
    return (tc, np.minimum.reduceat(y, starts), np.maximum.reduceat(y, starts),
            np.add.reduceat(y, starts) / counts)


def trace(ax, t, y, *, color, lw=0.8, alpha=1.0, zorder=2, label=None, ls="-"):
    """A time series: a plain line if it has at most two samples per pixel column, else
    its envelope and the column mean (line).

    The envelope is the min and max per pixel column: a faint fill between two thin
    edges in the series' colour (fainter edges for a faint series).  A series that
    chatters at the sampling rate (an observer's sign term: its error flips sign every
    sample) has an envelope as wide as the chatter in every column, a band of constant
    width filling the panel: faint, it leaves the mean lines of both plants readable
    inside it, and the edges tell the two plants' bands apart.  The fill is labelled
    `ENVELOPE_LABEL`, the legend's one entry for every such band (`figure_legend`)."""
    y = np.asarray(y, dtype=float)
    columns = pixel_columns(ax)
    if t.size <= 2 * columns:
        ax.plot(t, y, color=color, lw=lw, alpha=alpha, zorder=zorder, label=label, ls=ls)
        return
    tc, lo, hi, mean = envelope(np.asarray(t, float), y, columns)
    ax.fill_between(tc, lo, hi, color=color, alpha=0.06, lw=0, zorder=zorder - 0.5,
                    label=ENVELOPE_LABEL)
    for edge in (lo, hi):
        ax.plot(tc, edge, color=color, lw=0.5, alpha=0.8 * alpha, zorder=zorder - 0.4)
    ax.plot(tc, mean, color=color, lw=lw, alpha=alpha, zorder=zorder, label=label, ls=ls)


def plant_trace(ax, run, t, y, *, label=True, suffix="") -> None:
    """`trace` of a run in its plant's style (`PLANT_STYLE`), labelled by its plant."""
    st = PLANT_STYLE.get(run.role, dict(color="k", lw=1.0))
    trace(ax, t, y, label=(run.plant_label + suffix) if label else None, **st)


def fit_ylim(ax, series, transient: float, bound: float | None = None, unit: str = "") -> None:
    """y-range from the samples after the transient (the start-up may leave the frame);
    a symmetric ±bound joins the range if it is within 4× the data's extent, else it
    is named in the panel: a note under the frame's top edge, in headroom the y-range
    leaves above the data after the transient (`NOTE_PT` type), so that it sits over
    none of them."""
    late = [y[t >= transient] for t, y in series if (t >= transient).any()]
    if not late:
        return
    lo = min(float(np.nanmin(s)) for s in late)
    hi = max(float(np.nanmax(s)) for s in late)
    note = None
    if bound is not None:
        extent = max(abs(lo), abs(hi), 1e-300)
        if bound <= 4 * extent:
            lo, hi = min(lo, -bound), max(hi, bound)
        else:
            note = f"bound ±{bound:.3g} {unit} off scale"
    pad = 0.08 * (hi - lo) or 1e-12
    lo, hi = lo - pad, hi + pad
    if note is not None:
        # The note wrapped to the panel's width and its lines with their margins as a
        # share of the panel's height (at most 0.45: the data keep the rest).  The layout
        # engine shrinks a panel after this, for titles, labels and the legend (Fig. 7's:
        # 75 -> 52 pt high, 85 -> 59 pt wide): both are taken 1.5x what the panel's size
        # now asks (a character: ~0.6 of the type size).
        size = ax.get_position().size * ax.figure.get_size_inches() * 72  # [pt]
        note = textwrap.fill(note, max(10, int(size[0] / 1.5 / (0.6 * NOTE_PT))))
        lines = note.count("\n") + 1
        share = min(0.45, 1.5 * (1.2 * NOTE_PT * lines + 2 * _NOTE_MARGIN) / size[1])
        hi += share * (hi - lo) / (1 - share)
        ax.annotate(note, (1.0, 1.0), xycoords="axes fraction", ha="right", va="top",
                    xytext=(-_NOTE_MARGIN, -_NOTE_MARGIN), textcoords="offset points",
                    fontsize=NOTE_PT, color=BOUND_STYLE["color"], linespacing=1.1)
    ax.set_ylim(lo, hi)


def bound_lines(ax, bound: float, label: str) -> None:
    """A symmetric bound ±``bound`` in `BOUND_STYLE`."""
    ax.axhline(bound, label=label, **BOUND_STYLE)
    ax.axhline(-bound, **BOUND_STYLE)


# --- the paper's Figs. 3 and 4 -------------------------------------------------------------
def draw_tracking(axes, group, transient: float, bound: float | None = None) -> None:
    """The panels of the paper's Fig. 3 into ``axes`` (2 × N: θ per joint above, θ − θ_d
    [mrad] below), every run of ``group`` ((run, result) pairs) overlaid, with the
    tracking claim's bound ``bound`` [rad]; the error axes scaled after ``transient``."""
    joints = range(axes.shape[1])
    errs = {j: [] for j in joints}
    for run, res in group:
        for j in joints:
            plant_trace(axes[0, j], run, res.time, res[f"theta{j + 1}"])
            e = 1e3 * (res[f"theta{j + 1}"].astype(float) - res[f"theta{j + 1}_ref"])
            plant_trace(axes[1, j], run, res.time, e, label=False)
            errs[j].append((res.time, e))
    ref = group[0][1]
    for j in joints:
        axes[0, j].plot(ref.time, ref[f"theta{j + 1}_ref"], color="k", lw=0.6, ls=":",
                        label="reference, eq. (37)", zorder=4)
        axes[0, j].set_ylabel(f"θ{j + 1} [rad]".translate(SUB))
        axes[1, j].set_ylabel(f"θ{j + 1} − θ{j + 1},d [mrad]".translate(SUB))
        axes[1, j].axvline(transient, color="grey", lw=0.5, ls=":")
        if bound is not None:
            bound_lines(axes[1, j], 1e3 * bound, f"tracking bound ±{1e3 * bound:g} mrad")
        fit_ylim(axes[1, j], errs[j], transient, None if bound is None else 1e3 * bound, "mrad")


def draw_deflections(axes, group, transient: float, cutoff_hz: float | None = None,
                     bound: float | None = None) -> None:
    """The panels of the paper's Fig. 4 into ``axes`` (a row per link's tip deflection
    [mm], and with ``cutoff_hz`` a second row: its oscillatory part above that frequency,
    the vibration the claim judges, with the bound ``bound`` [m] on its RMS)."""
    from .vibration import oscillatory
    links = range(axes.shape[1])
    vib, rms = {j: [] for j in links}, {j: [] for j in links}
    for run, res in group:
        for j in links:
            plant_trace(axes[0, j], run, res.time, 1e3 * res[f"tip_defl{j + 1}"].astype(float))
        if cutoff_hz and res.time.size > 16:
            v = 1e3 * oscillatory(res, cutoff_hz)
            late = res.time >= transient
            for j in links:
                plant_trace(axes[1, j], run, res.time, v[j], label=False)
                vib[j].append((res.time, v[j]))
                if late.any():
                    rms[j].append(f"{run.role} {np.sqrt(np.mean(v[j][late] ** 2)):.3g}")
    for j in links:
        axes[0, j].set_ylabel(f"tip deflection {j + 1} [mm]")
        if cutoff_hz:
            axes[1, j].set_ylabel(f"vibration {j + 1} [mm]\n(> {cutoff_hz:.2f} Hz)")
            axes[1, j].axvline(transient, color="grey", lw=0.5, ls=":")
            axes[1, j].set_title(f"RMS after {transient:g} s: {', '.join(rms[j])}",
                                 fontsize="small")
            if bound is not None:
                bound_lines(axes[1, j], 1e3 * bound, f"vibration bound (on the RMS) "
                                                     f"±{1e3 * bound:g} mm")
            fit_ylim(axes[1, j], vib[j], transient, None if bound is None else 1e3 * bound, "mm")


def plot_results(results, *, transient: float | None = None):
    """One figure of the paper's Figs. 3–4 layout for ``results`` (RunResults of one arm,
    overlaid: the same scenario on two plants, say): θ per joint with the reference,
    θ − θ_d [mrad] and the tip deflections [mm], a column per joint (and its link).  The error axes are scaled after
    ``transient`` (default: the first result's)."""
    import matplotlib.pyplot as plt
    results = [r for r in results if r.time.size]
    group = [(_View(r.config), r) for r in results]
    if transient is None:
        transient = float(results[0].config.get("transient", 0.0))
    from .reductions import joints_of
    joints = joints_of(results[0])
    fig, axes = plt.subplots(3, joints, figsize=(1.5 + 3.75 * joints, 7), sharex=True,
                             layout="constrained", squeeze=False)
    draw_tracking(axes[:2], group, transient)
    draw_deflections(axes[2:], group, transient)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    figure_legend(fig, axes)
    names = " / ".join(dict.fromkeys(str(r.config.get("name", "")) for r in results))
    stopped = "".join(f"; {v.plant_label} {r.status.upper()} at {r.end_time:g} s"
                      for v, r in group if r.status != "ok")
    figure_title(fig, f"{names}: joint tracking and tip deflections (cf. the paper's Figs. "
                      f"3–4){stopped}")
    return fig


class _View:
    """What the drawing asks of a run, from its resolved scenario: its plant's role and
    label."""

    def __init__(self, config: dict):
        from .plants import label_of, role_of
        self.role, self.plant_label = role_of(config), label_of(config)
