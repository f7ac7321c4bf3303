"""Reports a reader can trust: tables well formed in HTML and markdown, every section
from stored data, diverged runs named and never drawn as data (marked in a strip of their
own), nothing from the network, what was run stated, every table whole on the printed
page, and an unchanged report not rendered again."""
import re
import shutil
import subprocess
from html.parser import HTMLParser

import pytest

from validation.batch.campaign import campaign_from_mapping

from validation.batch.queue import run_campaign
from validation.report.sweep_figures import sweep_figures
from validation.report.report import write_report
from validation.batch.store.folder import ResultStore

class Tables(HTMLParser):
    """Every <table>: its header cells (count and texts), the cell count of each body row,
    and whether it is printed (not inside an element the print stylesheet leaves out:
    class ``noprint`` or a collapsed ``detail``)."""

    BLOCKS = ("div", "section")

    def __init__(self):
        super().__init__()
        self.tables, self._row, self._in_head, self._th = [], None, False, None
        self._hidden = []  # per open div/section: whether print leaves it out

    def handle_starttag(self, tag, attrs):
        if tag in self.BLOCKS:
            classes = (dict(attrs).get("class") or "").split()
            self._hidden.append("noprint" in classes or "detail" in classes)
        if tag == "table":
            self.tables.append({"head": 0, "rows": [], "headers": [],
                                "printed": not any(self._hidden)})
        elif tag == "thead":
            self._in_head = True
        elif tag == "tr":
            self._row = 0
        elif tag in ("td", "th") and self._row is not None:
            self._row += 1
            if tag == "th":
                self._th = []

    def handle_data(self, data):
        if self._th is not None:
            self._th.append(data)

    def handle_endtag(self, tag):
        if tag in self.BLOCKS:
            self._hidden.pop()
        if tag == "thead":
            self._in_head = False
        elif tag == "th" and self._th is not None:
            self.tables[-1]["headers"].append(" ".join("".join(self._th).split()))
            self._th = None
        elif tag == "tr" and self._row is not None:
            t = self.tables[-1]
            if self._in_head:
                t["head"] = self._row
            else:
                t["rows"].append(self._row)
            self._row = None


@pytest.fixture(scope="module")
def report(reported):
    html_path, md_path = write_report(reported, progress=False)
    return reported, html_path.read_text(), md_path.read_text()


def test_every_html_table_row_has_as_many_cells_as_its_header(report):
    _, page, _ = report
    parser = Tables()
    parser.feed(page)
    assert len(parser.tables) >= 3
    for t in parser.tables:
        assert t["rows"] and all(n == t["head"] for n in t["rows"]), t


def test_markdown_tables_are_well_formed(report):
    _, _, md = report
    lines = md.splitlines()
    blocks, current = [], []
    for line in lines + [""]:
        if line.startswith("|"):
            current.append(line)
        elif current:
            blocks.append(current)
            current = []
    assert len(blocks) >= 3
    for block in blocks:
        # Cells split on unescaped pipes only: "max \\|e₁\\|" is one cell.
        counts = {len(re.split(r"(?<!\\)\|", row.strip())) for row in block}
        assert len(counts) == 1, block[:3]


def test_what_was_run_and_what_diverged_is_stated(report):
    out, page, md = report
    assert "Report: rep" in md and "report test" in md
    assert "arm: default" in md and "control periods Ts: 0.5 ms, 1 ms, 8 ms" in md
    diverged = [r for r in ResultStore(out).rows() if r.status == "diverged"]
    assert len(diverged) == 1 and diverged[0].config["Ts"] == 8e-3
    assert "diverged: " in md and "<tr class=\"diverged\">" in page
    # Self-contained: no link or script from the network.
    body = page.split("<body>")[1]
    assert "http://" not in body and "https://" not in body and "<script" not in body
    assert page.count("data:image/png;base64,") >= 6  # paper figures, sweeps, validity map
    assert (out / "report" / "arm.gif").stat().st_size > 10_000
    # The window the metrics are taken over, and the summary with margins and Δ.
    assert "metrics after the transient: 1 s of 3 s runs" in md
    assert "## Summary" in md and "margin +" in md and "Δ " in md
    assert "track_max" not in md and "tau_tv" not in md  # human names, not metric keys


