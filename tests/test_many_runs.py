"""The report of many runs (issue 46): above `validation.report.many.MANY` reported runs
it summarises — quantiles of the main metrics and of each requirement's ρ, the worst
runs, the runs nearest a requirement's boundary — read from the rows' metric columns,
instead of a table row per run."""
import numpy as np
import pytest

from validation.batch.campaign import campaign_from_mapping
from validation.batch.executor import SerialRunner
from validation.batch.queue import run_campaign
from validation.batch.store.records import metric_matrix
from validation.batch.store.folder import ResultStore
from validation.report import many
from validation.report.report import report_data

CAMPAIGN = {"name": "many", "scenario": {"duration": 0.2, "transient": 0.1,
                                         "observer": {"kind": "smo-paper"},
                                         "sensors": {"encoder_noise": 1e-3}},
            "requirement": [{"name": "track",
                             "formula": "always[0.1,0.2](abs(theta1 - theta1_ref) <= 0.0497)"}],
            "keep": {"signals": "none"},
            "sweep": [{"name": "seeds", "grid": {"seed": [1, 2, 3, 4, 5]}}]}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("many")
    run_campaign(campaign_from_mapping(CAMPAIGN), out, runner=SerialRunner(), progress=False)
    return out


def test_many_runs_are_summarised_from_their_columns(folder, monkeypatch):
    """Known-good: 5 runs over a threshold of 3: no table row per run, the quantiles are
    numpy's over the stored metrics, the worst run is the largest value, and the runs
    nearest the requirement's boundary are those of smallest |ρ|."""
    monkeypatch.setattr(many, "MANY", 3)
    data = report_data(folder, animate=False, progress=False)
    assert data.runs is None and data.metrics is None and data.many["count"] == 5
    rows = ResultStore(folder).rows()
    values = metric_matrix(rows, ["track_max_1", "rho_track"])
    head = data.many["quantiles"]["rows"][0]
    assert head[0].startswith("max |e₁|") and head[1] == "5"
    expected = np.quantile(values[:, 0], (0.0, 0.5, 1.0)) * 1e3
    assert [float(head[i]) for i in (2, 4, 6)] == pytest.approx(expected, rel=5e-3)  # 3 digits
    worst = data.many["worst"]["rows"][0][1]
    assert worst.startswith(many.fmt_number(1e3 * values[:, 0].max()))
    assert rows[int(np.argmax(values[:, 0]))].run_id in worst.split(";")[0]
    (deciding,) = data.many["deciding"]["rows"]
    nearest = rows[int(np.argmin(np.abs(values[:, 1])))].run_id
    assert nearest in deciding[2].split(";")[0]
    assert deciding[1] == f"{int((values[:, 1] < 0).sum())} of 5"
    assert any(f.section == "Distributions" for f in data.figures)


def test_a_few_runs_keep_their_table(folder):
    """Known-bad for the summary: at or below the threshold every run has its row."""
    data = report_data(folder, animate=False, progress=False)
    assert data.many is None and len(data.runs["rows"]) == 5
    assert len(data.metrics["rows"]) == 5


def test_a_figure_not_drawn_is_left_out(folder, monkeypatch):
    """Known-bad for the figures: the histograms return None (no run completed, no
    headline metric); the report leaves that figure out instead of writing None."""
    from validation.report import report
    monkeypatch.setattr(many, "MANY", 3)
    monkeypatch.setattr(report, "histograms", lambda done: None)
    data = report_data(folder, animate=False, progress=False)
    assert data.many["count"] == 5 and data.figures
    assert all(f.png is not None for f in data.figures)
    assert not any(f.section == "Distributions" for f in data.figures)
