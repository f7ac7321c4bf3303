"""A Ctrl-C stops any command at any moment — while it starts, checks, runs or writes a
report: one line, exit status 130, no traceback, no process left behind."""
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from campaign_testing import wait_gone
from conftest import write_files

ROOT = Path(__file__).resolve().parents[2]

HANGS = textwrap.dedent('''
    import time

    class Hangs:
        """A law that never returns: a command running it only ends when stopped."""
        def __init__(self, model, *, Ts):
            pass

        def __call__(self, t, x, ref):
            while True:
                time.sleep(1.0)
''')


def interrupt(cwd, args, *, after: float = 0.0, once=None) -> subprocess.CompletedProcess:
    """Start the CLI in its own session, send SIGINT ``after`` seconds later (or as soon
    as ``once()`` holds), and wait for it to end."""
    proc = subprocess.Popen([sys.executable, "-m", "validation.cli", *args], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    start = time.time()
    while once is not None and not once() and time.time() - start < 300:
        time.sleep(0.01)
    time.sleep(after)
    assert proc.poll() is None, f"ended before the signal: {proc.communicate()}"
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert wait_gone(proc.pid), "a process outlived the interrupted command"
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


def assert_interrupted(done):
    assert done.returncode == 130, done.stderr
    assert "Traceback" not in done.stderr + done.stdout, done.stderr
    lines = done.stderr.strip().splitlines()
    # "flexarm: interrupted", and from a campaign how many finished runs it kept.
    assert len(lines) <= 2 and lines[-1].startswith("flexarm: interrupted"), done.stderr


@pytest.fixture()
def lab(tmp_path):
    return write_files(tmp_path, {"hanglaws.py": HANGS})


# 0.1 s: the interpreter imports the libraries; 2 s: the scenario is checked, the worker
# started, or the run under way (the run never ends, so every moment is before the end).
@pytest.mark.parametrize("after", [0.1, 2.0])
def test_ctrl_c_stops_flexarm_run(lab, after):
    done = interrupt(lab, ["run", "--controller", "hanglaws:Hangs", "--duration", "0.5",
                           "--set", "transient=0.1", "--out", str(lab / "out")], after=after)
    assert_interrupted(done)


@pytest.mark.parametrize("after", [0.1, 2.0])
def test_ctrl_c_stops_a_campaign_while_it_starts(lab, after):
    (lab / "c.toml").write_text('name = "c"\n[scenario]\nduration = 0.5\ntransient = 0.1\n'
                                'controller.kind = "hanglaws:Hangs"\n'
                                '[[sweep]]\ngrid.seed = [0, 1, 2, 3]\n')
    done = interrupt(lab, ["campaign", "c.toml", "--out", str(lab / "out"), "--workers", "1",
                           "--no-progress"], after=after)
    assert_interrupted(done)


def test_ctrl_c_stops_a_report_being_written(lab):
    from validation.batch.campaign import campaign_from_mapping
    from validation.batch.queue import run_campaign
    results = lab / "results"
    run_campaign(campaign_from_mapping({"name": "r", "scenario": {"duration": 0.5,
                                                                 "transient": 0.1},
                                        "sweep": [{"grid": {"seed": [0, 1]}}]}),
                 results, progress=False)
    figures = results / "report" / "figures"
    # Once its figures folder exists the report is being drawn (figures are written at
    # the end, with the tables): the signal lands mid-way.
    done = interrupt(lab, ["report", str(results), "--no-progress"],
                     once=figures.is_dir)
    assert_interrupted(done)
    assert not (results / "report" / "report.html").exists()



# 20 000 constant powers take ~0.1 s to compile here; the timer fires 10 ms in, so the
# signal lands while the compiler folds them (each fold checks for signals).
POWERS = "\n".join(f"x{i} = 2**31 - {i}" for i in range(20_000))


def _compile_with_a_signal_midway(handler) -> BaseException | None:
    """Compile `POWERS` with SIGALRM, handled by ``handler``, arriving 10 ms in: the
    exception that came out of ``compile``, or None if it returned normally."""
    previous = signal.signal(signal.SIGALRM, handler)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.01)
        compile(POWERS, "powers", "exec")
    except BaseException as exc:  # noqa: BLE001 - which one is what the test looks at
        return exc
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    return None


