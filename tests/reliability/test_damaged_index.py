"""A damaged index row is named in one line by every reader and mended by ``repair``
(issue 59, items 4 and 6-8): text where the index keeps a number (a metric, ``Ts``), a
damaged ``metric_sets`` row, a row that differs from its run file.  Every reader of the
columns that hold numbers checks them the same way (`index.mistyped`); `repair` rebuilds
each damaged row from its run file.  Each case was reproduced first: a traceback from
``report`` (``Ts``) and from export/report/repair (``names = '[1, 2, 3]'``), "Expecting
value: line 1 column 1" naming neither file nor table (``'not json'``), the text copied
into metrics.csv by ``export``, and ``repair`` keeping the text ("4 runs indexed")."""
import shutil
import sqlite3

import pytest

from validation.batch.store.index import TEXT_METRICS
from validation.batch.store.folder import ResultStore
from validation.cli import main


@pytest.fixture(scope="module")
def healthy(tmp_path_factory):
    """A folder of 4 stored runs (reduced plant, 0.2 s), exported; its rows' metrics."""
    out = tmp_path_factory.mktemp("healthy") / "out"
    path = out.parent / "f.toml"
    path.write_text('name = "f"\n[scenario]\nduration = 0.2\ntransient = 0.1\n'
                    '[[sweep]]\ngrid.seed = [0, 1, 2, 3]\n')
    assert main(["campaign", str(path), "--out", str(out), "--no-progress"]) == 0
    store = ResultStore(out)
    metrics = {r.run_id: r.metrics for r in store.rows()}
    store.close()
    return out, metrics


@pytest.fixture()
def folder(healthy, tmp_path):
    out, metrics = healthy
    shutil.copytree(out, tmp_path / "out")
    return tmp_path / "out", metrics


def damage(folder, sql: str) -> None:
    with sqlite3.connect(folder / "index.sqlite") as db:
        db.execute(sql)
    db.close()


def one_line(capsys, *texts) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flexarm: error:"), err
    assert all(t in lines[0] for t in texts), lines[0]
    return lines[0]


DAMAGES = {
    "Ts text": ("UPDATE runs SET Ts = 'fast'", "its Ts holds 'fast', not a number"),
    "metric text": ("UPDATE runs SET \"m:track_max_1\" = 'abc'",
                    "its m:track_max_1 holds 'abc', not a number"),
    "metric broken json": ("UPDATE runs SET \"m:track_max_1\" = '{not json'",
                           "its m:track_max_1 holds '{not json', not a number"),
    "end_time blob": ("UPDATE runs SET end_time = x'00ff'", "its end_time holds"),
    "metric set of numbers": ("UPDATE metric_sets SET names = '[1, 2, 3]'",
                              "table metric_sets, row 1: names '[1, 2, 3]' is not "
                              "[[swept names], [metric names]]"),
    "metric set not json": ("UPDATE metric_sets SET names = 'not json'",
                            "table metric_sets, row 1: names 'not json' is not"),
}


@pytest.mark.parametrize("case", DAMAGES)
def test_a_damaged_row_is_one_line_for_every_reader_and_repaired(folder, capsys, case):
    """export, report and show say what is damaged (the index file, the column or table)
    and the cure in one line, exit 2, write nothing; repair rebuilds the rows from the run
    files: the metrics and metrics.csv come back as they were."""
    out, metrics = folder
    exported = (out / "metrics.csv").read_text()
    sql, why = DAMAGES[case]
    damage(out, sql)
    rid = sorted(metrics)[0]
    for args in (["export", str(out)], ["report", str(out), "--no-progress"],
                 ["show", f"{out}/{rid}", "--no-open"]):
        assert main(args) == 2, args
        one_line(capsys, str(out / "index.sqlite"), why, f"flexarm repair {out}")
    assert (out / "metrics.csv").read_text() == exported and not (out / "report").exists()
    assert main(["repair", str(out)]) == 0
    assert "adopted: 4" in capsys.readouterr().out
    assert {r.run_id: r.metrics for r in ResultStore(out).rows()} == metrics
    assert main(["export", str(out)]) == 0
    assert (out / "metrics.csv").read_text() == exported


