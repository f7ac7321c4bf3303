"""The arguments of every ``flexarm`` command, with their defaults."""
from __future__ import annotations

import argparse
import math
from importlib.metadata import version

from controllers import CONTROLLERS, OBSERVERS
from reduced_model import named_arms

from ..batch.executor import available_cores
from ..run.config import did_you_mean, fraction_hint
from ..run.scenario import DEFAULT_TRANSIENT, PLANT_KINDS, Scenario

from .calibrate import cmd_calibrate
from .campaigns import cmd_campaign, cmd_reproduce_paper
from .common import EXIT_USAGE
from .export_fmu import cmd_export_fmu
from .modes import cmd_arms, cmd_modes
from .one_run import cmd_run, cmd_show
from .results import cmd_export, cmd_repair, cmd_report
from .verdicts import (cmd_attribute, cmd_baseline_add, cmd_baseline_check,
                       cmd_baseline_update, cmd_stability, cmd_validity, cmd_verify)

class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, status 2 (argparse's own convention)
        self.exit(EXIT_USAGE, f"flexarm: error: {message}\n")

    def parse_args(self, args=None, namespace=None):
        """argparse's, with the closest flag suggested for each unknown one (`did_you_mean`
        over the flags of the command given)."""
        namespace, extras = self.parse_known_args(args, namespace)
        if extras:
            flags = list(_chosen(self, namespace)._option_string_actions)
            self.error("unrecognized arguments: " + " ".join(extras) + "".join(
                did_you_mean(e.partition("=")[0], flags) for e in extras if e.startswith("-")))
        return namespace

    def _check_value(self, action, value):
        """argparse's, with the closest choice suggested (`did_you_mean`)."""
        if action.choices is not None and value not in action.choices:
            hint = did_you_mean(value, action.choices, quote=True)
            raise argparse.ArgumentError(action, f"invalid choice: {value!r} (choose from "
                                                 f"{', '.join(map(repr, action.choices))})"
                                                 f"{hint}")


def _chosen(parser: argparse.ArgumentParser, namespace) -> argparse.ArgumentParser:
    """The (sub)parser of the command ``namespace`` was parsed for."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and getattr(namespace, action.dest,
                                                                       None) in action.choices:
            return _chosen(action.choices[getattr(namespace, action.dest)], namespace)
    return parser


def _fraction(text: str) -> float:
    """argparse type: a number; a percentage ("5%") is told to give its fraction."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}"
                                         f"{fraction_hint(text)}") from None


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


def _run_defaults(d: Scenario) -> str:
    """The epilog of ``flexarm run --help``: the defaults no flag shows."""
    sensors = d.sensors
    noise = "none" if not (sensors.encoder_noise or sensors.modal_noise or sensors.rate_noise) \
        else f"{sensors.encoder_noise:g} rad, {sensors.modal_noise:g} m, {sensors.rate_noise:g} rad/s"
    return f"""\
defaults of a plain run (no --config, no --like):
  reference            eq. (37): theta_d = 2 sin(0.1 pi t), 2 sin(0.2 pi t) rad
  arm                  {d.arm} (the paper's two flexible links, horizontal)
  plant                {d.plant.kind}, the arm's modes per link, internal step {d.plant.step:g} s
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


def _add_limits(p) -> None:
    p.add_argument("--run-timeout", type=_positive, default=None, metavar="SECONDS",
                   help="wall-time limit of each run; a run without a result by then is "
                        "stopped and recorded as failed (default: derived from each run's "
                        "duration and plant, far beyond what a healthy run takes)")
    p.add_argument("--memory-limit", type=_int_in(1, 1 << 40), default=None, metavar="MIB",
                   help="memory limit of each worker process, MiB (default: three quarters "
                        "of the machine's memory shared among the workers)")


def _add_cases(p) -> None:
    """--plant and --arm of the commands that take a scenario or a campaign's cases."""
    p.add_argument("--plant", action="append", choices=PLANT_KINDS,
                   help="plant(s) (default: both for a scenario, the campaign's own)")
    p.add_argument("--arm", action="append", metavar="ARM",
                   help="arm(s): a shipped arm's name or an arm file .toml (default: default "
                        "and table1 for a scenario, the campaign's own)")


