"""Reports a reader can trust: tables well formed in HTML and markdown, every section
from stored data, diverged runs named and never drawn as data, nothing from the
network, what was run stated."""
import re
from html.parser import HTMLParser

import pytest

from validation.batch.campaign import campaign_from_mapping, run_campaign
from validation.report.figures import sweep_figures
from validation.report.report import write_report
from validation.batch.store import ResultStore

SPEC = {"name": "rep", "description": "report test",
        "scenario": {"duration": 3.0, "transient": 1.0, "observer": {"kind": "smo-bl"},
                     "sensors": {"encoder_noise": 1e-4, "modal_noise": 1e-5, "rate_noise": 1e-3}},
        "report": {"figures": ["both"]},
        "sweep": [{"name": "both", "grid": {"plant.kind": ["reduced", "exudyn"]}},
                  # Ts = 8 ms is beyond the sampled loop's limit (~2.8 ms): it diverges.
                  {"name": "ts", "grid": {"Ts": [5e-4, 1e-3, 8e-3], "plant.step": [5e-4]}}]}


class Tables(HTMLParser):
    """Every <table>: its header cells and the cell count of each body row."""

    def __init__(self):
        super().__init__()
        self.tables, self._row, self._in_head = [], None, False

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self.tables.append({"head": 0, "rows": []})
        elif tag == "thead":
            self._in_head = True
        elif tag == "tr":
            self._row = 0
        elif tag in ("td", "th") and self._row is not None:
            self._row += 1

    def handle_endtag(self, tag):
        if tag == "thead":
            self._in_head = False
        elif tag == "tr" and self._row is not None:
            t = self.tables[-1]
            if self._in_head:
                t["head"] = self._row
            else:
                t["rows"].append(self._row)
            self._row = None


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    run_campaign(campaign_from_mapping(SPEC), out, progress=False)
    html_path, md_path = write_report(out, progress=False)
    return out, html_path.read_text(), md_path.read_text()


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


def test_a_diverged_run_is_never_a_data_point(report, monkeypatch):
    out, _, _ = report
    rows = [r for r in ResultStore(out).rows() if r.sweep == "ts"]
    drawn = []
    import validation.report.figures as figures
    real_plot = figures.plt.Axes.plot

    def spy(ax, *args, **kw):
        drawn.append((args, kw))
        return real_plot(ax, *args, **kw)
    monkeypatch.setattr(figures.plt.Axes, "plot", spy)
    sweep_figures("ts", rows)
    data_x = [x for args, kw in drawn if kw.get("label") and args and "marker" in kw
              for x in args[0]]
    marks = [x for args, kw in drawn if args and args[-1] == "x" for x in args[0]]
    assert 8.0 not in data_x  # Ts = 8 ms has no value...
    assert 8.0 in marks  # ...it is marked as diverged
