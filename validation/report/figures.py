"""Figures of a report, drawn from stored results (matplotlib, Agg), returned as PNG bytes.

Conventions every figure follows, so that none misleads its reader:

- units on every axis, in the units a reader expects (errors in mrad, deflections in
  mm), time in seconds, states named as in the paper (θ₁, q̇₁₂ …), never metric keys;
- what was run (arm, plant, control period, initial condition) in a title wrapped to the
  figure's width, so a long title never squeezes the plots;
- the bound a claim is judged against is drawn, or, where it lies far off the data's
  scale, named in the panel, in headroom above the data (never over them);
- truth and reduced plant both stay visible: the reduced plant wide and light
  underneath, the truth plant thin and dark on top;
- a dense series (more samples than the panel has pixel columns) is drawn as its
  envelope — min and max per pixel column, a faint fill between thin edges — with the
  column mean as a line, so chatter reads as a band of known width around the signal
  it rides on;
- diverged and failed runs are never drawn as data: the paper's figures name them in
  the title, sweeps mark them in a strip of their own above the data (its own y-range);
- legends sit outside the panels, and every shaded band has its entry.
"""
from __future__ import annotations

import io
import math
import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..run.plotting import (BOUND_STYLE, DPI, PLANT_STYLE, SUB, bound_lines,  # noqa: E402
                             draw_deflections, draw_tracking, envelope, pixel_columns,
                             figure_legend, figure_title, fit_ylim, plant_trace, trace)
from ..run.reductions import joints_of, per_joint  # noqa: E402
from ..run.results import write_atomic  # noqa: E402

__all__ = ["png", "state_label", "state_unit", "state_display", "tracking", "deflections",
           "rates", "estimation_errors", "phase_portrait", "animation", "arm_snapshots",
           "describe_run",
           "envelope", "figure_title", "figure_legend", "PLANT_STYLE",
           "BOUND_STYLE"]

def png(fig, dpi: int = DPI) -> bytes:
    """The figure as PNG bytes (its layout engine already fits everything in: no second
    "tight" layout pass)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return buf.getvalue()


def state_label(state: str) -> str:
    """theta2_dot → θ̇₂, q12 → q₁₂."""
    rate = state.endswith("_dot")
    base = state.removesuffix("_dot")
    symbol, index = ("θ", base[5:]) if base.startswith("theta") else (base[0], base[1:])
    return symbol + ("\u0307" if rate else "") + index.translate(SUB)


def state_unit(state: str) -> str:
    """The SI unit of a state (rad, m, rad/s, m/s)."""
    angle = state.startswith("theta")
    return ("rad" if angle else "m") + ("/s" if state.endswith("_dot") else "")


def state_display(state: str) -> tuple[float, str]:
    """(factor, unit) in which an *error* of the state reads well: mrad, mm, mrad/s, mm/s."""
    return 1e3, {"rad": "mrad", "m": "mm", "rad/s": "mrad/s", "m/s": "mm/s"}[state_unit(state)]


def describe_run(config: dict) -> str:
    """What was run, in a few words: arm, Ts, initial condition."""
    start = "from rest" if config.get("initial_state") == "rest" else "moving with the reference"
    return f"{config.get('arm', 'default')} arm, Ts = {1e3 * config['Ts']:g} ms, {start}"


# --- the paper's figures ------------------------------------------------------------------------
def tracking(group, title: str, transient: float, bound: float | None = None) -> bytes:
    """Fig. 3 analogue: θ and θ − θ_d per joint, every plant of the group overlaid; the
    errors in mrad with the tracking claim's bound ``bound`` [rad]."""
    joints = joints_of(group[0][1])
    fig, axes = plt.subplots(2, joints, figsize=(1.0 + 3.0 * joints, 4.6), sharex=True,
                             squeeze=False, layout="constrained")
    draw_tracking(axes, group, transient, bound)
    for ax in axes[1]:
        ax.set_xlabel("t [s]")
    figure_legend(fig, axes)
    figure_title(fig, f"{title}: joint tracking (cf. the paper's Fig. 3); error axis scaled after "
                f"the {transient:g} s transient (grey line)")
    return png(fig)


