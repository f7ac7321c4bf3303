"""The signals of stored runs (issue 48, items 3, 8, 10, 13), grouped by the promise each
case keeps: nothing stale is shown or fitted; a crafted file is bounded before it is
inflated; a re-simulation that cannot run says why, naming the file; bad input is one
line naming the flag, exit 2, nothing written."""
import io
import json
from pathlib import Path

import numpy as np
import pytest

from cli_testing import flexarm
from validation.batch.campaign import campaign_from_mapping
from validation.batch.queue import run_campaign
from validation.batch.executor import SerialRunner
from validation.batch.store.index import transaction
from validation.batch.store.folder import ResultStore

#: One short metrics-only run (its signals are re-simulated on demand).
METRICS_ONLY = {"name": "m", "scenario": {"duration": 0.3, "transient": 0.1,
                                          "observer": {"kind": "smo-paper"}},
                "keep": {"signals": "none"}}


def one_line(done, status: int, *words) -> None:
    assert done.returncode == status, done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1, \
        done.stderr
    for word in words:
        assert word in done.stderr, done.stderr


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("signals") / "out"
    run_campaign(campaign_from_mapping(METRICS_ONLY), out, runner=SerialRunner(),
                 progress=False)
    return out


def _stale_copy(folder, tmp_path) -> Path:
    """``folder`` as other code would have stored it: its run's fingerprint differs (the
    run code changed a signal, not a metric: re-simulating would give other signals)."""
    import shutil
    out = tmp_path / "stale"
    shutil.copytree(folder, out)
    store = ResultStore(out)
    with transaction(store.connection(create=True)) as db:
        db.execute("UPDATE runs SET fingerprint = '0123456789abcdef'")
    store.close()
    return out


# --- nothing stale is shown or fitted (item 3) ------------------------------------------
def test_export_signals_of_a_fresh_metrics_only_run_re_simulates_it(folder, tmp_path):
    """Known-good: made by this code, its signals are re-simulated and written."""
    (rid,) = [r.run_id for r in ResultStore(folder).rows()]
    done = flexarm(tmp_path, "export", "--signals", f"{folder}/{rid}", "--to", "e.csv")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "e.csv").is_file()


@pytest.mark.parametrize("command", ["export", "calibrate"])
def test_a_run_stored_by_other_code_is_not_re_simulated_for_its_signals(folder, tmp_path,
                                                                        command):
    """Known-bad: export --signals wrote, and calibrate fitted, the new code's signals
    with no word; now both refuse, saying what `show` says, and write nothing."""
    out = _stale_copy(folder, tmp_path)
    (rid,) = [r.run_id for r in ResultStore(out).rows()]
    if command == "export":
        done = flexarm(tmp_path, "export", "--signals", f"{out}/{rid}", "--to", "e.csv")
        assert not (tmp_path / "e.csv").exists()
    else:
        (tmp_path / "m.toml").write_text('[calibrate]\nfit = ["true_params.EI1"]\n')
        done = flexarm(tmp_path, "calibrate", f"{out}/{rid}", "--config", "m.toml",
                       "--out", "cal")
        assert not (tmp_path / "cal").exists()
    one_line(done, 2, rid, "stored by other code than this installation")


# --- a crafted file is bounded before it is inflated (item 8) ---------------------------
def _craft(path: Path, shape) -> None:
    """A compressed run file of a 500-sample run whose metadata declares ``shape``."""
    import zlib
    meta = {"status": "ok", "message": "", "end_time": 0.5, "config": {}, "timings": {},
            "packed": {"codec": "float32-differences-shuffled-zlib1", "shape": shape}}
    buf = io.BytesIO()
    np.savez(buf, time=np.zeros(500), names=np.array(["a"] * 50),
             signals=np.frombuffer(zlib.compress(bytes(1 << 20), 9), np.uint8),
             meta=np.frombuffer(json.dumps(meta).encode(), np.uint8))
    path.write_bytes(buf.getvalue())


def test_a_packed_shape_unlike_the_runs_is_refused_before_inflating(tmp_path):
    """Known-bad: 50 × 21,474,836 declared for a 500-sample run of 50 signals (4.3 GB
    inflated by resume and repair); refused from the header, nothing inflated.
    Known-good: the run's own shape is unpacked."""
    from validation.run.results import RunResult
    _craft(tmp_path / "bad.npz", [50, 21_474_836])
    with pytest.raises(ValueError, match="the run has 50 signals at 500 samples"):
        RunResult.from_bytes((tmp_path / "bad.npz").read_bytes())
    good = RunResult(time=np.arange(500) * 1e-3, names=tuple(f"s{i}" for i in range(50)),
                     signals=np.ones((50, 500), np.float32), status="ok", message="",
                     config={}, timings={})
    back, _ = RunResult.from_bytes(good.to_bytes(packed=True))
    np.testing.assert_array_equal(back.signals, good.signals)


def test_repair_sets_a_crafted_run_file_aside(folder, tmp_path):
    """The crafted file under a run id's name: repair names it unreadable and keeps it
    aside (a resume would redo the run), never inflates it."""
    import shutil
    out = tmp_path / "crafted"
    shutil.copytree(folder, out)
    _craft(out / "runs" / "0123456789ab.npz", [50, 21_474_836])
    report = ResultStore(out).repair()
    assert [u.split()[0] for u in report["unreadable"]] == ["0123456789ab"]
    assert (out / "runs" / "0123456789ab.npz.damaged").is_file()


# --- a re-simulation that cannot run says why (item 10) ---------------------------------
def test_a_relative_torque_file_shown_from_elsewhere_is_named(tmp_path):
    """A metrics-only run replaying torques from a relative path: shown from its own
    directory (known-good) its signals come back; from another one the message names
    the unreadable torque file (it said "did not reproduce its stored metrics")."""
    from controllers._replay import file_sha256
    here, elsewhere = tmp_path / "lab", tmp_path / "elsewhere"
    here.mkdir()
    elsewhere.mkdir()
    np.save(here / "tq.npy", np.zeros((400, 2)))
    (here / "c.toml").write_text(
        'name = "r"\n[scenario]\nduration = 0.3\ntransient = 0.1\n'
        '[scenario.controller]\nkind = "replay"\n[scenario.controller.options]\n'
        f'file = "tq.npy"\nsha256 = "{file_sha256(here / "tq.npy")}"\n'
        '[keep]\nsignals = "none"\n')
    done = flexarm(here, "campaign", "c.toml", "--out", "out", "--workers", "1",
                   "--no-progress")
    assert done.returncode == 0, done.stderr
    (rid,) = [r.run_id for r in ResultStore(here / "out").rows()]
    assert flexarm(here, "export", "--signals", f"out/{rid}").returncode == 0
    done = flexarm(elsewhere, "export", "--signals", f"{here}/out/{rid}")
    one_line(done, 2, rid, "tq.npy", "relative path")


# --- bad input: one line naming the flag, exit 2, nothing written (item 13) -------------
def test_export_signals_to_an_existing_directory_names_to(folder, tmp_path):
    (rid,) = [r.run_id for r in ResultStore(folder).rows()]
    (tmp_path / "adir").mkdir()
    done = flexarm(tmp_path, "export", "--signals", f"{folder}/{rid}", "--to", "adir")
    one_line(done, 2, "--to", "adir")
    assert list((tmp_path / "adir").iterdir()) == [] and not any(
        p.name.endswith(".tmp") for p in tmp_path.iterdir())
