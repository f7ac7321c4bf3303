"""Figures of the verdicts: the frequency validity map, the stability map and the
attribution waterfalls (the conventions of `validation.report.figures`)."""
from __future__ import annotations

import math

import numpy as np
from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

from ..run.plotting import SUB
from .figures import figure_legend, figure_title, plt, png

__all__ = ["validity_map", "stability_chart", "waterfall", "RIGID_HZ"]

#: Frequencies below this are the FE model's rigid modes, not its bending [Hz]: its
#: eigen-solver gives them 1e-8..1e-4 Hz instead of 0, and an arm with drives has one per
#: rotor more than the two it drops with free joints; every bending mode of the shipped
#: arms lies above 0.5 Hz.
RIGID_HZ = 1e-2


def validity_map(params, modes: tuple[int, ...], arm_text: str) -> bytes:
    """Frequencies of the reduced model vs the FE model's bending modes (above
    `RIGID_HZ`) over the last joint's angle (the others at 0), and their gap in %."""
    from plant_exudyn import Mesh, natural_frequencies
    from reduced_model import ArmModel
    swept = np.linspace(0.0, np.pi, 13)
    model = ArmModel(params, modes)
    N = model.n_joints
    joint = N - 1
    name = f"θ{joint + 1}".translate(SUB)
    fig, axes = plt.subplots(2, 2, figsize=(7, 4.8), sharex=True, layout="constrained")
    for col, joints in enumerate(("locked", "free")):
        red, fe = [], []
        for angle in swept:
            theta = np.zeros(N)
            theta[joint] = angle
            Q = np.zeros(model.n)
            Q[:N] = theta
            red.append(model.natural_frequencies(Q, joints)[:4])
            found = natural_frequencies(params, Mesh(), theta=tuple(theta), joints=joints,
                                        n=len(red[-1]) + 4)
            elastic = found[found > RIGID_HZ][:len(red[-1])]
            fe.append(np.pad(elastic, (0, len(red[-1]) - len(elastic)),
                             constant_values=np.nan))
        red, fe = np.array(red), np.array(fe)
        for k in range(red.shape[1]):
            axes[0, col].plot(swept, red[:, k], color=f"C{k}", label=f"mode {k + 1}, reduced")
            axes[0, col].plot(swept, fe[:, k], color=f"C{k}", ls="--", marker=".",
                              label=f"mode {k + 1}, FE")
            relative = np.divide(red[:, k] - fe[:, k], fe[:, k], out=np.full(len(fe), np.nan),
                                 where=fe[:, k] > 0)
            axes[1, col].plot(swept, 100 * relative, color=f"C{k}", marker=".")
        axes[0, col].set_yscale("log")
        # ticks at 1, 2, 5 per decade, labelled plainly: legible on a narrow panel
        axes[0, col].yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        axes[0, col].yaxis.set_major_formatter(FormatStrFormatter("%g"))
        axes[0, col].yaxis.set_minor_formatter(NullFormatter())
        axes[0, col].set_ylabel("frequency [Hz]")
        axes[0, col].set_title(f"joints {joints}", fontsize=10)
        axes[1, col].set_ylabel("(reduced − FE)/FE [%]")
        axes[1, col].set_xlabel(f"{name} [rad]")
        axes[1, col].axhline(0, color="k", lw=0.5)
    figure_legend(fig, axes[0, :1])
    others = ", ".join(f"θ{i + 1}".translate(SUB) for i in range(N) if i != joint)
    figure_title(fig, f"validity map, {arm_text}: reduced model ({'+'.join(map(str, modes))} "
                      f"modes, solid) vs FE (ANCF, 4 elements per link, dashed)"
                      + (f", {others} = 0" if others else ""))
    return png(fig)