def test_a_diverged_run_is_never_a_data_point(report, monkeypatch):
    """Diverged runs are crimson × marks in a strip of their own: never on the axes that
    hold the data, so a mark can never be read as a value in the data's y-range."""
    out, _, _ = report
    rows = [r for r in ResultStore(out).rows() if r.sweep == "ts"]
    drawn = []
    import validation.report.figures as figures
    real_plot = figures.plt.Axes.plot

    def spy(ax, *args, **kw):
        drawn.append((ax, args, kw))
        return real_plot(ax, *args, **kw)
    monkeypatch.setattr(figures.plt.Axes, "plot", spy)
    sweep_figures("ts", rows)
    data = [(ax, args) for ax, args, kw in drawn if kw.get("label") and args and "marker" in kw]
    marks = [(ax, args) for ax, args, kw in drawn if args and args[-1] == "x"]
    data_x = [x for _, args in data for x in args[0]]
    assert 8.0 not in data_x  # Ts = 8 ms has no value...
    assert 8.0 in [x for _, args in marks for x in args[0]]  # ...it is marked as diverged
    data_axes = {id(ax) for ax, _ in data}
    assert marks and all(id(ax) not in data_axes for ax, _ in marks)
    for ax, args in marks:  # the strip has rows of its own, no scale: one per series
        assert ax.get_ylim() == (0.6, -0.6) and list(args[1]) == [0]
    named = [t.get_text() for ax, _ in marks for t in ax.get_yticklabels()]
    assert "truth plant (Exudyn)" in named or "reduced plant" in named  # which plant diverged


def test_attribution_rule_is_whole():
    """attribution.md states the rule for diverged worlds from its first word."""
    from validation.verdicts.attribution import DIVERGED_RULE
    assert DIVERGED_RULE.startswith("Worlds that diverge or fail have no metrics. Rule: ")
    assert DIVERGED_RULE.endswith("No diverged run's metric is ever used.")


def test_an_unchanged_report_is_not_rendered_again(report):
    """Same runs, same code: the content key matches and nothing is written; a changed
    input (here: the animation, the campaign's report settings) changes the key."""
    from validation.report.content_key import content_key, report_is_current
    out, _, _ = report
    html = out / "report" / "report.html"
    assert report_is_current(out)
    before = html.stat().st_mtime_ns
    write_report(out, progress=False)
    assert html.stat().st_mtime_ns == before
    key = content_key(out, animate=True)
    assert content_key(out, animate=False) != key
    store = ResultStore(out)
    store.set_campaign("rep", {"description": "changed"})
    store.close()
    assert not report_is_current(out)


CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")
                 if shutil.which(n)), None)
PDFTOTEXT = shutil.which("pdftotext")


def word_pieces(text: str) -> list[str]:
    """The letter/digit runs of a header: what survives any line break the browser or
    pdftotext makes inside it."""
    return re.findall(r"\w+", text)


@pytest.mark.skipif(not (CHROMIUM and PDFTOTEXT), reason="the print test needs chromium and "
                    "pdftotext: apt-get install chromium poppler-utils")
def test_the_printed_report_shows_every_column_of_every_table(report, tmp_path):
    """Print report.html with headless Chromium, read the PDF back with
    ``pdftotext -layout``, and find every table's header row: a line holding the first
    word of every header cell, left to right (headers are top-aligned, so their first
    lines share a line), with every word of every header in it or the 4 lines below.  A
    table cut at the page's edge loses its right columns, collapsed sections that stay
    collapsed lose their tables: either fails here.  Tables the print leaves out on
    purpose (runs and metrics, the folded details: in the HTML and the CSV files) are said
    to be left out, on the printed page."""
    out, page, _ = report
    pdf = tmp_path / "report.pdf"
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
                    "--disable-background-networking", "--no-pdf-header-footer",
                    f"--print-to-pdf={pdf}", (out / "report" / "report.html").as_uri()],
                   capture_output=True, timeout=180, check=True)
    text = subprocess.run([PDFTOTEXT, "-layout", str(pdf), "-"], capture_output=True,
                          text=True, check=True).stdout
    lines = text.splitlines()
    parser = Tables()
    parser.feed(page)
    printed = [t for t in parser.tables if t["printed"]]
    assert len(printed) >= 3 and len(printed) < len(parser.tables)
    assert "Runs and metrics: not printed (in report.html, metrics.csv and manifest.json)" \
        in " ".join(text.split())
    at = 0
    for table in printed:
        firsts = [word_pieces(h)[0] for h in table["headers"]]

        def holds_in_order(line):
            pos = 0
            for w in firsts:
                pos = line.find(w, pos)
                if pos < 0:
                    return False
                pos += len(w)
            return True
        found = next((i for i in range(at, len(lines)) if holds_in_order(lines[i])), None)
        assert found is not None, f"no printed header row for {table['headers']}"
        block = " ".join(lines[found:found + 5])
        missing = [h for h in table["headers"] if not all(w in block for w in word_pieces(h))]
        assert not missing, f"headers cut from the printed table: {missing}"
        at = found + 1


