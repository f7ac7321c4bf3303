"""A results folder holds its own files and survives what is done to them: nothing is
written or read through links inside it, damaged rows and files are repaired or refused
by name (never hung on, never a traceback), and an intact run file is never thrown away.
Every case was reproduced against the landed tree first (issue 32, groups 5 and 6)."""
import os
import shutil
import sqlite3
import textwrap
from pathlib import Path

import pytest

from cli_testing import flexarm
from validation.batch.store.folder import ResultStore

CAMPAIGN = textwrap.dedent('''
    name = "f"
    [scenario]
    duration = 0.2
    transient = 0.1
    [[sweep]]
    grid.seed = [0, 1, 2, 3]
''')


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """A folder of 4 stored runs (reduced plant, 0.2 s), made once per module."""
    where = tmp_path_factory.mktemp("stored")
    (where / "f.toml").write_text(CAMPAIGN)
    proc = flexarm(where, "campaign", "f.toml", "--out", "out", "--no-progress")
    assert proc.returncode == 0, proc.stderr
    return where / "out"


@pytest.fixture()
def folder(stored, tmp_path):
    """A copy of `stored` in the test's own folder (``tmp_path / "out"``): each test
    damages its own."""
    (tmp_path / "f.toml").write_text(CAMPAIGN)
    return Path(shutil.copytree(stored, tmp_path / "out", symlinks=True))


def one_line_error(proc, *words):
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert all(w in proc.stderr for w in words), proc.stderr


@pytest.mark.parametrize("link", ["runs", "index.sqlite", "report", "report/figures"])
def test_nothing_is_written_through_a_link_inside_the_folder(folder, tmp_path, link):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    target = folder / link
    if link == "index.sqlite":
        target.rename(elsewhere / "index.sqlite")
        target.symlink_to(elsewhere / "index.sqlite")
    else:
        if target.exists():
            os.rename(target, elsewhere / "moved")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.symlink_to(elsewhere, target_is_directory=True)
    before = sorted(p.name for p in elsewhere.rglob("*"))
    commands = [["report", "out"]] if link.startswith("report") else \
        [["campaign", "f.toml", "--out", "out", "--no-progress"], ["repair", "out"]]
    for args in commands:
        proc = flexarm(tmp_path, *args)
        if args[0] == "repair" and link == "index.sqlite":  # the link set aside, not used
            assert proc.returncode == 0 and (folder / "index.sqlite.damaged").is_symlink()
        else:
            one_line_error(proc, link, "symbolic link")
    assert sorted(p.name for p in elsewhere.rglob("*")) == before


# Issue 48.1: calibrate wrote its torques through a link out of --out (exit 0).
CALIBRATION_DATA = "t,tau1,tau2,theta1,theta2\n" + "".join(
    f"{k / 1000:g},0.1,0.0,{5e-5 * k * k / 1000:.9g},0.0\n" for k in range(40))


@pytest.mark.parametrize("link", ["experiments", "experiments/exp.npy", "experiments/exp.csv",
                                  "calibration.json"])
def test_calibrate_writes_nothing_through_a_link_inside_its_folder(tmp_path, link):
    """``out/experiments`` as a link to a folder outside, or one of the files calibrate
    writes (the torques replayed, the experiment as read, its result) as a link to a file
    outside: refused in one line naming it, exit 2, the outside untouched and nothing
    written in the folder (no index, no runs).  Known-good (once): the same command into
    a plain folder fits (exit 0)."""
    (tmp_path / "exp.csv").write_text(CALIBRATION_DATA)
    (tmp_path / "m.toml").write_text('[calibrate]\nfit = ["true_params.EI1"]\n')
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "victim").write_bytes(b"outside the folder")
    out = tmp_path / "out"
    (out / "experiments").mkdir(parents=True)
    target = out / link
    if link == "experiments":
        target.rmdir()
        target.symlink_to(elsewhere, target_is_directory=True)
    else:
        target.symlink_to(elsewhere / "victim")
    before = {p: p.read_bytes() for p in elsewhere.rglob("*")}
    inside = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    args = ("calibrate", "exp.csv", "--config", "m.toml", "--workers", "1", "--no-progress")
    one_line_error(flexarm(tmp_path, *args, "--out", "out"), link, "symbolic link")
    assert {p: p.read_bytes() for p in elsewhere.rglob("*")} == before
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == inside
    if link != "experiments":
        return
    proc = flexarm(tmp_path, *args, "--out", "plain")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "plain" / "experiments" / "exp.npy").is_file()


def _corrupt_row(folder, sql):
    db = sqlite3.connect(folder / "index.sqlite")
    rid = db.execute("SELECT run_id FROM runs ORDER BY run_id").fetchone()[0]
    db.execute(sql, (rid,))
    db.commit()
    db.close()
    return rid


@pytest.mark.parametrize("sql", ["UPDATE runs SET size = -5 WHERE run_id = ?",
                                 "UPDATE runs SET status = 'excellent' WHERE run_id = ?"],
                         ids=["negative-size", "unknown-status"])
def test_repair_keeps_an_intact_run_file_whatever_its_row_said(folder, tmp_path, sql):
    rid = _corrupt_row(folder, sql)
    proc = flexarm(tmp_path, "repair", "out")
    assert proc.returncode == 0, proc.stderr
    rows = {r.run_id: r for r in ResultStore(folder).rows()}
    assert len(rows) == 4 and rows[rid].status == "ok"  # known bad: 3 of 4, or "excellent"
    assert not list((folder / "runs").glob("*.damaged"))