def stability_chart(results) -> bytes:
    """Tested Ts per case by outcome (stable, lost tracking, diverged, failed), the largest
    Ts with no divergence and the largest that keeps tracking (bars), and the predicted
    limit (grey diamond); a panel per arm, side by side (legible on a printed page)."""
    style = {"stable": ("o", "seagreen", 5), "lost tracking": ("^", "darkorange", 6),
             "diverged": ("x", "crimson", 7), "failed": ("s", "k", 6)}
    arms = list(dict.fromkeys(r.case.arm for r in results))
    rows = max(sum(r.case.arm == arm for r in results) for arm in arms)
    fig, axes = plt.subplots(1, len(arms), figsize=(5.5 * len(arms), 0.3 * rows + 1.6),
                             sharex=True, squeeze=False, layout="constrained")
    for ax, arm in zip(axes[0], arms):
        cases = [r for r in results if r.case.arm == arm]
        for i, r in enumerate(cases):
            for Ts, (outcome, _) in r.tested.items():
                marker, color, size = style[outcome]
                ax.plot(1e3 * Ts, i, marker, color=color, ms=size, mew=2,
                        mfc="none" if outcome == "failed" else color)
            # The longer black bar stays visible where both limits coincide.
            for limit, color, half in ((r.divergence, "k", 0.42),
                                       (r.tracking, "darkorange", 0.25)):
                if not math.isnan(limit.largest):
                    ax.plot([1e3 * limit.largest] * 2, [i - half, i + half], color=color, lw=2)
            if math.isfinite(r.predicted):
                ax.plot(1e3 * r.predicted, i, "D", color="0.5", ms=5, mfc="none")
        ax.set_yticks(range(len(cases)))
        ax.set_yticklabels([f"{r.case.label} · {r.case.plant}" for r in cases], fontsize=8)
        ax.set_ylim(rows - 0.5, -0.5)
        ax.set_xscale("log")
        ax.set_xlabel("control period Ts [ms]")
        ax.set_title(f"{arm} arm", fontsize=9)
        ax.axvline(1.0, color="grey", lw=0.5, ls=":")
    for outcome, (marker, color, size) in style.items():
        axes[0, 0].plot([], [], marker, color=color, ms=size, mew=2,
                        mfc="none" if outcome == "failed" else color, label=outcome)
    axes[0, 0].plot([], [], "|", color="k", ms=10, mew=2, label="no divergence up to")
    axes[0, 0].plot([], [], "|", color="darkorange", ms=10, mew=2, label="keeps tracking up to")
    axes[0, 0].plot([], [], "D", color="0.5", mfc="none", label="predicted (ZOH eigenvalues)")
    fig.legend(fontsize=8, loc="outside lower center", ncol=4)
    figure_title(fig, "sampled-data stability map (case · plant, a panel per arm; dotted: "
                      "Ts = 1 ms)")
    return png(fig)


def waterfall(study: str, metric: str, unit: str, ideal: float, contributions: dict,
              total: float) -> bytes:
    """From m(ideal) to m(real): one bar per factor's Shapley contribution, in the
    display unit the caller chose (``metric`` is its human name)."""
    parts = [(f, v) for f, v in contributions.items() if not f.startswith("plant: ")]
    fig, ax = plt.subplots(figsize=(1.2 * len(parts) + 3.4, 3.8), layout="constrained")
    level, levels = ideal, [0.0, ideal, ideal + total]
    ax.bar(0, ideal, color="0.6")
    for i, (f, v) in enumerate(parts, start=1):
        if not math.isfinite(v):
            ax.text(i, level, "diverges", rotation=90, ha="center", va="bottom", fontsize=8,
                    color="crimson")
            continue
        ax.bar(i, v, bottom=level, color="tab:red" if v > 0 else "tab:green")
        level += v
        levels.append(level)
    ax.bar(len(parts) + 1, ideal + total, color="0.3")
    labels = ["ideal", *(f"{f}\n{v:+.3g}" if math.isfinite(v) else f"{f}\n(diverges)"
                         for f, v in parts), "real"]
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels, fontsize=7)
    lo, hi = min(levels), max(levels)
    steps = [ideal, ideal + total, *(ideal + sum(v for _, v in parts[:k] if math.isfinite(v))
                                     for k in range(1, len(parts) + 1))]
    gap = max(steps) - min(steps)
    zoom = 0 < gap < 0.3 * max(abs(lo), abs(hi))  # the contributions would be slivers
    if zoom:  # show the steps; the bars from 0 are cut at the bottom, and the axis says so
        ax.set_ylim(min(steps) - 1.2 * gap, max(steps) + 0.5 * gap)
        ax.text(0.01, 0.02, "y axis does not start at 0", transform=ax.transAxes, fontsize=7,
                color="0.3")
    else:
        span = (hi - lo) or abs(hi) or 1.0
        ax.set_ylim(min(0.0, lo - 0.1 * span), hi + 0.25 * span)  # room above the bars
    ax.set_ylabel(f"{metric} [{unit}]")
    ax.axhline(ideal, color="grey", lw=0.5, ls=":")
    figure_title(fig, f"{study}: {metric}, from the ideal world of the design to the real one "
                "(red: worsens, green: improves)", fontsize=9)
    return png(fig)