def deflections(group, title: str, transient: float, cutoff_hz: float | None,
                bound: float | None = None) -> bytes:
    """Fig. 4 analogue: tip deflections [mm], and their oscillatory part (the vibration)
    with the vibration claim's bound on its RMS, ``bound`` [m]."""
    rows = 2 if cutoff_hz else 1
    links = joints_of(group[0][1])
    fig, axes = plt.subplots(rows, links, figsize=(1.0 + 3.0 * links, 2.0 * rows + 0.6),
                             sharex=True, squeeze=False, layout="constrained")
    draw_deflections(axes, group, transient, cutoff_hz, bound)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    figure_legend(fig, axes)
    figure_title(fig, f"{title}: tip deflections (cf. Fig. 4) and their oscillatory part (the "
                "vibration the claim judges)")
    return png(fig)


def _state_grid(states):
    """A grid of panels, one per state: positions in the first rows, rates after."""
    cols = min(3 if len(states) <= 6 else 4, len(states))
    rows = math.ceil(len(states) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(7, 1.2 * rows + 1.0),
                             sharex=True, layout="constrained", squeeze=False)
    for ax in axes.ravel()[len(states):]:
        ax.set_visible(False)
    return fig, axes


#: Rates figure: (true, estimate) colours per plant, distinct from each other.
_RATE_STYLE = {"truth": ("black", "darkred"), "reduced": ("0.45", "tab:blue")}


def rates(group, title: str, transient: float) -> bytes:
    """Figs. 5–6 analogue: true rates (black, grey) and their estimates (colours), each an
    envelope where it chatters; y-range after the transient; modal rates in mm/s."""
    observed = [(r, res) for r, res in group if "xhat_theta1" in res]
    states = [n.removeprefix("xhat_") for n in observed[0][1].names_with("xhat_") if n.endswith("_dot")]
    fig, axes = _state_grid(states)
    for ax, s in zip(axes.ravel(), states):
        scale, unit = (1.0, "rad/s") if s.startswith("theta") else (1e3, "mm/s")
        series = []
        for run, res in observed:
            true_color, estimate_color = _RATE_STYLE.get(run.role, ("k", "C1"))
            name = run.plant_label
            estimate = scale * res[f"xhat_{s}"].astype(float)
            true = scale * res[s].astype(float)
            trace(ax, res.time, estimate, color=estimate_color, lw=0.8, zorder=2,
                   label=f"{name}: estimate")
            trace(ax, res.time, true, color=true_color, lw=0.7, zorder=4,
                   label=f"{name}: true")
            series += [(res.time, estimate), (res.time, true)]
        fit_ylim(ax, series, transient)
        ax.axvline(transient, color="grey", lw=0.5, ls=":")
        ax.set_title(state_label(s), fontsize=10)
        ax.set_ylabel(f"[{unit}]")
        ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    figure_legend(fig, axes)
    figure_title(fig, f"{title}: true vs estimated rates (cf. Figs. 5–6), y-range after the "
                f"{transient:g} s transient (grey line)")
    return png(fig)


#: The edges of the measurement error's band: dotted, drawn over the data.
_SIGMA_EDGE = dict(lw=0.7, ls=":")


