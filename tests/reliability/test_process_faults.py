"""A campaign outlives its worst run: whatever a plug-in law does to the process that
runs it — exit, crash, hang, hoard memory, raise KeyboardInterrupt — the run is recorded
as failed with what happened, the other runs complete, the command exits 1 without a
traceback, and no process is left behind; serially (one worker process) and with two
workers.

One campaign holds every fault and is run once per worker count (module fixtures); each
fault is then its own test on the stored results."""
import math
import os
import subprocess
import sys
import textwrap
import time

import pytest

from campaign_testing import wait_gone
from conftest import write_files
from validation.batch.store.folder import ResultStore
from validation.run.config import ConfigError

FAULTS = textwrap.dedent('''
    """Laws that misbehave from t = 0.1 s on, written for the tests."""
    import ctypes
    import os
    import sys
    import time

    import numpy as np

    # Held by the module: it stays in the worker process after the run.  The runner replaces
    # a worker whose run reached the memory limit, else the good runs after it on that
    # worker would fail (before: they did or did not, by what the 64 MiB steps left below
    # the limit).
    _hoard = []


    class Fault:
        def __init__(self, model, *, Ts, fault="none"):
            self.fault = fault

        def __call__(self, t, x, ref):
            if t >= 0.1:
                if self.fault == "sys.exit":
                    sys.exit(0)
                if self.fault == "os._exit":
                    os._exit(0)
                if self.fault == "segfault":
                    ctypes.string_at(0)
                if self.fault == "KeyboardInterrupt":
                    raise KeyboardInterrupt
                if self.fault == "sleep":
                    while True:
                        time.sleep(1.0)
                if self.fault == "hoard":  # 64 MiB more address space at every sample
                    _hoard.append(np.empty(8 << 20))
            n = x.shape[0] // 2
            theta_d, dtheta_d, _ = ref(t)
            return 30.0 * (theta_d - x[:2]) + 18.0 * (dtheta_d - x[n:n + 2])
''')

#: fault -> what the run's stored message must contain.
EXPECTED = {
    "sys.exit": "the run called sys.exit(0)",
    "os._exit": "the worker exited with status 0 during the run",
    "segfault": "the worker was killed by signal 11 (SIGSEGV) during the run",
    "KeyboardInterrupt": "KeyboardInterrupt raised during the run (not a Ctrl-C)",
    "sleep": "no result after {timeout} s",
    "hoard": "exceeded the memory limit of 2048 MiB",
}
GOOD_RUNS = 4
#: An idle worker takes ~650 MiB of address space; the hoarding law passes 2 GiB in ~25
#: samples.
MEMORY_LIMIT = "2048"


def run_timeout() -> int:
    """The campaign's time limit [s], from what its costliest run that must not reach it
    costs on this machine now: the hoarding law reaching the memory limit, timed in a
    fresh Python (its start included).  The limit is on address space, so the law takes it
    untouched (`np.empty`): filling 2 GiB with ones cost 5.4 s of page faults on a quiet
    machine and more under load, where a fixed 8 s raced it.  Ten times the cost, at least
    8 s (160 times the ~0.05 s of a healthy 0.5 s run)."""
    fill = f"import numpy as np; h = [np.empty(8 << 20) for _ in range({MEMORY_LIMIT} // 64)]"
    started = time.perf_counter()
    subprocess.run([sys.executable, "-c", fill], check=True)
    return max(8, math.ceil(10 * (time.perf_counter() - started)))


def campaign_text() -> str:
    names = ", ".join(f'"{f.replace("_", "").replace(".", "-")}"' for f in EXPECTED)
    return textwrap.dedent(f'''
        name = "faults"
        [scenario]
        duration = 0.5
        transient = 0.1
        [[sweep]]
        name = "good"
        grid.seed = {list(range(GOOD_RUNS // 2))}
        [[sweep]]
        name = "bad"
        zip.name = [{names}]
        zip.controller.kind = [{", ".join('"faultlaws:Fault"' for _ in EXPECTED)}]
        zip.controller.options = [{", ".join(f'{{fault = "{f}"}}' for f in EXPECTED)}]
        [[sweep]]
        name = "good-after"
        grid.seed = {list(range(GOOD_RUNS // 2, GOOD_RUNS))}
    ''')


