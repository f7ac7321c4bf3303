"""``flexarm calibrate``: the plant's parameters fitted to measured experiments, and
``flexarm export --signals``: a stored run written as such an experiment."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..run.config import ConfigError
from ..run.experiments import from_run, read_experiment, read_frequency_response, write_experiment

from .common import EXIT_FAILED, runner_for
from .one_run import stored_run
from ..batch.compiling import compile_for
from ..batch.store.resimulate import every_signal

#: Failing residual tests listed on the terminal (all are in calibration.json).
_FAILING_SHOWN = 8


def _experiment(spec: str):
    """DATA: a CSV file, or a stored run RESULTS/RUN (with its own scenario)."""
    path = Path(spec)
    if path.suffix.lower() == ".csv" or path.is_file():
        return read_experiment(path), None
    store, row = stored_run(spec, "DATA")
    return from_run(every_signal(store, row), row.run_id, spec), row.config


def _fit_names(text: str | None) -> list[str] | None:
    return None if text is None else [n.strip() for n in text.split(",") if n.strip()]


def cmd_calibrate(args: argparse.Namespace) -> int:
    from ..verdicts.calibration import (RESULT_FILES, FitFailed, base_scenario, calibrate,
                                        calibration_settings, data_fingerprint,
                                        plan_calibration, read_fits, refuse_links)
    base, table = base_scenario(args.config)
    settings = calibration_settings(table, _fit_names(args.fit), base)
    experiments = [_experiment(spec) for spec in args.data]
    responses = [read_frequency_response(f) for f in args.frf or []]
    # The plan's units check replays each experiment on the plant here: its kernels are
    # compiled first, with progress, not silently inside the check.
    compile_for([base] if experiments else [])
    plan = plan_calibration(base, settings, experiments, responses)
    out = Path(args.out or Path("results") / f"calibrate-{Path(args.config).stem}")
    others = [f for f in args.compare or [] if Path(f).resolve() != out.resolve()]
    fits = read_fits(others, data_fingerprint(plan))
    refuse_links(plan, out)  # before the results folder is opened: nothing written
    scenarios = [base] if plan.targets else []  # its plant's kernels, compiled before the fork
    with runner_for(args, scenarios, out) as runner:
        print(f"calibrating {', '.join(settings.names)} on {len(plan.targets)} experiment(s)"
              f"{f' and {len(responses)} frequency response(s)' if responses else ''} "
              f"({settings.inputs}, {base.plant.kind} plant) into {out}")
        try:
            result = calibrate(plan, out, runner=runner, compare=fits,
                               search=not args.no_search,
                               export_inadequate=args.export_inadequate)
        except FitFailed as exc:  # a failed computation, not bad input: status 1
            print(f"flexarm: error: {exc}; no result written (the simulations are in "
                  f"{out})", file=sys.stderr)
            return EXIT_FAILED
    print(f"{result['iterations']} iterations, {result['simulations']} simulations, cost "
          f"{result['cost']:.6g} (residual variance {result['residual_variance']:.3g}, in units "
          "of the noise levels)")
    _print_parameters(result)
    for exp, signals in result["residual_rms"].items():
        if "relative_rms" in signals:  # a frequency response
            print(f"  residual RMS / noise, {exp}: "
                  f"{signals['relative_rms'] / signals['noise']:.3g} (relative)")
            continue
        ratios = [f"{s} {v['rms'] / v['noise']:.3g}" for s, v in signals.items()
                  if v["noise"]]
        if ratios:
            print(f"  residual RMS / noise, {exp}: {', '.join(ratios)}")
    _print_adequacy(result["adequacy"])
    if "extensions" in result:
        _print_extensions(result["extensions"])
    if "comparison" in result:
        _print_comparison(result["comparison"])
    written = [f for f in RESULT_FILES if (out / f).is_file()]
    print(f"wrote {', '.join(str(out / f) for f in written)}; report: flexarm report {out}")
    _print_next(result, out)
    if result["failed_runs"]:
        print(f"flexarm: {len(result['failed_runs'])} simulation(s) failed, read as no data "
              "(trial points rejected, screen probes left out); the estimate and its "
              f"intervals rest on none of them: {', '.join(result['failed_runs'][:8])}",
              file=sys.stderr)
        return EXIT_FAILED
    return 0


def _print_extensions(search: dict) -> None:
    print(f"  what the model lacks: {search['verdict']}")
    for row in search["fits"]:
        print(f"    {row['name']}: {'adequate' if row['model_adequate'] else 'INADEQUATE'}, "
              f"AIC {row['aic']:.6g} (dAIC {row['delta_aic']:.4g})")


def _print_next(result: dict, out: Path) -> None:
    """What to do with the result: run and verify the calibrated arm, or what to try
    when the model is inadequate."""
    from ..verdicts.calibration import EXTENDED
    verify = (f'include = ["{{0}}/calibrated.toml", "{{0}}/uncertainty.toml"] in a verify file, '
              "then flexarm verify FILE")
    if result["model_adequate"] is not False:
        print(f"next: flexarm run --config {out / 'calibrated.toml'} runs the calibrated arm; "
              + (verify.format(out) + " judges a controller over its intervals"
                 if (out / "uncertainty.toml").is_file() else
                 "no parameter has an interval to verify over"))
        return
    search = result.get("extensions", {})
    screened = [r["name"] for r in result.get("screen", []) if r["significant"]]
    if search.get("adequate"):
        extended = out / EXTENDED
        print(f"next: the model with {search['adequate']} explains the data: flexarm run "
              f"--config {extended / 'calibrated.toml'}; "
              + (verify.format(extended) + " (its 95 % intervals)"
                 if (extended / "uncertainty.toml").is_file() else
                 "its intervals hold only at the estimate of a parameter the data do not "
                 "identify (extended/calibration.json), so no uncertainty.toml was written"))
        return
    if screened and not search:
        print(f"next: the residual follows {', '.join(screened[:3])} (screen): run again "
              "without --no-search to fit them, or add them to the scenario and --compare")
        return
    print("next: the model misses physics the toolkit cannot name here: add it to the "
          "scenario (its joints: --fit true_params.coulomb1,... with [calibrate] start and "
          "bounds; plant.kinematics = \"exact\"; a finer plant), fit each candidate into its "
          "own folder and rank them with --compare"
          + ("" if result.get("exported") else "; no uncertainty.toml was written "
             "(--export-inadequate writes its effective ranges, with a warning)"))


def _print_parameters(result: dict) -> None:
    effective = result["model_adequate"] is not True
    if effective:
        print(f"  intervals: {result['interval_kind']}")
    width = max(len(n) for n in result["parameters"])
    for name, p in result["parameters"].items():
        if not p["identifiable"]:
            print(f"  {name:<{width}}  {p['estimate']:.7g}  NOT IDENTIFIABLE: {p['why']}")
            continue
        lo, hi = p["interval"]
        if effective:
            print(f"  {name:<{width}}  {p['estimate']:.7g}  (effective: {lo:.7g} .. {hi:.7g}; "
                  f"noise ± {p['std']:.2g}, model error ± {p['model_error']:.2g})")
        else:
            print(f"  {name:<{width}}  {p['estimate']:.7g} ± {p['std']:.2g}  "
                  f"(95 %: {lo:.7g} .. {hi:.7g})")
    rough = [(n, p["jacobian"]) for n, p in result["parameters"].items()
             if not p["jacobian"]["settled"]]
    if rough:
        print("  the outputs jump as " + ", ".join(
            f"{n.rsplit('.', 1)[-1]} ({100 * j['halves']:.3g} %)" for n, j in rough)
            + " change (stick-slip or backlash events moving across integration steps: its "
              "forward and backward differences disagree by that much); the slope its "
              "interval rests on is uncertain (docs: Calibrate, friction and drives)")


def _print_adequacy(adequacy: dict) -> None:
    print(f'  "model_adequate": {json.dumps(adequacy["model_adequate"])} — '
          f"{adequacy['verdict']}")
    failing = adequacy["failing"]
    for line in failing[:_FAILING_SHOWN]:
        print(f"    fails: {line}")
    if len(failing) > _FAILING_SHOWN:
        print(f"    ... and {len(failing) - _FAILING_SHOWN} more failing tests "
              "(calibration.json: adequacy)")


def _print_comparison(rows: list[dict]) -> None:
    print("which model explains the data (best AIC first; AIC = chi2 + 2p, BIC = chi2 + "
          "p ln m):")
    header = ("model", "fitted", "chi2", "RMS/noise", "adequacy", "AIC", "dAIC", "BIC")
    table = [(f"{r['plant']} ({r['folder']})", ",".join(r["fitted"]), f"{r['chi2']:.6g}",
              f"{r['rms']:.3g}", r["adequacy"], f"{r['aic']:.6g}", f"{r['delta_aic']:.4g}",
              f"{r['bic']:.6g}") for r in rows]
    widths = [max(len(str(c)) for c in column) for column in zip(header, *table)]
    for line in (header, *table):
        print("  " + "  ".join(f"{c:<{w}}" for c, w in zip(line, widths)))


def export_signals(args: argparse.Namespace) -> int:
    """``flexarm export --signals RESULTS/RUN [--to FILE]``: the run as an experiment CSV."""
    if args.to is not None and (Path(args.to).is_dir() or Path(args.to).is_symlink()):
        raise ConfigError("--to", f"{args.to} is a directory or a link: give the CSV "
                                  "file to write")
    store, row = stored_run(args.signals, "--signals")
    exp = from_run(every_signal(store, row), row.run_id, args.signals)
    comment = (f"run {row.run_id} ({row.name}) of {store.out}, as flexarm calibrate reads "
               f"an experiment: t [s], the joint torques applied [N m], the measurements")
    if args.to is None:
        write_experiment(exp, sys.stdout, comment)
        return 0
    from ..run.results import write_atomic
    write_atomic(Path(args.to), lambda fh: write_experiment(exp, fh, comment))
    print(f"wrote {args.to}: {exp.samples} samples of {', '.join(exp.names)}")
    return 0
