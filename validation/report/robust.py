"""The report's "Robust verdicts" section: what ``flexarm verify`` found in a results folder.

Read from ``OUT/verdict.json`` and the stored runs it names: the verdict's numbers as a
table; for an estimate, the distribution of each requirement's robustness ρ over the
draws (diverged draws counted, not drawn); for a falsification and a conformance search,
ρ (or the plants' disagreement) against the simulations spent on each plant; and the
counterexample's (or worst case's, or largest disagreement's) joint tracking and tip
deflections on both plants — the analogues of the paper's Figs. 3 and 4.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..run.results import conforms, read_json
from . import figures as fig
from .render import fmt_number

__all__ = ["robust_section", "SECTION"]

SECTION = "Robust verdicts"

_NUMBER, _MAYBE = (int, float), (int, float, type(None))
_FILE = (str, type(None))
_SIMULATIONS = {"reduced": int, "truth": int}
_RUNS = {"truth?": str, "reduced?": str}
#: What this section reads of each kind of verdict.json (`validation.run.results.read_json`).
_VERDICTS = {
    "estimate": {"system": str, "plant": str, "distribution?": [str], "runs": [str],
                 "requirements": {str: {
                     "criterion": str, "n": int, "failures": int, "p_low": _NUMBER,
                     "p_high": _NUMBER, "level": _NUMBER, "rho_min": _MAYBE,
                     "sequential": {"decision": str, "draws": int, "p0": _NUMBER,
                                    "indifference": _NUMBER, "alpha": _NUMBER,
                                    "beta": _NUMBER}}}},
    "falsify": {"system": str, "distribution?": [str], "requirement": str, "criterion": str,
                "found": bool, "rho_truth": _MAYBE, "rho_reduced": _MAYBE,
                "truth_status?": str, "simulations": _SIMULATIONS, "spurious": [dict],
                "trace": [{"reduced": int, "truth": int, "best_rho_reduced": _MAYBE,
                           "best_rho_truth": _MAYBE}],
                "runs?": _RUNS, "counterexample?": _FILE, "worst_case?": _FILE},
    "conform": {"system": str, "distribution?": [str], "distance": _MAYBE,
                "simulations": _SIMULATIONS, "rho_difference?": {str: _MAYBE},
                "trace": [{"reduced": int, "truth": int, "distance": _MAYBE}],
                "runs?": _RUNS, "scenario?": _FILE},
}


def robust_section(store, runs) -> tuple[dict | None, list]:
    """(table data for the templates, figure tasks (section, caption, make)) of the
    verdict in ``store``'s folder; (None, []) if there is none."""
    path = Path(store.out) / "verdict.json"
    if not path.is_file():
        return None, []
    verdict = read_json(path, {"mode": str})
    mode = verdict["mode"]
    if mode not in _VERDICTS:
        raise ValueError(f"{path}: mode: {mode!r} is no mode of flexarm verify (not a file "
                         "this program wrote)")
    conforms(verdict, _VERDICTS[mode], path)
    by_id = {r.run_id: r for r in runs}
    data = {"mode": mode, "system": verdict["system"], "rows": _rows(verdict),
            "distribution": verdict.get("distribution", []), "files": _files(verdict)}
    tasks = []
    if mode == "estimate":
        drawn = [by_id[i] for i in verdict["runs"] if i in by_id]
        for name, numbers in verdict["requirements"].items():
            tasks.append((SECTION, f"{verdict['system']}: distribution of ρ of {name} over "
                                   f"{numbers['n']} draws ({verdict['plant']} plant)",
                          lambda rs=drawn, n=name, v=numbers: _histogram(rs, n, v)))
    else:
        what = "ρ" if mode == "falsify" else "largest |θ_truth − θ_reduced|"
        tasks.append((SECTION, f"{verdict['system']}: {what} against the simulations spent on "
                               "each plant", lambda: _trace(verdict)))
        tasks += _case_figures(verdict, store)
    return data, tasks


def _rows(v: dict) -> list[list[str]]:
    if v["mode"] == "estimate":
        rows = []
        for name, r in v["requirements"].items():
            seq = r["sequential"]
            rows.append([name, r["criterion"], f"{r['n'] - r['failures']}/{r['n']}",
                         f"[{r['p_low']:.3f}, {r['p_high']:.3f}]", f"{r['level']:g}",
                         f"{seq['decision']} after {seq['draws']} (p0 = {seq['p0']:g} ± "
                         f"{seq['indifference']:g}, α = {seq['alpha']:g}, β = {seq['beta']:g})",
                         fmt_number(r["rho_min"]) if r["rho_min"] is not None else "−∞"])
        return rows
    sims = v["simulations"]
    if v["mode"] == "falsify":
        found = "counterexample" if v["found"] else \
            f"{v['verdict']}; worst case" if v.get("undecided") else "none found; worst case"
        if v.get("convergence"):
            found += f" ({v['convergence']['verdict']} on the refined sequence)"
        # null in verdict.json: −∞, a run that diverged (its status says so), or no case
        truth = fmt_number(v["rho_truth"]) if v["rho_truth"] is not None else (
            f"−∞ ({v['truth_status']})" if v.get("truth_status") else "—")
        reduced = fmt_number(v["rho_reduced"]) if v["rho_reduced"] is not None else (
            "−∞ (diverged)" if v.get("truth_status") else "—")
        return [[v["requirement"], v["criterion"], found, truth, reduced, str(sims["reduced"]),
                 str(sims["truth"]), str(len(v["spurious"]))]]
    return [[fmt_number(v["distance"]), str(sims["reduced"]), str(sims["truth"]),
             ", ".join(f"{k}: {fmt_number(d)}" for k, d in (v.get("rho_difference") or {}).items()
                       if d is not None)]]


