"""A results store that loses nothing: concurrent writers, signals, code-aware resume,
verification of damaged folders, repair, confined names and caps (issue 13's defects,
each reproduced and shown fixed)."""
import errno
import os
import re
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from campaign_testing import campaign_toml
from cli_testing import flexarm
from validation.batch.campaign import campaign_from_mapping
from validation.batch.queue import run_campaign
from validation.cli import main
from validation.batch.store.folder import ResultStore, StoreError


def spec(name: str, n: int, duration: float = 0.5) -> dict:
    return {"name": name, "scenario": {"duration": duration, "transient": 0.1,
                                       "sensors": {"encoder_noise": 1e-4}},
            "sweep": [{"grid": {"seed": list(range(n))}}]}


def cli(*args, **kw):
    return subprocess.Popen([sys.executable, "-m", "validation.cli", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def wait_rows(out, n, timeout=120):
    deadline = time.time() + timeout
    while time.time() < deadline:
        try:
            if len(ResultStore(out).rows()) >= n:
                return
        except (StoreError, sqlite3.Error):
            pass
        time.sleep(0.02)
    raise AssertionError(f"fewer than {n} runs stored after {timeout} s")


def test_two_campaigns_into_one_folder_both_keep_every_row(tmp_path):
    out = tmp_path / "shared"
    files = []
    for name in ("c", "d"):
        path = tmp_path / f"{name}.toml"
        path.write_text(campaign_toml(spec(name, 12)))
        files.append(path)
    procs = [cli("campaign", str(f), "--out", str(out), "--workers", "1", "--no-progress")
             for f in files]
    results = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], results
    store = ResultStore(out)
    rows = store.rows()
    assert len(rows) == 24 and len(list((out / "runs").glob("*.npz"))) == 24
    assert store.verify() == {}
    assert {r.campaign for r in rows} == {"c", "d"}
    assert (out / "metrics.csv").read_text().count("\n") == 25  # header + every run


OPEN_OUTPUT_REPEATEDLY = """
import sys
from validation.cli.common import open_output
from validation.batch.store.folder import StoreError
refused = 0
for _ in range(200):
    try:
        open_output(sys.argv[1])
    except StoreError:
        refused += 1
print(refused)
"""


def test_commands_opening_one_folder_at_once_all_find_it_writable(tmp_path):
    """Each command checks that --out is writable with a file of its own: with one shared
    probe name, two commands starting together deleted each other's probe and one was
    told "not writable" (the concurrent-campaign test above failed so; measured 42 of
    600 checks refused from two processes)."""
    procs = [subprocess.Popen([sys.executable, "-c", OPEN_OUTPUT_REPEATEDLY,
                               str(tmp_path / "out")], stdout=subprocess.PIPE, text=True)
             for _ in range(2)]
    refused = [int(p.communicate(timeout=300)[0]) for p in procs]
    assert refused == [0, 0]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["index.sqlite", "runs"]


CREATE_FOLDERS_AT = """
import sys, time
from validation.batch.store.folder import ResultStore, StoreError
start, folders = float(sys.argv[1]), sys.argv[2:]
time.sleep(max(0.0, start - time.time()))
refused = 0
for folder in folders:
    try:
        ResultStore(folder).prepare()
    except StoreError:
        refused += 1
print(refused)
"""


def test_commands_creating_one_folder_at_once_both_open_it(tmp_path):
    """Two commands creating the same new folder race to switch its index to a WAL
    journal, which SQLite refuses at once (no busy wait) to the loser: the concurrent
    campaign test above failed so in CI ("busy ... locked for 120 s" after 0 s).  Two
    processes create the same 200 folders in the same order from one start time; without
    the retry 5 to 14 of 400 creations were refused (four runs), with it none may be."""
    folders = [str(tmp_path / f"out{i}") for i in range(200)]
    start = str(time.time() + 2.0)  # both interpreters are up by then
    procs = [subprocess.Popen([sys.executable, "-c", CREATE_FOLDERS_AT, start, *folders],
                              stdout=subprocess.PIPE, text=True) for _ in range(2)]
    refused = [int(p.communicate(timeout=300)[0]) for p in procs]
    assert refused == [0, 0]
    assert all(ResultStore(f).rows() == [] for f in folders)


@pytest.mark.parametrize("workers, sig, status", [("1", signal.SIGTERM, 143),
                                                  ("2", signal.SIGINT, 130)])
def test_a_signal_keeps_finished_runs_and_ends_the_workers(tmp_path, workers, sig, status):
    cfg = tmp_path / "s.toml"
    cfg.write_text(campaign_toml(spec("s", 40, duration=1.0)))
    out = tmp_path / "out"
    proc = cli("campaign", str(cfg), "--out", str(out), "--workers", workers, "--no-progress",
               start_new_session=True)
    wait_rows(out, 3)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert "interrupted" in err and "Traceback" not in err
    rows = ResultStore(out).rows()
    assert 3 <= len(rows) < 40  # what finished is kept, the rest was not run
    assert ResultStore(out).verify() == {}
    deadline = time.time() + 10  # the resource tracker leaves when its pipe closes
    while time.time() < deadline:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    with pytest.raises(ProcessLookupError):  # no worker left behind in its session
        os.killpg(proc.pid, 0)
    again = subprocess.run([sys.executable, "-m", "validation.cli", "campaign", str(cfg),
                            "--out", str(out), "--workers", "1", "--no-progress"],
                           capture_output=True, text=True)
    # A worker may have written the run it held as the signal came (its file complete,
    # not yet in the index): the resume finds it stored too, at most one per worker.
    stored = re.search(r"(\d+) already stored; ran (\d+)", again.stdout)
    assert again.returncode == 0 and stored, again.stdout
    assert len(rows) <= int(stored[1]) <= len(rows) + int(workers)
    assert int(stored[1]) + int(stored[2]) == 40


def _one_run_folder(tmp_path, n=3):
    c = campaign_from_mapping(spec("r", n))
    run_campaign(c, tmp_path, progress=False)
    return c, ResultStore(tmp_path)


def test_results_of_other_code_are_rerun_not_reused(tmp_path):
    c, store = _one_run_folder(tmp_path)
    with sqlite3.connect(store.index_path) as db:  # as if stored by an older loop.py
        db.execute("UPDATE runs SET fingerprint = 'older-code'")
    summary = run_campaign(c, tmp_path, progress=False, reuse_stale=True)
    assert summary.skipped == 3 and summary.done == 0  # only on request
    summary = run_campaign(c, tmp_path, progress=False)
    assert len(summary.stale) == 3 and summary.ok == 3
    assert all(r.fingerprint != "older-code" for r in store.rows())


def _corrupt(path, how):
    data = path.read_bytes()
    if how == "truncate":
        path.write_bytes(data[: len(data) // 2])
    elif how == "garbage":  # same size, different bytes: only the checksum tells
        path.write_bytes(bytes(b ^ 0x5A for b in data))
    elif how == "delete":
        path.unlink()


@pytest.mark.parametrize("how", ["truncate", "garbage", "delete"])
def test_a_damaged_run_file_is_detected_and_redone(tmp_path, how):
    c, store = _one_run_folder(tmp_path)
    victim = store.rows()[1]
    _corrupt(tmp_path / victim.file, how)
    assert victim.run_id in store.verify()
    with pytest.raises(StoreError, match=victim.run_id):
        store.load(victim.run_id)
    summary = run_campaign(c, tmp_path, progress=False)
    assert list(summary.damaged) == [victim.run_id] and summary.ok == 1
    assert store.verify() == {}


def test_a_lost_index_is_rebuilt_from_the_run_files(tmp_path, capsys):
    c, store = _one_run_folder(tmp_path)
    before = {r.run_id: r.metrics for r in store.rows()}
    store.close()
    store.index_path.write_bytes(b"this is not a database" * 100)
    for suffix in ("-wal", "-shm"):
        (tmp_path / f"index.sqlite{suffix}").unlink(missing_ok=True)
    assert main(["report", str(tmp_path)]) == 2  # one line, naming the index and the cure
    assert "flexarm repair" in capsys.readouterr().err
    assert main(["repair", str(tmp_path)]) == 0
    after = ResultStore(tmp_path)
    assert {r.run_id: r.metrics for r in after.rows()} == before
    assert run_campaign(c, tmp_path, progress=False).skipped == 3


def test_names_cannot_escape_the_results_folder(tmp_path, capsys):
    for name in ("../../escaped", "/abs/path", "", "a/b", "line\nbreak", ".hidden"):
        cfg = tmp_path / "c.toml"
        cfg.write_text(f'name = "{name.encode("unicode_escape").decode()}"\n[scenario]\n'
                       'duration = 0.5\ntransient = 0.1\n')
        assert main(["campaign", str(cfg), "--workers", "1"]) == 2
        assert "name: must be a plain name" in capsys.readouterr().err
    assert not (tmp_path.parent / "escaped").exists()
    assert main(["run", "--name", "x\ny", "--duration", "0.5"]) == 2  # a label: printable


@pytest.mark.parametrize("args, text", [
    (["--set", "duration=1e9"], "duration: 1e+09 s at Ts = 0.001 s is 1e+12 samples"),
    (["--set", "plant.step=1e-9"], "internal steps"),
    (["--set", "true_params.L1=1e300"], "true_params"),
    (["--set", "true_params.rho1=5e-324"], "true_params"),
    (["--set", "sensors.encoder_noise=1e300"], "sensors.encoder_noise: must be <= 1000"),
    (["--set", "sensors.delay=100000", "--duration", "1"], "sensors.delay"),
    (["--set", "transient=30", "--duration", "10"], "transient"),
    (["--Ts", "1e-300"], "Ts"),
])
def test_caps_are_one_line_errors(tmp_path, capsys, args, text):
    out = tmp_path / "never"
    assert main(["run", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and text in err[0], err
    assert not out.exists()


def test_include_caps(tmp_path, capsys):
    """Includes that would take forever or without end are one line: a nesting beyond
    the parser's, a file that is no regular file, a chain deeper than 16, and a file
    named twice in one include (each file including the next twice was 2^22 loads)."""
    deep = tmp_path / "deep.toml"
    deep.write_text("x = " + "[" * 1500 + "]" * 1500 + "\n")
    (tmp_path / "zero.toml").write_text('include = "/dev/zero"\n')
    for i in range(22):
        nxt = f'"c{i + 1}.toml"' if i < 21 else None
        (tmp_path / f"c{i}.toml").write_text(f"include = {nxt}\n" if nxt else "duration = 1.0\n")
    (tmp_path / "twice.toml").write_text('include = ["c21.toml", "c21.toml"]\n')
    for name, text in (("deep.toml", "nested deeper than 32"), ("zero.toml", "not a regular file"),
                       ("c0.toml", "nested deeper than 16"), ("twice.toml", "more than once")):
        assert main(["run", "--config", str(tmp_path / name)]) == 2
        assert text in capsys.readouterr().err, name


def test_workers_beyond_the_cores_need_force(capsys, tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(campaign_toml(spec("w", 1)))
    assert main(["campaign", str(cfg), "--workers", "1024", "--out", str(tmp_path / "o")]) == 2
    assert "--force-workers" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_a_full_disk_is_one_line_naming_the_folder(tmp_path, capsys, monkeypatch):
    import validation.batch.store.runfiles as store_module

    def full(path, *a, **k):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))
    monkeypatch.setattr(store_module, "write_atomic", full)
    assert main(["run", "--duration", "0.5", "--set", "transient=0.1",
                 "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no space left on the device" in err[0] and str(tmp_path) in err[0]


def test_failed_runs_keep_the_exit_status_on_a_plain_rerun(tmp_path):
    from validation.run.results import RunResult
    from validation.run.scenario import scenario_to_mapping
    c = campaign_from_mapping(spec("f", 1))
    run = __import__("validation.batch.campaign", fromlist=["expand"]).expand(c)[0]
    ResultStore(tmp_path).add(run.run_id, RunResult(
        time=np.zeros(0), names=(), signals=np.zeros((0, 0)), status="failed",
        message="boom", config=scenario_to_mapping(run.scenario)), {"status": "failed"})
    summary = run_campaign(c, tmp_path, progress=False)
    assert summary.failed_before == [run.run_id] and summary.any_failed
    assert "1 failed earlier" in summary.line("f", tmp_path)


# --- a store that trusts nothing it reads (issue 23) ----------------------------------------
EVIL = '''
import pathlib
pathlib.Path(__file__).with_name("IMPORTED").write_text("this module was imported")


class X:
    """A plug-in whose import leaves a mark."""
    def __init__(self, model, *, Ts):
        pass

    def __call__(self, t, x, ref):
        n = x.shape[0] // 2
        theta_d, dtheta_d, _ = ref(t)
        return 30.0 * (theta_d - x[:2]) + 18.0 * (dtheta_d - x[n:n + 2])
'''


@pytest.fixture(scope="module")
def healthy(tmp_path_factory):
    """A results folder of 3 runs, one of them by the plug-in ``evilpkg.mod:X`` (its
    package in ``work/``), and the metrics of each run."""
    root = tmp_path_factory.mktemp("healthy")
    (root / "work" / "evilpkg").mkdir(parents=True)
    (root / "work" / "evilpkg" / "__init__.py").write_text("")
    (root / "work" / "evilpkg" / "mod.py").write_text(EVIL)
    c = campaign_from_mapping({"name": "h", "scenario": {"duration": 0.5, "transient": 0.1},
                               "sweep": [{"zip": {"name": ["a", "b", "plugin"],
                                                  "seed": [0, 1, 0],
                                                  "controller.kind": ["pbc", "pbc",
                                                                      "evilpkg.mod:X"]}}]})
    sys.path.insert(0, str(root / "work"))
    try:
        run_campaign(c, root / "results", progress=False)
    finally:
        sys.path.remove(str(root / "work"))
        sys.modules.pop("evilpkg.mod", None)
        sys.modules.pop("evilpkg", None)
    (root / "work" / "evilpkg" / "IMPORTED").unlink()
    store = ResultStore(root / "results")
    metrics = {r.run_id: r.metrics for r in store.rows()}
    store.close()
    return root, c, metrics


@pytest.fixture()
def folder(healthy, tmp_path):
    """A copy of the healthy results folder (and the plug-in's work directory)."""
    import shutil
    root, c, metrics = healthy
    shutil.copytree(root / "results", tmp_path / "results")
    shutil.copytree(root / "work", tmp_path / "work")
    return tmp_path / "results", c, metrics


def one_line_error(done, status: int, *texts) -> None:
    assert done.returncode == status, done
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flexarm: error:"), done.stderr
    assert all(t in lines[0] for t in texts), lines[0]
    assert "Traceback" not in done.stdout + done.stderr


def test_repair_adopts_a_run_file_only_under_its_own_id(folder):
    out, c, metrics = folder
    ids = {r.name: r.run_id for r in ResultStore(out).rows()}
    a, b = (out / "runs" / f"{ids[name]}.npz" for name in ("h/a", "h/b"))
    b.write_bytes(a.read_bytes())  # one run's file copied over another's
    (out / "index.sqlite").unlink()
    done = flexarm(None, "repair", out)
    assert done.returncode == 0, done.stderr
    assert f"unreadable: 1 ({b.stem} (its scenario does not hash to its name" in done.stdout
    rows = {r.run_id: r for r in ResultStore(out).rows()}
    assert b.stem not in rows and a.stem in rows  # never two rows of one scenario
    assert (out / "runs" / f"{b.name}.damaged").exists()
    summary = run_campaign(c, out, progress=False)  # so the overwritten run is redone
    assert (summary.skipped, summary.ok) == (2, 1)
    assert {r.run_id: r.metrics["track_max_1"] for r in ResultStore(out).rows()} == \
        {rid: m["track_max_1"] for rid, m in metrics.items()}


def _index_pages_overwritten(out) -> None:
    path = out / "index.sqlite"
    data = bytearray(path.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 4096] = np.random.default_rng(23).bytes(4096)
    path.write_bytes(bytes(data))


# Random bytes in make test; the empty file and the foreign database (7 s each) in
# make test-all.
@pytest.mark.parametrize("damage", ["random bytes mid-file",
                                    pytest.param("0 bytes", marks=pytest.mark.slow),
                                    pytest.param("not a database", marks=pytest.mark.slow)])
def test_a_damaged_index_is_named_and_rebuilt_whatever_the_damage(folder, damage):
    out, c, metrics = folder
    (out / "metrics.csv").write_text((out / "metrics.csv").read_text())  # as exported
    exported = (out / "metrics.csv").read_text()
    if damage == "random bytes mid-file":
        _index_pages_overwritten(out)
    elif damage == "0 bytes":
        (out / "index.sqlite").write_bytes(b"")
    else:
        (out / "index.sqlite").write_bytes(b"this is not a database" * 300)
    cfg = out.parent / "h.toml"
    cfg.write_text(campaign_toml({"name": "h", "scenario": {"duration": 0.5,
                                                             "transient": 0.1}}))
    for args in (["export", out], ["report", out, "--no-progress"],
                 ["campaign", cfg, "--out", out, "--workers", "1", "--dry-run"]):
        one_line_error(flexarm(None, *args), 2, "index", f"flexarm repair {out}")
    assert (out / "metrics.csv").read_text() == exported  # never overwritten with less
    done = flexarm(None, "repair", out)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert "rebuilt: 1 (index.sqlite (unreadable; kept as index.sqlite.damaged))" in done.stdout
    after = ResultStore(out)
    assert {r.run_id: r.metrics for r in after.rows()} == metrics
    assert after.verify() == {}


def test_export_never_writes_fewer_runs_than_the_last_export_without_saying_so(folder):
    out, c, metrics = folder
    exported = (out / "metrics.csv").read_text()
    victim = sorted(metrics)[0]
    with sqlite3.connect(out / "index.sqlite") as db:  # a row lost from the index
        db.execute("DELETE FROM runs WHERE run_id = ?", (victim,))
    one_line_error(flexarm(None, "export", out), 2,
                   f"lacks 1 of the runs the last export listed (e.g. {victim})",
                   "flexarm repair")
    assert (out / "metrics.csv").read_text() == exported
    done = flexarm(None, "repair", out)  # adopts the run's file again
    assert done.returncode == 0 and f"adopted: 1 ({victim})" in done.stdout, done
    assert flexarm(None, "export", out).returncode == 0


def test_an_export_written_in_slices_is_the_export_written_whole(folder, monkeypatch):
    """Known-good: the 3 runs' metrics.csv written by 3 workers, a row each, is the one
    written in one piece; known-bad: the slices out of order give other bytes."""
    from validation.batch import executor
    from validation.batch.store import export
    out, c, metrics = folder
    monkeypatch.setattr(export, "_ROWS_A_WORKER", 10**9)  # one slice
    ResultStore(out).export()
    whole = (out / "metrics.csv").read_bytes()
    monkeypatch.setattr(export, "_ROWS_A_WORKER", 1)
    monkeypatch.setattr(executor, "available_cores", lambda: 3)
    ResultStore(out).export()
    assert (out / "metrics.csv").read_bytes() == whole
    head, *lines = whole.decode().splitlines(keepends=True)
    assert len(lines) == 3 and "".join([head, *reversed(lines)]).encode() != whole


def test_repair_skips_directories_named_like_run_files(folder):
    out, c, metrics = folder
    (out / "runs" / "0123456789ab.npz").mkdir()  # named like a run file
    (out / "runs" / "not-an-id.npz").mkdir()
    (out / "index.sqlite").unlink()
    done = flexarm(None, "repair", out)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert "skipped: 2 (runs/0123456789ab.npz (not a run file), runs/not-an-id.npz " \
           "(not a run file))" in done.stdout
    assert {r.run_id for r in ResultStore(out).rows()} == set(metrics)


def test_run_ids_read_from_the_index_never_name_a_path(folder):
    out, c, metrics = folder
    victim_dir = out.parent / "victimdir"
    victim_dir.mkdir()
    (victim_dir / "precious.npz").write_text("precious")
    crafted = "../../victimdir/precious"
    with sqlite3.connect(out / "index.sqlite") as db:
        db.execute("UPDATE runs SET run_id = ?, file = ? WHERE run_id = ?",
                   (crafted, f"runs/{crafted}.npz", sorted(metrics)[0]))
    for args in (["export", out], ["report", out, "--no-progress"]):
        one_line_error(flexarm(None, *args), 2, repr(crafted), "is not a stored run",
                       "flexarm repair")
    done = flexarm(None, "repair", out)
    assert done.returncode == 0, done.stderr
    assert f"dropped: 1 ({crafted!r} (not a stored run: its id must be 12 hex digits" \
        in done.stdout
    assert (victim_dir / "precious.npz").read_text() == "precious"  # untouched
    assert sorted(p.name for p in victim_dir.iterdir()) == ["precious.npz"]
    assert {r.run_id for r in ResultStore(out).rows()} == set(metrics)  # re-adopted


def test_reading_a_results_folder_never_imports_a_plugin(folder):
    out, c, metrics = folder
    work = out.parent / "work"  # the plug-in's package is importable from here
    for args in (["report", out, "--no-progress", "--no-animation"], ["export", out],
                 ["repair", out]):
        done = flexarm(work, *args)
        assert done.returncode == 0, done.stderr
        assert not (work / "evilpkg" / "IMPORTED").exists(), args


def _mounted(tmp_path, options: list[str], source="tmpfs") -> Path:
    """A mount point under ``tmp_path`` (the test is skipped where mounting is not
    allowed)."""
    point = tmp_path / "mnt"
    point.mkdir()
    kind = ["-t", "tmpfs"] if source == "tmpfs" else ["--bind"]
    done = subprocess.run(["mount", *kind, *options, source, str(point)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount here: {done.stderr.decode().strip()}")
    return point


def _unmount(point) -> None:
    subprocess.run(["umount", "-l", str(point)], check=True)  # lazy: even if still in use


def test_a_full_disk_is_no_space_left_exit_1(folder, tmp_path):
    import shutil
    out, c, metrics = folder
    point = _mounted(tmp_path, ["-o", "size=4M"])
    try:
        full = point / "results"
        shutil.copytree(out, full)
        with open(point / "filler", "wb") as fh:  # fill the disk
            try:
                while True:
                    fh.write(b"\0" * 65536)
            except OSError:
                pass
        cfg = tmp_path / "more.toml"
        cfg.write_text(campaign_toml(spec("more", 2)))
        for args in (["campaign", cfg, "--out", full, "--workers", "1", "--no-progress"],
                     ["campaign", cfg, "--out", point / "new", "--workers", "1", "--no-progress"],
                     ["run", "--duration", "0.5", "--set", "transient=0.1", "--out", full],
                     ["export", full]):
            one_line_error(flexarm(None, *args), 1, "no space left on the device")
        # What is stored can still be read: the dry run lists it.
        done = flexarm(None, "campaign", cfg, "--out", full, "--dry-run")
        assert done.returncode == 0 and "2 runs planned: 2 to run" in done.stdout, done
        store = ResultStore(full)
        assert {r.run_id for r in store.rows()} == set(metrics)
        store.close()
    finally:
        _unmount(point)


def test_a_read_only_folder_is_read_not_advised_to_repair(folder, tmp_path):
    out, c, metrics = folder
    point = _mounted(tmp_path, [], source=str(out))
    try:
        subprocess.run(["mount", "-o", "remount,ro,bind", str(point)], check=True)
        cfg = out.parent / "h.toml"
        cfg.write_text(campaign_toml({"name": "h", "scenario": {"duration": 0.5,
                                                                 "transient": 0.1},
                                      "sweep": [{"zip": {"name": ["a", "b"],
                                                         "seed": [0, 1]}}]}))
        done = flexarm(None, "campaign", cfg, "--out", point, "--dry-run")
        assert done.returncode == 0, done.stderr
        assert "2 runs planned: 0 to run, 2 already stored" in done.stdout
        for args in (["export", point], ["repair", point],
                     ["campaign", cfg, "--out", point, "--workers", "1", "--retry-failed"]):
            done = flexarm(None, *args)
            one_line_error(done, 2, "read-only")
            assert "repair " + str(point) not in done.stderr  # not the cure here
        store = ResultStore(point)
        assert {r.run_id: r.metrics for r in store.rows()} == metrics
        store.close()
    finally:
        _unmount(point)


def test_metrics_csv_spells_every_run_as_its_row_holds_it(tmp_path):
    """metrics.csv is written from the typed columns: each run's swept values (a list as
    JSON, a bool as Python spells it), every metric as csv writes a float (NaN "nan"),
    and "" where a run lacks a column another run has (runs of three layouts: other
    swept values, metrics only some observers have).  Known-bad: a column picked by a
    name the metrics also use ("status") shifted every absent column onto a metric."""
    import csv
    import json
    import math
    from validation.batch.executor import SerialRunner
    c = campaign_from_mapping({
        "name": "mixed", "scenario": {"duration": 0.2, "transient": 0.1,
                                      "observer": {"kind": "smo-paper"}},
        "sweep": [{"name": "a", "grid": {"seed": [1, 2]}},
                  {"name": "b", "grid": {"reference.amplitude": [[1.0, 1.0]],
                                         "sensors.rates": [True]}},
                  {"name": "c", "grid": {"observer.kind": ["none"]}}]})
    run_campaign(c, tmp_path, runner=SerialRunner(), progress=False)
    rows = {r.run_id: r for r in ResultStore(tmp_path).rows()}
    with (tmp_path / "metrics.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert [t["run_id"] for t in table] == [r.run_id for r in sorted(
        rows.values(), key=lambda r: (r.name, r.run_id))]
    lacking = 0
    for t in table:
        r = rows[t["run_id"]]
        for key, text in t.items():
            if key.startswith("axis:"):
                value = r.axes.get(key[5:])
                expected = "" if value is None else json.dumps(value) \
                    if isinstance(value, list) else str(value)
            elif key in r.metrics and key not in ("status",):
                value = r.metrics[key]
                expected = "nan" if isinstance(value, float) and math.isnan(value) \
                    else repr(value) if isinstance(value, float) else str(value)
            elif key in ("run_id", "name", "campaign", "sweep", "status", "message",
                         "plant", "observer", "controller", "arm", "Ts", "initial_state"):
                continue
            else:
                expected = ""
                lacking += 1
            assert text == expected, (r.run_id, key, text, expected)
    assert lacking > 0  # the layouts differ: some runs lack some columns
