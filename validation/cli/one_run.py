"""``flexarm run`` and ``flexarm show``: one scenario, from flags, a file or a stored run,
and the figures of one stored run."""
from __future__ import annotations

import argparse
import copy
import dataclasses
import functools
import math
import re
import sys
from pathlib import Path

from ..batch.campaign import PlannedRun
from ..batch.executor import available_cores, check_runner, make_runner
from ..batch.interrupts import Interrupted
from ..batch.queue import run_planned
from ..batch.store.resimulate import every_signal
from ..batch.store.folder import ResultStore, StoreError, run_id
from ..run.config import ConfigError, check_label, to_mapping
from ..run.plants import is_truth
from ..run.arms import arm_of, flat_config, flat_values
from ..run.scenario import (PARAMETER_TABLES, Scenario, default_transient,
                            own_parameters, scenario_from_mapping)
from ..run.tomlfiles import deep_merge, flatten, parse_value, set_dotted
from ..verdicts.mesh import is_check

from .common import EXIT_FAILED, mesh_checks, open_output


_RUN_FLAGS = {"plant": "plant.kind", "controller": "controller.kind", "arm": "arm",
              "observer": "observer.kind", "duration": "duration", "seed": "seed", "Ts": "Ts",
              "feedback": "feedback", "initial_state": "initial_state", "name": "name"}


def stored_run(spec: str, flag: str):
    """(store, row) of the stored run ``RESULTS/RUN``: RESULTS is the leading part of the path that holds
    a results index; RUN is a run id (or a unique prefix of one, at least 4 characters)
    or a run name (in full, or its part after the campaign's "/").  A name shared by a
    run and its mesh/step checks (which keep its name) means the run itself."""
    from ..batch.store.folder import INDEX_NAME
    parts = Path(spec).parts
    for k in range(len(parts) - 1, 0, -1):
        if (Path(*parts[:k]) / INDEX_NAME).is_file():
            folder, selector = Path(*parts[:k]), "/".join(parts[k:])
            break
    else:
        raise ConfigError(flag, f"{spec}: expected RESULTS/RUN (a results folder holding "
                                f"{INDEX_NAME}, then a run id or name)")
    store = ResultStore(folder)
    rows = store.rows()
    found = [r for r in rows if r.run_id == selector] or \
        [r for r in rows if len(selector) >= 4 and r.run_id.startswith(selector)] or \
        [r for r in rows if r.name == selector] or \
        [r for r in rows if r.name.split("/")[-1] == selector]
    if not found:
        names = sorted({r.name for r in rows})
        raise ConfigError(flag, f"{folder} has no run {selector!r} (names: "
                                f"{', '.join(names[:12])}{', ...' if len(names) > 12 else ''})")
    nominal = [r for r in found if not is_check(r)]
    if len(found) > 1 and len(nominal) == 1:
        return store, nominal[0]
    if len(found) > 1:
        choices = "; ".join(f"{r.run_id} ({_kind_of_run(r)})" for r in found[:12])
        raise ConfigError(flag, f"{len(found)} runs of {folder} are named {selector!r}; give "
                                f"one's id: {choices}{'; ...' if len(found) > 12 else ''}")
    return store, found[0]


def _kind_of_run(row) -> str:
    """"nominal run, exudyn plant, default arm, Ts = 1 ms, from rest" or "mesh/step check
    ANCF 8 el/link, step/2 of <id>": what tells runs of one name apart."""
    from ..report.figures import describe_run
    if is_check(row):
        return f"mesh/step check {row.axes.get('mesh', '')} of {row.axes.get('of', '?')}"
    return f"nominal run, {row.plant} plant, {describe_run(row.config)}"


def _checks_note(store, row) -> str:
    """What --like says about the mesh/step checks stored under the same name."""
    checks = [r.run_id for r in store.rows() if is_check(r) and r.axes.get("of") == row.run_id]
    if not checks:
        return ""
    return (f"; the nominal run: its {len(checks)} mesh/step check(s) share its name "
            f"({', '.join(checks)}: give one's id to rerun it)")


def auto_name(s: Scenario) -> str:
    """A run's name from what it is: controller (+ observer) @ plant, e.g.
    "pbc+smo-paper@exudyn": a law by its name (`laws.law_name`: a plug-in's own ``name``,
    the one its failures give), a plug-in plant by its class name; what a name may not
    hold (`check_label`) becomes "-"."""
    from ..run.laws import law_name
    observer = "" if s.observer.kind == "none" else "+" + law_name(s, "observer")
    name = f"{law_name(s, 'controller')}{observer}@{s.plant.kind.rsplit(':', 1)[-1]}"
    return re.sub(r"[^A-Za-z0-9._+@-]", "-", name).lstrip(".")[:100]


