"""Figures of a report, drawn from stored results (matplotlib, Agg), returned as PNG bytes.

Conventions every figure follows: units on every axis, time in seconds, states named as
in the paper (θ₁, q̇₁₂ …), the arm, plant, control period and initial condition in the
title or legend, diverged and failed runs marked as such and never drawn as data.
"""
from __future__ import annotations

import io
import json
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.transforms import blended_transform_factory  # noqa: E402

__all__ = ["png", "state_label", "state_unit", "tracking", "deflections", "rates",
           "estimation_errors", "phase_portrait", "sweep_figures", "validity_map",
           "stability_chart", "animation", "waterfall", "AXIS_UNITS", "axis_label",
           "describe_run"]

PLANT_STYLE = {"reduced": dict(color="C0", ls="-"), "exudyn": dict(color="C3", ls="--")}
PLANT_NAME = {"reduced": "reduced plant", "exudyn": "truth plant (Exudyn)"}
_SUB = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")

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


def png(fig, dpi: int = 90) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def state_label(state: str) -> str:
    """theta2_dot → θ̇₂, q12 → q₁₂."""
    rate = state.endswith("_dot")
    base = state.removesuffix("_dot")
    symbol, index = ("θ", base[5:]) if base.startswith("theta") else (base[0], base[1:])
    return symbol + ("\u0307" if rate else "") + index.translate(_SUB)


def state_unit(state: str) -> str:
    angle = state.startswith("theta")
    return ("rad" if angle else "m") + ("/s" if state.endswith("_dot") else "")


def axis_label(axis: str) -> str:
    """A sweep axis as an axis label with its unit, e.g. "true_params.Mp [kg]"."""
    unit = AXIS_UNITS.get(axis) or AXIS_UNITS.get(axis.split(".")[-1])
    if axis in ("Ts", "plant.step"):
        return f"{axis} [ms]"
    return f"{axis} [{unit}]" if unit else axis


def describe_run(config: dict) -> str:
    """What was run, in a few words: arm, Ts, initial condition."""
    start = "from rest" if config.get("initial_state") == "rest" else "moving with the reference"
    return f"{config.get('arm', 'default')} arm, Ts = {1e3 * config['Ts']:g} ms, {start}"


def _legend(ax, **kw) -> None:
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(fontsize=7, **kw)