def test_a_folder_in_a_runs_place_is_set_aside_and_every_run_stored(tmp_path):
    (tmp_path / "f.toml").write_text(CAMPAIGN)
    proc = flexarm(tmp_path, "campaign", "f.toml", "--out", "out", "--no-progress")
    rids = sorted(p.stem for p in (tmp_path / "out" / "runs").glob("*.npz"))
    for p in (tmp_path / "out" / "runs").glob("*.npz"):
        p.unlink()
    for name in ("index.sqlite", "manifest.json", "metrics.csv"):
        (tmp_path / "out" / name).unlink()
    (tmp_path / "out" / "runs" / f"{rids[0]}.npz").mkdir()  # squatting one run's place
    proc = flexarm(tmp_path, "campaign", "f.toml", "--out", "out", "--no-progress")
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert len(ResultStore(tmp_path / "out").rows()) == 4  # known bad: 1 of 7 stored
    assert (tmp_path / "out" / "runs" / f"{rids[0]}.npz.damaged").is_dir()


# The sparse giant is slow (10 s; the FIFO keeps the rule in make test).
@pytest.mark.parametrize("what", ["fifo", pytest.param("sparse", marks=pytest.mark.slow)])
def test_a_fifo_or_a_giant_in_a_run_files_place_is_damaged_not_read(folder, tmp_path, what):
    rid = sorted(p.stem for p in (folder / "runs").glob("*.npz"))[0]
    path = folder / "runs" / f"{rid}.npz"
    path.unlink()
    if what == "fifo":
        os.mkfifo(path)
    else:
        with path.open("wb") as fh:
            fh.truncate(64 << 30)  # 64 GiB, sparse: reading it would take the memory
    for args in (["show", f"out/{rid}", "--no-open"], ["export", "out"], ["report", "out"]):
        proc = flexarm(tmp_path, *args, timeout=120)  # known bad: hung, or MemoryError
        assert "Traceback" not in proc.stderr and proc.returncode in (0, 1, 2), (args, proc.stderr)
    proc = flexarm(tmp_path, "campaign", "f.toml", "--out", "out", "--no-progress", timeout=120)
    assert proc.returncode == 0 and "1 damaged, rerun" in proc.stdout, proc.stdout + proc.stderr
    assert len(ResultStore(folder).rows()) == 4 and not ResultStore(folder).verify()


def test_a_fifo_in_the_manifests_place_does_not_hang_export(folder, tmp_path):
    (folder / "manifest.json").unlink()
    os.mkfifo(folder / "manifest.json")
    proc = flexarm(tmp_path, "export", "out", timeout=120)
    assert "Traceback" not in proc.stderr, proc.stderr


def test_a_run_file_declaring_a_huge_array_is_set_aside(folder, tmp_path):
    rid = sorted(p.stem for p in (folder / "runs").glob("*.npz"))[0]
    path = folder / "runs" / f"{rid}.npz"
    data = bytearray(path.read_bytes())
    # The signals' header: its shape (1, 200...) becomes (10**12, ...)
    at = data.find(b"'shape': (")
    end = data.find(b")", at)
    data[at:end + 1] = b"'shape': (999999999999, 9)".ljust(end + 1 - at)
    path.write_bytes(bytes(data))
    (folder / "index.sqlite").unlink()
    proc = flexarm(tmp_path, "repair", "out")  # known bad: _ArrayMemoryError
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert rid in proc.stdout and len(ResultStore(folder).rows()) == 3


def test_an_index_that_is_a_folder_is_set_aside_by_repair(folder, tmp_path):
    (folder / "index.sqlite").unlink()
    (folder / "index.sqlite").mkdir()
    one_line_error(flexarm(tmp_path, "report", "out"), "index.sqlite", "flexarm repair")
    proc = flexarm(tmp_path, "repair", "out")  # known bad: it told the user to run repair
    assert proc.returncode == 0, proc.stderr
    assert len(ResultStore(folder).rows()) == 4 and (folder / "index.sqlite.damaged").is_dir()


def test_a_one_sample_run_is_reported(tmp_path):
    proc = flexarm(tmp_path, "run", "--duration", "0.001", "--out", "out")
    assert proc.returncode == 0, proc.stderr
    proc = flexarm(tmp_path, "report", "out")  # known bad: "max() arg is an empty sequence"
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr


# smo-bl is slow (12 s; the EKF keeps the rule in make test).
@pytest.mark.parametrize("observer", [pytest.param("smo-bl", marks=pytest.mark.slow), "ekf"])
def test_a_one_sample_run_with_an_observer_is_shown_and_reported_without_warnings(
        tmp_path, observer):
    """Known bad (issue 48, 17): a run that ends before its transient drew its estimation
    figure's measurement band from no samples, and `show` and `report` printed numpy's
    "Mean of empty slice" RuntimeWarning."""
    proc = flexarm(tmp_path, "run", "--duration", "0.001", "--observer", observer,
                   "--name", "one", "--out", "out")
    assert proc.returncode == 0, proc.stderr
    for args in (["show", "out/one", "--no-open"], ["report", "out"]):
        proc = flexarm(tmp_path, *args)
        assert proc.returncode == 0, proc.stderr
        assert "Warning" not in proc.stderr, (args, proc.stderr)