def _add_tolerance(p) -> None:
    """--tolerance of the commands that map stability limits."""
    p.add_argument("--tolerance", type=_fraction, metavar="REL",
                   help="relative width each stability limit is bisected to (default: the "
                        "file's [stability] tolerance, else 0.01 = 1 %%)")


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
    parser = _Parser(prog="flexarm", description="Validate controllers and observers of a flexible "
                     "arm (1-4 links, rigid or flexible, in a plane or in gravity) on its "
                     "reduced model and a flexible multibody truth plant.")
    parser.add_argument("--version", action="version",
                        version=f"flexarm-validation {version('flexarm-validation')}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    modes = sub.add_parser("modes", help="natural frequencies of the reduced model (and FE)")
    modes.add_argument("--arm", default="default", metavar="ARM",
                       help="a shipped arm (flexarm arms) or an arm file (default: default)")
    modes.add_argument("--params", metavar="TOML",
                       help="the arm's fields changed by flat key (top-level keys or a [params] "
                            "table)")
    modes.add_argument("--table1", action="store_true", help=argparse.SUPPRESS)
    modes.add_argument("--modes-per-link", nargs="+", type=int, metavar="N",
                       help="assumed modes per link, from the base out (1..4; 0 for a rigid "
                            "link; default: the arm's)")
    modes.add_argument("--theta2", nargs="+", type=_finite, default=[0.0], metavar="RAD",
                       help="joint-2 angles at which to linearise (default 0; the other joints "
                            "at 0)")
    modes.add_argument("--compare", action="store_true",
                       help="also print the Exudyn FE model's frequencies and the gap")
    modes.add_argument("--element", choices=ELEMENTS, default="ancf",
                       help="FE beam element for --compare (default ancf)")
    modes.add_argument("--elements", type=_int_in(1, 64), default=4, metavar="N",
                       help="FE elements per link for --compare (default 4)")
    modes.set_defaults(func=cmd_modes)

    arms = sub.add_parser("arms", help="the shipped arms, or one arm in full")
    arms.add_argument("arm", nargs="?", metavar="ARM", help="a shipped arm or an arm file")
    arms.set_defaults(func=cmd_arms)

    d = Scenario()
    run = sub.add_parser("run", help="simulate one closed-loop scenario",
                         formatter_class=argparse.RawDescriptionHelpFormatter,
                         description="Simulate one closed-loop scenario and store it.",
                         epilog=_run_defaults(d))
    run.add_argument("--config", metavar="TOML",
                     help="scenario file, or a campaign file (its [scenario] base); flags "
                          "override it")
    run.add_argument("--like", metavar="RESULTS/RUN",
                     help="rerun a stored run exactly (RUN: its id or name; a name shared "
                          "with mesh/step checks means the nominal run), with the flags and "
                          "--set as changes")
    run.add_argument("--arm", metavar="ARM",
                     help=f"a shipped arm ({', '.join(named_arms())}; `flexarm arms` "
                          f"describes them) or an arm file .toml (default: {d.arm})")
    run.add_argument("--plant", choices=PLANT_KINDS, help=f"reduced model or Exudyn truth plant "
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
    run.add_argument("--name", help="a label for the run, replacing its file's (default: "
                                    "controller+observer@plant, e.g. pbc+smo-paper@reduced)")
    run.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="any scenario field by dotted key, value in TOML syntax, e.g. "
                          "--set true_params.Mp=0.5 --set sensors.encoder_noise=1e-4")
    run.add_argument("--out", metavar="DIR", help="results folder (default: results/run-<id>)")
    run.add_argument("--mesh-check", action="store_true",
                     help="truth plant: also run the same loop on refined meshes and steps "
                          "and say whether its numbers converged")
    _add_limits(run)
    run.set_defaults(func=cmd_run)

    fmu = sub.add_parser("export-fmu", help="write a scenario's reduced plant and its laws as "
                                            "co-simulation FMUs (the fmi extra)")
    fmu.add_argument("--config", metavar="TOML", help="scenario file (default: the default "
                                                     "scenario); flags override it")
    fmu.add_argument("--arm", metavar="ARM", help="a shipped arm or an arm file .toml")
    fmu.add_argument("--controller", metavar="KIND", help="the law exported with --law-fmu")
    fmu.add_argument("--observer", metavar="KIND", help="its observer (none: the controller "
                                                        "reads the whole state)")
    fmu.add_argument("--Ts", type=_positive, metavar="S", help="control period [s]")
    fmu.add_argument("--set", action="append", metavar="KEY=VALUE",
                     help="any scenario field by dotted key, value in TOML syntax")
    fmu.add_argument("--plant-fmu", metavar="FILE.fmu",
                     help="write the reduced plant of the scenario's true arm here")
    fmu.add_argument("--law-fmu", metavar="FILE.fmu",
                     help="write the scenario's controller and observer here")
    fmu.set_defaults(func=cmd_export_fmu, like=None, plant=None, duration=None, seed=None,
                     feedback=None, initial_state=None, name=None)

    show = sub.add_parser("show", help="the paper's Figs. 3-8 for one stored run")
    show.add_argument("run", metavar="RESULTS/RUN",
                      help="a results folder, then a run id or name")
    show.add_argument("--no-open", action="store_true",
                      help="do not open the figures in a browser (never opened without a "
                           "display)")
    show.set_defaults(func=cmd_show, imports_no_plugin=True)

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
                      help="also run every truth-plant run on the check meshes and with a "
                           "finer step (closed-loop convergence; the report and claims need "
                           "it for a verdict)")
    camp.set_defaults(func=cmd_campaign)

    rep = sub.add_parser("report", help="write report.html and report.md of a results folder")
    rep.add_argument("results", metavar="RESULTS_DIR")
    rep.add_argument("--no-animation", action="store_true", help="skip the GIF")
    rep.add_argument("--no-progress", action="store_true", help="no progress bar")
    rep.add_argument("--force", action="store_true",
                     help="render even if the report is up to date (same runs, same code)")
    rep.set_defaults(func=cmd_report, imports_no_plugin=True)

    paper = sub.add_parser("reproduce-paper",
                           help="run campaigns/paper.toml, the stability map, the claims "
                                "table and the report")
    paper.add_argument("--lab", action="store_true",
                       help="the paper's claims on the lab arm (harmonic drives: friction, "
                            "drives, current loops; campaigns/lab.toml) instead of its two arms")
    paper.add_argument("--out", metavar="DIR",
                       help="results folder (default results/paper, with --lab results/lab)")
    _add_execution(paper, dask=False)
    paper.add_argument("--no-stability", action="store_true", help="skip the stability map")
    _add_tolerance(paper)
    paper.add_argument("--no-report", action="store_true", help="skip the report")
    paper.add_argument("--no-animation", action="store_true", help="skip the GIF")
    paper.set_defaults(func=cmd_reproduce_paper)

    stab = sub.add_parser("stability", help="largest stable control period per controller, "
                                            "plant and arm")
    stab.add_argument("file", metavar="SCENARIO_OR_CAMPAIGN.toml")
    stab.add_argument("--out", metavar="DIR",
                      help="results folder (default results/stability-<file name>)")
    _add_cases(stab)
    _add_tolerance(stab)
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
                     help="stability map to compare with (default: OUT/stability or OUT, "
                          "else results/NAME/stability as reproduce-paper and campaign store "
                          "it, else results/stability-STEM as flexarm stability does)")
    _add_cases(val)
    val.add_argument("--no-progress", action="store_true", help="no progress bar")
    val.set_defaults(func=cmd_validity)

    exp = sub.add_parser("export", help="write metrics.csv and manifest.json from the index "
                                        "(--signals: one run as an experiment CSV)")
    exp.add_argument("results", metavar="RESULTS_DIR", nargs="?")
    exp.add_argument("--signals", metavar="RESULTS/RUN",
                     help="write this run's torques and measurements as the CSV flexarm "
                          "calibrate reads (to stdout, or --to FILE)")
    exp.add_argument("--to", metavar="FILE", help="with --signals: the CSV file to write")
    exp.set_defaults(func=cmd_export, imports_no_plugin=True)

    rep = sub.add_parser("repair", help="rebuild a results folder's index from its run files")
    rep.add_argument("results", metavar="RESULTS_DIR")
    rep.set_defaults(func=cmd_repair, imports_no_plugin=True)

    att = sub.add_parser("attribute", help="which modelling assumption costs how much "
                                           "(Shapley attribution over 2^k runs)")
    att.add_argument("file", metavar="SCENARIO_OR_CAMPAIGN.toml",
                     help="the real world (a campaign: one attribution per run, factors from "
                          "its [attribution] table)")
    att.add_argument("--factors", metavar="F1,F2,...",
                     help="plant, truncation, parameters, sensing, estimation, sampling, "
                          "actuation, friction, drive, bandwidth, kinematics (default: every "
                          "factor the scenario has but the joints' and kinematics)")
    att.add_argument("--out", metavar="DIR", help="results folder")
    att.add_argument("--mesh-check", action="store_true",
                     help="also run every truth-plant world on the check meshes and with a "
                          "finer step (closed-loop convergence, shown by the report)")
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

    cal = sub.add_parser("calibrate", help="fit the plant's parameters to measured experiments "
                                           "(time series, frequency responses), with standard "
                                           "errors, intervals and identifiability")
    cal.add_argument("data", metavar="DATA", nargs="*",
                     help="experiments: CSV files (t, one torque per joint tau1, tau2, …, "
                          "measured signals) or stored runs RESULTS/RUN")
    cal.add_argument("--config", required=True, metavar="SCENARIO.toml",
                     help="the scenario the experiments ran (plant, arm and start values; "
                          "[calibrate] settings)")
    cal.add_argument("--fit", metavar="NAME[,NAME...]",
                     help="scenario fields to fit, e.g. true_params.EI1,true_params.Mp "
                          "(default: [calibrate] fit)")
    cal.add_argument("--frf", action="append", metavar="FILE.csv",
                     help="a frequency response (f [Hz], OUT/IN.re, OUT/IN.im), fitted on the "
                          "linearised plant")
    cal.add_argument("--out", metavar="DIR",
                     help="results folder (default results/calibrate-<config name>)")
    cal.add_argument("--compare", nargs="+", metavar="OTHER_DIR",
                     help="calibrations of other models on the same data: one table of "
                          "residual, adequacy and information criteria (AIC, BIC)")
    cal.add_argument("--no-search", action="store_true",
                     help="do not fit the toolkit's physics extensions (friction, Stribeck, "
                          "drives, backlash, exact kinematics) to an inadequate model (the "
                          "screen still ranks them)")
    cal.add_argument("--export-inadequate", action="store_true",
                     help="write uncertainty.toml even for a model the residual tests call "
                          "inadequate (its ranges are of effective parameters and may "
                          "exclude the arm's values; a warning says so)")
    _add_execution(cal)
    cal.set_defaults(func=cmd_calibrate)

    base = sub.add_parser("baseline", help="error-bound regression checks (baselines.toml)")
    bsub = base.add_subparsers(dest="action", required=True, parser_class=_Parser)
    from ..verdicts.baselines import DEFAULT_FILE
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
    add = bsub.add_parser("add", help="add a check from a measured run: its value and a "
                                      "margin make the bound")
    add.add_argument("run", metavar="RESULTS/RUN",
                     help="a stored run (a results folder, then a run id or name), made by "
                          "this code")
    add.add_argument("--metric", action="append", required=True, metavar="KEY",
                     help="the metric to bound (repeat: their maximum), e.g. track_max_1")
    add.add_argument("--margin", default="25%", metavar="SHARE",
                     help="headroom of the bound over the measured value, e.g. 25%% or 0.25 "
                          "(default 25%%)")
    add.add_argument("--op", choices=("<=", ">="), default="<=",
                     help="the value must stay <= the bound (default) or >= it")
    add.add_argument("--name", help="the check's name (default: scenario-metric)")
    add.add_argument("--file", default=str(DEFAULT_FILE), metavar="TOML",
                     help="the checks (default: the repository's baselines.toml)")
    add.set_defaults(func=cmd_baseline_add, imports_no_plugin=True)
    return parser