def scenario_from_args(args: argparse.Namespace) -> tuple[Scenario, list[str]]:
    """The scenario of ``flexarm run`` and what to tell the user about where it came from."""
    from ..batch.campaign import load_study, own_name
    notes, like = [], getattr(args, "like", None)
    if like and args.config:
        raise ConfigError("--like", "--like and --config exclude each other")
    settings = []
    for item in args.set or []:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", f"expected KEY=VALUE, got {item!r}")
        settings.append((key.strip(), parse_value(text.strip(), key.strip())))
    # A name given here names this one run: a plain name, as a scenario file's own (which
    # it replaces); "<campaign>/<label>" is a campaign's run, kept only by --like.
    given = next((v for k, v in reversed(settings) if k == "name"), args.name)
    if given is not None:
        check_label(given, "name")
    if like:
        store, row = stored_run(like, "--like")
        data = own_parameters(copy.deepcopy(row.config))  # over whichever arm is named
    elif args.config:
        study = load_study(args.config, name=given)
        data = deep_merge({}, study.base) | own_name(study)
        if study.sweeps and not own_name(study):
            notes.append(f"{args.config} is a campaign: running its [scenario] base (its "
                         f"{len(study.sweeps)} sweep(s) are not run: flexarm campaign "
                         f"{args.config})")
    else:
        data = {}
    named = "name" in data or given is not None
    if args.duration is not None and "transient" not in dict(settings) and \
            "transient" in data and \
            data["transient"] == default_transient(data.get("duration", Scenario.duration)):
        del data["transient"]  # it was the default for the old duration: follow the new one
    for attr, key in _RUN_FLAGS.items():
        value = getattr(args, attr)
        if value is not None:
            set_dotted(data, key, value)
    for key, value in settings:
        set_dotted(data, key, value)
    scenario = scenario_from_mapping(data)
    if not named:
        scenario = dataclasses.replace(scenario, name=auto_name(scenario))
    if like:
        from ..batch.fingerprint import run_fingerprint
        from ..run.scenario import scenario_to_mapping
        old, new = flat_config(row.config), flat_config(scenario_to_mapping(scenario))
        changed = [k for k in sorted(old | new) if old.get(k) != new.get(k)]
        followed = _following_the_arm(changed, new, row.config.get("arm"), scenario.arm)
        changed = [f"{k} = {new.get(k)!r} (was {old.get(k)!r})" for k in changed
                   if k not in followed]
        follow = (f"; {len(followed)} value(s) of {' and '.join(PARAMETER_TABLES)} follow "
                  f"the {scenario.arm} arm (those the stored run set itself are kept)"
                  if followed else "")
        head = f"rerunning {row.run_id} ({row.name}, stored in {store.out}" \
               f"{_checks_note(store, row) if not is_check(row) else ''})"
        notes.append(head + (" exactly" if not changed else
                             f" with {len(changed)} change(s): " + "; ".join(changed)) + follow)
        if row.fingerprint != run_fingerprint(row.config):
            notes.append("  it was stored by other code (its fingerprint differs): the "
                         "numbers may differ")
        args.like_row = None if changed else row
    return scenario, notes


def _following_the_arm(changed: list[str], new: dict, old_arm: str, arm: str) -> set[str]:
    """Of the dotted keys ``changed`` by a rerun with another arm, the parameter values
    that are now the new arm's own (the physics that follows ``arm``)."""
    if arm == old_arm:
        return set()
    values = {f"{t}.{k}": v for t in PARAMETER_TABLES for k, v in flat_values(arm_of(arm)).items()}
    return {k for k in changed if k in values and new.get(k) == values[k]}


#: The rows of a run's table: (metric key, label, format, scale); ``{i}``: each joint (or
#: link) from 1, a row per joint the run has.
_TABLE = [("status", "status", "{}"),
          ("track_max_{i}", "max |θ{i} − θ{i}d| [mrad]", "{:.4g}", 1e3),
          ("track_rms_{i}", "RMS θ{i} − θ{i}d [mrad]", "{:.3g}", 1e3),
          ("tip_err_max", "max payload error vs the rigid arm [mm]", "{:.3g}", 1e3),
          ("defl_max_{i}", "max tip deflection, link {i} [mm]", "{:.3g}", 1e3),
          ("vib_rms_{i}", "vibration RMS, link {i} [mm]", "{:.3g}", 1e3),
          ("tau_max_{i}", "max |τ{i}| [N m]", "{:.3g}"),
          ("tau_tv_{i}", "τ{i} variation [N m/s]", "{:.3g}"),
          ("wall_s", "wall time [s]", "{:.3g}"), ("realtime_factor", "real-time factor", "{:.3g}")]
