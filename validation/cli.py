"""The ``flexarm`` command line: a thin layer over the library.

Bad input ends with one line on stderr and exit status 2, before anything is written;
a run or campaign with failed runs exits 1; SIGINT/SIGTERM exit 130/143 after keeping
what finished; a full disk is one line naming the folder, exit 1.  Never a traceback.
"""
from __future__ import annotations

import os

from .batch.threads import prefer_one_thread

prefer_one_thread()  # before numpy is imported; a user's setting wins

import argparse  # noqa: E402
import dataclasses
import errno
import math
import sys
from importlib.metadata import version
from pathlib import Path

import numpy as np

from controllers import CONTROLLERS, OBSERVERS

from .run._config import ConfigError
from .batch.executor import (Interrupted, available_cores, exit_status, make_runner,
                             signals_interrupt)
from .run.scenario import ARMS, PLANTS, Scenario, scenario_from_mapping
from .batch.store import ResultStore, StoreError, run_id
from .run.tomlfiles import deep_merge, load_toml, parse_value, set_dotted

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
                print(row(f"{'':<10}gap [%]", 100 * (reduced - fe) / fe))
    if mesh:
        print(f"FE: {mesh.element}, {mesh.elements_per_link[0]}+{mesh.elements_per_link[1]} "
              "elements; gap = (reduced - FE) / FE")
    return 0


# --- flexarm run ----------------------------------------------------------------------
_RUN_FLAGS = {"plant": "plant.kind", "controller": "controller.kind", "arm": "arm",
              "observer": "observer.kind", "duration": "duration", "seed": "seed", "Ts": "Ts",
              "feedback": "feedback", "initial_state": "initial_state", "name": "name"}


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    data = {}
    if args.config:
        from .batch.campaign import load_study
        study = load_study(args.config)
        data = deep_merge({}, study.base)
        if study.sweeps and any(set(s) - {"name"} for s in study.sweeps):
            print(f"{args.config} is a campaign: run simulates its [scenario] base (use "
                  "'flexarm campaign' for its sweeps)", file=sys.stderr)
    for attr, key in _RUN_FLAGS.items():
        value = getattr(args, attr)
        if value is not None:
            set_dotted(data, key, value)
    for item in args.set or []:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", f"expected KEY=VALUE, got {item!r}")
        set_dotted(data, key.strip(), parse_value(text.strip()))
    return scenario_from_mapping(data)


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


_TABLE = [("status", "status", "{}"), ("track_max_1", "max |e1| after transient [rad]", "{:.4g}"),
          ("track_max_2", "max |e2| after transient [rad]", "{:.4g}"),
          ("track_rms_1", "rms e1 [rad]", "{:.3g}"), ("track_rms_2", "rms e2 [rad]", "{:.3g}"),
          ("tip_err_max", "max tip error vs rigid [m]", "{:.3g}"),
          ("defl_max_1", "max tip deflection 1 [m]", "{:.3g}"),
          ("defl_max_2", "max tip deflection 2 [m]", "{:.3g}"),
          ("vib_rms_1", "vibration rms 1 after transient [m]", "{:.3g}"),
          ("vib_rms_2", "vibration rms 2 after transient [m]", "{:.3g}"),
          ("tau_max_1", "max |tau1| [N m]", "{:.3g}"), ("tau_max_2", "max |tau2| [N m]", "{:.3g}"),
          ("tau_tv_1", "tau1 variation [N m/s]", "{:.3g}"),
          ("tau_tv_2", "tau2 variation [N m/s]", "{:.3g}"),
          ("wall_s", "wall time [s]", "{:.3g}"), ("realtime_factor", "real-time factor", "{:.3g}")]


def format_metrics(metrics: dict) -> str:
    lines = [f"  {label:<44} {fmt.format(metrics[key])}" for key, label, fmt in _TABLE
             if key in metrics and not (isinstance(metrics[key], float) and math.isnan(metrics[key]))]
    ratios = {k.removeprefix("est_to_noise_"): v for k, v in metrics.items()
              if k.startswith("est_to_noise_") and isinstance(v, float) and math.isfinite(v)}
    if ratios:
        worst = max(ratios, key=ratios.get)
        lines.append(f"  {'estimate / measurement error, worst':<44} {ratios[worst]:.3g} ({worst})")
    if metrics.get("est_worse"):
        lines.append(f"  {'estimate worse than the measurement':<44} {metrics['est_worse']}")
    for key, value in metrics.items():  # the requirements' robustness (rho >= 0 holds)
        if key.startswith("rho_") and isinstance(value, float) and not math.isnan(value):
            verdict = "holds" if value >= 0 else "fails"
            lines.append(f"  {'requirement ' + key.removeprefix('rho_') + ': rho':<44} "
                         f"{value:.6g} ({verdict})")
    return "\n".join(lines)


