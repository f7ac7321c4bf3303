"""Commands on a results folder: ``report``, ``export``, ``repair``."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..batch.store.folder import ResultStore, StoreError


def render_report(results, *, animate: bool, progress: bool, force: bool = False) -> str:
    """Render the report of ``results`` unless it is current; the line to print."""
    from ..report.content_key import report_is_current
    from ..report.report import write_report
    if not force and report_is_current(results, animate=animate):
        html_path = Path(results) / "report" / "report.html"
        return f"report: {html_path} is up to date (same runs, same code): not rendered again"
    html_path, md_path = write_report(results, animate=animate, progress=progress, force=True)
    return f"report: {html_path} (self-contained) and {md_path}"


def cmd_report(args: argparse.Namespace) -> int:
    print(render_report(args.results, animate=not args.no_animation,
                        progress=not args.no_progress, force=args.force))
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    if args.signals is not None or args.to is not None:
        from ..run.config import check
        check(args.signals is not None and args.results is None, "--signals",
              "give RESULTS/RUN with --signals (and --to FILE), or a RESULTS_DIR alone")
        from .calibrate import export_signals
        return export_signals(args)
    if args.results is None:
        raise StoreError("export: give RESULTS_DIR (or --signals RESULTS/RUN)")
    store = ResultStore(args.results)
    csv_path, json_path = store.export()
    count = len(store.columns(["run_id"]))  # the rows exported, not read again whole
    print(f"exported {count} runs: {csv_path} and {json_path}")
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
