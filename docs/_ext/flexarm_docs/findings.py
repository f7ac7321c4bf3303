"""The findings page: what the paper reproduction found, read from the stored report of a
``flexarm reproduce-paper`` results folder (its record, `validation.report.record`) — its
answer per arm and plant first, then the claims at a glance, the claims value by value,
the sampled-data stability map and the report's main figures with their captions — the
same for the lab arm (``flexarm reproduce-paper --lab``), and the share of the
reduced-vs-truth gap the paper's kinematics explain (``flexarm attribute
campaigns/kinematics.toml``), or, without them, how to produce them.  The verdicts, units
and rounding are the report's own; never a number typed here.

The folders are ``$FLEXARM_FINDINGS`` or ``results/paper``, ``$FLEXARM_FINDINGS_LAB`` or
``results/lab`` and ``$FLEXARM_FINDINGS_KINEMATICS`` or ``results/kinematics`` (where
``make demo`` and ``make findings`` write).
"""
from __future__ import annotations

import csv
import os
import shutil
from pathlib import Path

from .rst import escape_bars, heading, list_table

_HOW = """\
No report of a paper reproduction was found at ``{folder}`` when this site was built, so
this part holds no numbers.  To produce them, run from the repository::

    make demo          # flexarm reproduce-paper --out results/paper
    make docs          # this page is then generated from results/paper

(``FLEXARM_FINDINGS=DIR make docs`` reads another results folder of ``flexarm
reproduce-paper``; a folder whose report predates ``report/report.json``: ``flexarm report
DIR --force``.)  What the reproduction runs and how to read its verdicts:
:doc:`guide/verdicts`.

"""

_HOW_LAB = """\
No report of the lab arm was found at ``{folder}`` when this site was built.  To produce
it (``make findings`` does)::

    flexarm reproduce-paper --lab --no-stability --out results/lab

"""

_HOW_KINEMATICS = """\
No stored attribution of the kinematics was found at ``{folder}`` when this site was
built.  To produce it (``make findings`` does)::

    flexarm attribute campaigns/kinematics.toml --out results/kinematics

"""

#: The stability map's columns shown here (the report's heads): the limits, not how the
#: bisection got there (the report has every column).
_STABILITY_COLUMNS = ("case", "plant", "arm", "no divergence up to [ms]",
                      "keeps tracking up to [ms]", "predicted [ms]")

#: The report's figure sections shown here, each with how many of its figures (the
#: first: the paper's figures of its own scenario, the stability map's chart).
_FIGURES = {"Stability map": 1, "Paper figures": 5}

#: The metrics the kinematics table shows (`validation.verdicts.attribution.METRICS`).
_KINEMATICS_METRICS = ("track_rms", "track_max", "vib_rms", "est_rms_q")


def _plain(value) -> str:
    """A report cell's text: a folded cell (`validation.report.render.folded`) by its short
    text, the detail being the report's."""
    return value["text"] if isinstance(value, dict) else str(value)


def _text(value) -> str:
    """`_plain` as reStructuredText: emphasis and literal marks as text."""
    return _plain(value).replace("\\", "\\\\").replace("*", r"\*").replace("`", r"\`") \
        .replace("_", r"\_")


def _prose(value) -> str:
    """`_text` outside a table: its bars escaped too (`list_table` escapes a cell's)."""
    return escape_bars(_text(value))


def _table(head, rows) -> str:
    return list_table([_text(h) for h in head], [[_text(c) for c in r] for r in rows],
                      classes="config-table")


def _shown(folder: Path, root: Path):
    return folder.relative_to(root) if folder.is_relative_to(root) else folder


def _folder(root: Path, variable: str, default: str) -> Path:
    return Path(os.environ.get(variable, root / "results" / default))


def _records(root: Path) -> dict:
    """The records of the paper's and the lab arm's reports ({"paper": (folder, record
    or None), "lab": …})."""
    from validation.report.record import load_record
    folders = {"paper": _folder(root, "FLEXARM_FINDINGS", "paper"),
               "lab": _folder(root, "FLEXARM_FINDINGS_LAB", "lab")}
    return {name: (folder, load_record(folder)) for name, folder in folders.items()}