def estimation_errors(group, title: str, transient: float, bound: float | None = None) -> bytes:
    """Fig. 7 analogue: x̂ − x per state (mrad, mm, mrad/s, mm/s), y-range after the
    transient, with ±1 RMS of the raw measurement's error (grey band, dotted edges) where
    the state is measured, and the angle-estimation claim's bound ``bound`` [rad] on θ₁,
    θ₂ (named in the panel where it is off the errors' scale).

    Each plant's error is a line, its mean per pixel column, inside its envelope (min
    and max per column: a faint band between thin edges).  Where the sign observer
    chatters, the envelope is the chatter: on the paper's arm the q₂₂ error flips sign
    every sample on both plants, so its panel is a band of constant width, twice the
    error's amplitude, with the mean, near zero, inside it."""
    observed = [(r, res) for r, res in group if "xhat_theta1" in res]
    states = [n.removeprefix("xhat_") for n in observed[0][1].names_with("xhat_")]
    fig, axes = _state_grid(states)
    for ax, s in zip(axes.ravel(), states):
        scale, unit = state_display(s)
        series = []
        for run, res in observed:
            e = scale * (res[f"xhat_{s}"].astype(float) - res[s])
            series.append((res.time, e))
            plant_trace(ax, run, res.time, e)
            late = res.time >= transient
            if f"y_{s}" in res and late.any():  # a run that ended before its transient: no band
                sigma = scale * float(np.sqrt(np.mean(
                    (res[f"y_{s}"][late].astype(float) - res[s][late]) ** 2)))
                if sigma > 0:  # a band under the data, its edges on top of it
                    ax.axhspan(-sigma, sigma, facecolor="0.85", edgecolor="0.35", zorder=0,
                               label="measurement error, ±1 RMS (grey band)", **_SIGMA_EDGE)
                    for y in (sigma, -sigma):
                        ax.axhline(y, color="0.35", zorder=5, **_SIGMA_EDGE)
        angle_bound = bound is not None and s in ("theta1", "theta2")
        if angle_bound:
            bound_lines(ax, 1e3 * bound, f"angle-estimation bound ±{1e3 * bound:g} mrad")
        fit_ylim(ax, series, transient, 1e3 * bound if angle_bound else None, unit)
        ax.set_title(f"{state_label(s)} error", fontsize=10)
        ax.set_ylabel(f"[{unit}]")
        ax.tick_params(labelsize=7)
        ax.yaxis.get_offset_text().set_fontsize(7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    figure_legend(fig, axes)
    figure_title(fig, f"{title}: estimation errors x̂ − x (cf. Fig. 7), y-range after the "
                f"{transient:g} s transient")
    return png(fig)


def phase_portrait(group, title: str, transient: float,
                   rate_bound: float | None = None) -> bytes:
    """Fig. 8 analogue, with the reference's own orbit, the phase claim's band (the
    reference's rate ± ``rate_bound`` × its peak) and the paper's ±1.2 rad/s.  The
    y-range is the orbit's after ``transient`` (a start-up beyond it is named, not
    drawn to scale); a rate that chatters (its band within a pixel column wider than a
    quarter of the reference's peak rate, after the transient) is drawn as its mean per
    pixel column with the band light behind it, the y-range at most 3× the orbit's and
    the chatter's extent named."""
    ref = group[0][1]
    joints = joints_of(ref)
    fig, axes = plt.subplots(1, joints, figsize=(3.5 * joints, 3.5), layout="constrained",
                             squeeze=False)
    for j, ax in enumerate(axes[0]):
        name = f"θ̇{j + 1}".translate(SUB)
        th_ref, w_ref = ref[f"theta{j + 1}_ref"], ref[f"theta{j + 1}_dot_ref"].astype(float)
        peak = float(np.max(np.abs(w_ref))) or 1.0
        lo, hi, notes = -peak, peak, []
        for run, res in group:
            st = PLANT_STYLE.get(run.role, {})
            th, w = res[f"theta{j + 1}"].astype(float), res[f"theta{j + 1}_dot"].astype(float)
            late = res.time >= transient
            columns = 4 * pixel_columns(ax)
            band = None
            if late.sum() > 2 * columns:
                band = envelope(res.time[late], w[late], columns)
            if band is not None and np.median(band[2] - band[1]) > 0.25 * peak:  # chatter
                _, w_lo, w_hi, w_mean = band
                th_mean = envelope(res.time[late], th[late], columns)[3]
                ax.vlines(th_mean, w_lo, w_hi, color=st.get("color"), alpha=0.12, lw=0.5)
                ax.plot(th_mean, w_mean, label=f"{run.plant_label}: mean, chatter as a band",
                        **st)
                # the band joins the y-range up to 3× the orbit's: beyond, it is named
                lo = min(lo, max(float(np.percentile(w_lo, 5)), -3 * peak))
                hi = max(hi, min(float(np.percentile(w_hi, 95)), 3 * peak))
                notes.append(f"{run.role}: {name} chatters over {w[late].min():.3g}…"
                             f"{w[late].max():.3g} rad/s")
            else:
                ax.plot(th, w, label=run.plant_label, **st)
                if late.any():
                    lo, hi = min(lo, float(w[late].min())), max(hi, float(w[late].max()))
            early = w[~late]
            if early.size and (early.min() < lo - 0.5 * peak or early.max() > hi + 0.5 * peak):
                notes.append(f"{run.role}: start-up reaches {early.min():.3g}…{early.max():.3g} "
                             "rad/s")
        ax.plot(th_ref, w_ref, color="k", lw=0.6, ls=":", label="reference orbit", zorder=4)
        if rate_bound is not None:
            band = rate_bound * peak
            for sign in (1, -1):
                ax.plot(th_ref, w_ref + sign * band, label=f"phase bound: reference ± "
                        f"{100 * rate_bound:g} % of its peak rate" if sign > 0 else None,
                        **BOUND_STYLE)
        ax.set_xlabel(f"θ{j + 1} [rad]".translate(SUB))
        ax.set_ylabel(f"{name} [rad/s]")
        for y in (1.2, -1.2):
            ax.axhline(y, color="grey", lw=0.5, ls=":",
                       label="the paper's ±1.2 rad/s" if y > 0 else None)
        pad = 0.15 * (hi - lo)
        ax.set_ylim(min(lo, -1.2) - pad, max(hi, 1.2) + pad)
        if notes:  # above the panel, never over the orbit
            ax.set_title("\n".join(notes), fontsize=7, color="0.25")
    figure_legend(fig, axes[0])
    figure_title(fig, f"{title}: phase portrait (cf. Fig. 8), y-range after the "
                      f"{transient:g} s transient")
    return png(fig)


# --- animation -----------------------------------------------------------------------------------
def animation(group, params, model, title: str, path, *, fps: int = 8) -> str | None:
    """A GIF of the whole run, truth and reduced plant, deflection magnified; returns the
    caption (None: no run has two samples to move between).  The axes, legend and title
    are drawn once; each frame redraws only the arms and the clock over them
    (matplotlib's blitting), and Pillow writes the GIF."""
    from PIL import Image
    coords = model.coordinate_names
    ok = [(r, res) for r, res in group if res.time.size > 1]
    if not ok:
        return None
    magnify = _magnification(ok, params)
    t_end = max(res.time[-1] for _, res in ok)
    frames = np.arange(0.0, t_end, 1.0 / fps * 2)  # 2 s of motion per second of GIF
    fig, ax = plt.subplots(figsize=(5, 5.6), layout="constrained", dpi=80)
    lengths = [link.length for link in params.links]
    reach = sum(lengths)
    ax.set_xlim(-1.1 * reach, 1.1 * reach)
    ax.set_ylim(-1.1 * reach, 1.1 * reach)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    lines = [ax.plot([], [], lw=2, label=r.plant_label, animated=True,
                     color=PLANT_STYLE.get(r.role, {}).get("color"))[0] for r, _ in ok]
    ref_line, = ax.plot([], [], color="k", lw=0.8, alpha=0.5, label="rigid arm at θd",
                        animated=True)
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=8,
                    animated=True)
    ax.set_title(f"{textwrap.fill(title, 70)}\ndeflection ×{magnify:g}", fontsize=8)
    fig.legend(loc="outside lower center", fontsize=7, ncol=3)
    shape = _arm_shape(params, model, magnify)
    states = [(res.time, res.select(coords).astype(float)) for _, res in ok]
    longest = max((res for _, res in ok), key=lambda r: r.time.size)
    reference = (longest.time, longest.select(per_joint(longest, "theta{}_ref")).astype(float))

    fig.canvas.draw()  # the static parts, laid out once
    fig.set_layout_engine("none")
    background = fig.canvas.copy_from_bbox(fig.bbox)
    images = []
    for t in frames:
        fig.canvas.restore_region(background)
        for line, (time, values) in zip(lines, states):
            z = shape(_sample(time, values, t))
            line.set_data(z.real, z.imag)
        th = _sample(*reference, t)
        zr = np.cumsum([0, *(np.array(lengths) * np.exp(1j * np.cumsum(th)))])
        ref_line.set_data(zr.real, zr.imag)
        clock.set_text(f"t = {t:4.1f} s")
        for artist in (*lines, ref_line, clock):
            ax.draw_artist(artist)
        rgba = np.asarray(fig.canvas.buffer_rgba())
        images.append(Image.fromarray(rgba[..., :3].copy()).quantize(colors=64))
    plt.close(fig)
    write_atomic(path, lambda fh: images[0].save(fh, format="GIF", save_all=True,
                                                 append_images=images[1:],
                                                 duration=int(1000 / fps), loop=0),
                 binary=True)
    return (f"{title}: arm motion over the whole {t_end:.0f} s run (2× speed), truth and "
            f"reduced plant, deflection ×{magnify:g}")


