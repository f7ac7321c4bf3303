"""The ``flexarm`` command line: a thin layer over the library.

Bad input ends with one line on stderr and exit status 2, before anything is written;
a run or campaign with failed runs exits 1; SIGINT/SIGTERM exit 130/143 after keeping
what finished (at once, while the program is still starting); a full disk is one line
naming the folder, exit 1.  Never a traceback, and never status 0 because code a
command ran (a plug-in) called ``sys.exit``.
"""
from __future__ import annotations

import os
import signal
import sys


def _stop_while_starting(signum, frame):
    print("flexarm: interrupted", file=sys.stderr)
    os._exit(128 + signum)


# A Ctrl-C while the program imports its libraries (numpy, numba, Exudyn: a second or
# two, nothing written yet) ends it at once, without a traceback.  Only when this module
# is the program: importing it (tests, notebooks) leaves the handlers alone.
if __name__ == "__main__" or os.path.basename(sys.argv[0]) == "flexarm":
    for _signal in (signal.SIGINT, signal.SIGTERM):
        signal.signal(_signal, _stop_while_starting)

from .batch.threads import prefer_one_thread

prefer_one_thread()  # before numpy is imported; a user's setting wins

import argparse  # noqa: E402
import copy
import dataclasses
import errno
import math
import sqlite3
from importlib.metadata import version
from pathlib import Path

import numpy as np

from controllers import CONTROLLERS, OBSERVERS

from .run._config import ConfigError
from .batch.executor import (Interrupted, available_cores, check_runner, exit_status,
                             make_runner, signals_interrupt)
from .run.scenario import (ARMS, DEFAULT_TRANSIENT, PLANTS, Scenario, default_transient,
                           scenario_from_mapping)
from .batch.store import ResultStore, StoreError, run_id
from .run.tomlfiles import deep_merge, flatten, load_toml, parse_value, set_dotted

