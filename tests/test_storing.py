"""Workers store their own runs (issue 35): the file is written where the run was made and
only its row comes back; rows are committed in batches; a crash between a file and its
row loses no run (resume and repair adopt the file); a worker that cannot reach the
folder sends the file's bytes; and what a run keeps is the campaign's choice, the exact
scenario always kept so that its signals are re-simulated bit for bit."""
import shutil

import numpy as np
import pytest

from campaign_testing import metrics_table
from validation.batch.store import committing
from validation.batch.campaign import campaign_from_mapping, expand
from validation.batch.queue import run_campaign
from validation.batch.executor import SerialRunner
from validation.batch.store.errors import StoreError
from validation.batch.store.resimulate import every_signal
from validation.batch.store.folder import ResultStore, environment
from validation.batch.store.writing import (Destination, StoreTask, landed, leave_token,
                                      run_and_store)
from validation.run.config import ConfigError

SMALL = {"name": "small", "scenario": {"duration": 0.3, "transient": 0.1,
                                       "observer": {"kind": "smo-paper"},
                                       "sensors": {"encoder_noise": 1e-4}},
         "sweep": [{"grid": {"seed": [1, 2, 3, 4]}}]}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """SMALL stored with every signal (the default)."""
    out = tmp_path_factory.mktemp("reference")
    run_campaign(campaign_from_mapping(SMALL), out, runner=SerialRunner(), progress=False)
    return out


def test_a_crash_between_files_and_rows_loses_no_run(reference, tmp_path, monkeypatch):
    """The command dies after its workers put every file in place and before any row was
    committed (as kill -9 can leave it): resume adopts the files without running them
    again, repair rebuilds the same index."""
    monkeypatch.setattr(committing.Committer, "flush", lambda self: None)
    crashed = tmp_path / "crashed"
    run_campaign(campaign_from_mapping(SMALL), crashed, runner=SerialRunner(), progress=False)
    monkeypatch.undo()
    store = ResultStore(crashed)
    assert store.rows() == [] and len(store.unindexed_files()) == 4
    store.close()
    repaired = tmp_path / "repaired"
    shutil.copytree(crashed, repaired)
    assert sorted(ResultStore(repaired).repair()["adopted"]) == sorted(metrics_table(reference))
    assert metrics_table(repaired) == metrics_table(reference)
    summary = run_campaign(campaign_from_mapping(SMALL), crashed, runner=SerialRunner(),
                           progress=False)
    assert (summary.skipped, summary.done) == (4, 0)  # adopted, not run again
    assert metrics_table(crashed) == metrics_table(reference)


def test_rows_arriving_together_share_a_transaction(monkeypatch):
    """Rows are committed INTERVAL after the last commit at the latest (when the runner
    asks before a wait), at once when they arrive after a quiet spell, and all of them
    when the command stops."""
    now = [100.0]
    monkeypatch.setattr(committing.time, "monotonic", lambda: now[0])
    commits = []

    class Store:
        def insert(self, rows):
            commits.append(list(rows))

    c = committing.Committer(Store())
    now[0] += 1.0  # a quiet spell: the first row is committed as soon as the runner waits
    c.add(("a",))
    assert c.idle() is None and commits == [[("a",)]]
    for row in ("b", "c", "d"):  # a burst: within INTERVAL of the last commit
        c.add((row,))
        wait = c.idle()
        assert wait is not None and 0 < wait <= committing.INTERVAL
    assert commits == [[("a",)]]
    now[0] += committing.INTERVAL
    assert c.idle() is None and commits[-1] == [("b",), ("c",), ("d",)]
    c.add(("e",))
    c.flush()  # the command stops: nothing waits
    assert commits[-1] == [("e",)] and c.idle() is None


def test_a_worker_that_cannot_reach_the_folder_sends_the_file(reference, tmp_path):
    """No token to read (a Dask worker on another machine): the worker sends the file's
    bytes with the row, the command writes them; the same row, the same file."""
    (run,) = [r for r in expand(campaign_from_mapping(SMALL)) if r.scenario.seed == 1]
    store = ResultStore(tmp_path)
    store.prepare()
    for reach in (None, leave_token(tmp_path)):
        task = StoreTask(run.run_id, run.scenario, run.sweep, dict(run.axes),
                         Destination(str(tmp_path), "small", environment(), reach=reach))
        (store.runs_dir / f"{run.run_id}.npz").unlink(missing_ok=True)
        stored = run_and_store(task)
        assert (stored.data is None) == (reach is not None)
        assert (store.runs_dir / f"{run.run_id}.npz").exists() == (reach is not None)
        store.insert([landed(tmp_path, stored).values])
        assert store.verify() == {}
        assert metrics_table(tmp_path) == {run.run_id: metrics_table(reference)[run.run_id]}
        np.testing.assert_array_equal(store.load(run.run_id).signals,
                                      ResultStore(reference).load(run.run_id).signals)


