"""The verdict commands: ``stability``, ``validity``, ``attribute``, ``verify``,
``baseline check|update``."""
from __future__ import annotations

import argparse
import dataclasses
import math
import shlex
import sys
from pathlib import Path

from ..batch.interrupts import signals_interrupt
from ..batch.store.folder import ResultStore, StoreError
from ..run.config import ConfigError, check
from ..run.plants import ROLES
from ..run.results import own_folder
from ..run.scenario import PAPER_ARMS, PLANT_KINDS, scenario_from_mapping

from .common import EXIT_FAILED, finish, mesh_checks, runner_for


def stability_map_into(runner, scenarios, out: Path, *, progress: bool, tolerance: float,
                       plants=None, arms=None) -> tuple[int, list]:
    """Run the stability map into ``out`` (opened by the caller), each limit bisected to
    ``tolerance``, and print its summary; (the exit status, the results): 130/143 if it
    was interrupted, 1 if a limit is missing because a run failed where it lies (a
    failure above a limit found decides nothing: counted only)."""
    from ..report.verdict_tables import write_stability
    from ..verdicts.stability import cases_from_scenarios, stability_map
    from .summaries import stability_summary
    cases = cases_from_scenarios(scenarios, plants=plants, arms=arms)
    results, summary = stability_map(cases, out, runner=runner, progress=progress,
                                     tolerance=tolerance)
    if summary.interrupted:
        return finish(summary, "stability", out), []
    write_stability(results, out, tolerance=tolerance)
    lines, missing = stability_summary(results, out / "stability.md", tolerance=tolerance)
    print("\n".join(lines))
    return EXIT_FAILED if missing else 0, results


def _stability_scenarios(args: argparse.Namespace) -> tuple[list, list | None, list | None]:
    """(scenarios, plants, arms) of `flexarm stability`/`validity FILE`: a single scenario
    on both plants and the paper's two arms (unless --plant/--arm), or every run of a
    campaign."""
    from ..batch.campaign import expand, load_study
    scenarios = [r.scenario for r in expand(load_study(args.file))]
    if len(scenarios) == 1:
        return scenarios, args.plant or list(PLANT_KINDS), args.arm or list(PAPER_ARMS)
    return scenarios, args.plant, args.arm


def cmd_stability(args: argparse.Namespace) -> int:
    from ..batch.campaign import load_study
    from ..verdicts.bisection import tolerance_from
    from ..verdicts.stability import cases_from_scenarios
    tolerance = tolerance_from(load_study(args.file).stability, args.tolerance)
    scenarios, plants, arms = _stability_scenarios(args)
    out = Path(args.out or Path("results") / f"stability-{Path(args.file).stem}")
    cases = cases_from_scenarios(scenarios, plants=plants, arms=arms)  # what will run
    if ResultStore(out).exists():
        print(f"{out} holds runs: a map stored there is refined to {tolerance:g}, reusing "
              "its runs")
    runner = runner_for(args, [scenario_from_mapping(c.base) for c in cases], out)
    with runner:
        return stability_map_into(runner, scenarios, out, progress=not args.no_progress,
                                  tolerance=tolerance, plants=plants, arms=arms)[0]


def _default_maps(file: str) -> list[Path]:
    """Where the commands that measure a stability map put it by default for ``file``:
    ``reproduce-paper``/``campaign`` into results/NAME/stability (NAME: the campaign's),
    ``stability`` into results/stability-STEM."""
    from ..batch.campaign import load_study
    return [Path("results") / load_study(file).name / "stability",
            Path("results") / f"stability-{Path(file).stem}"]


def _stability_folder(args, out: Path) -> Path | None:
    """The stability map whose measurements `flexarm validity` joins: --stability, else
    OUT/stability, else OUT itself if it holds one, else the first of `_default_maps`
    that holds one, else none."""
    if args.stability:
        store = ResultStore(args.stability)
        if not store.exists():
            raise StoreError(f"--stability {args.stability}: not a results folder "
                             "(no index.sqlite)")
        return store.out
    for folder in (out / "stability", out, *_default_maps(args.file)):
        if ResultStore(folder).exists() and ResultStore(folder).rows(where="sweep = 'stability'"):
            return folder
    return None