def test_a_sweep_over_the_plant_table_draws_both_plants_titled_in_words(tmp_path):
    """A campaign sweeping whole plant tables (not plant.kind): each scenario's runs on
    the two plants are one figure group, its title names no plant table."""
    from validation.report.groups import _title, figure_groups, plant_groups
    spec = {"name": "p", "scenario": {"duration": 0.1, "transient": 0.05,
                                      "observer": {"kind": "none"}},
            "sweep": [{"name": "plants", "grid": {"plant": [{"kind": "reduced"},
                                                            {"kind": "exudyn"}],
                                                  "seed": [1, 2]}}]}
    run_campaign(campaign_from_mapping(spec), tmp_path, progress=False)
    runs = ResultStore(tmp_path).rows()
    groups = plant_groups(runs)
    assert len(groups) == 2 and all([r.role for r in g] == ["truth", "reduced"] for g in groups)
    (drawn,), _ = figure_groups(runs, None)
    assert len(drawn) == 2
    assert "plant=" not in _title(drawn) and "{" not in _title(drawn)


def test_the_report_is_navigable_and_its_figures_named_by_content(report):
    """A table of contents whose every entry is a section (collapsible: a checkbox, open at
    first); the summary counts verdicts and does not repeat the claims table; figure
    files say what they show; the animation prints as a still, not its first frame."""
    out, page, md = report
    toc = re.search(r'<nav class="toc".*?</nav>', page, flags=re.S).group(0)
    anchors = re.findall(r'href="#([\w-]+)"', toc)
    assert anchors[:2] == ["summary", "claims"] and "paper-figures" in anchors
    for anchor in anchors:
        assert re.search(rf'<section class="fold section[^"]*" id="{anchor}"><input '
                         rf'type="checkbox" id="sec-{anchor}" checked', page), anchor
    summary = page[page.index('id="summary"'):page.index('id="claims"')]
    assert "1 window-sensitive" in summary or "holds" in summary
    counts = summary.split("<tbody>")[1].split("</tbody>")[0]
    assert "margin" not in counts and "mrad" not in counts  # counts, not the claims' cells
    files = sorted(p.name for p in (out / "report" / "figures").iterdir())
    assert not [f for f in files if re.fullmatch(r"fig\d+\.png", f)]
    assert any(f.endswith("joint-tracking-fig-3.png") for f in files)
    assert any(f.endswith("phase-portrait-fig-8.png") for f in files)
    assert 'class="screen-only"><img src="data:image/gif' in page
    assert 'class="print-only"><img src="data:image/png' in page


def test_a_chattering_rate_is_drawn_as_its_mean_and_band(monkeypatch):
    """A θ̇₂ that chatters ±35 rad/s around the reference (Table 1 on the truth plant) is
    not a solid block: its mean per pixel column is the line, the chatter a light band,
    and the y-range stays the orbit's, with the chatter's extent named."""
    import numpy as np
    from types import SimpleNamespace
    from validation.report import figures
    from validation.run.results import RunResult
    t = np.arange(0, 20, 2e-4)
    ref = {f"theta{j}_ref": 2 * np.sin(0.1 * j * np.pi * t) for j in (1, 2)}
    rates = {f"theta{j}_dot_ref": 0.2 * j * np.pi * np.cos(0.1 * j * np.pi * t) for j in (1, 2)}
    chatter = 35.0 * np.where(np.arange(t.size) % 2, 1.0, -1.0)
    signals = {**ref, **rates, "theta1": ref["theta1_ref"], "theta2": ref["theta2_ref"],
               "theta1_dot": rates["theta1_dot_ref"], "theta2_dot": rates["theta2_dot_ref"] + chatter}
    res = RunResult(t, tuple(signals), np.array(list(signals.values())))
    run = SimpleNamespace(role="truth", plant_label="truth plant (Exudyn)")
    texts, limits = [], []
    real_png = figures.png

    def spy(fig):
        ax = fig.axes[1]
        texts.append(ax.get_title())
        limits.append(ax.get_ylim())
        return real_png(fig)
    monkeypatch.setattr(figures, "png", spy)
    figures.phase_portrait([(run, res)], "table1", 2.0, 0.05)
    assert any(re.search(r"truth: θ̇₂ chatters over -3\d\.?\d*…3\d\.?\d* rad/s", text)
               for text in texts), texts
    lo, hi = limits[0]
    assert -6 < lo < -1.2 and 1.2 < hi < 6  # at most 3× the orbit's ±1.26 rad/s, not ±35