def test_a_ctrl_c_while_python_compiles_a_module_is_not_lost():
    """CPython's compiler clears any error but a KeyboardInterrupt raised while it folds a
    constant power: a Ctrl-C landing while a module was compiled on its first import was
    lost.  `Interrupted` is a KeyboardInterrupt and comes through."""
    from validation.batch.interrupts import Interrupted, signals_interrupt

    class Other(BaseException):
        pass

    handled = []

    def raise_other(signum, frame):
        handled.append(signum)
        raise Other

    # Known bad: another BaseException raised by the handler vanishes inside compile.
    assert _compile_with_a_signal_midway(raise_other) is None and handled
    with signals_interrupt():  # SIGALRM handled as SIGINT is here
        caught = _compile_with_a_signal_midway(signal.getsignal(signal.SIGINT))
    assert isinstance(caught, Interrupted), caught


# A script that sends itself SIGINT from a fork callback (where logging releases its lock)
# while it starts a child process the way ``START`` says; "ran on" if the Ctrl-C was lost.
SIGNAL_WHILE_FORKING = textwrap.dedent('''
    import os, signal, sys
    from validation.batch.interrupts import Interrupted, signals_interrupt
    sent = []

    def send_once():
        if not sent and os.getpid() == parent:
            sent.append(1)
            os.kill(parent, signal.SIGINT)

    parent = os.getpid()
    os.register_at_fork(after_in_parent=send_once)
    try:
        with signals_interrupt():
            START
            print("ran on")
    except Interrupted:
        sys.exit(130)
''')

STARTS = {
    "a contained check": "from validation.run.processes import contained; "
                         "contained(int, timeout=30, during='a check')",
    "a run worker": "from validation.batch.executor import LocalPoolRunner; "
                    "LocalPoolRunner(1, scenarios=[]).close()",
    "report drawers": "with __import__('validation.batch.beside', fromlist=['_'])"
                      ".beside([int, int], progress=False) as done: done()",
}


def _signal_while_forking(start: str) -> subprocess.CompletedProcess:
    script = SIGNAL_WHILE_FORKING.replace("START", start)
    return subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)


def test_a_ctrl_c_in_a_fork_callback_is_lost_where_signals_are_not_held():
    """Known bad: starting a process without holding signals loses the Ctrl-C."""
    done = _signal_while_forking("import multiprocessing as mp; "
                                 "p = mp.get_context('fork').Process(target=int); "
                                 "p.start(); p.join()")
    assert "Exception ignored" in done.stderr and "ran on" in done.stdout, done


@pytest.mark.parametrize("start", STARTS)
def test_a_ctrl_c_while_a_process_is_forked_is_not_lost(start):
    from validation.batch.executor import available_cores
    if start == "report drawers" and available_cores() < 2:
        pytest.skip("one core: a report draws its figures without forking")
    done = _signal_while_forking(STARTS[start])
    assert done.returncode == 130 and "ran on" not in done.stdout, done
    assert "Exception ignored" not in done.stderr, done.stderr


def test_no_process_is_forked_while_another_thread_works_between_forks():
    """A thread computing beside the runs (the stability map's predictions) works within
    `between_forks`; a fork (`signals_held`) waits until it leaves, so no child inherits
    a lock that thread holds.  Known good: with no such work the fork goes at once."""
    import threading

    from validation.run.processes import between_forks, signals_held
    inside, leave, order = threading.Event(), threading.Event(), []

    def work():
        with between_forks():
            inside.set()
            leave.wait()
            order.append("work")

    def fork():
        with signals_held():
            order.append("fork")

    worker = threading.Thread(target=work)
    worker.start()
    inside.wait()
    forking = threading.Thread(target=fork)
    forking.start()
    forking.join(0.5)  # ample for a lock that is free; it is not: still waiting
    assert forking.is_alive() and order == []
    leave.set()
    worker.join()
    forking.join()
    assert order == ["work", "fork"]
    fork()  # no work between forks: straight through
    assert order == ["work", "fork", "fork"]
    # The thread working between forks may start a process itself (known bad, before: a
    # plug-in plant checked apart while the map's predictions built its case waited for
    # itself for ever).
    def work_and_fork():
        with between_forks():
            fork()

    alone = threading.Thread(target=work_and_fork)
    alone.start()
    alone.join(5.0)  # a free lock takes microseconds; 5 s is a deadlock
    assert not alone.is_alive() and order == ["work", "fork", "fork", "fork"]