def _magnification(ok, params) -> float:
    """How much the deflections are magnified to be seen: to a tenth of link 1 (95th
    percentile of the tips' deflections)."""
    typical = max(float(np.percentile(np.abs(res.select(per_joint(res, "tip_defl{}"))
                                             .astype(float)), 95)) for _, res in ok)
    return float(max(1, round(0.1 * params.links[0].length / max(typical, 1e-9))))


def _sample(time, values, t):
    """The column of ``values`` at the sample nearest to ``t``."""
    return values[:, min(int(round(t / (time[1] - time[0]))), time.size - 1)]


def _arm_shape(params, model, magnify: float):
    """``shape(Q)``: the arm's centre line at the coordinates Q as complex points (x + iy),
    the deflections (assumed modes) magnified ``magnify`` times; each link starts at the
    previous one's tip, turned by its joint angle and the previous tip's slope."""
    N = len(params.links)
    spans = [np.linspace(0, link.length, 15) for link in params.links]
    shapes = [(modes.phi(x).T, modes.tip_values[1]) for modes, x in zip(model.mode_shapes, spans)]
    first = N + np.cumsum([0, *model.modes_per_link])

    def shape(Q):
        points, tip, angle = [np.zeros(1, complex)], 0j, 0.0
        for i, (x, (phi, slope)) in enumerate(zip(spans, shapes)):
            q = Q[first[i]:first[i + 1]]
            angle += Q[i]
            z = tip + np.exp(1j * angle) * (x + 1j * magnify * (phi @ q))
            points.append(z)
            tip, angle = z[-1], angle + magnify * (slope @ q)
        return np.concatenate(points)
    return shape


