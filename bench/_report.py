"""Shared output of the benchmark scripts: a printed table, which targets are met and
which are missed, and a JSON file."""
from __future__ import annotations

import json
import operator
import os
import platform
from datetime import datetime, timezone
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
_OPS = {"<=": operator.le, ">=": operator.ge}


def target(value: float, op: str, bound: float) -> dict:
    """Columns "target" and "met" of a row: ``value op bound``."""
    return {"target": f"{op} {bound:g}", "met": "yes" if _OPS[op](value, bound) else "MISSED"}


def report(name: str, rows: list[dict], *, columns: list[str], title: str) -> Path:
    """Print ``rows`` as a table, then the targets met and missed, and write them to
    bench/results/<name>.json."""
    widths = [max(len(c), *(len(_fmt(r.get(c))) for r in rows)) for c in columns]
    print(f"\n{title}")
    print("  ".join(c.ljust(w) for c, w in zip(columns, widths)))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print("  ".join(_fmt(r.get(c)).ljust(w) for c, w in zip(columns, widths)))
    judged = [r for r in rows if "met" in r]
    if judged:
        missed = [r for r in judged if r["met"] != "yes"]
        print(f"targets: {len(judged) - len(missed)} of {len(judged)} met"
              + (f"; MISSED: {len(missed)}" if missed else ""))
    RESULTS.mkdir(exist_ok=True)
    path = RESULTS / f"{name}.json"
    meta = {"when": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "machine": platform.processor() or platform.machine(),
            "python": platform.python_version(), "cores": os.cpu_count()}
    path.write_text(json.dumps({"meta": meta, "rows": rows}, indent=2))
    print(f"(written to {path})")
    return path


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return "" if value is None else str(value)