def _answers(records: dict, root: Path) -> str:
    """The page's first lines: per arm and plant, what became of the paper's claims (the
    reports' bottom lines), or which report is missing."""
    from validation.verdicts.claims import SYSTEM
    lines = []
    for name, (folder, record) in records.items():
        if record is None:
            lines.append(f"No report of the {'lab arm' if name == 'lab' else 'paper reproduction'}"
                         f" at ``{_shown(folder, root)}`` (below: how to produce it).")
        else:
            lines += [_prose(s) for s in record["answers"]]
    return (f"The paper's system (``{SYSTEM}``: the PBC fed by the paper's sign sliding-mode "
            "observer), its claims on each plant and arm:\n\n"
            + "".join(f"* {line}\n" for line in lines) + "\n")


def _claims(record: dict, folder: Path, root: Path) -> str:
    """The claims at a glance and value by value, as the report has them."""
    out = [f"From the report in ``{_shown(folder, root)}`` (``report/report.html`` there: "
           "every table whole, with the details this page leaves out).  ",
           " ".join(_prose(s) for s in record["bottom_line"][len(record["answers"]):]), "\n\n"]
    summary = record["summary"]
    if summary:
        out.append(heading("At a glance", "~"))
        out.append("Each claim's verdicts counted over the columns of one arm on one plant "
                   "(control period, initial condition).\n\n")
        out.append(_table(["claim", *summary["arms"]],
                          [[row["claim"], *row["cells"]] for row in summary["rows"]]))
    for t in record["claims"] or []:
        out.append(heading(f"Value by value: the {t['arm']} arm", "~"))
        about = _prose(t["arm_text"])
        out.append(f"{about[:1].upper()}{about[1:]}.  A cell: the value, the verdict and its "
                   "margin = 1 − value/bound (at twice the bound or more: the multiple of the "
                   "bound).\n\n")
        for plant in dict.fromkeys(t["plants"]):  # a table per plant: a page's width
            shown = [i for i, p in enumerate(t["plants"]) if p == plant]
            out.append(heading(f"The {t['arm']} arm on the {plant}", "^"))
            out.append(_table(["claim", "bound", *(t["conditions"][i] for i in shown)],
                              [[row["claim"], row["bound"] or "—",
                                *(row["cells"][i] for i in shown)] for row in t["rows"]]))
        out += [f".. note::\n\n   {_prose(note)}\n\n" for note in t["notes"]]
    return "".join(out)


def _stability(record: dict) -> str:
    """The stability map as one row per case and a column per arm and plant: the report's
    limits (`_STABILITY_COLUMNS`), the first divergence and the width of each bracket
    left to the report."""
    if not record["stability"]:
        return ""
    from validation.verdicts.stability import DURATION, GRID, TRACKING_LIMIT
    table = record["stability"]["table"]
    at = {h: table["head"].index(h) for h in _STABILITY_COLUMNS}
    cells: dict = {}  # case → (arm, plant) → cell
    for row in table["rows"]:
        value = {h: _plain(row[i]) for h, i in at.items()}
        text = value["no divergence up to [ms]"]
        if value["keeps tracking up to [ms]"] != text:
            text += f", keeps tracking up to {value['keeps tracking up to [ms]']}"
        cells.setdefault(value["case"], {})[value["arm"], value["plant"]] = \
            f"{text} ({value['predicted [ms]']})"
    arms, plants = ({w[k]: None for c in cells.values() for w in c} for k in (0, 1))
    wheres = [(arm, plant) for arm in arms for plant in plants
              if any((arm, plant) in c for c in cells.values())]
    about = (f"{DURATION:g} s runs moving with the reference, control periods from "
             f"{1e3 * GRID[0]:g} to {1e3 * GRID[-1]:g} ms.  A cell: the largest control "
             f"period with no divergence at or below it [ms] (\"< {1e3 * GRID[0]:g}\": even "
             f"the smallest tested diverged; {1e3 * GRID[-1]:g}: none did), the largest that "
             f"keeps tracking (max |θ − θd| ≤ {TRACKING_LIMIT:g} rad over the second half) "
             "where it is smaller, and in brackets the limit the law's linearised sampled "
             "loop predicts.\n\n")
    return (heading("The sampled-data stability map", "~") + escape_bars(about)
            + _table(["case", *(f"{arm} arm, {plant} plant" for arm, plant in wheres)],
                     [[case, *(by.get(w, "not mapped on this arm and plant") for w in wheres)]
                      for case, by in cells.items()]))


def _figure(f: dict, folder: Path, target: Path, indent: str) -> str:
    """The ``figure`` directive of one of the report's figures, copied to ``target``."""
    source = folder / "report" / f["file"]
    shutil.copy2(source, target / source.name)
    site = target.relative_to(target.parents[2])  # _generated/findings/<name>
    return "".join(f"{indent}{line}\n" if line else "\n" for line in (
        f".. figure:: /{site.as_posix()}/{source.name}", "   :width: 100%",
        f"   :alt: {_text(f['caption'])}", "", f"   {_prose(f['caption'])}", ""))