def cmd_run(args: argparse.Namespace) -> int:
    from .batch.worker import compile_kernels, execute_run
    from .run.scenario import scenario_to_mapping
    scenario = scenario_from_args(args)
    data = scenario_to_mapping(scenario)
    rid = run_id(data)
    store = open_output(args.out or Path("results") / f"run-{rid}")
    compile_kernels([scenario], report=lambda line: print(line, file=sys.stderr, flush=True))
    result, metrics = execute_run(scenario)
    path = store.add(rid, result, metrics)
    store.export()
    s = scenario
    obs = "" if s.observer.kind == "none" else f" + {s.observer.kind}"
    print(f"{s.name}: {s.controller.kind}{obs} on the {s.plant.kind} plant, {s.arm} arm, "
          f"{s.duration:g} s at Ts = {s.Ts:g} s, from {s.initial_state}")
    if result.message:
        print(f"  {result.status}: {result.message}")
    print(format_metrics(metrics))
    print(f"results: {path} (index and metrics.csv in {store.out})")
    return 0 if result.status != "failed" else EXIT_FAILED


# --- campaigns ----------------------------------------------------------------------------
def _runner(args):
    return make_runner(args.executor, args.workers, args.scheduler,
                       force=getattr(args, "force_workers", False))


def _finish(summary, name: str, out) -> int:
    print(summary.line(name, out))
    if summary.interrupted:
        print(f"interrupted ({summary.done} finished runs kept): rerun the same command to "
              "resume", file=sys.stderr)
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
    runner = _runner(args)
    with runner:
        open_output(out)
        summary = run_campaign(campaign, out, runner=runner, retry_failed=args.retry_failed,
                               reuse_stale=args.reuse_stale, progress=not args.no_progress,
                               only=runs)
    return _finish(summary, campaign.name, out)


def cmd_report(args: argparse.Namespace) -> int:
    from .report.report import write_report
    html_path, md_path = write_report(args.results, animate=not args.no_animation,
                                      progress=not args.no_progress)
    print(f"report: {html_path} (self-contained) and {md_path}")
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
    from .verdicts.claims import write_claims
    campaign = load_campaign(campaigns_dir() / "paper.toml")
    runs = expand(campaign)
    out = Path(args.out or Path("results") / "paper")
    runner = make_runner("local", args.workers, force=args.force_workers)
    with runner:
        open_output(out)
        summary = run_campaign(campaign, out, runner=runner, progress=not args.no_progress,
                               only=runs)
        if summary.interrupted:
            return _finish(summary, campaign.name, out)
        print(summary.line(campaign.name, out))
        if not args.no_stability:
            stability = _stability(runner, [r.scenario for r in runs if not
                                            r.scenario.disturbances], out / "stability",
                                   progress=not args.no_progress)
            if stability:
                return stability
    print()
    print(write_claims(out))
    print(f"claims: {out / 'claims.md'} and claims.csv")
    if not args.no_report:
        from .report.report import write_report
        html_path, _ = write_report(out, animate=not args.no_animation,
                                    progress=not args.no_progress)
        print(f"report: {html_path}")
    return EXIT_FAILED if summary.any_failed else 0


def _stability(runner, scenarios, out: Path, *, progress: bool, plants=None, arms=None) -> int:
    """Run the stability map into ``out`` and print it; a non-zero exit status if it was
    interrupted."""
    from .verdicts.stability import cases_from_scenarios, stability_map, write_stability
    cases = cases_from_scenarios(scenarios, plants=plants, arms=arms)
    open_output(out)
    results, summary = stability_map(cases, out, runner=runner, progress=progress)
    if summary.interrupted:
        return _finish(summary, "stability", out)
    print(write_stability(results, out))
    print(f"stability map: {out / 'stability.md'} and stability.csv")
    return 0


def cmd_stability(args: argparse.Namespace) -> int:
    from .batch.campaign import expand, load_study
    study = load_study(args.file)
    scenarios = [r.scenario for r in expand(study)]
    if len(scenarios) == 1:  # one scenario: its laws on both plants and both arms
        plants, arms = args.plant or list(PLANTS), args.arm or list(ARMS)
    else:
        plants, arms = args.plant, args.arm
    out = Path(args.out or Path("results") / f"stability-{Path(args.file).stem}")
    runner = _runner(args)
    with runner:
        return _stability(runner, scenarios, out, progress=not args.no_progress,
                          plants=plants, arms=arms)


def cmd_export(args: argparse.Namespace) -> int:
    store = ResultStore(args.results)
    csv_path, json_path = store.export()
    print(f"exported {len(store.rows())} runs: {csv_path if args.format == 'csv' else json_path}")
    return 0


