"""``flexarm campaign`` and ``flexarm reproduce-paper``."""
from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
from pathlib import Path

from ..batch.store.resimulate import every_signal
from ..batch.store.folder import ResultStore

from .common import EXIT_FAILED, finish, mesh_checks, runner_for
from .job_clock import LAB, PAPER, JobClock
from .results import render_report
from .verdicts import stability_map_into


def cmd_campaign(args: argparse.Namespace) -> int:
    from ..batch.campaign import expand, load_campaign
    from ..batch.queue import classify, run_campaign
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
    runner = runner_for(args, [r.scenario for r in runs], out)
    with runner:
        summary = run_campaign(campaign, out, runner=runner, retry_failed=args.retry_failed,
                               reuse_stale=args.reuse_stale, progress=not args.no_progress,
                               only=runs)
        if args.mesh_check and not summary.interrupted:
            status = mesh_checks(runner, out, {r.run_id for r in runs},
                                  progress=not args.no_progress)
            if status:
                return status
    return finish(summary, campaign.name, out)


def campaigns_dir() -> Path:
    """The shipped campaigns/ folder of this checkout."""
    here = Path(__file__).resolve().parents[2] / "campaigns"
    if not (here / "paper.toml").exists():
        raise ValueError(f"shipped campaigns not found in {here}; run from the repository "
                         "(pip install -e .)")
    return here


def cmd_reproduce_paper(args: argparse.Namespace) -> int:
    """The paper's campaign (with ``--lab`` its claims' runs on the lab arm), the
    stability map, the mesh checks of the truth-plant runs the claims are judged on (but
    those the map explains), the claims and the report; a short summary on the terminal.
    Exit 1 only if a verdict is missing (a run that decides one failed); failures that
    decide nothing are counted in the summary."""
    from ..batch.campaign import expand, load_campaign
    from ..batch.queue import run_campaign
    from ..report.verdict_tables import write_claims
    from ..verdicts.bisection import tolerance_from
    from ..verdicts.claims import CLAIM_RUNS, claim_columns
    from ..verdicts.claims import beyond_every_limit
    from .summaries import claims_summary
    which = "lab" if args.lab else "paper"
    campaign = load_campaign(campaigns_dir() / f"{which}.toml")
    tolerance = tolerance_from(campaign.stability, args.tolerance)
    runs = paper_keep(expand(campaign), campaign)
    out = Path(args.out or Path("results") / which)
    scenarios = [r.scenario for r in runs]
    runner = runner_for(args, scenarios, out, *([] if args.no_stability else [out / "stability"]))
    profile = LAB if args.lab else PAPER
    clock = JobClock("reproduce-paper" + " --lab" * args.lab, profile,
                     stream=None if args.no_progress else sys.stderr)
    clock.begin(skipped=(["the stability map"] if args.no_stability else [])
                + (["the report"] if args.no_report else []))
    with runner:
        summary = run_campaign(campaign, out, runner=runner, progress=not args.no_progress,
                               only=runs)
        if summary.interrupted:
            return finish(summary, campaign.name, out)
        print(summary.line(campaign.name, out))
        clock.done(profile[0][0])  # the campaign's runs, the profile's first phase
        stability, explained = 0, set()
        if not args.no_stability:
            stability, results = stability_map_into(
                runner, [r.scenario for r in runs if not r.scenario.disturbances],
                out / "stability", progress=not args.no_progress, tolerance=tolerance)
            if stability not in (0, EXIT_FAILED):  # interrupted
                return stability
            explained = beyond_every_limit(results, ResultStore(out).rows())
            clock.done("the stability map")
        judged = {r.run_id for r in runs if r.scenario.name.split("/")[-1] in CLAIM_RUNS}
        checks = mesh_checks(runner, out, judged, beyond=explained,
                             progress=not args.no_progress)
        if checks and checks != EXIT_FAILED:  # interrupted
            return checks
        clock.done("the mesh checks")
    store = ResultStore(out)
    columns = claim_columns(store.rows(), functools.partial(every_signal, store))
    write_claims(out, columns)
    lines, missing = claims_summary(columns, out / "claims.md")
    print("\n".join(lines))
    clock.done("the claims")
    if not args.no_report:
        print(render_report(out, animate=not args.no_animation, progress=not args.no_progress))
    return EXIT_FAILED if missing or stability else 0


def paper_keep(runs, campaign) -> list:
    """The paper's runs, each keeping what its verdicts and figures read: every signal
    (compressed) for the paper's system — the claims' window family and the report's
    figures (``[report] figures``) read them —, the claims' signals for the disturbance
    run (`mesh.CHECK_KEEP`), the metrics alone for every other run (re-simulated bit for
    bit on demand: ``flexarm run --like``)."""
    from ..batch.store.runfiles import KEEP_NONE, Keep
    from ..verdicts.claims import DISTURBED, SYSTEM
    from ..verdicts.mesh import CHECK_KEEP
    everything = {SYSTEM, *campaign.report.get("figures", [])}
    keeps = {name: Keep(compress=True) for name in everything} | {DISTURBED: CHECK_KEEP}
    return [dataclasses.replace(r, keep=keeps.get(r.scenario.name.split("/")[-1],
                                                  KEEP_NONE)) for r in runs]