EXIT_USAGE = 2
EXIT_FAILED = 1


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, status 2 (argparse's own convention)
        self.exit(EXIT_USAGE, f"flexarm: error: {message}\n")


def _int_in(lo: int, hi: int):
    """argparse type: an integer in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in {lo}..{hi}, got {value}")
        return value
    return parse


def _finite(text: str) -> float:
    """argparse type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def _positive(text: str) -> float:
    value = _finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


# --- flexarm modes ------------------------------------------------------------------------
#: Independent reference frequencies [Hz] of Table 1's arm at θ1 = θ2 = 0: a converged
#: Euler–Bernoulli finite-element model built outside this code (the paper publishes
#: none).  Joints free: the two rigid modes left out.
TABLE1_REFERENCE_HZ = {"locked": (0.6316, 3.8312, 6.3499, 33.665),
                       "free": (2.2359, 6.1233, 31.414, 34.302)}


def _gap_percent(ours, reference) -> np.ndarray:
    """100 (ours − reference)/reference, rounded to the printed 4 decimals with no −0."""
    return np.round(100 * (np.asarray(ours) - reference) / reference, 4) + 0.0


def cmd_modes(args: argparse.Namespace) -> int:
    from plant_exudyn import Mesh, natural_frequencies
    from reduced_model import ArmModel, ArmParameters, validate_modes_per_link
    if args.params and args.table1:
        raise ValueError("--params and --table1 exclude each other")
    if args.table1:
        params, source = ArmParameters.table1(), ARMS["table1"]
    elif args.params:
        data = load_toml(args.params)
        if set(data) == {"params"} and isinstance(data["params"], dict):
            data = data["params"]
        params = ArmParameters.from_mapping(data, where=f"{args.params}:params")
        source = args.params
    else:
        params, source = ArmParameters(), ARMS["default"]
    model = ArmModel(params, validate_modes_per_link(args.modes_per_link, where="--modes-per-link"))
    mesh = Mesh(element=args.element, elements_per_link=args.elements) if args.compare else None
    n1, n2 = model.modes_per_link
    row = lambda label, values: f"  {label:<30}" + "".join(f"{v:>11.4f}" for v in values)  # noqa: E731
    print(f"Reduced model, {n1}+{n2} clamped-mass modes, arm: {source}")
    print("Clamped-mass link frequencies [Hz]")
    for i, modes in enumerate(model.mode_shapes, start=1):
        print(row(f"link {i}", modes.frequencies_hz))
    referenced = False
    for theta2 in args.theta2:
        Q = np.zeros(model.n)
        Q[1] = theta2
        print(f"Coupled frequencies at theta1 = 0, theta2 = {theta2:g} rad [Hz]")
        for joints in ("locked", "free"):
            reduced = model.natural_frequencies(Q, joints)
            label = "joints locked" if joints == "locked" else "joints free (non-zero)"
            print(row(label + (" reduced" if mesh else ""), reduced))
            if mesh:
                fe = natural_frequencies(params, mesh, theta=(0.0, theta2), joints=joints,
                                         n=len(reduced))
                print(row(f"{'':<14}FE", fe))
                print(row(f"{'':<10}gap [%]", _gap_percent(reduced, fe)))
            if args.table1 and theta2 == 0:
                reference = np.array(TABLE1_REFERENCE_HZ[joints][:len(reduced)])
                print(row(f"{'':<4}independent reference", reference))
                print(row(f"{'':<4}gap to reference [%]", _gap_percent(reduced[:len(reference)],
                                                                       reference)))
                referenced = True
    if mesh:
        print(f"FE: {mesh.element}, {mesh.elements_per_link[0]}+{mesh.elements_per_link[1]} "
              "elements; gap = (reduced - FE) / FE")
    if referenced:
        print("independent reference: a converged Euler-Bernoulli FE model of Table 1's arm, "
              "built outside this code (the paper publishes no frequencies)")
    return 0


# --- flexarm run ----------------------------------------------------------------------
_RUN_FLAGS = {"plant": "plant.kind", "controller": "controller.kind", "arm": "arm",
              "observer": "observer.kind", "duration": "duration", "seed": "seed", "Ts": "Ts",
              "feedback": "feedback", "initial_state": "initial_state", "name": "name"}
#: Metrics that measure the computer, not the run (left out when a rerun is compared).
_WALL_CLOCK = {"wall_s", "startup_s", "realtime_factor"}


def stored_run(spec: str, flag: str):
    """The stored run ``RESULTS/RUN``: RESULTS is the leading part of the path that holds
    a results index; RUN is a run id (or a unique prefix of one, at least 4 characters)
    or a run name (in full, or its part after the campaign's "/")."""
    from .batch.store import INDEX_NAME
    parts = Path(spec).parts
    for k in range(len(parts) - 1, 0, -1):
        if (Path(*parts[:k]) / INDEX_NAME).is_file():
            folder, selector = Path(*parts[:k]), "/".join(parts[k:])
            break
    else:
        raise ConfigError(flag, f"{spec}: expected RESULTS/RUN (a results folder holding "
                                f"{INDEX_NAME}, then a run id or name)")
    rows = ResultStore(folder).rows()
    found = [r for r in rows if r.run_id == selector] or \
        [r for r in rows if len(selector) >= 4 and r.run_id.startswith(selector)] or \
        [r for r in rows if r.name == selector] or \
        [r for r in rows if r.name.split("/")[-1] == selector]
    if not found:
        names = sorted({r.name for r in rows})
        raise ConfigError(flag, f"{folder} has no run {selector!r} (names: "
                                f"{', '.join(names[:12])}{', ...' if len(names) > 12 else ''})")
    if len(found) > 1:
        from .report.figures import describe_run
        choices = "; ".join(f"{r.run_id} ({r.plant} plant, {describe_run(r.config)})"
                            for r in found[:12])
        raise ConfigError(flag, f"{len(found)} runs of {folder} are named {selector!r}; give "
                                f"one's id: {choices}{'; ...' if len(found) > 12 else ''}")
    return found[0]


def auto_name(s: Scenario) -> str:
    """A run's name from what it is: controller (+ observer) @ plant, e.g.
    "pbc+smo-paper@exudyn" (a plug-in by its class name)."""
    law = lambda kind: kind.rsplit(":", 1)[-1]  # noqa: E731
    observer = "" if s.observer.kind == "none" else "+" + law(s.observer.kind)
    return f"{law(s.controller.kind)}{observer}@{s.plant.kind}"


def scenario_from_args(args: argparse.Namespace) -> tuple[Scenario, list[str]]:
    """The scenario of ``flexarm run`` and what to tell the user about where it came from."""
    from .batch.campaign import load_study
    notes, like = [], getattr(args, "like", None)
    if like and args.config:
        raise ConfigError("--like", "--like and --config exclude each other")
    if like:
        row = stored_run(like, "--like")
        data = copy.deepcopy(row.config)
    elif args.config:
        study = load_study(args.config)
        data = deep_merge({}, study.base)
        if len(study.sweeps) == 1 and set(study.sweeps[0]) == {"name"}:
            data["name"] = study.sweeps[0]["name"]  # a scenario file's own name
        elif study.sweeps:
            notes.append(f"{args.config} is a campaign: running its [scenario] base (its "
                         f"{len(study.sweeps)} sweep(s) are not run: flexarm campaign "
                         f"{args.config})")
    else:
        data = {}
    named = "name" in data or args.name is not None
    sets = {item.partition("=")[0].strip() for item in args.set or []}
    if args.duration is not None and "transient" not in sets and "transient" in data and \
            data["transient"] == default_transient(data.get("duration", Scenario.duration)):
        del data["transient"]  # it was the default for the old duration: follow the new one
    for attr, key in _RUN_FLAGS.items():
        value = getattr(args, attr)
        if value is not None:
            set_dotted(data, key, value)
    for item in args.set or []:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", f"expected KEY=VALUE, got {item!r}")
        set_dotted(data, key.strip(), parse_value(text.strip(), key.strip()))
        named = named or key.strip() == "name"
    scenario = scenario_from_mapping(data)
    if not named:
        scenario = dataclasses.replace(scenario, name=auto_name(scenario))
    if like:
        from .batch.fingerprint import run_fingerprint
        from .run.scenario import scenario_to_mapping
        old, new = flatten(row.config), flatten(scenario_to_mapping(scenario))
        changed = [f"{k} = {new.get(k)!r} (was {old.get(k)!r})" for k in sorted(old | new)
                   if old.get(k) != new.get(k)]
        head = f"rerunning {row.run_id} ({row.name}, stored in {row.store.out})"
        notes.append(head + (" exactly" if not changed else
                             f" with {len(changed)} change(s): " + "; ".join(changed)))
        if row.fingerprint != run_fingerprint(row.config):
            notes.append("  it was stored by other code (its fingerprint differs): the "
                         "numbers may differ")
        args.like_row = None if changed else row
    return scenario, notes


def open_output(out: str | Path) -> ResultStore:
    """Create (or open) a results folder; one line naming it if that is impossible."""
    store = ResultStore(out)
    try:
        store.prepare()
    except StoreError as exc:
        raise StoreError(f"--out {exc}") from None
    probe = store.out / ".write-test"
    try:
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise StoreError(f"--out {out}: not writable ({exc.strerror or exc})") from None
    return store


_TABLE = [("status", "status", "{}"),
          ("track_max_1", "max |θ1 − θ1d| [mrad]", "{:.4g}", 1e3),
          ("track_max_2", "max |θ2 − θ2d| [mrad]", "{:.4g}", 1e3),
          ("track_rms_1", "RMS θ1 − θ1d [mrad]", "{:.3g}", 1e3),
          ("track_rms_2", "RMS θ2 − θ2d [mrad]", "{:.3g}", 1e3),
          ("tip_err_max", "max payload error vs the rigid arm [mm]", "{:.3g}", 1e3),
          ("defl_max_1", "max tip deflection, link 1 [mm]", "{:.3g}", 1e3),
          ("defl_max_2", "max tip deflection, link 2 [mm]", "{:.3g}", 1e3),
          ("vib_rms_1", "vibration RMS, link 1 [mm]", "{:.3g}", 1e3),
          ("vib_rms_2", "vibration RMS, link 2 [mm]", "{:.3g}", 1e3),
          ("tau_max_1", "max |τ1| [N m]", "{:.3g}"), ("tau_max_2", "max |τ2| [N m]", "{:.3g}"),
          ("tau_tv_1", "τ1 variation [N m/s]", "{:.3g}"),
          ("tau_tv_2", "τ2 variation [N m/s]", "{:.3g}"),
          ("wall_s", "wall time [s]", "{:.3g}"), ("realtime_factor", "real-time factor", "{:.3g}")]


def format_metrics(metrics: dict) -> str:
    lines = []
    if "transient_s" in metrics and "end_time" in metrics:
        lines.append(f"  metrics after the {metrics['transient_s']:g} s transient, over "
                     f"{metrics['transient_s']:g}–{metrics['end_time']:g} s (maxima of "
                     "deflection and torque, torque variation: the whole run)")
    for key, label, fmt, *scale in _TABLE:
        value = metrics.get(key)
        if value is None or (isinstance(value, float) and math.isnan(value)):
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
            lines.append(f"  {'requirement ' + key.removeprefix('rho_') + ': rho':<44} "
                         f"{value:.6g} ({verdict})")
    return "\n".join(lines)


def _compare_with_stored(stored, metrics: dict) -> str:
    """One line: does a rerun reproduce the stored run's metrics?"""
    keys = [k for k, v in stored.metrics.items() if k not in _WALL_CLOCK | set(stored.timings)
            and isinstance(v, float)]
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
    from .batch.campaign import check_run_name
    from .run.scenario import scenario_to_mapping
    scenario, notes = scenario_from_args(args)
    check_run_name(scenario.name, "name")
    for note in notes:
        print(note)
    data = scenario_to_mapping(scenario)
    rid = run_id(data)
    check_runner(run_timeout=args.run_timeout, memory_limit=args.memory_limit)
    store = open_output(args.out or Path("results") / f"run-{rid}")  # bad --out: nothing ran
    with make_runner("local", 1, run_timeout=args.run_timeout, memory_limit=args.memory_limit,
                     scenarios=[scenario], progress=sys.stderr) as runner:  # a worker process
        (_, result, metrics), = runner.results([(rid, scenario)])
    path = store.add(rid, result, metrics)
    store.export()
    s = scenario
    obs = "" if s.observer.kind == "none" else f" + {s.observer.kind}"
    print(f"{s.name}: {s.controller.kind}{obs} on the {s.plant.kind} plant, {s.arm} arm, "
          f"{s.duration:g} s at Ts = {s.Ts:g} s, from {s.initial_state}")
    if result.message:
        print(f"  {result.status}: {result.message}")
    print(format_metrics(metrics))
    if getattr(args, "like_row", None) is not None and result.status == "ok":
        print(_compare_with_stored(args.like_row, metrics))
    print(f"results: {path} (index and metrics.csv in {store.out}); figures: "
          f"flexarm show {store.out}/{rid}")
    return 0 if result.status != "failed" else EXIT_FAILED


def _run_defaults(d: Scenario) -> str:
    """The epilog of ``flexarm run --help``: the defaults no flag shows."""
    sensors = d.sensors
    noise = "none" if not (sensors.encoder_noise or sensors.modal_noise or sensors.rate_noise) \
        else f"{sensors.encoder_noise:g} rad, {sensors.modal_noise:g} m, {sensors.rate_noise:g} rad/s"
    return f"""\
defaults of a plain run (no --config, no --like):
  reference            eq. (37): theta_d = 2 sin(0.1 pi t), 2 sin(0.2 pi t) rad
  plant                {d.plant.kind}, {d.plant.modes_per_link[0]}+{d.plant.modes_per_link[1]} modes, internal step {d.plant.step:g} s
  sensors              angles and q read directly, rates measured; noise: {noise};
                       no quantisation, no delay
  observer start       exact (initial_error: none)
  disturbances         none; torque limit: none
  transient            {DEFAULT_TRANSIENT:g} s, or half of a run shorter than {2 * DEFAULT_TRANSIENT:g} s
                       (metrics are taken after it; the output states the window)

The shipped campaigns add sensor noise and an observer that starts off the true
state (campaigns/base.toml), so a plain run does not give their numbers.  To run
like them:  flexarm run --config campaigns/base.toml --observer smo-paper
Rerun a stored run:  flexarm run --like results/paper/RUN_ID  (--set KEY=VALUE to change it)
"""


# --- campaigns ----------------------------------------------------------------------------
def _runner(args, scenarios, *folders: Path):
    """The runner of a command's runs: its options checked, then the results ``folders``
    created or opened (bad input writes nothing), then, for local workers, the kernels the
    runs of ``scenarios`` use compiled here with progress on stderr (workers fork with
    them)."""
    executor = getattr(args, "executor", "local")
    options = dict(force=args.force_workers, run_timeout=args.run_timeout,
                   memory_limit=args.memory_limit)
    check_runner(executor, args.workers, getattr(args, "scheduler", None), **options)
    for folder in folders:
        open_output(folder)
    return make_runner(executor, args.workers, getattr(args, "scheduler", None), **options,
                       scenarios=list(scenarios) or None, progress=sys.stderr)


def _finish(summary, name: str, out) -> int:
    print(summary.line(name, out))
    if summary.interrupted:
        print(f"flexarm: interrupted ({summary.done} finished runs kept): rerun the same "
              "command to resume", file=sys.stderr)
        return exit_status(summary.interrupted)
    return EXIT_FAILED if summary.any_failed else 0


def cmd_campaign(args: argparse.Namespace) -> int:
    from .batch.campaign import classify, expand, load_campaign, run_campaign
    campaign = load_campaign(args.file)
    runs = expand(campaign)  # every scenario checked before anything runs
    out = Path(args.out or Path("results") / campaign.name)
    if args.dry_run:
        store = ResultStore(out)
        todo = classify(runs, store, retry_failed=args.retry_failed,
                        reuse_stale=args.reuse_stale)[0] if store.exists() else runs
        todo_ids = {r.run_id for r in todo}
        for r in runs:
            axes = ", ".join(f"{k}={v}" for k, v in r.axes.items())
            mark = "run " if r.run_id in todo_ids else "done"
            print(f"{mark} {r.run_id}  {r.sweep:<16} {axes}")
        print(f"{len(runs)} runs planned: {len(todo)} to run, {len(runs) - len(todo)} already "
              f"stored in {out}")
        return 0
    runner = _runner(args, [r.scenario for r in runs], out)
    with runner:
        summary = run_campaign(campaign, out, runner=runner, retry_failed=args.retry_failed,
                               reuse_stale=args.reuse_stale, progress=not args.no_progress,
                               only=runs)
        if args.mesh_check and not summary.interrupted:
            status = _mesh_checks(runner, out, {r.run_id for r in runs},
                                  progress=not args.no_progress)
            if status:
                return status
    return _finish(summary, campaign.name, out)


def _mesh_checks(runner, out: Path, run_ids: set, *, progress: bool) -> int:
    """Run the mesh checks of the truth-plant runs ``run_ids`` stored in ``out``; a
    non-zero exit status if interrupted or a check failed."""
    from .verdicts.mesh import MESH_SWEEP, run_checks
    rows = [r for r in ResultStore(out).rows() if r.run_id in run_ids]
    summary = run_checks(rows, out, runner=runner, progress=progress)
    if summary.planned:
        print(summary.line(MESH_SWEEP, out))
    if summary.interrupted:
        return _finish(summary, MESH_SWEEP, out)
    return EXIT_FAILED if summary.any_failed else 0


def _write_report(results, *, animate: bool, progress: bool, force: bool = False) -> str:
    """Render the report of ``results`` unless it is current; the line to print."""
    from .report.report import report_is_current, write_report
    if not force and report_is_current(results, animate=animate):
        html_path = Path(results) / "report" / "report.html"
        return f"report: {html_path} is up to date (same runs, same code): not rendered again"
    html_path, md_path = write_report(results, animate=animate, progress=progress, force=True)
    return f"report: {html_path} (self-contained) and {md_path}"


def cmd_report(args: argparse.Namespace) -> int:
    print(_write_report(args.results, animate=not args.no_animation,
                        progress=not args.no_progress, force=args.force))
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from .report.show import open_in_browser, show_run
    row = stored_run(args.run, "RESULTS/RUN")
    if row.status != "ok":
        print(f"{row.run_id} ({row.name}) {row.status}: {row.message}; a run that did not "
              "complete is not drawn", file=sys.stderr)
        return EXIT_FAILED
    page, files, note = show_run(row)
    if note:
        print(note)
    for f in files:
        print(f"  {f}")
    print(f"figures of {row.run_id} ({row.name}): {page}")
    if not args.no_open and open_in_browser(page):
        print("opened in the browser")
    return 0


def campaigns_dir() -> Path:
    """The shipped campaigns/ folder of this checkout."""
    here = Path(__file__).resolve().parent.parent / "campaigns"
    if not (here / "paper.toml").exists():
        raise ValueError(f"shipped campaigns not found in {here}; run from the repository "
                         "(pip install -e .)")
    return here


def cmd_reproduce_paper(args: argparse.Namespace) -> int:
    from .batch.campaign import expand, load_campaign, run_campaign
    from .report.verdict_tables import write_claims
    campaign = load_campaign(campaigns_dir() / "paper.toml")
    runs = expand(campaign)
    out = Path(args.out or Path("results") / "paper")
    scenarios = [r.scenario for r in runs]
    runner = _runner(args, scenarios, out, *([] if args.no_stability else [out / "stability"]))
    with runner:
        summary = run_campaign(campaign, out, runner=runner, progress=not args.no_progress,
                               only=runs)
        if summary.interrupted:
            return _finish(summary, campaign.name, out)
        print(summary.line(campaign.name, out))
        checks = _mesh_checks(runner, out, {r.run_id for r in runs},
                              progress=not args.no_progress)
        if checks and checks != EXIT_FAILED:
            return checks
        stability = 0
        if not args.no_stability:
            stability = _stability(runner, [r.scenario for r in runs if not
                                            r.scenario.disturbances], out / "stability",
                                   progress=not args.no_progress)
            if stability not in (0, EXIT_FAILED):  # interrupted
                return stability
    print()
    print(write_claims(out))
    print(f"claims: {out / 'claims.md'} and claims.csv")
    if not args.no_report:
        print(_write_report(out, animate=not args.no_animation, progress=not args.no_progress))
    return EXIT_FAILED if summary.any_failed or checks or stability else 0


def _stability(runner, scenarios, out: Path, *, progress: bool, plants=None, arms=None) -> int:
    """Run the stability map into ``out`` (opened by the caller) and print it; the exit
    status: 130/143 if it was interrupted, 1 if some of its runs failed (a failure is no
    verdict on stability: the map is incomplete there)."""
    from .report.verdict_tables import write_stability
    from .verdicts.stability import cases_from_scenarios, stability_map
    cases = cases_from_scenarios(scenarios, plants=plants, arms=arms)
    results, summary = stability_map(cases, out, runner=runner, progress=progress)
    if summary.interrupted:
        return _finish(summary, "stability", out)
    print(write_stability(results, out))
    print(f"stability map: {out / 'stability.md'} and stability.csv")
    failed = [f"{r.case.label} ({r.case.plant}, {r.case.arm}) at {1e3 * Ts:.3g} ms"
              for r in results for Ts in r.failed]
    if failed or summary.any_failed:
        print(f"flexarm: {len(failed)} stability run(s) failed — no verdict on stability "
              f"there: {'; '.join(failed) or 'mesh-check runs'}", file=sys.stderr)
        return EXIT_FAILED
    return 0


def _stability_scenarios(args: argparse.Namespace) -> tuple[list, list | None, list | None]:
    """(scenarios, plants, arms) of `flexarm stability`/`validity FILE`: a single scenario
    on both plants and both arms (unless --plant/--arm), or every run of a campaign."""
    from .batch.campaign import expand, load_study
    scenarios = [r.scenario for r in expand(load_study(args.file))]
    if len(scenarios) == 1:
        return scenarios, args.plant or list(PLANTS), args.arm or list(ARMS)
    return scenarios, args.plant, args.arm


def cmd_stability(args: argparse.Namespace) -> int:
    from .verdicts.stability import cases_from_scenarios
    scenarios, plants, arms = _stability_scenarios(args)
    out = Path(args.out or Path("results") / f"stability-{Path(args.file).stem}")
    cases = cases_from_scenarios(scenarios, plants=plants, arms=arms)  # what will run
    runner = _runner(args, [scenario_from_mapping(c.base) for c in cases], out)
    with runner:
        return _stability(runner, scenarios, out, progress=not args.no_progress,
                          plants=plants, arms=arms)


def _stability_folder(args, out: Path) -> Path | None:
    """The stability map whose measurements `flexarm validity` joins: --stability, else
    OUT/stability, else OUT itself if it holds one, else none."""
    if args.stability:
        store = ResultStore(args.stability)
        if not store.exists():
            raise StoreError(f"--stability {args.stability}: not a results folder "
                             "(no index.sqlite)")
        return store.out
    for folder in (out / "stability", out):
        if ResultStore(folder).exists() and ResultStore(folder).rows(where="sweep = 'stability'"):
            return folder
    return None


def cmd_validity(args: argparse.Namespace) -> int:
    from .verdicts.stability import cases_from_scenarios
    from .report.verdict_tables import write_validity
    from .verdicts.validity import validity_analysis
    scenarios, plants, arms = _stability_scenarios(args)
    cases = cases_from_scenarios(scenarios, plants=plants, arms=arms)
    out = Path(args.out or Path("results") / f"validity-{Path(args.file).stem}")
    stability = _stability_folder(args, out)
    folder = out / "validity"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise StoreError(f"--out {out}: cannot write ({exc.strerror or exc})") from None

    def progress(row):
        if not args.no_progress:
            print(f"  {row['case']} · {row['plant']} · {row['arm']}: predicted "
                  f"{1e3 * row['predicted_s']:.4g} ms, certified {1e3 * row['certified_s']:.3g} ms "
                  f"({row['seconds']:.1f} s)", flush=True)
    print(f"linear validity of {len(cases)} cases"
          + (f", measured map: {stability}" if stability else ", no measured stability map"))
    data = validity_analysis(cases, stability_dir=stability, progress=progress)
    print(write_validity(data, folder))
    print(f"validity: {folder / 'validity.md'}, validity.csv, nugap.csv, validity.json, figures/")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    store = ResultStore(args.results)
    csv_path, json_path = store.export()
    print(f"exported {len(store.rows())} runs: {csv_path if args.format == 'csv' else json_path}")
    return 0


def cmd_repair(args: argparse.Namespace) -> int:
    store = ResultStore(args.results)
    if not store.runs_dir.is_dir():
        raise StoreError(f"{args.results}: no runs/ folder (not a results folder)")
    if not store.writable():
        raise StoreError(f"{args.results}: read-only; repair rewrites the index")
    report = store.repair()
    store.remove_stale_temporaries(older_than=0.0)
    store.export(allow_fewer=True)  # what repair dropped is listed below
    for action, ids in report.items():
        print(f"{action}: {len(ids)}" + (f" ({', '.join(ids)})" if ids else ""))
    print(f"{store.out}: {len(store.rows())} runs indexed")
    return 0


def cmd_attribute(args: argparse.Namespace) -> int:
    from .batch.campaign import expand, load_study
    from .report.verdict_tables import write_attribution
    from .verdicts.attribution import attribute, default_factors, parse_factors
    study = load_study(args.file)
    systems = [(r.scenario.name.split("/")[-1], r.scenario) for r in expand(study)]
    default_out = Path("results") / (study.name if study.sweeps or study.attribution
                                     else f"attribution-{study.name}")
    names = [n.strip() for n in args.factors.split(",") if n.strip()] \
        if args.factors is not None else study.attribution.get("factors")
    if names is not None and not isinstance(names, list):
        raise ConfigError("attribution.factors", "must be a list of factor names")
    plans = [(label, s, parse_factors(names, s) if names is not None else default_factors(s))
             for label, s in systems]
    from .verdicts.attribution import plan
    for label, s, factors in plans:  # every world checked before anything runs
        plan(s, factors, label)
    out = Path(args.out or default_out)
    results = []
    runner = _runner(args, [s for _, s, _ in plans], out)
    with runner:
        for label, s, factors in plans:
            att, summary = attribute(s, factors, out, name=label, runner=runner,
                                     progress=not args.no_progress)
            print(summary.line(f"attribution {label}", out))
            if summary.interrupted:
                return _finish(summary, label, out)
            results.append(att)
        if args.mesh_check:
            status = _mesh_checks(runner, out, {r.run_id for r in ResultStore(out).rows()},
                                  progress=not args.no_progress)
            if status:
                return status
    print(write_attribution(results, out))
    print(f"attribution: {out / 'attribution.csv'} and attribution.md; "
          f"'flexarm report {out}' draws the waterfalls")
    return 0


# --- flexarm verify --------------------------------------------------------------------------
def cmd_verify(args: argparse.Namespace) -> int:
    from .verdicts.uncertainty import load_systems
    from .verdicts.verify import conform, estimate, falsify
    systems = load_systems(args.file)
    if args.system is not None:
        names = [s.name for s in systems]
        if args.system not in names:
            raise ConfigError("--system", f"no system {args.system!r} in {args.file} "
                                          f"(systems: {', '.join(names)})")
        systems = [s for s in systems if s.name == args.system]
    # The requirement of each system, checked before anything runs (estimate reports every
    # requirement; its headline is the named one or the first).
    requirements = [s.requirement(args.requirement) if args.mode == "falsify" or args.requirement
                    else s.requirements[0] for s in systems]
    default = Path("results") / f"verify-{Path(args.file).stem}-{args.mode}"
    out = Path(args.out or default)
    folders = {s.name: out if len(systems) == 1 else out / s.name for s in systems}
    # The kernels of every system's laws, on both plants, before the workers fork.
    runner = _runner(args, [s.scenario({}, plant=plant) for s in systems
                            for plant in ("reduced", "exudyn")], *folders.values())
    failed = False
    # A signal between two batches of a search (not only during one) stops it: exit 143.
    with runner, signals_interrupt():
        for system, requirement in zip(systems, requirements):
            where = folders[system.name]
            print(f"{system.name}: {args.mode} over {', '.join(system.uncertainty.describe())}")
            if args.mode == "estimate":
                v = estimate(system, requirement, where, runner=runner, samples=args.samples,
                             seed=args.seed)
                for r in v["requirements"].values():
                    print(f"  {r['requirement']}: {r['n'] - r['failures']}/{r['n']} hold, "
                          f"P(holds) in [{r['p_low']:.3f}, {r['p_high']:.3f}] at "
                          f"{r['level']:g} (Clopper-Pearson); sequential test: "
                          f"{r['sequential']['decision']}")
            elif args.mode == "falsify":
                v = falsify(system, requirement, where, runner=runner, budget=args.budget,
                            seed=args.seed)
                what = "counterexample" if v["found"] else "no counterexample; worst case"
                truth = (f"{v['rho_truth']:.6g}" if v["rho_truth"] is not None else
                         f"-inf ({v.get('truth_status', 'no run')})")
                reduced = (f"{v['rho_reduced']:.6g}" if v["rho_reduced"] is not None
                           else "-inf (diverged)")
                print(f"  {requirement.name}: {what}: rho truth {truth}, reduced {reduced} "
                      f"({v['counterexample'] or v['worst_case']}); simulations "
                      f"{v['simulations']}")
            else:
                v = conform(system, where, runner=runner, budget=args.budget, seed=args.seed)
                print(f"  largest |theta_truth - theta_reduced| = {v['distance']} rad "
                      f"({v['scenario']}); simulations {v['simulations']}")
            failed |= bool(v["failed_runs"])
            print(f"  verdict: {where / 'verdict.json'}")
    return EXIT_FAILED if failed else 0


# --- flexarm baseline -----------------------------------------------------------------------
def _baseline_rows(args) -> tuple:
    from .verdicts.baselines import evaluate, load_baselines
    if args.only is not None and not args.only.strip():
        raise ConfigError("--only", "must be a non-empty pattern")
    baselines = load_baselines(args.file)
    rows = evaluate(baselines, out=args.out or Path("results") / "baselines", tier=args.tier,
                    only=args.only, campaign=args.campaign,
                    results=getattr(args, "results", None))
    if not rows:
        tiers = sorted({c.tier for c in baselines.checks
                        if not args.campaign or c.campaign == args.campaign})
        raise ValueError(f"no check matches the selection (--tier {args.tier}"
                         + (f", --campaign {args.campaign}" if args.campaign else "")
                         + (f", --only {args.only}" if args.only else "")
                         + f"); matching tiers: {', '.join(tiers) or 'none'}")
    return baselines, rows


def _print_checks(rows, extra=None) -> None:
    print(f"  {'check':<40} {'metric':<28} {'bound':>12} {'value':>12}  status")
    for i, row in enumerate(rows):
        c = row["check"]
        metric = c.metric[0] if len(c.metric) == 1 else f"max({', '.join(c.metric)})"
        if len(metric) > 28:
            metric = metric[:25] + "..."
        status = "ok" if row["ok"] else "FAIL"
        print(f"  {c.name:<40} {metric:<28} {c.op}{c.bound:>10.4g} {row['value']:>12.4g}  "
              f"{status}{extra[i] if extra else ''}")


def cmd_baseline_check(args: argparse.Namespace) -> int:
    _, rows = _baseline_rows(args)
    _print_checks(rows)
    failed = [r for r in rows if not r["ok"]]
    for r in failed:
        c = r["check"]
        print(f"FAIL {c.name}: {'/'.join(c.metric)} = {r['value']:.6g}, bound {c.op} {c.bound:.6g}"
              f" (measured {c.measured} when set); result: {r['path'] or 'no simulation'}",
              file=sys.stderr)
    print(f"{len(rows) - len(failed)} of {len(rows)} checks hold")
    return EXIT_FAILED if failed else 0


def cmd_baseline_update(args: argparse.Namespace) -> int:
    from .verdicts.baselines import proposed_bounds, write_baselines
    baselines, rows = _baseline_rows(args)
    proposals = proposed_bounds(rows, baselines)
    notes, loosened, changed = [], [], {}
    for r in rows:
        p = proposals.get(r["check"].name)
        if p is None:
            notes.append("  (not measurable: the run did not complete)")
            continue
        notes.append(f"  -> {r['check'].op}{p['bound']:.4g}" + ("  LOOSER" if p["looser"] else
                                                                 "" if p["changed"] else "  (same)"))
        if p["looser"]:
            loosened.append(r["check"].name)
        if p["changed"]:
            changed[r["check"].name] = p
    _print_checks(rows, notes)
    if loosened and not args.allow_loosen:
        print(f"refusing to loosen {len(loosened)} bound(s): {', '.join(loosened)} "
              "(pass --allow-loosen if that is intended)", file=sys.stderr)
        return EXIT_FAILED
    if not changed:
        print(f"no change: every bound in {baselines.path} already matches the policy")
        return 0
    checks = [dataclasses.replace(c, bound=changed[c.name]["bound"],
                                  measured=changed[c.name]["measured"])
              if c.name in changed else c for c in baselines.checks]
    write_baselines(baselines, checks)
    print(f"updated {len(changed)} bound(s) in {baselines.path}")
    return 0


# --- the parser ---------------------------------------------------------------------------------
def _add_limits(p) -> None:
    p.add_argument("--run-timeout", type=_positive, default=None, metavar="SECONDS",
                   help="wall-time limit of each run; a run without a result by then is "
                        "stopped and recorded as failed (default: derived from each run's "
                        "duration and plant, far beyond what a healthy run takes)")
    p.add_argument("--memory-limit", type=_int_in(1, 1 << 40), default=None, metavar="MIB",
                   help="memory limit of each worker process, MiB (default: three quarters "
                        "of the machine's memory shared among the workers)")


def _add_execution(p, *, dask: bool = True) -> None:
    p.add_argument("--workers", type=_int_in(1, 4096), default=None, metavar="N",
                   help=f"parallel runs (default: the {available_cores()} cores; 1 = one "
                        "worker process)")
    _add_limits(p)
    p.add_argument("--force-workers", action="store_true",
                   help="allow more workers than cores")
    if dask:
        p.add_argument("--executor", choices=("local", "dask"), default="local",
                       help="local processes (default) or a Dask cluster")
        p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="Dask scheduler (with --executor dask; default "
                            "$DASK_SCHEDULER_ADDRESS)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    from plant_exudyn import ELEMENTS
    parser = _Parser(prog="flexarm", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version",
                        version=f"flexarm-validation {version('flexarm-validation')}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    modes = sub.add_parser("modes", help="natural frequencies of the reduced model (and FE)")
    modes.add_argument("--params", metavar="TOML",
                       help="arm parameters (top-level keys or a [params] table)")
    modes.add_argument("--table1", action="store_true",
                       help="the paper's Table 1 exactly (no stator inertia, no damping)")
    modes.add_argument("--modes-per-link", nargs=2, type=int, default=[2, 2],
                       metavar=("N1", "N2"), help="assumed modes of link 1 and 2 (1..4)")
    modes.add_argument("--theta2", nargs="+", type=_finite, default=[0.0], metavar="RAD",
                       help="joint-2 angles at which to linearise (default 0)")
    modes.add_argument("--compare", action="store_true",
                       help="also print the Exudyn FE model's frequencies and the gap")
    modes.add_argument("--element", choices=ELEMENTS, default="ancf",
                       help="FE beam element for --compare (default ancf)")
    modes.add_argument("--elements", type=_int_in(1, 64), default=4, metavar="N",
                       help="FE elements per link for --compare (default 4)")
    modes.set_defaults(func=cmd_modes)

    d = Scenario()
    run = sub.add_parser("run", help="simulate one closed-loop scenario",
                         formatter_class=argparse.RawDescriptionHelpFormatter,
                         description="Simulate one closed-loop scenario and store it.",
                         epilog=_run_defaults(d))
    run.add_argument("--config", metavar="TOML",
                     help="scenario file, or a campaign file (its [scenario] base); flags "
                          "override it")
    run.add_argument("--like", metavar="RESULTS/RUN",
                     help="rerun a stored run exactly (RUN: its id or name), with the flags "
                          "and --set as changes")
    run.add_argument("--arm", choices=tuple(ARMS), help=f"default arm or the paper's table1 "
                                                        f"(default: {d.arm})")
    run.add_argument("--plant", choices=PLANTS, help=f"reduced model or Exudyn truth plant "
                                                     f"(default: {d.plant.kind})")
    run.add_argument("--controller", metavar="KIND",
                     help=f"{', '.join(CONTROLLERS)} or package.module:Class "
                          f"(default: {d.controller.kind})")
    run.add_argument("--observer", metavar="KIND",
                     help=f"none, {', '.join(OBSERVERS)} or package.module:Class "
                          f"(default: {d.observer.kind})")
    run.add_argument("--feedback", choices=("auto", "true", "estimate"),
                     help="state the controller sees (auto: the estimate if there is an "
                          f"observer; default: {d.feedback})")
    run.add_argument("--initial-state", dest="initial_state", choices=("rest", "reference"),
                     help="start at rest or moving with the reference "
                          f"(default: {d.initial_state})")
    run.add_argument("--duration", type=_positive, metavar="S",
                     help=f"simulated time [s] (default: {d.duration:g})")
    run.add_argument("--Ts", type=_positive, metavar="S",
                     help=f"control period [s] (default: {d.Ts:g})")
    run.add_argument("--seed", type=_int_in(0, 2**63 - 1),
                     help=f"noise seed (default: {d.seed})")
    run.add_argument("--name", help="a label for the run (default: controller+observer@plant, "
                                    "e.g. pbc+smo-paper@reduced)")
    run.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="any scenario field by dotted key, value in TOML syntax, e.g. "
                          "--set true_params.Mp=0.5 --set sensors.encoder_noise=1e-4")
    run.add_argument("--out", metavar="DIR", help="results folder (default: results/run-<id>)")
    _add_limits(run)
    run.set_defaults(func=cmd_run)

    show = sub.add_parser("show", help="the paper's Figs. 3-8 for one stored run")
    show.add_argument("run", metavar="RESULTS/RUN",
                      help="a results folder, then a run id or name")
    show.add_argument("--no-open", action="store_true",
                      help="do not open the figures in a browser (never opened without a "
                           "display)")
    show.set_defaults(func=cmd_show)

    camp = sub.add_parser("campaign", help="run a campaign of scenarios (resumable)")
    camp.add_argument("file", metavar="CAMPAIGN.toml")
    camp.add_argument("--out", metavar="DIR", help="results folder (default results/NAME)")
    _add_execution(camp)
    camp.add_argument("--retry-failed", action="store_true", help="redo runs that failed")
    camp.add_argument("--reuse-stale", action="store_true",
                      help="keep stored runs made by other code instead of rerunning them")
    camp.add_argument("--dry-run", action="store_true",
                      help="list the runs and which are already stored; run nothing")
    camp.add_argument("--mesh-check", action="store_true",
                      help="also run every truth-plant run on the check meshes (closed-loop "
                           "mesh convergence; the report and claims need it for a verdict)")
    camp.set_defaults(func=cmd_campaign)

    rep = sub.add_parser("report", help="write report.html and report.md of a results folder")
    rep.add_argument("results", metavar="RESULTS_DIR")
    rep.add_argument("--no-animation", action="store_true", help="skip the GIF")
    rep.add_argument("--no-progress", action="store_true", help="no progress bar")
    rep.add_argument("--force", action="store_true",
                     help="render even if the report is up to date (same runs, same code)")
    rep.set_defaults(func=cmd_report)

    paper = sub.add_parser("reproduce-paper",
                           help="run campaigns/paper.toml, the stability map, the claims "
                                "table and the report")
    paper.add_argument("--out", metavar="DIR", help="results folder (default results/paper)")
    _add_execution(paper, dask=False)
    paper.add_argument("--no-stability", action="store_true", help="skip the stability map")
    paper.add_argument("--no-report", action="store_true", help="skip the report")
    paper.add_argument("--no-animation", action="store_true", help="skip the GIF")
    paper.set_defaults(func=cmd_reproduce_paper)

    stab = sub.add_parser("stability", help="largest stable control period per controller, "
                                            "plant and arm")
    stab.add_argument("file", metavar="SCENARIO_OR_CAMPAIGN.toml")
    stab.add_argument("--out", metavar="DIR",
                      help="results folder (default results/stability-<file name>)")
    stab.add_argument("--plant", action="append", choices=PLANTS,
                      help="plant(s) to test (default: both for a scenario, the campaign's own)")
    stab.add_argument("--arm", action="append", choices=tuple(ARMS),
                      help="arm(s) to test (default: both for a scenario, the campaign's own)")
    _add_execution(stab)
    stab.set_defaults(func=cmd_stability)

    val = sub.add_parser("validity", help="is the reduced model good enough for control: "
                                          "frequency responses, ν-gap, predicted and "
                                          "certified stable control periods")
    val.add_argument("file", metavar="SCENARIO_OR_CAMPAIGN.toml")
    val.add_argument("--out", metavar="DIR",
                     help="results folder; writes DIR/validity (default "
                          "results/validity-<file name>)")
    val.add_argument("--stability", metavar="DIR",
                     help="stability map to compare with (default: DIR/stability or DIR)")
    val.add_argument("--plant", action="append", choices=PLANTS,
                     help="plant(s) (default: both for a scenario, the campaign's own)")
    val.add_argument("--arm", action="append", choices=tuple(ARMS),
                     help="arm(s) (default: both for a scenario, the campaign's own)")
    val.add_argument("--no-progress", action="store_true", help="no line per case")
    val.set_defaults(func=cmd_validity)

    exp = sub.add_parser("export", help="write metrics.csv and manifest.json from the index")
    exp.add_argument("results", metavar="RESULTS_DIR")
    exp.add_argument("--format", choices=("csv", "json"), default="csv",
                     help="the file to name in the output (both are written)")
    exp.set_defaults(func=cmd_export)

    rep = sub.add_parser("repair", help="rebuild a results folder's index from its run files")
    rep.add_argument("results", metavar="RESULTS_DIR")
    rep.set_defaults(func=cmd_repair)

    att = sub.add_parser("attribute", help="which modelling assumption costs how much "
                                           "(Shapley attribution over 2^k runs)")
    att.add_argument("file", metavar="SCENARIO_OR_CAMPAIGN.toml",
                     help="the real world (a campaign: one attribution per run, factors from "
                          "its [attribution] table)")
    att.add_argument("--factors", metavar="F1,F2,...",
                     help="plant, truncation, parameters, sensing, estimation, sampling, "
                          "actuation (default: every factor the scenario has)")
    att.add_argument("--out", metavar="DIR", help="results folder")
    att.add_argument("--mesh-check", action="store_true",
                     help="also run every truth-plant world on the check meshes (closed-loop "
                          "mesh convergence, shown by the report)")
    _add_execution(att)
    att.set_defaults(func=cmd_attribute)

    ver = sub.add_parser("verify", help="verdicts over uncertainty: P(holds), the worst case "
                                        "(falsification on both plants), where the reduced "
                                        "model stops being valid")
    ver.add_argument("file", metavar="FILE", help="a scenario or campaign file with [uncertainty] "
                                                  "and [[requirement]]")
    ver.add_argument("--mode", required=True, choices=("estimate", "falsify", "conform"),
                     help="estimate: P(holds) over seeded draws; falsify: the truth-confirmed "
                          "minimum of rho; conform: the largest disagreement of the two plants")
    ver.add_argument("--requirement", metavar="NAME",
                     help="the requirement (default: the only one; estimate reports all)")
    ver.add_argument("--system", metavar="NAME",
                     help="one system of a campaign file (default: each, into OUT/NAME)")
    ver.add_argument("--samples", type=_int_in(1, 100_000), default=59, metavar="N",
                     help="estimate: draws at most (default 59: no failure certifies P >= 0.95 "
                          "at 95 %% one-sided)")
    ver.add_argument("--budget", type=_int_in(1, 100_000), default=50, metavar="N",
                     help="falsify, conform: truth-plant simulations at most (default 50)")
    ver.add_argument("--seed", type=_int_in(0, 2**63 - 1), default=0, metavar="N",
                     help="seed of the draws and of the search (default 0)")
    ver.add_argument("--out", metavar="DIR",
                     help="results folder (default results/verify-<file>-<mode>)")
    _add_execution(ver)
    ver.set_defaults(func=cmd_verify)

    base = sub.add_parser("baseline", help="error-bound regression checks (baselines.toml)")
    bsub = base.add_subparsers(dest="action", required=True, parser_class=_Parser)
    from .verdicts.baselines import DEFAULT_FILE
    for action, helptext in (("check", "measure and compare with the bounds"),
                             ("update", "re-measure and rewrite the bounds")):
        b = bsub.add_parser(action, help=helptext)
        b.add_argument("--file", default=str(DEFAULT_FILE), metavar="TOML",
                       help="the checks (default: the repository's baselines.toml)")
        b.add_argument("--tier", choices=("short", "full", "all"), default=None,
                       help="short: <= 5 s scenarios (make test); full: the 20 s campaign "
                            "runs (default: short, or full with --campaign)")
        b.add_argument("--only", metavar="GLOB", help="checks whose name matches")
        b.add_argument("--campaign", metavar="NAME", help="checks on runs of this campaign")
        b.add_argument("--out", metavar="DIR", help="where runs are stored "
                                                    "(default results/baselines)")
        b.add_argument("--results", metavar="DIR",
                       help="reuse verified runs of this results folder (made by this code)")
        if action == "check":
            b.set_defaults(func=cmd_baseline_check)
        else:
            b.add_argument("--allow-loosen", action="store_true",
                           help="accept bounds looser than the stored ones")
            b.set_defaults(func=cmd_baseline_update)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        with signals_interrupt():  # SIGINT/SIGTERM raise Interrupted from here on
            args = build_parser().parse_args(argv)
            if getattr(args, "tier", "") is None:
                args.tier = "full" if args.campaign else "short"
            # Plug-ins named "package.module:Class" are found like `python -m` finds
            # modules: the current directory first (spawned workers inherit this path;
            # commands that only read results locate plug-in files for the code
            # fingerprint on the same path, without importing them).
            if os.getcwd() not in sys.path:
                sys.path.insert(0, os.getcwd())
            return _command(args)
    except Interrupted as exc:
        print("flexarm: interrupted", file=sys.stderr)
        return exit_status(exc.signum)


def _command(args: argparse.Namespace) -> int:
    """Run the command: every error one line on stderr, and its exit status."""
    try:
        return args.func(args)
    except (ValueError, StoreError) as exc:  # ConfigError, StoreError: bad input
        return _error(exc, EXIT_USAGE)
    except RecursionError:  # a structure the checks did not bound
        return _error("input nested too deeply", EXIT_USAGE)
    except SystemExit as exc:  # flexarm's own code never exits from inside a command
        return _error(f"sys.exit({exc.code!r}) was called by code this command ran "
                      "(a plug-in's?); stopped", EXIT_FAILED)
    except KeyboardInterrupt:  # a Ctrl-C raises Interrupted: this one was raised by code
        return _error("KeyboardInterrupt raised by code this command ran (a plug-in's?), "
                      "not by a Ctrl-C; stopped", EXIT_FAILED)
    except sqlite3.Error as exc:  # the store turns its own into StoreError: a last resort
        where = getattr(args, "out", None) or getattr(args, "results", None) or "the index"
        return _error(f"{where}: the index cannot be used ({exc})", EXIT_FAILED)
    except OSError as exc:
        where = exc.filename or getattr(args, "out", None) or getattr(args, "results", None) \
            or "the results folder"
        reason = "no space left on the device" if exc.errno == errno.ENOSPC else \
            (exc.strerror or str(exc))
        return _error(f"{where}: {reason}", EXIT_FAILED)


def _error(message, status: int) -> int:
    print(f"flexarm: error: {message}", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
