"""The ``flexarm`` command line: a thin layer over the library.

Errors in user input end with one line on stderr and exit status 2, never a traceback.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from importlib.metadata import version
from pathlib import Path

import numpy as np

from plant_exudyn import ELEMENTS, Mesh, natural_frequencies
from reduced_model import ArmModel, ArmParameters, validate_modes_per_link

from ._config import ConfigError
from .baselines import DEFAULT_FILE, evaluate, load_baselines, updated_bound, write_baselines
from .campaign import expand, load_campaign, make_executor, run_campaign
from .claims import write_claims
from .report import write_report
from .loop import run_scenario
from .metrics import all_metrics
from .scenario import CONTROLLERS, OBSERVERS, PLANTS, Scenario, scenario_from_mapping
from .store import ResultStore, run_id
from .tomlfiles import load_toml, parse_value, set_dotted

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


def _format_row(label: str, values) -> str:
    return f"  {label:<30}" + "".join(f"{v:>11.4f}" for v in values)


def cmd_modes(args: argparse.Namespace) -> int:
    if args.params and args.table1:
        raise ValueError("--params and --table1 exclude each other")
    if args.table1:
        params, source = ArmParameters.table1(), "the paper's Table 1 (no stator, no damping)"
    elif args.params:
        data = load_toml(args.params)
        if set(data) == {"params"} and isinstance(data["params"], dict):
            data = data["params"]
        params = ArmParameters.from_mapping(data, where=f"{args.params}:params")
        source = args.params
    else:
        params, source = ArmParameters(), "defaults (Table 1 + stator inertia + damping)"
    model = ArmModel(params, validate_modes_per_link(args.modes_per_link, where="--modes-per-link"))
    mesh = Mesh(element=args.element, elements_per_link=args.elements) if args.compare else None
    n1, n2 = model.modes_per_link
    print(f"Reduced model, {n1}+{n2} clamped-mass modes, parameters: {source}")
    print("Clamped-mass link frequencies [Hz]")
    for i, modes in enumerate(model.mode_shapes, start=1):
        print(_format_row(f"link {i}", modes.frequencies_hz))
    for theta2 in args.theta2:
        Q = np.zeros(model.n)
        Q[1] = theta2
        print(f"Coupled frequencies at theta1 = 0, theta2 = {theta2:g} rad [Hz]")
        for joints in ("locked", "free"):
            reduced = model.natural_frequencies(Q, joints)
            label = "joints locked" if joints == "locked" else "joints free (non-zero)"
            print(_format_row(label + (" reduced" if mesh else ""), reduced))
            if mesh:
                fe = natural_frequencies(params, mesh, theta=(0.0, theta2), joints=joints,
                                         n=len(reduced))
                print(_format_row(f"{'':<14}FE", fe))
                print(_format_row(f"{'':<10}gap [%]", 100 * (reduced - fe) / fe))
    if mesh:
        print(f"FE: {mesh.element}, {mesh.elements_per_link[0]}+{mesh.elements_per_link[1]} "
              "elements; gap = (reduced - FE) / FE")
    return 0


# --- flexarm run ----------------------------------------------------------------------
_RUN_FLAGS = {"plant": "plant.kind", "controller": "controller.kind",
              "observer": "observer.kind", "duration": "duration", "seed": "seed", "Ts": "Ts",
              "feedback": "feedback", "initial_state": "initial_state", "name": "name"}


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    data = load_toml(args.config) if args.config else {}
    for attr, key in _RUN_FLAGS.items():
        value = getattr(args, attr)
        if value is not None:
            set_dotted(data, key, value)
    if args.idealised:
        set_dotted(data, "controller.pbc.idealised", True)
    for item in args.set or []:
        key, sep, text = item.partition("=")
        if not sep or not key:
            raise ConfigError("--set", f"expected KEY=VALUE, got {item!r}")
        set_dotted(data, key.strip(), parse_value(text.strip()))
    return scenario_from_mapping(data)


def prepare_output(out: str | Path) -> ResultStore:
    store = ResultStore(out)
    try:
        store.prepare()
        probe = store.out / ".write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ValueError(f"--out {out}: not writable ({exc.strerror or exc})") from None
    return store


_TABLE = [("status", "status", "{}"), ("track_max_1", "max |e1| after transient [rad]", "{:.4g}"),
          ("track_max_2", "max |e2| after transient [rad]", "{:.4g}"),
          ("track_rms_1", "rms e1 [rad]", "{:.3g}"), ("track_rms_2", "rms e2 [rad]", "{:.3g}"),
          ("tip_err_max", "max tip error vs rigid [m]", "{:.3g}"),
          ("defl_max_1", "max tip deflection 1 [m]", "{:.3g}"),
          ("defl_max_2", "max tip deflection 2 [m]", "{:.3g}"),
          ("tau_max_1", "max |tau1| [N m]", "{:.3g}"), ("tau_max_2", "max |tau2| [N m]", "{:.3g}"),
          ("tau_tv_1", "tau1 variation [N m/s]", "{:.3g}"),
          ("tau_tv_2", "tau2 variation [N m/s]", "{:.3g}"),
          ("wall_s", "wall time [s]", "{:.3g}"), ("realtime_factor", "real-time factor", "{:.3g}")]


def format_metrics(metrics: dict) -> str:
    lines = [f"  {label:<44} {fmt.format(metrics[key])}" for key, label, fmt in _TABLE
             if key in metrics and not (isinstance(metrics[key], float) and math.isnan(metrics[key]))]
    est = {k: v for k, v in metrics.items() if k.startswith("est_max_")}
    if est:
        for kind, label in (("theta", "positions θ [rad]"), ("q", "modal q [m]"),
                            ("theta_dot", "rates θ̇ [rad/s]"), ("q_dot", "modal rates q̇ [m/s]")):
            vals = [v for k, v in est.items() if _state_kind(k.removeprefix("est_max_")) == kind]
            if vals:
                lines.append(f"  {'max estimation error, ' + label:<44} {max(vals):.3g}")
    return "\n".join(lines)


def _state_kind(state: str) -> str:
    return ("theta" if state.startswith("theta") else "q") + ("_dot" if state.endswith("_dot") else "")


def cmd_run(args: argparse.Namespace) -> int:
    scenario = scenario_from_args(args)
    store = prepare_output(args.out or Path("results") / scenario.name)
    result = run_scenario(scenario)
    metrics = all_metrics(result)
    rid = run_id(result.config)
    path = store.add(rid, result, metrics)
    s = scenario
    print(f"{s.name}: plant {s.plant.kind}, controller {s.controller.kind}"
          f"{' (idealised)' if s.controller.pbc.idealised and s.controller.kind == 'pbc' else ''},"
          f" observer {s.observer.kind}, {s.duration:g} s at Ts = {s.Ts:g} s")
    if result.message:
        print(f"  stopped: {result.message}")
    print(format_metrics(metrics))
    print(f"results: {path} (metrics.csv, manifest.json in {store.out})")
    return 0 if result.status != "failed" else EXIT_FAILED


# --- flexarm campaign --------------------------------------------------------------------
EXIT_INTERRUPTED = 130


def cmd_campaign(args: argparse.Namespace) -> int:
    campaign = load_campaign(args.file)
    runs = expand(campaign)  # every scenario checked before anything runs
    out = Path(args.out or Path("results") / campaign.name)
    if args.dry_run:
        for r in runs:
            axes = ", ".join(f"{k}={v}" for k, v in r.axes.items())
            print(f"{r.run_id}  {r.sweep:<16} {axes}")
        print(f"{len(runs)} runs would be written to {out}")
        return 0
    prepare_output(out)
    executor, close = make_executor(args.executor, args.workers, args.scheduler)
    try:
        summary = run_campaign(campaign, out, executor=executor, retry_failed=args.retry_failed,
                               progress=not args.no_progress, only=runs)
    finally:
        close()
    print(f"{campaign.name}: {summary.planned} runs planned, {summary.skipped} already done, "
          f"{summary.ok} ok, {summary.diverged} diverged, {summary.failed} failed -> {out}")
    if summary.interrupted:
        print(f"interrupted: rerun the same command to resume ({summary.done} runs stored)",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    return EXIT_FAILED if summary.failed else 0


# --- flexarm report / reproduce-paper ----------------------------------------------------
def cmd_report(args: argparse.Namespace) -> int:
    html_path, md_path = write_report(args.results, animate=not args.no_animation)
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
    campaign = load_campaign(campaigns_dir() / "paper.toml")
    runs = expand(campaign)
    out = Path(args.out or Path("results") / "paper")
    prepare_output(out)
    executor, close = make_executor("local", args.workers)
    try:
        summary = run_campaign(campaign, out, executor=executor, progress=not args.no_progress,
                               only=runs)
    finally:
        close()
    if summary.interrupted:
        print("interrupted: rerun the same command to resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    table = write_claims(out)
    print(f"paper: {summary.planned} runs ({summary.skipped} already done), {summary.ok} ok, "
          f"{summary.diverged} diverged, {summary.failed} failed\n")
    print(table)
    print(f"\nclaims: {out / 'claims.md'}")
    if not args.no_report:
        html_path, _ = write_report(out, animate=not args.no_animation)
        print(f"report: {html_path}")
    return EXIT_FAILED if summary.failed else 0


# --- flexarm baseline -----------------------------------------------------------------------
def _baseline_rows(args) -> tuple:
    baselines = load_baselines(args.file)
    rows = evaluate(baselines, out=args.out or Path("results") / "baselines", tier=args.tier,
                    only=args.only, campaign=args.campaign,
                    results=getattr(args, "results", None))
    if not rows:
        raise ValueError("no check matches the selection (--tier/--only/--campaign)")
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
    baselines, rows = _baseline_rows(args)
    new = {r["check"].name: (r["value"], updated_bound(r["check"], r["value"], baselines))
           for r in rows if math.isfinite(r["value"])}
    loosened, notes = [], []
    for r in rows:
        c = r["check"]
        if c.name not in new:
            notes.append("  (not measurable: run did not complete)")
            continue
        value, bound = new[c.name]
        looser = bound > c.bound if c.op == "<=" else bound < c.bound
        if looser:
            loosened.append(c.name)
        notes.append(f"  -> {c.op}{bound:.4g}{'  LOOSER' if looser else ''}")
    _print_checks(rows, notes)
    if loosened and not args.allow_loosen:
        print(f"refusing to loosen {len(loosened)} bound(s): {', '.join(loosened)} "
              "(pass --allow-loosen if that is intended)", file=sys.stderr)
        return EXIT_FAILED
    checks = [dataclasses.replace(c, bound=float(f"{new[c.name][1]:.4g}"),
                                  measured=float(f"{new[c.name][0]:.4g}"))
              if c.name in new else c for c in baselines.checks]
    write_baselines(baselines, checks)
    print(f"updated {len(new)} bound(s) in {baselines.path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="flexarm", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version",
                        version=f"flexarm-validation {version('flexarm-validation')}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    modes = sub.add_parser("modes", help="natural frequencies of the reduced model")
    modes.add_argument("--params", metavar="TOML",
                       help="arm parameters (top-level keys or a [params] table)")
    modes.add_argument("--table1", action="store_true",
                       help="the paper's Table 1 exactly (no stator inertia, no damping)")
    modes.add_argument("--modes-per-link", nargs=2, type=int, default=[2, 2],
                       metavar=("N1", "N2"), help="assumed modes of link 1 and 2 (1..4)")
    modes.add_argument("--theta2", nargs="+", type=float, default=[0.0], metavar="RAD",
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
    run.add_argument("--plant", choices=PLANTS)
    run.add_argument("--controller", choices=CONTROLLERS)
    run.add_argument("--observer", choices=OBSERVERS)
    run.add_argument("--idealised", action="store_true",
                     help="PBC applies all n components of eq. 20 (reduced plant only)")
    run.add_argument("--feedback", choices=("auto", "true", "estimate"))
    run.add_argument("--initial-state", dest="initial_state", choices=("rest", "reference"))
    run.add_argument("--duration", type=float, metavar="S")
    run.add_argument("--Ts", type=float, metavar="S", help="control period")
    run.add_argument("--seed", type=int)
    run.add_argument("--name")
    run.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="any scenario field by dotted key, value in TOML syntax, e.g. "
                          "--set true_params.Mp=0.5 --set plant.mesh.elements_per_link=[8,8]")
    run.add_argument("--out", metavar="DIR", help="results folder (default results/NAME)")
    run.set_defaults(func=cmd_run)

    camp = sub.add_parser("campaign", help="run a campaign of scenarios (resumable)")
    camp.add_argument("file", metavar="CAMPAIGN.toml")
    camp.add_argument("--out", metavar="DIR", help="results folder (default results/NAME)")
    camp.add_argument("--workers", type=_int_in(1, 1024), default=None, metavar="N",
                      help="parallel runs (default: the number of cores; 1 = serial)")
    camp.add_argument("--executor", choices=("local", "dask"), default="local")
    camp.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                      help="Dask scheduler (default $DASK_SCHEDULER_ADDRESS)")
    camp.add_argument("--retry-failed", action="store_true", help="redo runs that failed")
    camp.add_argument("--no-progress", action="store_true", help="no progress bar")
    camp.add_argument("--dry-run", action="store_true", help="list the runs, run nothing")
    camp.set_defaults(func=cmd_campaign)

    rep = sub.add_parser("report", help="write report.html and report.md of a results folder")
    rep.add_argument("results", metavar="RESULTS_DIR")
    rep.add_argument("--no-animation", action="store_true", help="skip the GIF")
    rep.set_defaults(func=cmd_report)

    paper = sub.add_parser("reproduce-paper",
                           help="run campaigns/paper.toml, write the claims table and report")
    paper.add_argument("--out", metavar="DIR", help="results folder (default results/paper)")
    paper.add_argument("--workers", type=_int_in(1, 1024), default=None, metavar="N")
    paper.add_argument("--no-progress", action="store_true")
    paper.add_argument("--no-report", action="store_true")
    paper.add_argument("--no-animation", action="store_true")
    paper.set_defaults(func=cmd_reproduce_paper)

    base = sub.add_parser("baseline", help="error-bound regression checks (baselines.toml)")
    bsub = base.add_subparsers(dest="action", required=True, parser_class=_Parser)
    for action, helptext in (("check", "measure and compare with the bounds"),
                             ("update", "re-measure and rewrite the bounds")):
        b = bsub.add_parser(action, help=helptext)
        b.add_argument("--file", default=str(DEFAULT_FILE), metavar="TOML")
        b.add_argument("--tier", choices=("short", "full", "all"), default="short",
                       help="short: <= 5 s scenarios (make test); full: the 20 s campaign runs")
        b.add_argument("--only", metavar="GLOB", help="checks whose name matches")
        b.add_argument("--campaign", metavar="NAME", help="checks on runs of this campaign")
        b.add_argument("--out", metavar="DIR", help="where runs are stored "
                                                    "(default results/baselines)")
        if action == "check":
            b.add_argument("--results", metavar="DIR",
                           help="reuse completed runs of this results folder")
            b.set_defaults(func=cmd_baseline_check)
        else:
            b.add_argument("--allow-loosen", action="store_true")
            b.set_defaults(func=cmd_baseline_update)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as exc:
        print(f"flexarm: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