#: Of `_TABLE`, what measures the computer, not the run (the run's timings).
_TIMINGS = ("wall_s", "realtime_factor")


def format_metrics(metrics: dict, units: dict | None = None) -> str:
    """The metrics of a run as lines to print; ``units``: the requirements (their ρ's
    unit), by metric key."""
    lines = []
    transient, end = metrics.get("transient_s"), metrics.get("end_time")
    if transient is not None and end is not None:
        lines.append(f"  metrics after the {transient:g} s transient, over {transient:g}–"
                     f"{end:g} s (maxima of deflection and torque, torque variation: the "
                     "whole run)" if end > transient else
                     f"  no metrics after the transient: the run ended at {end:g} s, before "
                     f"its {transient:g} s transient did")
    joints = sum(1 for k in metrics if k.startswith("track_max_"))
    rows = [(key.format(i=i), label.format(i=i), fmt, *scale)
            for key, label, fmt, *scale in _TABLE
            for i in (range(1, joints + 1) if "{i}" in key else (None,))]
    for key, label, fmt, *scale in rows:
        value = metrics.get(key)
        if value is None or (isinstance(value, float) and not value >= 0 and key in _TIMINGS) \
                or (isinstance(value, float) and math.isnan(value)):
            continue
        lines.append(f"  {label:<44} {fmt.format(value * scale[0] if scale else value)}")
    ratios = {k.removeprefix("est_to_noise_"): v for k, v in metrics.items()
              if k.startswith("est_to_noise_") and isinstance(v, float) and math.isfinite(v)}
    if ratios:
        worst = max(ratios, key=ratios.get)
        lines.append(f"  {'estimate / measurement error, worst':<44} {ratios[worst]:.3g} ({worst})")
    if metrics.get("est_worse"):
        lines.append(f"  {'estimate worse than the measurement':<44} {metrics['est_worse']}")
    if metrics.get("est_worse_zero"):
        lines.append(f"  {'estimate worse than x̂ ≡ 0':<44} {metrics['est_worse_zero']}")
    for key, value in metrics.items():  # the requirements' robustness (rho >= 0 holds)
        if key.startswith("rho_") and isinstance(value, float) and not math.isnan(value):
            verdict = "holds" if value >= 0 else "fails"
            requirement = (units or {}).get(key)
            text = requirement.rho_text(value) if requirement else f"{value:.4g}"
            lines.append(f"  {'requirement ' + key.removeprefix('rho_') + ': ρ':<44} "
                         f"{text} ({verdict})")
    return "\n".join(lines)


def _compare_with_stored(stored, metrics: dict) -> str:
    """One line: does a rerun reproduce the stored run's metrics?"""
    keys = [k for k, v in stored.metrics.items() if isinstance(v, float)]
    worst, where = 0.0, ""
    for k in keys:
        a, b = stored.metrics[k], metrics.get(k, math.nan)
        if math.isnan(a) and isinstance(b, float) and math.isnan(b):
            continue
        diff = abs(a - b) / max(abs(a), 1e-300) if a != b else 0.0
        if not diff <= worst:
            worst, where = (math.inf if math.isnan(diff) else diff), k
    if worst <= 1e-12:
        return f"  the stored metrics are reproduced: {len(keys)} metrics, largest relative " \
               f"difference {worst:.1g}"
    return f"  DIFFERS from the stored run: {where} by {worst:.3g} (relative)"