def _figures(record: dict, folder: Path, docs: Path, name: str) -> str:
    """The report's main figures (`_FIGURES`) with its captions, copied into the site; a
    section of several two to a row (``findings-figures`` in ``_static/flexarm.css``), as
    the report lays them out."""
    target = docs / "_generated" / "findings" / name
    shutil.rmtree(target, ignore_errors=True)
    chosen = {section: [f for f in record["figures"] if f["section"] == section][:count]
              for section, count in _FIGURES.items()}
    if not any(chosen.values()):
        return ""
    target.mkdir(parents=True)
    out = [heading("Figures", "~")]
    for figures in chosen.values():
        if len(figures) > 1:
            out.append(".. container:: findings-figures\n\n")
        out += [_figure(f, folder, target, "   " if len(figures) > 1 else "") for f in figures]
    return "".join(out)


def _kinematics(root: Path) -> str:
    """How much of each paper system's reduced-vs-truth gap the paper's kinematics
    explain (:doc:`theory/exact-kinematics`), from a stored two-factor attribution."""
    folder = _folder(root, "FLEXARM_FINDINGS_KINEMATICS", "kinematics")
    out = [heading("The paper's largest modelling error: its kinematics", "-")]
    table = folder / "attribution.csv"
    if not table.is_file():
        return "".join(out) + _HOW_KINEMATICS.format(folder=_shown(folder, root))
    from validation.report.render import display_unit, fmt_number
    from validation.verdicts.attribution import METRIC_NAMES, METRICS
    with table.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    value = {(r["study"], r["metric"], r["factor"]): float(r["contribution"]) for r in rows}
    body = []
    for study in dict.fromkeys(r["study"] for r in rows):
        for metric in _KINEMATICS_METRICS:
            gap = value.get((study, metric, "total"))
            kin = value.get((study, metric, "kinematics"))
            if gap is None or kin is None:
                continue
            scale, unit = display_unit(METRICS[metric][1])
            closed = fmt_number(100 * 2 * kin / gap) if gap else ""
            # A metric without a value (NaN, "" from fmt_number): a world of it diverged.
            body.append([study, f"{METRIC_NAMES[metric]} [{unit}]",
                         *(fmt_number(scale * v) or "— (diverged)" for v in
                           (gap, kin, value[(study, metric, "plant")])),
                         f"{closed} %" if closed else "— (no gap)" if gap == 0
                         else "— (diverged)"])
    out.append("Each of the paper's systems on the truth plant "
               f"(``campaigns/kinematics.toml``), from ``{_shown(folder, root)}``: the gap "
               "m(truth) − m(reduced model as plant) of each metric, shared by Shapley "
               "values between ``plant`` and ``kinematics`` (:doc:`theory/exact-kinematics`). "
               " The kinematics act only on the reduced plant, so their value is half the "
               "change exact kinematics make there; *closed* = 2 × kinematics / gap is the "
               "share of the gap the exact kinematics close (erratic where the gap is at the "
               "level of a sign observer's chattering or the sensor noise).\n\n")
    out.append(_table(["system", "metric", "gap", "kinematics", "plant", "closed"], body))
    return "".join(out)


def render(docs: Path) -> str:
    """The page's generated part (``docs/_generated/findings.rst``), its figures copied
    into ``docs/_generated/findings/``."""
    root = docs.parent
    records = _records(root)
    out = [".. This file is generated by docs/_ext/flexarm_docs/findings.py.\n\n",
           _answers(records, root)]
    titles = {"paper": "The paper's claims on its own arms",
              "lab": "The paper's claims on the lab arm (friction, drives, current loops)"}
    for name, (folder, record) in records.items():
        out.append(heading(titles[name], "-"))
        if record is None:
            out.append((_HOW if name == "paper" else _HOW_LAB)
                       .format(folder=_shown(folder, root)))
            continue
        if name == "lab":
            out.append("The default arm behind small harmonic drives (``arm = \"lab\"``, "
                       ":doc:`theory/joints`): which of the paper's claims survive the joints "
                       "a real arm has.  ")
        out += [_claims(record, folder, root), _stability(record),
                _figures(record, folder, docs, name)]
    out.append(_kinematics(root))
    return "".join(out)