def cmd_repair(args: argparse.Namespace) -> int:
    store = ResultStore(args.results)
    if not store.runs_dir.is_dir():
        raise StoreError(f"{args.results}: no runs/ folder (not a results folder)")
    report = store.repair()
    store.remove_stale_temporaries(older_than=0.0)
    store.export()
    for action, ids in report.items():
        print(f"{action}: {len(ids)}" + (f" ({', '.join(ids)})" if ids else ""))
    print(f"{store.out}: {len(store.rows())} runs indexed")
    return 0


def cmd_attribute(args: argparse.Namespace) -> int:
    from .batch.campaign import expand, load_study
    from .verdicts.attribution import attribute, default_factors, parse_factors, write_attribution
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
    runner = _runner(args)
    with runner:
        open_output(out)
        for label, s, factors in plans:
            att, summary = attribute(s, factors, out, name=label, runner=runner,
                                     progress=not args.no_progress)
            print(summary.line(f"attribution {label}", out))
            if summary.interrupted:
                return _finish(summary, label, out)
            results.append(att)
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
    runner = _runner(args)
    failed = False
    # A signal between two batches of a search (not only during one) stops it: exit 143.
    with runner, signals_interrupt():
        for system, requirement in zip(systems, requirements):
            where = out if len(systems) == 1 else out / system.name
            open_output(where)
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
def _add_execution(p, *, dask: bool = True) -> None:
    p.add_argument("--workers", type=_int_in(1, 4096), default=None, metavar="N",
                   help=f"parallel runs (default: the {available_cores()} cores; 1 = serial, "
                        "in this process)")
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

    run = sub.add_parser("run", help="simulate one closed-loop scenario")
    run.add_argument("--config", metavar="TOML", help="scenario file (flags override it)")
    run.add_argument("--arm", choices=tuple(ARMS), help="default arm or the paper's table1")
    run.add_argument("--plant", choices=PLANTS, help="reduced model or Exudyn truth plant")
    run.add_argument("--controller", metavar="KIND",
                     help=f"{', '.join(CONTROLLERS)} or package.module:Class")
    run.add_argument("--observer", metavar="KIND",
                     help=f"none, {', '.join(OBSERVERS)} or package.module:Class")
    run.add_argument("--feedback", choices=("auto", "true", "estimate"),
                     help="state the controller sees (auto: the estimate if there is an observer)")
    run.add_argument("--initial-state", dest="initial_state", choices=("rest", "reference"),
                     help="start at rest or moving with the reference")
    run.add_argument("--duration", type=_positive, metavar="S", help="simulated time [s]")
    run.add_argument("--Ts", type=_positive, metavar="S", help="control period [s]")
    run.add_argument("--seed", type=_int_in(0, 2**63 - 1), help="noise seed")
    run.add_argument("--name", help="a label for the run (default paper)")
    run.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="any scenario field by dotted key, value in TOML syntax, e.g. "
                          "--set true_params.Mp=0.5 --set plant.mesh.elements_per_link=[8,8]")
    run.add_argument("--out", metavar="DIR", help="results folder (default results/run-<id>)")
    run.set_defaults(func=cmd_run)

    camp = sub.add_parser("campaign", help="run a campaign of scenarios (resumable)")
    camp.add_argument("file", metavar="CAMPAIGN.toml")
    camp.add_argument("--out", metavar="DIR", help="results folder (default results/NAME)")
    _add_execution(camp)
    camp.add_argument("--retry-failed", action="store_true", help="redo runs that failed")
    camp.add_argument("--reuse-stale", action="store_true",
                      help="keep stored runs made by other code instead of rerunning them")
    camp.add_argument("--dry-run", action="store_true",
                      help="list the runs and which are already stored; run nothing")
    camp.set_defaults(func=cmd_campaign)

    rep = sub.add_parser("report", help="write report.html and report.md of a results folder")
    rep.add_argument("results", metavar="RESULTS_DIR")
    rep.add_argument("--no-animation", action="store_true", help="skip the GIF")
    rep.add_argument("--no-progress", action="store_true", help="no progress bar")
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
    args = build_parser().parse_args(argv)
    if getattr(args, "tier", "") is None:
        args.tier = "full" if args.campaign else "short"
    # Plug-ins named "package.module:Class" are found like `python -m` finds modules: the
    # current directory first (spawned workers inherit this path).
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        return args.func(args)
    except (ValueError, StoreError) as exc:  # ConfigError, StoreError: bad input
        print(f"flexarm: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except Interrupted as exc:
        print("flexarm: interrupted", file=sys.stderr)
        return exit_status(exc.signum)
    except OSError as exc:
        where = exc.filename or getattr(args, "out", None) or "the results folder"
        reason = "no space left on the device" if exc.errno == errno.ENOSPC else \
            (exc.strerror or str(exc))
        print(f"flexarm: error: {where}: {reason}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