def arm_snapshots(group, params, model, title: str, *, count: int = 9) -> bytes | None:
    """The animation's still for print: the arm at ``count`` instants over the run, one
    panel per plant, later instants darker, each labelled with its time at the tip, the
    deflection magnified as in the animation (None: no run has two samples)."""
    coords = model.coordinate_names
    ok = [(r, res) for r, res in group if res.time.size > 1]
    if not ok:
        return None
    magnify = _magnification(ok, params)
    shape = _arm_shape(params, model, magnify)
    reach = 1.1 * sum(link.length for link in params.links)
    fig, axes = plt.subplots(1, len(ok), figsize=(3.5 * len(ok), 3.6), squeeze=False,
                             layout="constrained")
    for ax, (run, res) in zip(axes[0], ok):
        values = res.select(coords).astype(float)
        color = PLANT_STYLE.get(run.role, {}).get("color", "k")
        for k, t in enumerate(np.linspace(0.0, res.time[-1], count)):
            z = shape(_sample(res.time, values, t))
            ax.plot(z.real, z.imag, color=color, lw=1.4, alpha=0.25 + 0.75 * k / (count - 1))
            ax.annotate(f"{t:.3g} s", (z[-1].real, z[-1].imag), fontsize=6.5,
                        textcoords="offset points", xytext=(2, 2))
        ax.set(xlim=(-reach, reach), ylim=(-reach, reach), aspect="equal", xlabel="x [m]",
               ylabel="y [m]", title=run.plant_label)
    figure_title(fig, f"{title}: the arm at {count} instants (later: darker), deflection "
                      f"×{magnify:g}", fontsize=9)
    return png(fig)
