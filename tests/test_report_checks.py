"""What a report reads while it checks the stored runs (`validation.report.report`): the
content key from the rows already read is the one read from the index, and each arm's
validity map, drawn beside the check, is that of the first of its runs that verifies."""
import dataclasses
import sqlite3

import pytest

from reduced_model import ArmParameters
from validation.batch.campaign import campaign_from_mapping
from validation.batch.executor import SerialRunner
from validation.batch.queue import run_campaign
from validation.batch.store.folder import ResultStore
from validation.report.content_key import content_key
from validation.report.report import report_data
from validation.report.verdict_figures import validity_map
from validation.run.arms import parameter_value

# Two 0.2 s runs of one arm that differ in its payload: their validity maps differ.
CAMPAIGN = {"name": "payloads", "scenario": {"duration": 0.2, "transient": 0.1},
            "sweep": [{"name": "payload", "grid": {"true_params.Mp": [0.1, 0.5]}}]}


@pytest.fixture
def folder(tmp_path):
    run_campaign(campaign_from_mapping(CAMPAIGN), tmp_path, runner=SerialRunner(),
                 progress=False)
    return tmp_path


def _map_of(run) -> bytes:
    return validity_map(ArmParameters.from_mapping(run.config["true_params"]),
                        tuple(run.config["model"]["modes_per_link"]), f"{run.arm} arm")


def _drawn_map(folder) -> tuple[bytes, list]:
    data = report_data(folder, animate=False, progress=False)
    (png,) = [f.png for f in data.figures if f.caption.startswith("validity map")]
    return png, data.warnings


def test_the_content_key_of_rows_read_is_the_key_read_from_the_index(folder):
    """Known-good: the same key either way; known-bad: a row's status changed changes
    the key of the rows read."""
    rows = ResultStore(folder).rows()
    assert content_key(folder, animate=True, rows=rows) == content_key(folder, animate=True)
    assert content_key(folder, animate=True, rows=rows[::-1]) == content_key(folder,
                                                                             animate=True)
    changed = [dataclasses.replace(rows[0], status="failed"), *rows[1:]]
    assert content_key(folder, animate=True, rows=changed) != content_key(folder, animate=True)


def test_the_validity_map_is_that_of_the_first_run_of_its_arm_that_verifies(folder):
    """Known-good: every run verifies, the map is the first run's (drawn beside the
    check); known-bad for that map: the first run's file is gone, so the map drawn is the
    second run's (drawn again after the check), not the first's."""
    first, second = ResultStore(folder).rows()
    assert _map_of(first) != _map_of(second)  # the payloads tell the maps apart
    png, warnings = _drawn_map(folder)
    assert png == _map_of(first) and not warnings
    (folder / first.file).unlink()
    png, warnings = _drawn_map(folder)
    assert png == _map_of(second)
    assert any(first.run_id in w and "file missing" in w for w in warnings), warnings


def test_an_unreadable_first_run_leaves_the_map_to_the_next(folder):
    """Known-bad for drawing beside the check: the first run's detail is one byte (its
    scenario cannot be read to draw its arm's map); the report still draws the map, the
    second run's, and names the first as left out."""
    first, second = ResultStore(folder).rows()
    with sqlite3.connect(folder / "index.sqlite") as db:
        db.execute("UPDATE runs SET detail = X'00' WHERE run_id = ?", (first.run_id,))
    png, warnings = _drawn_map(folder)
    assert png == _map_of(second)
    assert any(first.run_id in w and "left out" in w for w in warnings), warnings


def test_a_map_that_fails_before_the_check_is_drawn_after_it(folder, monkeypatch):
    """Known-bad for drawing beside the check: the first run's map fails (its run, left
    out by the check, is one the map cannot be drawn for); the report still draws the
    map, the second run's, instead of stopping."""
    from validation.report import report
    first, second = ResultStore(folder).rows()
    bad = parameter_value(first.config, "true_params.Mp")

    def failing(params, *args):
        if params.Mp == bad:
            raise RuntimeError("not drawable")
        return validity_map(params, *args)

    monkeypatch.setattr(report, "validity_map", failing)
    (folder / first.file).unlink()
    png, warnings = _drawn_map(folder)
    assert png == _map_of(second)
    assert any(first.run_id in w for w in warnings), warnings