def _files(v: dict) -> list[str]:
    return [name for name in (v.get("counterexample"), v.get("worst_case"), v.get("scenario"))
            if name]


def _histogram(rows, name: str, numbers: dict) -> bytes:
    import matplotlib.pyplot as plt
    values = [r.metrics.get(f"rho_{name}", math.nan) for r in rows if r.status == "ok"]
    finite = np.array([v for v in values if isinstance(v, float) and math.isfinite(v)])
    diverged = sum(r.status == "diverged" for r in rows)
    figure, ax = plt.subplots(figsize=(7, 3), constrained_layout=True)
    if finite.size:
        ax.hist(finite, bins=min(30, max(5, finite.size // 3)), color="C0", alpha=0.8)
    ax.axvline(0.0, color="k", lw=1)
    ax.set_xlabel(f"ρ of {name} ({numbers['criterion']}); < 0 fails")
    ax.set_ylabel("draws")
    ax.set_title(f"{numbers['n'] - numbers['failures']}/{numbers['n']} hold, P(holds) in "
                 f"[{numbers['p_low']:.3f}, {numbers['p_high']:.3f}] at level "
                 f"{numbers['level']:g}" + (f"; {diverged} diverged (not drawn)"
                                            if diverged else ""), fontsize=9)
    return fig.png(figure)


def _trace(v: dict) -> bytes:
    import matplotlib.pyplot as plt
    trace = v["trace"]
    figure, axes = plt.subplots(1, 2, figsize=(10, 3.2), constrained_layout=True)
    if v["mode"] == "falsify":
        series = (("reduced", "best_rho_reduced", "reduced plant: best ρ found"),
                  ("truth", "best_rho_truth", "truth plant: lowest confirmed ρ"))
        ylabel = f"ρ of {v['requirement']}"
    else:
        series = (("reduced", "distance", "reduced-plant simulations"),
                  ("truth", "distance", "truth-plant simulations"))
        ylabel = "max |θ_truth − θ_reduced| [rad]"
    for ax, (plant, key, label) in zip(axes, series):
        x = [t[plant] for t in trace if t[key] is not None]
        y = [t[key] for t in trace if t[key] is not None]
        style = fig.PLANT_STYLE[plant]
        ax.step(x, y, where="post", marker="o", ms=3, **style)
        if v["mode"] == "falsify":
            ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel(f"{plant} simulations")
        ax.set_ylabel(ylabel)
        ax.set_title(label, fontsize=9)
    if v["mode"] == "falsify" and v["found"] and v["rho_truth"] is None:
        # ρ = −∞ cannot be drawn: say where the truth plant diverged
        axes[1].annotate(f"diverged (ρ = −∞) at truth simulation {v['simulations']['truth']}",
                         xy=(0.98, 0.04), xycoords="axes fraction", ha="right", fontsize=8,
                         color=fig.PLANT_STYLE["truth"]["color"])
    return fig.png(figure)


def _case_figures(v: dict, store) -> list:
    """Figs. 3-4 analogues of the verdict's case on both plants (the reduced run at the
    same point, when the search evaluated it)."""
    truth_id = (v.get("runs") or {}).get("truth")
    if truth_id is None:
        return []
    from ..batch.store.resimulate import every_signal
    from ..batch.store.folder import run_id
    from ..run.config import to_mapping
    from ..run.vibration import vibration_cutoff
    from ..run.plants import plant_for_role, plant_settings
    from reduced_model import ArmParameters
    truth = store.row(truth_id)
    if truth is None:
        return []
    reduced_id = (v.get("runs") or {}).get("reduced")
    if reduced_id is None:  # a falsification's case: its reduced twin, if it was run
        # (its id from the stored, resolved scenario: checking it would build its laws)
        plant = to_mapping(plant_settings(plant_for_role(truth.config, "reduced")))
        reduced_id = run_id(dict(truth.config, plant=plant))
    both = [r for r in (truth, store.row(reduced_id)) if r is not None]
    group = [r for r in both if r.status == "ok"]  # a run that diverged is named, not drawn
    if not group:
        return []
    what = {"falsify": "counterexample" if v.get("found") else "worst case found",
            "conform": "largest disagreement"}[v["mode"]]
    title = f"{v['system']}, {what} ({fig.describe_run(truth.config)})" + "".join(
        f"; {r.plant_label} {r.status.upper()}: {r.message}"
        for r in both if r.status != "ok")
    transient = float(truth.config.get("transient", 2.0))
    cutoff = vibration_cutoff(ArmParameters.from_mapping(truth.config["true_params"]))

    def loaded():
        return [(r, every_signal(store, r)) for r in group]
    return [(SECTION, f"{title}: joint tracking (Fig. 3)",
             lambda: fig.tracking(loaded(), title, transient)),
            (SECTION, f"{title}: tip deflections and vibration (Fig. 4)",
             lambda: fig.deflections(loaded(), title, transient, cutoff))]
