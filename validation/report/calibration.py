"""The report's "Calibration" section: what ``flexarm calibrate`` found in a results folder.

Read from ``OUT/calibration.json``, the experiments as the calibration read them
(``OUT/experiments/NAME.csv``) and the stored simulation of each at the estimate: the
verdict on the model and its residual tests, the parameters with their intervals (95 %,
or effective parameters' of an inadequate model; or why the data cannot determine
them), the residual RMS of every signal against its noise level, the comparison with
other models fitted to the same data, and for every experiment its measured and fitted
signals and their residuals.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..run.experiments import read_experiment
from . import figures as fig
from .render import fmt_number

__all__ = ["calibration_section", "SECTION"]

SECTION = "Calibration"


def calibration_section(store) -> tuple[dict | None, list]:
    """(table data for the templates, figure tasks (section, caption, make)) of the
    calibration in ``store``'s folder; (None, []) if there is none."""
    path = Path(store.out) / "calibration.json"
    if not path.is_file():
        return None, []
    result = json.loads(path.read_text())
    effective = result.get("model_adequate", True) is not True
    rows = []
    for name, p in result["parameters"].items():
        if not p["identifiable"]:
            rows.append([name, f"{p['estimate']:.7g}", "—", "—", "—",
                         f"NOT IDENTIFIABLE: {p.get('why') or p['reason']}"])
            continue
        lo, hi = p.get("interval") or p["ci95"]
        # as many digits as the interval needs to show its width
        rows.append([name, f"{p['estimate']:.7g}", f"{p['std']:.2g}", f"[{lo:.7g}, {hi:.7g}]",
                     f"{p['model_error']:.2g}" if p.get("model_error") is not None else "—",
                     "yes (effective)" if effective else "yes"])
    residuals = []
    for exp, signals in result["residual_rms"].items():
        if "relative_rms" in signals:
            residuals.append([exp, "(frequency response, relative)",
                              fmt_number(signals["relative_rms"]), fmt_number(signals["noise"]),
                              fmt_number(signals["relative_rms"] / signals["noise"])])
            continue
        for signal, v in signals.items():
            residuals.append([exp, signal, fmt_number(v["rms"]),
                              fmt_number(v["noise"]) if v["noise"] else "not declared",
                              fmt_number(v["rms"] / v["noise"]) if v["noise"] else "—"])
    data = {"rows": rows, "residuals": residuals, "inputs": result["inputs"],
            "interval": "effective interval" if effective else "95 % interval",
            "interval_kind": result.get("interval_kind", "95 % (the noise)"),
            "adequacy": _adequacy(result.get("adequacy")),
            "comparison": [_comparison_row(r) for r in result.get("comparison", [])],
            "extensions": _extensions(result),
            "summary": f"{result['iterations']} iterations, {result['simulations']} "
                       f"simulations, cost {fmt_number(result['cost'])}, residual variance "
                       f"{fmt_number(result['residual_variance'])} (in units of the noise "
                       f"levels), {result['dof']} degrees of freedom",
            "experiments": [f"{e['name']}: {e['source']}, {e['samples']} samples" for e in
                            result["experiments"]] + [f"{r['name']}: {r['source']} "
                                                      f"({', '.join(r['pairs'])})"
                                                      for r in result["responses"]]}
    tasks = []
    for e in result["experiments"]:
        csv = Path(store.out) / "experiments" / f"{e['name']}.csv"
        row = store.row(e["run"])
        if not csv.is_file() or row is None or row.status != "ok":
            continue
        tasks.append((SECTION, f"experiment {e['name']}: measured and fitted signals (top), "
                               "residuals (bottom)",
                      lambda csv=csv, row=row, name=e["name"]: _fit_figure(store, csv, row, name)))
    return data, tasks


#: The residual tests, in the order of the report's columns (a correlated residual's
#: level, judged with its noise model, in χ²'s).
_TESTS = (("chi2", "level"), ("noise",), ("whiteness",), ("inputs",))


def _test_cell(test: dict | None) -> str:
    if test is None:
        return "—"
    limit = test["threshold"]
    limit = (f"{fmt_number(limit[0])}..{fmt_number(limit[1])}" if isinstance(limit, list)
             else f"≤ {fmt_number(limit)}")
    return f"{fmt_number(test['statistic'])} ({limit}){'' if test['passed'] else ' FAILS'}"


def _adequacy(verdict: dict | None) -> dict | None:
    """The verdict on the model and one row per signal: each test's statistic against
    its threshold, and the diagnosis (None for a calibration made before the tests)."""
    if verdict is None:
        return None
    rows = [[exp, signal, *(_test_cell(next((tests[k] for k in kinds if k in tests), None))
                            for kinds in _TESTS),
             tests["diagnosis"] + (f" (AR({tests['noise_model']['order']}))"
                                   if "noise_model" in tests else "")]
            for exp, signals in verdict["signals"].items()
            for signal, tests in signals.items()]
    return {"verdict": verdict["verdict"], "rows": rows,
            "model_adequate": verdict["model_adequate"],
            "alpha": f"{verdict['family_alpha']:g} for all tests together, "
                     f"{fmt_number(verdict['test_alpha'])} each"}


def _extensions(result: dict) -> dict | None:
    """What the model lacks: the screen of the physics extensions (each candidate's score
    against its threshold) and the extended models fitted, best AIC first (None where
    nothing was screened)."""
    screen = result.get("screen") or []
    if not screen:
        return None
    search = result.get("extensions", {})
    return {"verdict": search.get("verdict", "the screen alone (no search)"),
            "screen": [[r["name"], fmt_number(r["score"]), fmt_number(r["threshold"]),
                        "yes" if r["significant"] else "no"] for r in screen],
            "fits": [[r["name"], "adequate" if r["model_adequate"] else "INADEQUATE",
                      fmt_number(r["aic"]), fmt_number(r["delta_aic"])]
                     for r in search.get("fits", [])]}


def _comparison_row(row: dict) -> list[str]:
    return [row["plant"], row["folder"], ", ".join(row["fitted"]), fmt_number(row["chi2"]),
            fmt_number(row["rms"]), row["adequacy"], fmt_number(row["aic"]),
            fmt_number(row["delta_aic"]), fmt_number(row["bic"])]


def _fit_figure(store, csv: Path, row, name: str) -> bytes:
    import matplotlib.pyplot as plt
    measured = read_experiment(csv)
    from ..batch.store.resimulate import every_signal
    fitted = every_signal(store, row)
    t = np.arange(measured.samples) * measured.Ts
    k = min(measured.samples, len(fitted.time))
    n = len(measured.names)
    figure, axes = plt.subplots(2, n, figsize=(3.2 * n, 4.4), squeeze=False,
                                constrained_layout=True)
    for j, signal in enumerate(measured.names):
        sim = fitted[f"y_{signal}"][:k]
        top, bottom = axes[0, j], axes[1, j]
        top.plot(t, measured.signals[j], color="0.55", lw=0.8, label="measured")
        top.plot(t[:k], sim, **fig.PLANT_STYLE.get(fitted.config["plant"]["kind"],
                                                    {"color": "C1"}), label="fitted")
        top.set_title(signal, fontsize=9)
        bottom.plot(t[:k], sim - measured.signals[j, :k], color="C3", lw=0.6)
        bottom.set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=8)
    axes[1, 0].set_ylabel("fitted − measured")
    figure.suptitle(f"{name}: the calibrated plant against the experiment", fontsize=10)
    return fig.png(figure)
