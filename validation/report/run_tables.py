"""The report's tables of runs: every run and its status, their metrics in the units a
reader expects, estimation against the measurement, and the truth plant's mesh and
time-step convergence; and the cells they share (a run's identity, its swept values)."""
from __future__ import annotations

import math

from . import figures as fig
from .render import fmt_number, folded
from .sweep_figures import short_value

__all__ = ["table", "swept", "identity", "runs_table", "metrics_table",
           "estimation_table", "mesh_table"]

#: Axes shown in their own columns (not repeated among the swept values); a swept plant
#: table is the plant column and the figures' legend.
_OWN_COLUMNS = {"name", "arm", "plant", "plant.kind", "initial_state", "Ts",
                "controller.kind", "observer.kind"}


def table(head: list[str], rows: list[list], classes: list[str] | None = None) -> dict:
    cells = [[c if isinstance(c, (str, dict)) else fmt_number(c) for c in row] for row in rows]
    return {"head": head, "rows": cells, "classes": classes or [""] * len(rows)}


def _start(config: dict) -> str:
    return "rest" if config.get("initial_state") == "rest" else "moving"


def swept(run) -> str:
    return ", ".join(f"{k}={short_value(v)}" for k, v in run.axes.items() if k not in _OWN_COLUMNS)


def identity(run) -> list:
    c = run.config
    return [run.name, c.get("arm", "default"), run.plant, f"{1e3 * c['Ts']:g}", _start(c)]


def runs_table(runs) -> dict:
    head = ["run", "name", "arm", "plant", "Ts [ms]", "start", "controller", "observer",
            "swept values", "status"]
    rows = [[r.run_id, *identity(r), r.config["controller"]["kind"],
             r.config["observer"]["kind"], swept(r),
             r.status + (f": {r.message}" if r.message else "")] for r in runs]
    return table(head, rows, [r.status for r in runs])


#: (metric key, column head, factor from SI to the unit in the head).
_METRICS = [("track_max_1", "max |e₁| [mrad]", 1e3), ("track_max_2", "max |e₂| [mrad]", 1e3),
            ("rate_err_rel", "rate error / peak rate", 1), ("vib_rms_1", "vibration 1 [mm]", 1e3),
            ("vib_rms_2", "vibration 2 [mm]", 1e3), ("defl_max_1", "max deflection 1 [mm]", 1e3),
            ("tau_max_1", "max |τ₁| [N m]", 1), ("tau_tv_1", "τ₁ variation [N m/s]", 1),
            ("tau_tv_2", "τ₂ variation [N m/s]", 1), ("realtime_factor", "real-time factor", 1),
            ("wall_s", "wall [s]", 1), ("startup_s", "first sample [s]", 1)]
#: Of `_METRICS`, what the run's timings hold (the computer's, not the run's).
_TIMINGS = ("realtime_factor", "wall_s", "startup_s")


def metrics_table(runs) -> dict:
    head = ["name", "arm", "plant", "Ts [ms]", "start", "swept values"] + [h for _, h, _ in _METRICS]
    rows = []
    for r in runs:
        if r.status == "ok":
            measured = r.metrics | {k: r.timings.get(k, math.nan) for k in _TIMINGS}
            values = [measured.get(k, math.nan) * scale if isinstance(measured.get(k), float)
                      else math.nan for k, _, scale in _METRICS]
        else:
            values = [r.status] + [""] * (len(_METRICS) - 1)
        rows.append([*identity(r), swept(r), *values])
    return table(head, rows, [r.status for r in runs])


def _fed(run) -> frozenset:
    """The states the run's observer was fed, as the run recorded them (a report never
    builds a law: that would import and run a plug-in's code)."""
    return frozenset(run.timings.get("observer_measured") or ())