def cmd_validity(args: argparse.Namespace) -> int:
    from ..verdicts.stability import cases_from_scenarios
    from ..report.verdict_tables import write_validity
    from ..batch.progress import progress as progress_bar
    from ..verdicts.validity import validity_analysis
    from .summaries import validity_summary
    scenarios, plants, arms = _stability_scenarios(args)
    plugins = sorted({s.plant.kind for s in scenarios if s.plant.kind not in PLANT_KINDS})
    check(not plugins or args.plant, "plant.kind", f"{', '.join(plugins)} is a plug-in plant, which declares "
                                     "no linear model: validity compares the reduced model's "
                                     "and the FE arm's (give --plant reduced --plant exudyn to "
                                     "judge the built-in arms for this law)")
    cases = cases_from_scenarios(scenarios, plants=plants, arms=arms)
    out = Path(args.out or Path("results") / f"validity-{Path(args.file).stem}")
    stability = _stability_folder(args, out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        folder = own_folder(out, "validity")
    except OSError as exc:
        raise StoreError(f"--out {out}: cannot write ({exc.strerror or exc})") from None

    where = " or ".join(str(f) for f in _default_maps(args.file))
    print(f"linear validity of {len(cases)} cases" + (
        f", measured map: {stability}" if stability else
        f", no measured stability map (none in {where}: 'flexarm stability {args.file}' or "
        "'flexarm reproduce-paper' measures one, --stability DIR names another)"))
    bar = progress_bar(len(cases), "validity", unit="case", enabled=not args.no_progress)
    try:
        data = validity_analysis(cases, stability_dir=stability,
                                 progress=lambda row: bar.update(1))
    finally:
        bar.close()
    write_validity(data, folder)
    print("\n".join(validity_summary(data, folder)))
    return 0


def cmd_attribute(args: argparse.Namespace) -> int:
    from ..batch.campaign import expand, load_study
    from ..report.verdict_tables import study_view, write_attribution
    from .summaries import attribution_summary
    from ..verdicts.attribution import attribute, default_factors, parse_factors
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
    from ..verdicts.attribution import plan
    for label, s, factors in plans:  # every world checked before anything runs
        plan(s, factors, label)
    out = Path(args.out or default_out)
    results = []
    runner = runner_for(args, [s for _, s, _ in plans], out)
    with runner:
        for label, s, factors in plans:
            att, summary = attribute(s, factors, out, name=label, runner=runner,
                                     progress=not args.no_progress)
            print(summary.line(f"attribution {label}", out))
            if summary.interrupted:
                return finish(summary, label, out)
            results.append(att)
        if args.mesh_check:
            status = mesh_checks(runner, out, {r.run_id for r in ResultStore(out).rows()},
                                  progress=not args.no_progress)
            if status:
                return status
    write_attribution(results, out)
    print("\n".join(attribution_summary([study_view(a) for a in results],
                                         out / "attribution.md")))
    print(f"  attribution.csv beside it; 'flexarm report {out}' draws the waterfalls")
    return 0


# --- flexarm verify --------------------------------------------------------------------------
def cmd_verify(args: argparse.Namespace) -> int:
    from ..verdicts.uncertainty import load_systems
    from ..batch.queue import answer_all
    from ..verdicts.verify import conform_question, estimate_question, falsify_question
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
    runner = runner_for(args, [s.scenario({}, plant=role) for s in systems
                            for role in ROLES], *folders.values())
    failed = False
    # A signal between two batches of a search (not only during one) stops it: exit 143.
    with runner, signals_interrupt():  # every system's runs on the one runner at once
        for system in systems:
            print(f"{system.name}: {args.mode} over "
                  f"{', '.join(system.uncertainty.describe())}")
        if args.mode == "estimate":
            questions = [estimate_question(s, r, folders[s.name], workers=runner.workers,
                                           samples=args.samples, seed=args.seed)
                         for s, r in zip(systems, requirements)]
        elif args.mode == "falsify":
            questions = [falsify_question(s, r, folders[s.name], budget=args.budget,
                                          seed=args.seed) for s, r in zip(systems, requirements)]
        else:
            questions = [conform_question(s, folders[s.name], budget=args.budget,
                                          seed=args.seed) for s in systems]
        verdicts = answer_all(questions, runner)
    for system, requirement, v in zip(systems, requirements, verdicts):
        if args.mode == "estimate":
            print(f"{system.name}: {v['draws']}/{v['samples']} draws")
            for r in v["requirements"].values():
                print(f"  {r['requirement']}: {r['n'] - r['failures']}/{r['n']} hold, "
                      f"P(holds) in [{r['p_low']:.3f}, {r['p_high']:.3f}] at "
                      f"{r['level']:g} (Clopper-Pearson, n = {r['n']}); sequential "
                      f"test: {r['sequential']['decision']} after "
                      f"{r['sequential']['draws']} draws")
        elif args.mode == "falsify":
            print(f"{system.name}:")
            what = "counterexample" if v["found"] else \
                f"{v['verdict']}; worst case" if v["undecided"] else \
                "no counterexample; worst case"
            truth = (requirement.rho_text(v["rho_truth"]) if v["rho_truth"] is not None
                     else f"−inf ({v.get('truth_status', 'no run')})")
            reduced = requirement.rho_text(v["rho_reduced"] if v["rho_reduced"] is not None
                                           else -math.inf)
            print(f"  {requirement.name}: {what}: ρ truth {truth}, reduced {reduced} "
                  f"({v['counterexample'] or v['worst_case']}); simulations "
                  f"{v['simulations']}")
            if "convergence" in v:
                print(f"  truth plant under refinement: {_checks_line(v['convergence'], requirement)}")
        else:
            print(f"{system.name}:")
            print(f"  largest |theta_truth - theta_reduced| = {v['distance']} rad "
                  f"({v['scenario']}); simulations {v['simulations']}")
        failed |= bool(v["failed_runs"])
        print(f"  verdict: {folders[system.name] / 'verdict.json'}")
    return EXIT_FAILED if failed else 0


def _checks_line(convergence: dict, requirement) -> str:
    """"converged: ρ = −0.261 ± 0.005 rad (order 1.4; ANCF 4 el/link: -0.223 rad; ...)": a
    verdict's ρ on the refined sequence and its other checks (or the status of a check
    whose run did not complete)."""
    rho = lambda v, status="": status if v is None else requirement.rho_text(v)  # noqa: E731
    checks = convergence["levels"] | convergence["checks"]
    every = [f"{label}: {rho(c['rho'], c['status'])}" for label, c in checks.items()]
    estimate = "" if convergence["rho"] is None else \
        f": ρ = {rho(convergence['rho'])} ± {convergence['error']:.2g}" + (
            f" (order {convergence['order']:.2g})" if convergence["order"] is not None else "")
    return f"{convergence['verdict']}{estimate} [{'; '.join(every)}]"


# --- flexarm baseline -----------------------------------------------------------------------
def _baseline_rows(args) -> tuple:
    from ..verdicts.baselines import evaluate, load_baselines
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
    from ..verdicts.baselines import proposed_bounds, write_baselines
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


def cmd_baseline_add(args: argparse.Namespace) -> int:
    from ..verdicts.baselines import (DEFAULT_FILE, check_from_run, load_baselines, parse_margin,
                                      write_baselines)
    from .one_run import stored_run
    margin = parse_margin(args.margin)
    store, row = stored_run(args.run, "RESULTS/RUN")
    baselines = load_baselines(args.file)
    metric = tuple(k.strip() for k in args.metric)
    updated, added = check_from_run(baselines, store, row, metric, margin=margin, op=args.op,
                                    name=args.name)
    write_baselines(updated, updated.checks)
    what = metric[0] if len(metric) == 1 else f"max({', '.join(metric)})"
    print(f"added check {added.name}: {what} {added.op} {added.bound:.4g} (measured "
          f"{added.measured:.4g} in {row.run_id}, margin {100 * margin:g} %) on scenario "
          f"{added.scenario}, in {updated.path}")
    duration = row.config["duration"]
    if duration > 5:
        print(f"  note: a {duration:g} s scenario: `make test` measures every short check; "
              "a scenario of 5 s or less keeps it short")
    where = "" if Path(args.file) == Path(DEFAULT_FILE) else f" --file {shlex.quote(args.file)}"
    print(f"  flexarm baseline check --only {added.name}{where}   # measures it again")
    return 0
