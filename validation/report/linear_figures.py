"""Figures of the linear validity analysis (`validation.verdicts.validity`), drawn from its
stored data: frequency responses of the reduced model and the FE arm side by side, the
ν-gap over θ2, and the predicted / certified / measured control periods per case."""
from __future__ import annotations

import math

import numpy as np

from .figures import plt, png

__all__ = ["frequency_responses", "gap_map", "periods_chart", "validity_figures"]

_SUBSCRIPTS = str.maketrans("0123456789", "₀₁₂₃₄₅₆₇₈₉")


def _title(channel: str) -> str:
    """"tau2->tip_defl2" → "τ₂ → w₂(L₂) [m/(N m)]"."""
    joint = channel.split("->")[0][3:].translate(_SUBSCRIPTS)
    if "->theta" in channel:
        return f"τ{joint} → θ{joint} [rad/(N m)]"
    return f"τ{joint} → w{joint}(L{joint}) [m/(N m)]"


def frequency_responses(arm: dict) -> bytes:
    """|τ_i → θ_i| (top row) and |τ_i → tip deflection| of each flexible link (bottom
    row) of both plants at three θ2 of the grid."""
    f = np.asarray(arm["frequencies_hz"])
    chosen = arm["responses"][::3]
    joints = len(arm["modes"])
    fig, axes = plt.subplots(2, joints, figsize=(5 * joints, 6.5), sharex=True,
                             constrained_layout=True, squeeze=False)
    panels = {f"tau{i}->{out}{i}": axes[row, i - 1] for i in range(1, joints + 1)
              for row, out in enumerate(("theta", "tip_defl"))}
    for channel, ax in panels.items():
        if channel not in chosen[0]["reduced"]:  # a rigid link's tip
            ax.set_axis_off()
            continue
        for k, entry in enumerate(chosen):
            ax.loglog(f, entry["reduced"][channel], color=f"C{k}", lw=0.9,
                      label=f"θ₂ = {entry['theta2']:.2f} rad, reduced")
            ax.loglog(f, entry["fe"][channel], color=f"C{k}", lw=1.6, ls=(0, (2, 2)),
                      alpha=0.8, label=f"θ₂ = {entry['theta2']:.2f} rad, FE")
        ax.set_title(_title(channel), fontsize=9)
        ax.grid(True, which="major", lw=0.3)
    for ax in axes[1]:
        ax.set_xlabel("frequency [Hz]")
    for ax in axes[:, 0]:
        ax.set_ylabel("magnitude")
    axes[0, 0].legend(fontsize=6, ncol=2)
    modes = "+".join(str(m) for m in arm["modes"])
    fig.suptitle(f"{arm['arm']} arm, θ₁ = 0: reduced model ({modes} "
                 f"modes, solid) vs {arm['truth']} (dashed), linearised at rest", fontsize=10)
    return png(fig)


def gap_map(arm: dict) -> bytes:
    """δν of the three views of the reduced model and the FE arm over θ2."""
    th = [g["theta2"] for g in arm["gaps"]]
    fig, ax = plt.subplots(figsize=(8, 3.6), constrained_layout=True)
    labels = {"theta": "τ → θ (continuous)", "tip": "τ → tip deflections (continuous)",
              "loop": f"{arm['law']} loop at the plant input (ZOH, Ts = {1e3 * arm['Ts']:g} ms)"}
    for k, (view, label) in enumerate(labels.items()):
        ax.plot(th, [g[view] for g in arm["gaps"]], marker="o", color=f"C{k}", label=label)
    ax.set_ylim(0, 1.05)
    ax.set_xlabel("θ₂ [rad]")
    ax.set_ylabel("ν-gap δν(reduced, FE)")
    ax.grid(True, lw=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"{arm['arm']} arm: ν-gap of the reduced model to the {arm['truth']} "
                 "(1 = as far apart as feedback can tell)", fontsize=9)
    return png(fig)


def periods_chart(cases: list[dict]) -> bytes:
    """Per case: the measured bracket (bar), predicted (diamond), predicted on the refined
    mesh (square) and certified (triangle) control periods."""
    fig, ax = plt.subplots(figsize=(9, 0.3 * len(cases) + 1.8), constrained_layout=True)
    labels = []
    for i, r in enumerate(cases):
        labels.append(f"{r['case']} · {r['plant']} · {r['arm']}")
        lo, hi = r["largest_stable_s"], r["first_unstable_s"]
        if not (math.isnan(lo) and math.isnan(hi)):
            a = 1e3 * lo if not math.isnan(lo) else 1e-4
            b = 1e3 * hi if not math.isnan(hi) else 1e2
            ax.plot([a, b], [i, i], color="0.75", lw=5, solid_capstyle="butt")
        for key, marker, color in (("predicted_s", "D", "C0"), ("predicted_fine_s", "s", "C1"),
                                   ("certified_s", "^", "C2")):
            v = r[key]
            if isinstance(v, float) and math.isfinite(v) and v > 0:
                ax.plot(1e3 * v, i, marker, color=color, ms=5, mfc="none", mew=1.5)
    ax.set_yticks(range(len(cases)))
    ax.set_yticklabels(labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("control period Ts [ms]")
    ax.plot([], [], color="0.75", lw=5, label="measured: no divergence up to – first divergence")
    ax.plot([], [], "D", color="C0", mfc="none", label="predicted (the case's plant)")
    ax.plot([], [], "s", color="C1", mfc="none", label="predicted, FE mesh ×2")
    ax.plot([], [], "^", color="C2", mfc="none", label="certified (ν-gap < b)")
    fig.legend(fontsize=7, loc="outside upper center", ncol=2)
    ax.set_title("largest stable control period per case (case · plant · arm)", fontsize=10)
    return png(fig)


def validity_figures(data: dict) -> list[tuple[str, bytes]]:
    """Every figure of a validity analysis, with its caption."""
    out = []
    for arm in data["arms"]:
        out.append((f"{arm['arm']} arm: frequency responses τ → θ and τ → tip deflection of "
                    f"the reduced model and the FE arm at three θ₂", frequency_responses(arm)))
        out.append((f"{arm['arm']} arm: ν-gap between the reduced model and the FE arm over θ₂",
                    gap_map(arm)))
    if data["cases"]:
        out.append(("predicted, certified and measured largest stable control period per case",
                    periods_chart(data["cases"])))
    return out
