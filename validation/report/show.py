"""The paper's Figs. 3–8 analogues of one stored run, as PNG files and a page to view them.

``show_run(row)`` draws the run (with the same scenario on the other plant, overlaid, if
its results folder holds it) into ``RESULTS/show/<run id>/``: nothing is written outside
the results folder.  `open_in_browser` opens the page only where there is a display, and
never fails.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from ..run.results import own_folder, write_atomic
from .render import render

__all__ = ["show_run", "open_in_browser"]

_FILES = {"(Fig. 3)": "fig3_tracking", "(Fig. 4)": "fig4_deflections",
          "(Figs. 5–6)": "fig5-6_rates", "(Fig. 7)": "fig7_estimation_errors",
          "(Fig. 8)": "fig8_phase_portrait"}


def show_run(store, row) -> tuple[Path, list[Path], str]:
    """Draw the paper's figures of the stored run ``row`` of ``store`` (ok runs only);
    returns the page, the PNG files and a note naming the run drawn with it (or "")."""
    from ..batch.fingerprint import is_fresh
    from ..batch.store.resimulate import STALE
    from .groups import claim_bounds, figure_group, paper_figure_tasks
    group = [r for r in figure_group(row, store.rows()) if r.status == "ok"]
    others = [r for r in group if r.run_id != row.run_id]
    note = "".join(f"with {r.run_id}, the same scenario on the {r.plant} plant, overlaid\n"
                   for r in others)
    if not is_fresh(row):
        note += f"note: this run was {STALE}\n"
    folder = own_folder(store.out, "show", row.run_id)
    files, figures = [], []
    for _, caption, draw in paper_figure_tasks(store, group, claim_bounds()):
        name = next(v for k, v in _FILES.items()
                    if caption.partition(" — ")[0].endswith(k)) + ".png"
        data = draw()
        write_atomic(folder / name, lambda fh, data=data: fh.write(data), binary=True)
        files.append(folder / name)
        figures.append({"file": name, "caption": caption})
    page = folder / "index.html"
    text = render("show.html.j2", title=f"{row.name} ({row.run_id})", figures=figures)
    write_atomic(page, lambda fh: fh.write(text))
    return page, files, note.rstrip("\n")


def open_in_browser(path: Path) -> bool:
    """Open ``path`` in a graphical browser if this session has a display; True if one
    was asked to.  Without a display (ssh, CI, containers) nothing is tried: a text
    browser would take over the terminal."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        return False
    import webbrowser
    try:
        return bool(webbrowser.open(path.resolve().as_uri()))
    except (webbrowser.Error, OSError):
        return False
