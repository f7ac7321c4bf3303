"""Which stored runs the report draws together (the same scenario on each plant, truth
plant first) and the paper's figures and animation of such a group, read from the stored
runs."""
from __future__ import annotations

import json
from pathlib import Path

from reduced_model import ArmParameters

from . import figures as fig
from ..batch.store.resimulate import every_signal
from ..verdicts.mesh import is_check
from .run_tables import swept

__all__ = ["plant_groups", "figure_group", "figure_groups", "claim_bounds",
           "paper_figure_tasks", "animation"]


def _scenario_key(r) -> str:
    """What a run is, but its plant and its name: runs of one key are the same scenario
    on different plants (their default names differ: "pbc@reduced", "pbc@exudyn")."""
    return _key({k: v for k, v in r.config.items() if k not in ("plant", "name")})


def _order(rs) -> list:
    return sorted(rs, key=lambda r: r.role != "truth")


def plant_groups(runs) -> list[list]:
    """``runs`` in groups drawn together: the same scenario but the plant, one run per
    plant role (by name where a role has several), truth plant first."""
    by_key: dict[str, dict[str, list]] = {}
    for r in sorted(runs, key=lambda r: (r.name, r.run_id)):
        by_key.setdefault(_scenario_key(r), {}).setdefault(r.role, []).append(r)
    groups = []
    for roles in by_key.values():
        for i in range(max(len(rs) for rs in roles.values())):
            groups.append(_order([rs[i] for rs in roles.values() if i < len(rs)]))
    return groups


def figure_group(row, rows) -> list:
    """The runs among ``rows`` drawn with ``row``: itself and, for each other plant role,
    the same scenario on that plant when the folder holds it (the one of the same name if
    there are several), whatever the names; truth plant first."""
    key = _scenario_key(row)
    others: dict[str, object] = {}
    for r in sorted(rows, key=lambda r: (r.name != row.name, r.name, r.run_id)):
        if r.role != row.role and _scenario_key(r) == key and not is_check(r):
            others.setdefault(r.role, r)
    return _order([row, *others.values()])


def figure_groups(runs, wanted: list[str] | None):
    groups = plant_groups([r for r in runs if r.status != "failed"])
    if wanted:
        groups = [g for g in groups if any(r.name == w or r.name.endswith("/" + w)
                                           for r in g for w in wanted)]
    else:
        both = [g for g in groups if len({r.plant for r in g}) > 1]
        groups = (both or groups)[:1]
    order = {"default": 0, "table1": 1, "rest": 0, "reference": 1}
    groups.sort(key=lambda g: (g[0].name, order.get(g[0].config.get("arm"), 9),
                               -g[0].config["Ts"], order.get(g[0].config.get("initial_state"), 9),
                               swept(g[0])))
    drawable = [g for g in groups if any(r.status == "ok" for r in g)]
    return drawable, [g[0] for g in groups if g not in drawable]


def _key(value) -> str:
    return json.dumps(value, sort_keys=True)


def claim_bounds() -> dict:
    """The claims' bounds, by claim key (SI units)."""
    from ..verdicts.claims import CLAIMS
    return {c.key: c.bound for c in CLAIMS}



def _loaded(store, group):
    """(row, every signal) of each run of a figure group (re-simulated where a run's file
    keeps less: `validation.batch.store.resimulate.every_signal`)."""
    return [(r, every_signal(store, r)) for r in group]


def _title(group) -> str:
    """What a group of runs is: its name(s), arm, Ts, start and swept values, then the
    runs of it that did not complete, after " — " (a figure's file name stops there)."""
    head = next(r for r in group if r.status == "ok")
    values = swept(head)
    names = " / ".join(dict.fromkeys(r.name for r in group))
    stopped = "; ".join(f"{r.plant_label} {r.status.upper()}: {r.message}"
                        for r in group if r.status != "ok")
    return f"{names} ({fig.describe_run(head.config)}{'; ' + values if values else ''})" + (
        f" — {stopped}" if stopped else "")


def paper_figure_tasks(store, group, bounds: dict | None = None) -> list:
    """The paper's figures of one group as (section, caption, draw) tasks; runs that
    diverged or failed are named in the title, not drawn (their last samples before
    leaving the bounds are not data).  ``bounds``: the claims' bounds by claim key."""
    from ..run.vibration import vibration_cutoff
    bounds = bounds or {}
    title = _title(group)
    group = [r for r in group if r.status == "ok"]
    head = group[0]
    transient = float(head.config["transient"])
    cutoff = vibration_cutoff(ArmParameters.from_mapping(head.config["true_params"]))
    cache = {}

    def results():
        if "r" not in cache:
            cache["r"] = _loaded(store, group)
        return cache["r"]
    what, _, stopped = title.partition(" — ")

    def caption(figure: str) -> str:  # what was run, the figure, then what did not complete
        return f"{what}: {figure}" + (f" — {stopped}" if stopped else "")
    tasks = [("Paper figures", caption("joint tracking (Fig. 3)"),
              lambda: fig.tracking(results(), title, transient, bounds.get("tracking"))),
             ("Paper figures", caption("tip deflections and vibration (Fig. 4)"),
              lambda: fig.deflections(results(), title, transient, cutoff,
                                      bounds.get("vibration")))]
    if head.config["observer"]["kind"] != "none":
        tasks += [("Paper figures", caption("true vs estimated rates (Figs. 5–6)"),
                   lambda: fig.rates(results(), title, transient)),
                  ("Paper figures", caption("estimation errors (Fig. 7)"),
                   lambda: fig.estimation_errors(results(), title, transient,
                                                 bounds.get("estimation")))]
    tasks.append(("Paper figures", caption("phase portrait (Fig. 8)"),
                  lambda: fig.phase_portrait(results(), title, transient,
                                             bounds.get("phase_portrait"))))
    return tasks


def animation(store, group, path: Path) -> tuple[str, bytes] | None:
    """The GIF of a group written to ``path`` and its still for print: (caption, PNG);
    None when no run moves (one sample)."""
    from ..run.laws import nominal_model
    head = group[0]
    params = ArmParameters.from_mapping(head.config["nominal_params"])
    model = nominal_model(params, tuple(head.config["model"]["modes_per_link"]))
    loaded = _loaded(store, [r for r in group if r.status == "ok"])
    caption = fig.animation(loaded, params, model, _title(group), path)
    if caption is None:
        return None
    return caption, fig.arm_snapshots(loaded, params, model, _title(group))