def estimation_table(runs) -> dict | None:
    """Two tables, one row per observed run: the error / measurement ratio per state
    (flagged), and each state's error, measurement error and signal RMS."""
    observed = [r for r in runs if r.status == "ok" and "est_rms_theta1" in r.metrics]
    if not observed:
        return None
    observed.sort(key=lambda r: (r.arm, r.name, r.role))
    # every run's states (arms differ in them): angles, then modal positions, then rates
    states = sorted({k.removeprefix("est_rms_") for r in observed for k in r.metrics
                     if k.startswith("est_rms_") and not k.startswith("est_rms_slope")},
                    key=lambda s: (s.endswith("_dot"), not s.startswith("theta"), s))
    ident = ["name", "arm", "plant", "Ts [ms]", "start", "observer"]
    head = ident + [fig.state_label(s) for s in states] + ["worse than the measurement it is fed",
                                                           "worse than x̂ ≡ 0"]
    detail_head = ident + [f"{fig.state_label(s)} [{fig.state_display(s)[1]}]" for s in states]
    rows, detail = [], []
    for r in observed:
        m, fed = r.metrics, _fed(r)
        cells, values = [], []
        for s in states:
            ratio = m.get(f"est_to_noise_{s}")
            zero = m.get(f"est_to_signal_{s}")
            zero = " ⊘" if isinstance(zero, float) and zero >= 1 else ""
            if not isinstance(ratio, float) or math.isnan(ratio):
                cells.append("—" + zero)
            elif s not in fed:
                cells.append(fmt_number(ratio, 2) + " †" + zero)
            else:
                cells.append(fmt_number(ratio, 2) + (" ⚠" if ratio > 1 else "") + zero)
            scale = fig.state_display(s)[0]
            rms = [m.get(f"{k}_rms_{s}") for k in ("est", "noise", "signal")]
            values.append(" / ".join(fmt_number(scale * v) if isinstance(v, float) else "—"
                                     for v in rms) + ("" if s in fed else " †"))
        worse = " ".join(fig.state_label(s) for s in (m.get("est_worse") or "").split()
                         if s in fed)
        zero = " ".join(fig.state_label(s) for s in (m.get("est_worse_zero") or "").split())
        ident_cells = [*identity(r), r.config["observer"]["kind"]]
        rows.append([*ident_cells, *cells, worse or "none", zero or "none"])
        detail.append([*ident_cells, *values])
    return {"compact": table(head, rows), "detail": table(detail_head, detail)}


def mesh_table(runs, signals) -> dict | None:
    """Closed-loop mesh convergence of the truth-plant runs that have checks: per run, its
    verdict and the values that moved (compact); each judged value (a claim's measure) on
    every mesh (detail)."""
    from ..verdicts.claims import mesh_rows
    from ..verdicts.mesh import MESH_ATOL, MESH_RTOL
    rows = sorted(mesh_rows(runs, signals), key=lambda r: (r.run.name, swept(r.run),
                                                           r.run.config["Ts"]))
    if not rows:
        return None
    labels = list(dict.fromkeys(label for r in rows for label, _ in r.values))

    def text(v, unit):
        if isinstance(v, str):
            return v
        return "never" if math.isinf(v) else f"{fmt_number(v)} {unit}".strip()
    detail, detail_classes, per_run = [], [], {}
    for r in rows:
        by_label = dict(r.values)
        unit = r.claim.unit if r.claim else ""
        values = [text(by_label[label], unit) if label in by_label else "" for label in labels]
        verdict = {True: "converged" if r.claim else "same outcome in every check",
                   False: "not converged", None: "check not run"}[r.converged]
        estimate = "" if not math.isfinite(r.error) else \
            f"± {fmt_number(r.error, 2)} {unit}".strip() + (
                f" (order {r.order:.2g})" if math.isfinite(r.order) else " (order not observed)")
        detail.append([*identity(r.run)[:2], *identity(r.run)[3:], swept(r.run),
                       r.claim.key if r.claim else "run status", *values, estimate, verdict])
        detail_classes.append({True: "holds", False: "fails", None: ""}[r.converged])
        per_run.setdefault(r.run.run_id, (r.run, []))[1].append((r, values))
    compact, classes = [], []
    for run, items in per_run.values():
        moved = [f"{r.claim.key if r.claim else 'status'} ({', '.join(v)})"
                 for r, v in items if r.converged is False]
        missing = any(r.converged is None for r, _ in items)
        verdict = ("not converged" if moved else "check not run" if missing else
                   "converged" if run.status == "ok" else f"{run.status} in every check")
        compact.append([*identity(run)[:2], *identity(run)[3:], swept(run), verdict,
                        folded(f"{len(moved)} value(s)", "; ".join(moved)) if moved else "—"])
        classes.append("fails" if moved else "" if missing else "holds")
    head = ["name", "arm", "Ts [ms]", "start", "swept values"]
    return {"compact": table(head + ["verdict", f"moved ({', '.join(labels)})"], compact,
                              classes),
            "detail": table(head + ["judged value", *labels, "estimated error", "verdict"],
                             detail, detail_classes),
            "tolerance": f"|a − b| ≤ {MESH_RTOL:.0%} of the larger value + {MESH_ATOL:.0%} "
                         "of the claim's bound"}