def flexarm(cwd, *args, **kw):
    """The CLI in its own session (its process group holds it and every worker)."""
    return subprocess.Popen([sys.executable, "-m", "validation.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, **kw)


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    return write_files(tmp_path_factory.mktemp("lab"),
                       {"faultlaws.py": FAULTS, "faults.toml": campaign_text()})


# One worker process: every run after the hoarding one is on the worker that hoarded
# (replaced); two workers in make test-all (11 s).
@pytest.fixture(scope="module", params=["1", pytest.param("2", marks=pytest.mark.slow)],
                ids=["serial", "2-workers"])
def campaign(request, lab):
    """The fault campaign run by the CLI: (workers, exit status, stdout, stderr, rows by
    name, whether its process group was gone after it, its time limit)."""
    out = lab / f"out-{request.param}"
    timeout = run_timeout()
    proc = flexarm(lab, "campaign", "faults.toml", "--out", str(out), "--workers",
                   request.param, "--force-workers", "--no-progress",
                   "--run-timeout", str(timeout), "--memory-limit", MEMORY_LIMIT)
    stdout, stderr = proc.communicate(timeout=600)
    gone = wait_gone(proc.pid)
    store = ResultStore(out)
    rows = {}
    for r in store.rows():
        rows.setdefault(r.name, []).append(r)
    store.close()
    return request.param, proc.returncode, stdout, stderr, rows, gone, timeout


def test_the_campaign_outlives_every_fault(campaign):
    workers, status, stdout, stderr, rows, gone, _ = campaign
    assert status == 1, stderr  # some runs failed
    assert "Traceback" not in stdout + stderr, stderr
    total = GOOD_RUNS + len(EXPECTED)
    assert f"faults: {total} runs; ran {total}: {GOOD_RUNS} ok, 0 diverged, " \
           f"{len(EXPECTED)} failed" in stdout, stdout
    good = rows["faults/good"] + rows["faults/good-after"]
    assert len(good) == GOOD_RUNS and all(r.status == "ok" for r in good)
    assert gone, "a worker outlived the campaign"


@pytest.mark.parametrize("fault", list(EXPECTED))
def test_a_fault_is_a_failed_run_saying_what_happened(campaign, fault):
    workers, status, stdout, stderr, rows, gone, timeout = campaign
    (row,) = rows[f"faults/{fault.replace('_', '').replace('.', '-')}"]
    assert row.status == "failed"
    assert EXPECTED[fault].format(timeout=timeout) in row.message, row.message
    # ... and when: the simulated time (the loop caught it), the wall time into the run
    # (the worker caught it or died), or the limit that stopped it.
    assert any(when in row.message for when in ("at t = ", "s after the run started",
                                                  "no result after"))
    assert row.config["controller"]["options"] == {"fault": fault}


@pytest.mark.parametrize("workers", ["1", "2"])
def test_workers_die_with_a_killed_campaign(lab, workers, tmp_path):
    out = tmp_path / "out"
    cfg = tmp_path / "hang.toml"
    cfg.write_text('name = "hang"\n[scenario]\nduration = 0.5\ntransient = 0.1\n'
                   'controller = { kind = "faultlaws:Fault", options = { fault = "sleep" } }\n'
                   '[[sweep]]\ngrid.seed = [0, 1, 2]\n')
    proc = flexarm(lab, "campaign", str(cfg), "--out", str(out), "--workers", workers,
                   "--force-workers", "--no-progress")
    deadline = time.time() + 300  # the workers start after the index is made: a loaded
    workers_pids = []               # machine takes seconds, so wait for them, not a time
    while time.time() < deadline and len(workers_pids) < 1 + int(workers):
        time.sleep(0.1)
        workers_pids = subprocess.run(["pgrep", "-s", str(proc.pid)], capture_output=True,
                                      text=True).stdout.split()
    time.sleep(1.0)  # every worker is now inside a run that never ends
    assert proc.poll() is None, proc.communicate()
    workers_pids = subprocess.run(["pgrep", "-s", str(proc.pid)], capture_output=True,
                                  text=True).stdout.split()
    assert len(workers_pids) == 1 + int(workers)  # the campaign and its workers
    proc.kill()
    proc.communicate()
    assert wait_gone(proc.pid), "a worker outlived its killed parent"


def test_sys_exit_in_the_plugin_run_by_flexarm_run_is_not_success(lab, tmp_path):
    proc = flexarm(lab, "run", "--controller", "faultlaws:Fault", "--set",
                   'controller.options.fault="sys.exit"', "--duration", "0.5", "--set",
                   "transient=0.1", "--out", str(tmp_path / "out"))
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 1 and "Traceback" not in stderr, stderr
    assert "failed: the run called sys.exit(0)" in stderr  # a failure: on stderr
    (row,) = ResultStore(tmp_path / "out").rows()
    assert row.status == "failed" and "sys.exit(0)" in row.message
    assert wait_gone(proc.pid)


CHECKED = textwrap.dedent('''
    """A law whose import or constructor misbehaves as FAULT_AT and FAULT say."""
    import ctypes
    import os
    import sys
    import time


    def misbehave():
        fault = os.environ.get("FAULT")
        if fault == "sys.exit":
            sys.exit(0)
        if fault == "sys.exit-repr":
            class Unprintable:
                def __repr__(self):
                    raise RuntimeError("no repr")
            sys.exit(Unprintable())
        if fault == "os._exit":
            os._exit(0)
        if fault == "segfault":
            ctypes.string_at(0)
        if fault == "KeyboardInterrupt":
            raise KeyboardInterrupt
        if fault == "hang":
            while True:
                time.sleep(1.0)


    if os.environ.get("FAULT_AT") == "module":
        misbehave()


    class Law:
        def __init__(self, model, *, Ts):
            if os.environ.get("FAULT_AT") == "__init__":
                misbehave()

        def __call__(self, t, x, ref):
            return x[:2] * 0.0
''')
#: fault -> what the one line says happened while the plug-in was imported or built.
CHECK_FAULTS = {
    "sys.exit": "it called sys.exit(0)",
    "sys.exit-repr": "it called sys.exit(<Unprintable object>)",
    "os._exit": "the process checking it exited with status 0",
    "segfault": "the process checking it was killed by signal 11 (SIGSEGV)",
    "KeyboardInterrupt": "it raised KeyboardInterrupt",
    "hang": "no answer after 3 s",
}


@pytest.mark.parametrize("where", ["module", "__init__"])
@pytest.mark.parametrize("fault", list(CHECK_FAULTS))
def test_a_plugin_misbehaving_while_checked_is_one_named_failure(plugin_lab, monkeypatch,
                                                                 where, fault):
    """Import and construction run apart from the command (as the command line checks
    plug-ins): exit, crash, hang — the check is a ConfigError saying what happened, and
    this process lives on."""
    from validation.run import laws, processes
    from validation.run.scenario import scenario_from_mapping
    plugin_lab({"checkedlaw.py": CHECKED})
    monkeypatch.setenv("FAULT", fault)
    monkeypatch.setenv("FAULT_AT", where)
    laws._checked.cache_clear()
    processes.contain_checks(3.0)  # the hang's limit [s]: long enough for a fork and an import
    try:
        with pytest.raises(ConfigError) as caught:
            scenario_from_mapping({"controller": {"kind": "checkedlaw:Law"}})
    finally:
        processes.contain_checks(None)
        laws._checked.cache_clear()
    assert caught.value.path == "controller.kind"
    assert CHECK_FAULTS[fault] in caught.value.message, caught.value.message
    assert "during its import and construction" in caught.value.message
    assert "checkedlaw" not in sys.modules  # never imported here


def test_the_command_ends_with_one_line_when_a_plugin_exits_at_import(tmp_path):
    """Known bad: os._exit(0) at import ended `campaign` with status 0, no message and
    none of its runs stored."""
    write_files(tmp_path, {"checkedlaw.py": CHECKED, "c.toml": textwrap.dedent('''
        name = "c"
        [scenario]
        duration = 0.5
        transient = 0.1
        controller.kind = "checkedlaw:Law"
        [[sweep]]
        grid.seed = [0, 1, 2]
    ''')})
    proc = flexarm(tmp_path, "campaign", "c.toml", "--out", str(tmp_path / "out"),
                   env={**os.environ, "FAULT": "os._exit", "FAULT_AT": "module"})
    _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flexarm: error: scenario.controller.kind: "
                                                   "checkedlaw:Law: "), stderr
    assert "exited with status 0 during its import and construction" in lines[0]
    assert not (tmp_path / "out").exists()
    assert wait_gone(proc.pid)


def test_a_helper_process_of_a_stopped_run_is_stopped_with_it(tmp_path):
    """Known bad: a run past its time limit was killed but the helper process its law
    started ran on."""
    write_files(tmp_path, {"helperlaw.py": textwrap.dedent('''
        import subprocess
        import time
        from pathlib import Path


        class Law:
            def __init__(self, model, *, Ts):
                pass

            def __call__(self, t, x, ref):
                helper = subprocess.Popen(["sleep", "600"])
                Path("helper.pid").write_text(str(helper.pid))
                while True:
                    time.sleep(1.0)
    ''')})
    proc = flexarm(tmp_path, "run", "--controller", "helperlaw:Law", "--duration", "0.5",
                   "--set", "transient=0.1", "--out", str(tmp_path / "out"),
                   "--run-timeout", str(run_timeout()))
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 1, stderr
    assert "no result after" in stderr
    helper = int((tmp_path / "helper.pid").read_text())
    deadline = time.time() + 10
    while time.time() < deadline and os.path.exists(f"/proc/{helper}"):
        time.sleep(0.05)  # the kill is immediate; the kernel reaps it in a moment
    assert not os.path.exists(f"/proc/{helper}"), "the law's helper outlived its run"
    assert wait_gone(proc.pid)


@pytest.mark.slow  # 19 s (a real Dask cluster); the local runners' limit is tested above
def test_a_run_past_its_time_limit_is_stopped_on_dask(lab, monkeypatch, tmp_path):
    distributed = pytest.importorskip("distributed")
    from validation.batch.campaign import campaign_from_mapping
    from validation.batch.queue import run_campaign
    from validation.batch.executor import make_runner
    monkeypatch.syspath_prepend(str(lab))  # the Dask workers find the plug-in module
    spec = {"name": "dask", "scenario": {"duration": 0.5, "transient": 0.1},
            "sweep": [{"zip": {"name": ["hangs", "runs"],
                               "controller.kind": ["faultlaws:Fault", "pd"],
                               "controller.options": [{"fault": "sleep"}, {}]}}]}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", host="127.0.0.1") as cluster:
        timeout = run_timeout()
        with make_runner("dask", scheduler=cluster.scheduler_address,
                         run_timeout=timeout) as dask:
            summary = run_campaign(campaign_from_mapping(spec), tmp_path, runner=dask,
                                   progress=False)
    rows = {r.name: r for r in ResultStore(tmp_path).rows()}
    assert (summary.ok, summary.failed) == (1, 1), {n: r.message for n, r in rows.items()}
    assert rows["dask/hangs"].status == "failed"
    assert f"no result after {timeout} s" in rows["dask/hangs"].message
    assert rows["dask/runs"].status == "ok"
