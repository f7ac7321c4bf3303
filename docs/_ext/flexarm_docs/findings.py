"""The findings page: the paper reproduction's results, generated from a stored
``flexarm reproduce-paper`` results folder — its claims table, its stability map and the
figures of its report — the same claims on the lab arm (``flexarm reproduce-paper
--lab``), and the share of the reduced-vs-truth gap the paper's kinematics explain
(``flexarm attribute campaigns/kinematics.toml``), or, without them, how to produce them.
Never a number typed here.

The folders are ``$FLEXARM_FINDINGS`` or ``results/paper``, ``$FLEXARM_FINDINGS_LAB`` or
``results/lab`` and ``$FLEXARM_FINDINGS_KINEMATICS`` or ``results/kinematics`` (where
``make findings`` writes).
"""
from __future__ import annotations

import csv
import os
import shutil
from pathlib import Path

from .rst import heading, list_table

_HOW = """\
No stored paper reproduction was found at ``{folder}`` when this site was built, so this
page holds no numbers.  To produce them, run from the repository::

    make demo          # flexarm reproduce-paper --out results/paper
    make docs          # this page is then generated from results/paper

(``FLEXARM_FINDINGS=DIR make docs`` reads another results folder of
``flexarm reproduce-paper``.)  What the reproduction runs and how to read its verdicts:
:doc:`guide/verdicts`.
"""


def _csv_table(path: Path) -> str:
    with path.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        return ""
    header, body = rows[0], rows[1:]
    escape = lambda text: text.replace("*", r"\*").replace("`", r"\`").replace("|", r"\|")  # noqa: E731
    return list_table([escape(h) for h in header], [[escape(c) for c in r] for r in body],
                      classes="config-table")


_HOW_LAB = """\
No stored results of the lab arm were found at ``{folder}`` when this site was built.  To
produce them (``make findings`` does)::

    flexarm reproduce-paper --lab --no-stability --out results/lab

"""


def _shown(folder: Path, root: Path):
    return folder.relative_to(root) if folder.is_relative_to(root) else folder


def _lab(root: Path) -> str:
    """The paper's claims on the lab arm (:doc:`theory/joints`), or how to produce them."""
    folder = Path(os.environ.get("FLEXARM_FINDINGS_LAB", root / "results" / "lab"))
    out = ["\n", heading("The paper's claims on the lab arm (friction, drives, current "
                         "loops)", "-")]
    claims = folder / "claims.csv"
    if not claims.is_file():
        return "".join(out) + _HOW_LAB.format(folder=_shown(folder, root))
    out.append(f"The default arm behind small harmonic drives (``arm = \"lab\"``, "
               f":doc:`theory/joints`), generated from ``{_shown(folder, root)}``: which of "
               "the paper's claims survive the joints a real arm has.\n\n")
    out.append(_csv_table(claims))
    return "".join(out)


_HOW_KINEMATICS = """\
No stored attribution of the kinematics was found at ``{folder}`` when this site was
built.  To produce it (``make findings`` does)::

    flexarm attribute campaigns/kinematics.toml --out results/kinematics

"""
#: The metrics the kinematics table shows (`validation.verdicts.attribution.METRICS`).
_KINEMATICS_METRICS = ("track_rms", "track_max", "vib_rms", "est_rms_q")


def _kinematics(root: Path) -> str:
    """How much of each paper system's reduced-vs-truth gap the paper's kinematics
    explain (:doc:`theory/exact-kinematics`), from a stored two-factor attribution."""
    folder = Path(os.environ.get("FLEXARM_FINDINGS_KINEMATICS", root / "results" / "kinematics"))
    out = ["\n", heading("The paper's largest modelling error: its kinematics", "-")]
    table = folder / "attribution.csv"
    if not table.is_file():
        return "".join(out) + _HOW_KINEMATICS.format(folder=_shown(folder, root))
    from validation.verdicts.attribution import METRIC_NAMES, METRICS
    with table.open(newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    value = {(r["study"], r["metric"], r["factor"]): float(r["contribution"]) for r in rows}
    studies = list(dict.fromkeys(r["study"] for r in rows))
    body = []
    for study in studies:
        for metric in _KINEMATICS_METRICS:
            gap = value.get((study, metric, "total"))
            kin = value.get((study, metric, "kinematics"))
            if gap is None or kin is None:
                continue
            closed = f"{2 * kin / gap:.0%}" if gap else ""
            body.append([study, f"{METRIC_NAMES[metric]} [{METRICS[metric][1]}]", f"{gap:.3g}",
                         f"{kin:.3g}", f"{value[(study, metric, 'plant')]:.3g}", closed])
    out.append(f"Each of the paper's systems on the truth plant (default arm, 20 s), from "
               f"``{_shown(folder, root)}``: the gap m(truth) − m(reduced model as plant) of "
               "each metric, shared by Shapley values between ``plant`` and ``kinematics`` "
               "(:doc:`theory/exact-kinematics`).  The kinematics act only on the reduced "
               "plant, so their value is half the change exact kinematics make there; "
               "*closed* = 2 × kinematics / gap is the share of the gap the exact "
               "kinematics close (erratic where the gap is at the level of a sign "
               "observer's chattering or the sensor noise).\n\n")
    out.append(list_table(["system", "metric", "gap", "kinematics", "plant", "closed"], body,
                          classes="config-table"))
    return "".join(out)


def render(docs: Path) -> str:
    root = docs.parent
    folder = Path(os.environ.get("FLEXARM_FINDINGS", root / "results" / "paper"))
    out = [".. This file is generated by docs/_ext/flexarm_docs/findings.py.\n\n"]
    shown = _shown(folder, root)
    claims = folder / "claims.csv"
    if not claims.is_file():
        return "".join(out) + _HOW.format(folder=shown) + _lab(root) + _kinematics(root)
    out.append(f"Generated from the stored results in ``{shown}`` when this site was "
               "built; the full report is ``report/report.html`` there.\n\n")
    out.append(heading("The paper's claims", "-"))
    out.append(_csv_table(claims))
    stability = folder / "stability" / "stability.csv"
    if stability.is_file():
        out.append(heading("The sampled-data stability map", "-"))
        out.append(_csv_table(stability))
    figures = sorted((folder / "report" / "figures").glob("*.png"))
    if figures:
        out.append(heading("Figures of the report", "-"))
        target = docs / "_generated" / "findings"
        shutil.rmtree(target, ignore_errors=True)
        target.mkdir(parents=True)
        for fig in figures:
            shutil.copy2(fig, target / fig.name)
            out.append(f".. figure:: /_generated/findings/{fig.name}\n   :width: 100%\n\n"
                       f"   ``{fig.name}``\n\n")
    return "".join(out) + _lab(root) + _kinematics(root)