def test_a_run_without_a_control_period_is_reported(folder, capsys):
    """Known good: NULL is what the index holds where a number is not given (a scenario
    without ``Ts``: the store writes it so); the report says so instead of raising."""
    out, metrics = folder
    damage(out, "UPDATE runs SET Ts = NULL")
    assert main(["report", str(out), "--no-progress", "--no-animation"]) == 0
    assert "control periods Ts: not given" in (out / "report" / "report.md").read_text()


@pytest.mark.parametrize("sql, column", [
    ("UPDATE runs SET \"m:track_max_1\" = 5.0 WHERE run_id = ?", "m:track_max_1"),
    ("UPDATE runs SET message = 'fine' WHERE run_id = ?", "message"),
    ("UPDATE runs SET name = 'other' WHERE run_id = ?", "name"),
    ("UPDATE runs SET \"a:seed\" = 7 WHERE run_id = ?", "a:seed")])
def test_repair_checks_each_row_against_its_run_file(folder, capsys, sql, column):
    """A row that reads well but holds other values than its run file is rebuilt from
    the file (known bad: repair kept it, "4 runs indexed")."""
    out, metrics = folder
    rid = sorted(metrics)[1]
    before = ResultStore(out).row(rid)
    with sqlite3.connect(out / "index.sqlite") as db:
        db.execute(sql, (rid,))
    db.close()
    assert main(["repair", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"dropped: 1 ({rid} (its row differs from its file: {column}))" in printed
    assert f"adopted: 1 ({rid})" in printed
    rows = {r.run_id: r for r in ResultStore(out).rows()}
    assert {k: r.metrics for k, r in rows.items()} == metrics
    assert (rows[rid].message, rows[rid].name, rows[rid].axes) == ("", "f/sweep0",
                                                                    before.axes)


def test_repair_of_a_healthy_folder_changes_nothing(folder, capsys):
    """Known good: every row is what its file says (no row rebuilt)."""
    out, metrics = folder
    assert main(["repair", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "dropped: 0" in printed and "adopted: 0" in printed


def test_a_metrics_only_row_holding_text_is_dropped_by_repair(tmp_path, capsys):
    """A run without a file has nothing to rebuild its row from: repair drops it, saying
    why, and the campaign redoes it."""
    path = tmp_path / "n.toml"
    path.write_text('name = "n"\n[scenario]\nduration = 0.2\ntransient = 0.1\n'
                    '[keep]\nsignals = "none"\n[[sweep]]\ngrid.seed = [0, 1]\n')
    out = tmp_path / "out"
    assert main(["campaign", str(path), "--out", str(out), "--no-progress"]) == 0
    rid = sorted(r.run_id for r in ResultStore(out).rows())[0]
    damage(out, f"UPDATE runs SET \"m:track_max_1\" = 'abc' WHERE run_id = '{rid}'")
    capsys.readouterr()
    assert main(["repair", str(out)]) == 0
    assert f"dropped: 1 ('{rid}' (not a stored run: its m:track_max_1 holds 'abc', not a " \
           "number))" in capsys.readouterr().out
    assert len(ResultStore(out).rows()) == 1


def test_the_text_metrics_are_those_a_run_makes():
    """`TEXT_METRICS` (the metric columns the readers let hold text) are exactly the
    metrics of a run with an observer and a requirement whose value is text."""
    from validation.batch.worker import execute_run
    from validation.run.scenario import scenario_from_mapping
    s = scenario_from_mapping({"duration": 0.2, "transient": 0.1,
                               "observer": {"kind": "smo-paper"},
                               "requirement": [{"name": "r", "claim": "tracking"}]})
    _, metrics = execute_run(s)
    assert {k for k, v in metrics.items() if isinstance(v, str)} == TEXT_METRICS
    assert all(isinstance(v, (int, float)) for k, v in metrics.items()
               if k not in TEXT_METRICS)