@pytest.mark.parametrize("keep", [{"signals": ["theta1", "tau2"]}, {"every": 7},
                                  {"signals": ["theta2"], "every": 10}, {"signals": "none"},
                                  {"compress": True}, {"signals": ["tau1"], "compress": True}])
def test_what_a_run_keeps_and_its_signals_on_demand(reference, tmp_path, keep):
    """A campaign that keeps a subset, decimated signals or metrics only stores the same
    metrics and, of the signals it keeps, the same values bit for bit (compressed too);
    every signal of any of its runs is re-simulated bit for bit; its files are smaller."""
    out = tmp_path / "kept"
    run_campaign(campaign_from_mapping(dict(SMALL, keep=keep)), out, runner=SerialRunner(),
                 progress=False)
    assert metrics_table(out) == metrics_table(reference)
    full, kept = ResultStore(reference), ResultStore(out)
    for row in kept.rows():
        everything = full.load(row.run_id)
        stored = kept.load(row.run_id)
        names = keep.get("signals", "all")
        names = everything.names if names == "all" else () if names == "none" else names
        every = keep.get("every", 1)
        assert stored.names == tuple(n for n in everything.names if n in names)
        if names:
            np.testing.assert_array_equal(stored.time, everything.time[::every])
            np.testing.assert_array_equal(stored.signals,
                                          everything.select(names)[:, ::every])
        assert row.size < full.row(row.run_id).size
        assert row.has_file == (names != ())  # metrics only: the row is all of it
        again = every_signal(kept, row)
        assert again.names == everything.names
        np.testing.assert_array_equal(again.signals, everything.signals)


def test_re_simulation_refuses_a_run_it_does_not_reproduce(tmp_path):
    """Known-bad: a stored metric that the scenario does not give (other code made it)."""
    from validation.batch.store.index import metric_column, transaction
    out = tmp_path / "kept"
    run_campaign(campaign_from_mapping(dict(SMALL, keep={"signals": "none"})), out,
                 runner=SerialRunner(), progress=False)
    store = ResultStore(out)
    row = store.rows()[0]
    with transaction(store.connection(create=True)) as db:  # as if other code had stored it
        db.execute(f"UPDATE runs SET {metric_column('track_max_1')} = ? WHERE run_id = ?",
                   (row.metrics["track_max_1"] * (1 + 1e-15), row.run_id))
    with pytest.raises(StoreError, match="did not reproduce its stored metrics"):
        every_signal(store, store.row(row.run_id))


def test_packed_signals_unpack_exactly_or_not_at_all():
    """Known-good: any float32 values (NaN, ±inf, subnormals, sign changes) come back bit
    for bit.  Known-bad: a stream that holds fewer or more values than its shape, or a
    shape no run has, is refused before anything is inflated beyond it."""
    from validation.run.packing import MAX_UNPACKED, pack, unpack
    rng = np.random.default_rng(3)
    values = rng.standard_normal((5, 1001)).astype(np.float32)
    values[0, :4] = [np.nan, np.inf, -np.inf, np.float32(1e-45)]
    packed = pack(values)
    assert unpack(packed, values.shape).tobytes() == values.tobytes()
    for shape in ((5, 1000), (5, 1002), (4, 1001)):
        with pytest.raises(ValueError):
            unpack(packed, shape)
    with pytest.raises(ValueError):
        unpack(packed[:-10], values.shape)
    with pytest.raises(ValueError):
        unpack(packed, (MAX_UNPACKED, 1))


@pytest.mark.parametrize("keep, key", [({"signals": ["theta1", "nope"]}, "keep.signals"),
                                       ({"signals": "some"}, "keep.signals"),
                                       ({"every": 0}, "keep.every"),
                                       ({"every": 1.5}, "keep.every"),
                                       ({"compress": "yes"}, "keep.compress"),
                                       ({"decimate": 2}, "keep.decimate")])
def test_a_bad_keep_table_names_its_key(keep, key):
    with pytest.raises(ConfigError) as err:
        expand(campaign_from_mapping(dict(SMALL, keep=keep)))
    assert err.value.path == key