def _figure_legend(fig, ax) -> None:
    """One legend for a grid of panels, below them (never over the data)."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 4),
                   fontsize=8)


def _late_ylim(ax, t, series, transient: float) -> None:
    """y-range from the samples after the transient (the steady state stays visible; the
    start-up error is drawn but may leave the frame)."""
    late = [s[t >= transient] for t, s in series if (t >= transient).any()]
    if not late:
        return
    lo = min(float(np.nanmin(s)) for s in late)
    hi = max(float(np.nanmax(s)) for s in late)
    pad = 0.1 * (hi - lo) or 1e-12
    ax.set_ylim(lo - pad, hi + pad)


def _status_note(run) -> str:
    return "" if run.status == "ok" else f" — {run.status.upper()}: {run.message}"


# --- the paper's figures ------------------------------------------------------------------------
def tracking(group, title: str, transient: float) -> bytes:
    """Fig. 3 analogue: θ and θ − θ_d per joint, every plant of the group overlaid."""
    fig, axes = plt.subplots(2, 2, figsize=(10, 5.5), sharex=True, constrained_layout=True)
    errs = {0: [], 1: []}
    for run, res in group:
        st = PLANT_STYLE.get(run.plant, {})
        for j in (0, 1):
            axes[0, j].plot(res.time, res[f"theta{j + 1}"], lw=1, label=PLANT_NAME.get(run.plant, run.plant) + _status_note(run), **st)
            e = res[f"theta{j + 1}"].astype(float) - res[f"theta{j + 1}_ref"]
            axes[1, j].plot(res.time, e, lw=0.8, **st)
            errs[j].append((res.time, e))
    ref = group[0][1]
    for j in (0, 1):
        axes[0, j].plot(ref.time, ref[f"theta{j + 1}_ref"], color="k", lw=0.6, label="reference, eq. (37)")
        axes[0, j].set_ylabel(f"θ{j + 1} [rad]".translate(_SUB))
        axes[1, j].set_ylabel(f"θ{j + 1} − θ{j + 1},d [rad]".translate(_SUB))
        axes[1, j].set_xlabel("t [s]")
        axes[1, j].axvline(transient, color="grey", lw=0.5, ls=":")
        _late_ylim(axes[1, j], None, errs[j], transient)
    _legend(axes[0, 0])
    fig.suptitle(f"{title}: joint tracking (cf. the paper's Fig. 3); error axis scaled after "
                 f"the {transient:g} s transient", fontsize=10)
    return png(fig)


def deflections(group, title: str, transient: float, cutoff_hz: float | None) -> bytes:
    """Fig. 4 analogue: tip deflections, and their oscillatory part (the vibration)."""
    from ..run.metrics import oscillatory
    rows = 2 if cutoff_hz else 1
    fig, axes = plt.subplots(rows, 2, figsize=(10, 2.8 * rows), sharex=True, squeeze=False,
                             constrained_layout=True)
    vib = {0: [], 1: []}
    for run, res in group:
        st = PLANT_STYLE.get(run.plant, {})
        label = PLANT_NAME.get(run.plant, run.plant) + _status_note(run)
        for j in (0, 1):
            axes[0, j].plot(res.time, 1e3 * res[f"tip_defl{j + 1}"].astype(float), lw=0.8, label=label, **st)
        if cutoff_hz and res.time.size > 16:
            v = 1e3 * oscillatory(res, cutoff_hz)
            for j in (0, 1):
                axes[1, j].plot(res.time, v[j], lw=0.7, **st)
                vib[j].append((res.time, v[j]))
    for j in (0, 1):
        axes[0, j].set_ylabel(f"tip deflection, link {j + 1} [mm]")
        axes[-1, j].set_xlabel("t [s]")
        if cutoff_hz:
            axes[1, j].set_ylabel(f"vibration (> {cutoff_hz:.2f} Hz), link {j + 1} [mm]")
            axes[1, j].axvline(transient, color="grey", lw=0.5, ls=":")
            _late_ylim(axes[1, j], None, vib[j], transient)
    _legend(axes[0, 0])
    fig.suptitle(f"{title}: tip deflections (cf. Fig. 4) and their oscillatory part", fontsize=10)
    return png(fig)


def _state_grid(states):
    """A grid of panels, one per state: positions in the first rows, rates after."""
    cols = min(3, len(states))
    rows = math.ceil(len(states) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols + 0.5, 2.3 * rows + 0.8),
                             sharex=True, constrained_layout=True, squeeze=False)
    for ax in axes.ravel()[len(states):]:
        ax.set_visible(False)
    return fig, axes


def rates(group, title: str, transient: float) -> bytes:
    """Figs. 5–6 analogue: true and estimated rates."""
    observed = [(r, res) for r, res in group if "xhat_theta1" in res]
    states = [n.removeprefix("xhat_") for n in observed[0][1].names_with("xhat_") if n.endswith("_dot")]
    fig, axes = _state_grid(states)
    for ax, s in zip(axes.ravel(), states):
        for run, res in observed:
            st = PLANT_STYLE.get(run.plant, {})
            name = PLANT_NAME.get(run.plant, run.plant)
            ax.plot(res.time, res[s], lw=0.8, label=f"{name}: true", **st)
            ax.plot(res.time, res[f"xhat_{s}"], lw=0.6, alpha=0.8, color=st.get("color"), ls=":",
                    label=f"{name}: estimate")
        ax.set_title(state_label(s), fontsize=10)
        ax.set_ylabel(f"[{state_unit(s)}]")
        ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    _figure_legend(fig, axes[0, 0])
    fig.suptitle(f"{title}: true vs estimated rates (cf. Figs. 5–6)", fontsize=10)
    return png(fig)


def estimation_errors(group, title: str, transient: float) -> bytes:
    """Fig. 7 analogue: x̂ − x per state, y-range after the transient, with ±1 σ of the
    raw measurement's error (grey band) where the state is measured."""
    observed = [(r, res) for r, res in group if "xhat_theta1" in res]
    states = [n.removeprefix("xhat_") for n in observed[0][1].names_with("xhat_")]
    fig, axes = _state_grid(states)
    for ax, s in zip(axes.ravel(), states):
        series = []
        for run, res in observed:
            e = res[f"xhat_{s}"].astype(float) - res[s]
            series.append((res.time, e))
            ax.plot(res.time, e, lw=0.6, label=PLANT_NAME.get(run.plant, run.plant),
                    **PLANT_STYLE.get(run.plant, {}))
            if f"y_{s}" in res:
                late = res.time >= transient
                sigma = float(np.sqrt(np.mean((res[f"y_{s}"][late].astype(float) - res[s][late]) ** 2)))
                if sigma > 0:
                    ax.axhspan(-sigma, sigma, color="0.85", zorder=0,
                               label="measurement error, ±1 RMS" if run is observed[0][0] else None)
        _late_ylim(ax, None, series, transient)
        ax.set_title(f"{state_label(s)} error", fontsize=10)
        ax.set_ylabel(f"[{state_unit(s)}]")
        ax.tick_params(labelsize=7)
        ax.yaxis.get_offset_text().set_fontsize(7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    _figure_legend(fig, axes[0, 0])
    fig.suptitle(f"{title}: estimation errors x̂ − x (cf. Fig. 7), y-range after the "
                 f"{transient:g} s transient", fontsize=10)
    return png(fig)


def phase_portrait(group, title: str) -> bytes:
    """Fig. 8 analogue, with the reference's own orbit and the paper's ±1.2 rad/s."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for run, res in group:
        for j in (0, 1):
            axes[j].plot(res[f"theta{j + 1}"], res[f"theta{j + 1}_dot"], lw=0.8,
                         label=PLANT_NAME.get(run.plant, run.plant) + _status_note(run),
                         **PLANT_STYLE.get(run.plant, {}))
    ref = group[0][1]
    for j in (0, 1):
        axes[j].plot(ref[f"theta{j + 1}_ref"], ref[f"theta{j + 1}_dot_ref"], color="k", lw=0.6,
                     label="reference orbit")
        axes[j].set_xlabel(f"θ{j + 1} [rad]".translate(_SUB))
        axes[j].set_ylabel(f"θ̇{j + 1} [rad/s]".translate(_SUB))
        for y in (1.2, -1.2):
            axes[j].axhline(y, color="grey", lw=0.5, ls=":")
    _legend(axes[0])
    fig.suptitle(f"{title}: phase portrait (cf. Fig. 8; dotted: the paper's ±1.2 rad/s)",
                 fontsize=10)
    return png(fig)


# --- sweeps -------------------------------------------------------------------------------------
SWEEP_METRICS = [
    ("track_max", "max |θ − θd| after transient [rad]", ("track_max_1", "track_max_2")),
    ("vib_rms", "vibration RMS after transient [m]", ("vib_rms_1", "vib_rms_2")),
    ("est_theta", "max angle estimation error [rad]", ("est_max_theta1", "est_max_theta2")),
    ("tau_tv", "torque variation [N m/s]", ("tau_tv_1", "tau_tv_2")),
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


def sweep_figures(sweep: str, runs) -> list[tuple[str, bytes]]:
    """Each metric of a sweep against its swept values.

    Axes that vary together (a zip) form one group and one x axis, labelled by the run
    names if ``name`` is among them.  A figure is drawn for every numeric group and every
    group of three or more values (the other groups become series, one per combination
    and plant); with no such group, the largest group is the x axis.  Constant axes are
    not drawn; list-valued axes are categories labelled by their value; diverged and
    failed runs are a crimson × at the top of the panel, never a data point."""
    axes = sorted({a for r in runs for a in r.axes})
    varying = [a for a in axes if a != "plant.kind"
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
                          numeric(g), metrics) for g in primary]


def _sweep_figure(sweep, runs, group, others, xs, numeric, metrics) -> tuple[str, bytes]:
    label_axis = "name" if "name" in group else group[0]
    scale = 1e3 if group[0] in ("Ts", "plant.step") else 1.0
    series: dict[tuple, list] = {}
    for r in runs:
        other = ", ".join(f"{a.split('.')[-1]}={_short(r.axes.get(a))}" for a in others)
        series.setdefault((other, r.plant), []).append(r)
    keys = sorted(series)
    others_order = sorted({k[0] for k in keys})
    fig, axs = plt.subplots(1, len(metrics), figsize=(4.0 * len(metrics) + 2.5, 3.6),
                            squeeze=False, constrained_layout=True)
    failed_any = False
    for ax, (key, title, names) in zip(axs[0], metrics):
        for n, (other, plant) in enumerate(keys):
            color = f"C{others_order.index(other) % 10}"
            pts, bad = [], []
            for r in series[(other, plant)]:
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
                    pts.append((x, max(vals)))
            label = PLANT_NAME.get(plant, plant) + (f", {other}" if other else "")
            style = dict(color=color, marker="o" if plant == "exudyn" else "s", ms=5,
                         mfc=color if plant == "exudyn" else "white", label=label)
            if pts:
                pts.sort()
                ax.plot(*zip(*pts), ls=PLANT_STYLE.get(plant, {}).get("ls", "-") if numeric
                        else "none", lw=1, **style)
            if bad:
                failed_any = True
                tr = blended_transform_factory(ax.transData, ax.transAxes)
                ax.plot(bad, [0.96] * len(bad), "x", color="crimson", ms=7, mew=2, transform=tr)
        ax.set_title(title, fontsize=9)
        zipped = [a.split(".")[-1] for a in group if a != label_axis]
        ax.set_xlabel(axis_label(label_axis) + (f"\n(zipped with {', '.join(zipped)})"
                                                if zipped else ""), fontsize=8)
        if numeric:
            lo = min(json.loads(x)[0] for x in xs) * scale
            hi = max(json.loads(x)[0] for x in xs) * scale
            if lo > 0 and hi / lo > 20:
                ax.set_xscale("log")
        else:
            ax.set_xticks(range(len(xs)))
            idx = group.index(label_axis)
            ax.set_xticklabels([_short(json.loads(x)[idx]).split("/")[-1] for x in xs],
                               rotation=30, ha="right", fontsize=7)
        ax.tick_params(labelsize=7)
    handles, labels = axs[0, 0].get_legend_handles_labels()
    if failed_any:
        handles.append(plt.Line2D([], [], ls="none", marker="x", color="crimson", mew=2))
        labels.append("diverged / failed (no value)")
    fig.legend(handles, labels, loc="outside right center", fontsize=7,
               title="filled: truth plant; hollow: reduced", title_fontsize=7)
    caption = f"sweep '{sweep}': metrics vs {' / '.join(group)}"
    fig.suptitle(caption, fontsize=10)
    return caption, png(fig)


def _sort_key(values):
    return [(0, v) if isinstance(v, (int, float)) else (1, _key(v)) for v in values]


def _short(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        return "; ".join(f"{d.get('kind', '?')} {d.get('target', '')} {d.get('amplitude', '')}"
                         .strip() for d in value)
    if value == []:
        return "none"
    return json.dumps(value) if isinstance(value, (list, dict)) else str(value)


# --- the reduced model's validity, the stability map --------------------------------------------
def validity_map(params, modes: tuple[int, int], arm_text: str) -> bytes:
    """Frequencies of the reduced model vs the FE model over θ2, and their gap in %."""
    from plant_exudyn import Mesh, natural_frequencies
    from reduced_model import ArmModel
    theta2 = np.linspace(0.0, np.pi, 13)
    model = ArmModel(params, modes)
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True, constrained_layout=True)
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
        axes[0, col].set_title(f"joints {joints}", fontsize=10)
        axes[1, col].set_ylabel("(reduced − FE)/FE [%]")
        axes[1, col].set_xlabel("θ₂ [rad]")
        axes[1, col].axhline(0, color="k", lw=0.5)
    axes[0, 0].legend(fontsize=7, ncol=2)
    axes[1, 0].legend(fontsize=7)
    fig.suptitle(f"validity map, {arm_text}: reduced model ({modes[0]}+{modes[1]} modes, "
                 "solid) vs FE (ANCF, 4 elements per link, dashed), θ₁ = 0", fontsize=10)
    return png(fig)


def stability_chart(results) -> bytes:
    """Tested Ts per case by outcome (stable, lost tracking, diverged, failed), the largest
    Ts with no divergence and the largest that keeps tracking (bars), and the predicted
    limit (grey diamond)."""
    style = {"stable": ("o", "seagreen", 5), "lost tracking": ("^", "darkorange", 6),
             "diverged": ("x", "crimson", 7), "failed": ("s", "k", 6)}
    fig, ax = plt.subplots(figsize=(9, 0.32 * len(results) + 1.6), constrained_layout=True)
    labels = []
    for i, r in enumerate(results):
        labels.append(f"{r.case.label} · {r.case.plant} · {r.case.arm}")
        for Ts, (outcome, _) in r.tested.items():
            marker, color, size = style[outcome]
            ax.plot(1e3 * Ts, i, marker, color=color, ms=size, mew=2,
                    mfc="none" if outcome == "failed" else color)
        # The longer black bar stays visible where both limits coincide.
        for limit, color, half in ((r.divergence, "k", 0.42), (r.tracking, "darkorange", 0.25)):
            if not math.isnan(limit.largest):
                ax.plot([1e3 * limit.largest] * 2, [i - half, i + half], color=color, lw=2)
        if math.isfinite(r.predicted):
            ax.plot(1e3 * r.predicted, i, "D", color="0.5", ms=5, mfc="none")
    ax.set_yticks(range(len(results)))
    ax.set_yticklabels(labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("control period Ts [ms]")
    ax.axvline(1.0, color="grey", lw=0.5, ls=":")
    for outcome, (marker, color, size) in style.items():
        ax.plot([], [], marker, color=color, ms=size, mew=2,
                mfc="none" if outcome == "failed" else color, label=outcome)
    ax.plot([], [], "|", color="k", ms=10, mew=2, label="no divergence up to")
    ax.plot([], [], "|", color="darkorange", ms=10, mew=2, label="keeps tracking up to")
    ax.plot([], [], "D", color="0.5", mfc="none", label="predicted 2/λmax(W G)")
    fig.legend(fontsize=7, loc="outside upper center", ncol=4)
    ax.set_title("sampled-data stability map (case · plant · arm; dotted: Ts = 1 ms)", fontsize=10)
    return png(fig)


# --- animation -----------------------------------------------------------------------------------
def animation(group, params, model, title: str, path, *, fps: int = 8) -> str:
    """A GIF of the whole run, truth and reduced plant, deflection magnified; returns the
    caption."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    coords = model.coordinate_names
    ok = [(r, res) for r, res in group if res.time.size > 1]
    typical = max(float(np.percentile(np.abs(res.select(["tip_defl1", "tip_defl2"]).astype(float)), 95))
                  for _, res in ok)
    magnify = float(max(1, round(0.1 * params.L1 / max(typical, 1e-9))))
    t_end = max(res.time[-1] for _, res in ok)
    frames = np.arange(0.0, t_end, 1.0 / fps * 2)  # 2 s of motion per second of GIF
    fig, ax = plt.subplots(figsize=(5, 5), constrained_layout=True)
    reach = params.L1 + params.L2
    ax.set_xlim(-1.1 * reach, 1.1 * reach)
    ax.set_ylim(-1.1 * reach, 1.1 * reach)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    lines = [ax.plot([], [], lw=2, label=PLANT_NAME.get(r.plant, r.plant),
                     **PLANT_STYLE.get(r.plant, {}))[0] for r, _ in ok]
    ref_line, = ax.plot([], [], color="k", lw=0.8, alpha=0.5, label="rigid arm at θd")
    text = ax.set_title("", fontsize=9)
    ax.legend(loc="lower left", fontsize=7)

    def shape(Q):
        n1 = model.modes_per_link[0]
        x1, x2 = np.linspace(0, params.L1, 15), np.linspace(0, params.L2, 15)
        m1, m2 = model.mode_shapes
        w1 = magnify * (m1.phi(x1).T @ Q[2:2 + n1])
        w2 = magnify * (m2.phi(x2).T @ Q[2 + n1:])
        slope1 = magnify * (m1.tip_values[1] @ Q[2:2 + n1])
        z1 = np.exp(1j * Q[0]) * (x1 + 1j * w1)
        z2 = z1[-1] + np.exp(1j * (Q[0] + Q[1] + slope1)) * (x2 + 1j * w2)
        return np.concatenate([[0], z1, z2])

    def draw(t):
        for line, (_, res) in zip(lines, ok):
            k = min(int(round(t / (res.time[1] - res.time[0]))), len(res.time) - 1)
            z = shape(res.select(coords)[:, k].astype(float))
            line.set_data(z.real, z.imag)
        res = max((res for _, res in ok), key=lambda r: r.time.size)
        k = min(int(round(t / (res.time[1] - res.time[0]))), len(res.time) - 1)
        th = res.select(["theta1_ref", "theta2_ref"])[:, k].astype(float)
        zr = np.cumsum([0, params.L1 * np.exp(1j * th[0]), params.L2 * np.exp(1j * th.sum())])
        ref_line.set_data(zr.real, zr.imag)
        text.set_text(f"{title}\nt = {t:4.1f} s, deflection ×{magnify:g}")
        return (*lines, ref_line, text)

    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    tmp = path.with_suffix(".tmp.gif")
    anim.save(tmp, writer=PillowWriter(fps=fps))
    plt.close(fig)
    tmp.replace(path)
    return (f"{title}: arm motion over the whole {t_end:.0f} s run (2× speed), truth and "
            f"reduced plant, deflection ×{magnify:g}")


def waterfall(study: str, metric: str, unit: str, ideal: float, contributions: dict,
              total: float) -> bytes:
    """From m(ideal) to m(real): one bar per factor's Shapley contribution."""
    parts = [(f, v) for f, v in contributions.items() if not f.startswith("plant: ")]
    fig, ax = plt.subplots(figsize=(1.1 * len(parts) + 3, 3.4), constrained_layout=True)
    level = ideal
    ax.bar(0, ideal, color="0.6")
    labels = ["ideal"]
    for i, (f, v) in enumerate(parts, start=1):
        if not math.isfinite(v):
            ax.text(i, level, "diverges", rotation=90, ha="center", va="bottom", fontsize=8,
                    color="crimson")
        else:
            ax.bar(i, v, bottom=level, color="C3" if v > 0 else "C2")
            level += v
        labels.append(f)
    ax.bar(len(parts) + 1, ideal + total, color="0.3")
    labels.append("real")
    labels = [labels[0], *(f"{f}\n{v:+.2g}" if math.isfinite(v) else f"{f}\n(diverges)"
                           for f, v in parts), labels[-1]]
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels, fontsize=7)
    ax.set_ylabel(f"{metric} [{unit}]")
    ax.axhline(ideal, color="grey", lw=0.5, ls=":")
    ax.set_title(f"{study}: {metric} from the ideal to the real world "
                 "(red: worsens, green: improves)", fontsize=9)
    return png(fig)
