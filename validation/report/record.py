"""The report's sentences and tables as data, for renderings made elsewhere (the docs'
findings page): ``report/report.json``, written with report.html and report.md from the
same `report.ReportData`, so that another page reads what the report says — the same
verdicts, units and rounding — without recomputing it or parsing the report's text.

It holds the fields in `RECORDED`, each as the report has it (strings, table dicts of
``head``/``rows``/``classes``, folded cells as ``{"text", "detail", "full"}``), and
``figures``: each figure's section, caption and file (relative to ``report/``), the
animation's still last.
"""
from __future__ import annotations

import json
from pathlib import Path

__all__ = ["RECORDED", "report_record", "load_record", "RECORD_FILE"]

#: Where in a results folder the record is.
RECORD_FILE = Path("report") / "report.json"

#: The fields of `report.ReportData` the record holds: the report's answer (the bottom
#: line), what was run and the tables of its verdicts, all of them text already.
RECORDED = ("title", "description", "folder", "scope", "answers", "bottom_line", "warnings",
            "arms_answers", "arms", "summary", "pairs", "claims", "claims_criteria",
            "claim_notes", "stability")


def report_record(data) -> dict:
    """The record of a report's data (``data``: a `report.ReportData` whose figures have
    their files)."""
    poster = [data.animation["poster"]] if data.animation else []
    return {**{name: getattr(data, name) for name in RECORDED},
            "figures": [{"section": f.section, "caption": f.caption, "file": f.file}
                        for f in data.figures + poster]}


def load_record(results_dir) -> dict | None:
    """The record of the report of ``results_dir``, or None if it has none (no report,
    or one written before reports kept it: ``flexarm report DIR`` writes it)."""
    path = Path(results_dir) / RECORD_FILE
    if not path.is_file():
        return None
    with path.open(encoding="utf-8") as fh:
        return json.load(fh)