def test_the_report_opens_with_its_bottom_line(report):
    """Issue 47: the first thing under the title is sentences a reviewer can quote,
    computed from the stored runs: the counts, where the divergence is, the claims."""
    out, page, md = report
    first = md.split("\n\n")[1]
    rows = [r for r in ResultStore(out).rows() if r.sweep != "mesh-check"]
    assert first.startswith("**On the truth plant, default arm (1 column × the paper's 9 "
                            "claims): "), first
    assert "On the reduced model, default arm (1 column × the paper's 9 claims)" in first
    assert first.endswith(f"{len(rows)} runs: {len(rows) - 1} completed, 1 diverged, 0 failed. "
                          "1 divergence is on the default arm at Ts = 8 ms, reduced plant.**")
    assert '<p class="bottom-line">' in page.split("<h2")[0]
    # The Summary counts each plant apart: the truth plant's verdicts are not mixed in.
    assert "| claim | default arm, truth plant (1 column) | default arm, reduced model (1 " \
        "column) | " in md


def _row(status, arm="table1", Ts=1e-3, plant="truth plant (Exudyn)", run_id=""):
    from types import SimpleNamespace
    return SimpleNamespace(status=status, arm=arm, Ts=Ts, plant_label=plant, run_id=run_id)


def test_the_bottom_line_says_where_runs_diverged_and_counts_checks_apart():
    """The first screen of issue 47's reproduction said "100 runs: 56 ok, 44 diverged, 0
    failed" while all 44 divergences were Table 1's arm at 1 ms and 22 mesh-check runs had
    failed: the sentences name the place and count the checks apart."""
    from validation.report.bottom_line import bottom_line
    runs = [_row("ok", "default")] * 56 + [_row("diverged")] * 40 + \
        [_row("diverged", plant="reduced plant")] * 4
    checks = [_row("failed")] * 22 + [_row("ok", "default")] * 44
    lines = bottom_line(runs, checks, [])
    assert lines == [
        "100 runs: 56 completed, 44 diverged, 0 failed; their 66 mesh/step-check runs (the "
        "truth-plant runs again on refined meshes and steps): 44 completed, 0 diverged, 22 "
        "failed.",
        "All 44 divergences are on the table1 arm at Ts = 1 ms, reduced plant and truth "
        "plant (Exudyn); all 22 failed checks are on the table1 arm at Ts = 1 ms, truth "
        "plant (Exudyn)."]
    # Divergences in several places: each named with its count, most first.
    spread = [_row("diverged")] * 3 + [_row("diverged", "default", 5e-3)] * 2
    assert bottom_line(spread, [], [])[1] == (
        "The 5 divergences: 3 on the table1 arm at Ts = 1 ms, truth plant (Exudyn); 2 on the "
        "default arm at Ts = 5 ms, truth plant (Exudyn).")
    # The divergences the stability map foresees are said to be expected; the rest named.
    foreseen = [_row("diverged", run_id=f"r{i}") for i in range(3)]
    other = [_row("diverged", "default", 5e-3, run_id="x")]
    assert bottom_line(foreseen, [], [], expected={"r0", "r1", "r2"})[1] == (
        "All of the 3 divergences are expected: at or beyond the stability map's first "
        "divergence of their arm and plant.")
    assert bottom_line(foreseen + other, [], [], expected={"r0", "r1", "r2"})[1] == (
        "3 of the 4 divergences are expected: at or beyond the stability map's first "
        "divergence of their arm and plant; 1 unexpected divergence is on the default arm "
        "at Ts = 5 ms, truth plant (Exudyn).")
    # Nothing stopped: no second sentence.
    assert bottom_line([_row("ok")] * 3, [], []) == ["3 runs: 3 completed, 0 diverged, 0 failed."]