def test_a_signal_between_two_results_ends_the_runs_in_flight_before_adopting_files(
        tmp_path, monkeypatch):
    """A Ctrl-C that lands while the command stores one result (not while it waits) left
    the other workers running while it looked for the files they had put in place, and
    skipped the run it was storing: runs that had finished were kept only on resume (their
    files adopted then).  The runner's runs end first; then every file in place without a
    row is adopted."""
    from validation.batch import queue
    from validation.batch.interrupts import Interrupted
    order = []

    class Runner:
        def results(self, tasks, idle=None):
            tasks = list(tasks)
            try:
                yield tasks[0][0], run_and_store(tasks[0][1])
                yield tasks[1][0], run_and_store(tasks[1][1])
            finally:  # as LocalPoolRunner ends the runs in flight
                order.append("runs ended")
                run_and_store(tasks[2][1])  # a worker that finished just as it was stopped

    def stopped(out, stored):
        order.append("signal")
        raise Interrupted(2)

    real_adopt = queue._landed_uncommitted

    def adopting(store, runs):
        order.append("files looked for")
        return real_adopt(store, runs)

    monkeypatch.setattr(queue, "landed", stopped)
    monkeypatch.setattr(queue, "_landed_uncommitted", adopting)
    summary = run_campaign(campaign_from_mapping(SMALL), tmp_path, runner=Runner(),
                           progress=False)
    assert summary.interrupted == 2
    assert order == ["signal", "runs ended", "files looked for"]  # known bad: looked first
    # Known bad: 0 (the one being stored was skipped), then 1 (the one after never looked for).
    assert len(ResultStore(tmp_path).rows()) == 2


def test_an_in_memory_store_keeps_float64_signals_and_writes_nothing(tmp_path, monkeypatch):
    """Known-good: the runs an inner loop asks for come back with every signal as the run
    made it (float64, equal to the run itself), rows and metrics as a folder's; nothing
    is written (the working directory stays empty).  Known-bad: the folder's copy of
    the same run is float32 (what calibration's residuals went through)."""
    from validation.batch.store.memory import MemoryStore
    from validation.run.loop import run_scenario
    from validation.run.scenario import scenario_from_mapping
    from validation.verdicts.evaluations import Evaluations
    monkeypatch.chdir(tmp_path)
    scenario = scenario_from_mapping(SMALL["scenario"] | {"seed": 5})
    memory = Evaluations(MemoryStore(), SerialRunner(), "inner")
    (row,) = memory.run([(scenario, "inner", {"seed": 5})])
    direct = run_scenario(scenario)
    kept = every_signal(memory.store, row)
    assert kept.signals.dtype == np.float64
    np.testing.assert_array_equal(kept.signals, direct.signals)
    assert list(tmp_path.iterdir()) == []
    folder = Evaluations(tmp_path / "out", SerialRunner(), "inner")
    (stored,) = folder.run([(scenario, "inner", {"seed": 5})])
    assert stored.metrics.keys() == row.metrics.keys()
    assert all(stored.metrics[k] == row.metrics[k] or k in ("status",) or
               (isinstance(row.metrics[k], float) and np.isnan(row.metrics[k]))
               for k in row.metrics)
    assert folder.store.load(stored.run_id).signals.dtype == np.float32


def test_store_errors_are_not_value_errors_and_reach_the_caller(tmp_path, monkeypatch):
    """A busy or damaged index while a campaign adopts a file without a row was swallowed
    by `except ValueError` (StoreError was one) and the run redone; now it reaches the
    caller.  Known-good: a file that is not a run file is still passed over."""
    from validation.batch.queue import classify
    from validation.batch.store.errors import IndexBusy, NotARunFile
    assert not issubclass(StoreError, ValueError)
    c = campaign_from_mapping(SMALL)
    planned = expand(c)
    store = ResultStore(tmp_path)
    store.prepare()
    (tmp_path / "runs" / f"{planned[0].run_id}.npz").write_bytes(b"not a run file")
    todo, _ = classify(planned, store, retry_failed=False, reuse_stale=False)
    assert len(todo) == len(planned)  # unreadable: redone
    with pytest.raises(NotARunFile):
        store.adopt(tmp_path / "runs" / f"{planned[0].run_id}.npz")

    def busy(path):
        raise IndexBusy("busy")
    monkeypatch.setattr(store, "adopt", busy)
    with pytest.raises(IndexBusy):
        classify(planned, store, retry_failed=False, reuse_stale=False)