def cmd_run(args: argparse.Namespace) -> int:
    from ..batch.campaign import check_run_name
    from ..run.scenario import scenario_to_mapping
    scenario, notes = scenario_from_args(args)
    check_run_name(scenario.name, "name")
    for note in notes:
        print(note)
    data = scenario_to_mapping(scenario)
    rid = run_id(data)
    check_runner(run_timeout=args.run_timeout, memory_limit=args.memory_limit)
    truth = is_truth(data)
    refinable = bool(scenario.plant.refinements())
    if args.mesh_check and not truth:
        raise ConfigError("--mesh-check", f"the {scenario.plant.kind} plant is not a "
                                          "discretisation: only a truth plant has mesh checks")
    if args.mesh_check and not refinable:
        raise ConfigError("--mesh-check", f"the {scenario.plant.label} declares no refinements "
                                          "(a plug-in plant is described without importing "
                                          "it): check its convergence yourself")
    store = open_output(args.out or Path("results") / f"run-{rid}")  # bad --out: nothing ran
    workers = min(available_cores(), 3) if args.mesh_check else 1  # the 3 checks side by side
    with make_runner("local", workers, run_timeout=args.run_timeout,
                     memory_limit=args.memory_limit, scenarios=[scenario],
                     progress=sys.stderr) as runner:  # worker processes
        summary = run_planned([PlannedRun(rid, scenario, "", {})], store.out, name="",
                              runner=runner, progress=False, export=False, rerun=True)
        if summary.unstored:
            raise StoreError(summary.unstored[0])
        if summary.interrupted:
            raise Interrupted(summary.interrupted)
        result = store.row(rid)
        path = store.out / result.file
        metrics = result.metrics
        if args.mesh_check:
            checked = mesh_checks(runner, store.out, {rid}, progress=True)
    store.export()
    s = scenario
    obs = "" if s.observer.kind == "none" else f" + {s.observer.kind}"
    print(f"{s.name}: {s.controller.kind}{obs} on the {s.plant.kind} plant, {s.arm} arm, "
          f"{s.duration:g} s at Ts = {s.Ts:g} s, from {s.initial_state}")
    if s.true_params.joints_text():
        print(f"  the true arm's joints: {s.true_params.joints_text()}")
    failed = result.status == "failed"
    if result.message:  # a failure is the command's error: on stderr, like show's
        print(f"  {result.status}: {result.message}", file=sys.stderr if failed else sys.stdout)
    if failed:
        if frames := failure_frames(store, rid):
            print(frames, file=sys.stderr)
        print(f"  no metrics: the run failed after {result.end_time or 0:g} of {s.duration:g} s "
              "(a run that failed measures nothing)", file=sys.stderr)
    else:
        units = {r.metric: r for r in s.requirement}
        print(format_metrics(metrics | {k: result.timings.get(k, math.nan) for k in _TIMINGS},
                             units))
    if getattr(args, "like_row", None) is not None and result.status == "ok":
        print(_compare_with_stored(args.like_row, metrics))
    # A run that failed has no numbers whose convergence a mesh check could tell.
    if truth and refinable and (args.mesh_check or not failed):
        print("  " + (convergence_line(store, rid) if args.mesh_check else
                      f"convergence not checked: these are the FE model's numbers on "
                      f"{scenario.plant.discretisation()}; --mesh-check runs the same loop on "
                      "refined meshes and steps"))
    elif truth and not failed:
        print(f"  convergence not checked: the {scenario.plant.label} declares no refinements "
              "(check its convergence yourself)")
    print(f"results: {path} (index and metrics.csv in {store.out})" + (
        f"; figures: flexarm show {store.out}/{rid}" if result.status == "ok" else ""))
    if args.mesh_check and checked:
        return checked
    return 0 if result.status != "failed" else EXIT_FAILED


def convergence_line(store, rid: str) -> str:
    """Whether the stored truth-plant run ``rid`` survived its mesh/step checks: every
    judged value (a claim's measure) within the tolerance on every check, or which moved."""
    from ..verdicts.claims import mesh_rows
    from ..verdicts.mesh import MESH_ATOL, MESH_RTOL, checked_against
    rows = mesh_rows(store.rows(), functools.partial(every_signal, store))
    mine = [r for r in rows if r.run.run_id == rid]
    against = "against " + checked_against(mine[0].values[1:] if mine else (), "; ")
    moved = [r for r in mine if r.converged is False]
    if any(r.converged is None for r in mine) or not mine:
        return f"convergence: checks incomplete ({against})"
    if moved:
        return f"NOT CONVERGED {against}: " + "; ".join(
            (r.claim.key if r.claim else "status") + " (" + ", ".join(
                f"{label}: {v if isinstance(v, str) else f'{v:.3g}'}" for label, v in r.values)
            + ")" for r in moved)
    return (f"converged {against}: {len(mine)} judged value(s), each within {MESH_RTOL:.0%} "
            f"+ {MESH_ATOL:.0%} of its bound")


def failure_frames(store: ResultStore, rid: str) -> str:
    """The stored frames of the code that raised in run ``rid`` (`RunResult.traceback`),
    indented under a heading, or ""."""
    frames = store.read(rid)[0].traceback
    if not frames:
        return ""
    return "  where it raised (its own code; innermost last):\n" + "\n".join(
        "  " + line for line in frames.splitlines())


def cmd_show(args: argparse.Namespace) -> int:
    from ..report.show import open_in_browser, show_run
    store, row = stored_run(args.run, "RESULTS/RUN")
    if row.status != "ok":
        print(f"{row.run_id} ({row.name}) {row.status}: {row.message}; a run that did not "
              "complete is not drawn", file=sys.stderr)
        if frames := failure_frames(store, row.run_id):
            print(frames, file=sys.stderr)
        return EXIT_FAILED
    page, files, note = show_run(store, row)
    if note:
        print(note)
    for f in files:
        print(f"  {f}")
    print(f"figures of {row.run_id} ({row.name}): {page}")
    if not args.no_open and open_in_browser(page):
        print("opened in the browser")
    return 0
