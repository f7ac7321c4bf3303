"""Processes that run a user's code on behalf of this one: how they end with it, and what
their end says.

`contained` calls a function in a forked child under the supervision the run workers
have (`validation.batch.executor`): whatever the code does to its process — exit, crash,
hang, raise ``SystemExit`` — the caller gets one `ContainedFault` saying what happened,
and no process is left behind.  `checked_apart` is how a scenario check imports and
constructs a plug-in (a law, a plant): in this process for a library caller, in a
contained child once the program has asked for it (`contain_checks`: the ``flexarm``
command line does), so that a plug-in's import or constructor cannot take the command
down.

Each such child leads its own process group and is killed with it: a helper process the
user's code starts dies with the child.

Every process is started under `signals_held`: ``os.fork`` runs the fork callbacks of the
libraries loaded (logging releases its lock in one), and an exception a signal handler
raises inside such a callback is printed as "Exception ignored" and lost — a Ctrl-C that
landed while a worker was forked was forgotten and the command ran on (seen in CI).
`signals_held` also waits for `between_forks`: a thread of this process that computes
beside the runs (the stability map's predictions) does each piece of its work inside it,
so that no child is forked while that thread holds a lock (numba's compiler lock, a
library's own mutex) that the child would inherit held by no one, for ever.
"""
from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
from contextlib import contextmanager

from .config import ConfigError

__all__ = ["die_with_parent", "lead_process_group", "kill_group", "describe_exit",
           "contained", "ContainedFault", "contain_checks", "checked_apart", "CHECK_TIMEOUT",
           "signals_held", "release_signals", "between_forks", "at_child_exit"]

#: How long importing and constructing a plug-in in its check may take by default [s]:
#: a plug-in that compiles a numba kernel on construction takes 10–45 s on a busy 2-core
#: machine.
CHECK_TIMEOUT = 120.0
_check_timeout: float | None = None  # None: plug-ins are checked in this process


class ContainedFault(RuntimeError):
    """The code a `contained` call ran ended its process, hung or exited (one line)."""


def die_with_parent(parent: int) -> None:
    """End this process with SIGKILL when ``parent`` (the process that forked it) dies:
    no worker outlives a killed campaign.  Linux: the kernel's parent-death signal;
    elsewhere a thread that watches the parent."""
    if sys.platform.startswith("linux"):
        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL))
        if os.getppid() != parent:  # the parent died before the signal was armed
            os._exit(1)
        return
    import threading
    import time

    def watch():
        while os.getppid() == parent:
            time.sleep(1.0)
        os.kill(os.getpid(), signal.SIGKILL)
    threading.Thread(target=watch, daemon=True, name="watch-parent").start()


_HELD = {signal.SIGINT, signal.SIGTERM}


#: Reentrant: the thread working between forks may start a process itself (a plug-in
#: checked apart while the map's predictions build its case) without waiting for itself.
_fork_lock = threading.RLock()


def _new_fork_lock() -> None:
    global _fork_lock
    _fork_lock = threading.RLock()  # a child's own: the parent's is held while it forks


os.register_at_fork(after_in_child=_new_fork_lock)


@contextmanager
def between_forks():
    """Inside, no process is forked from this one (module docstring)."""
    with _fork_lock:
        yield


@contextmanager
def signals_held():
    """SIGINT/SIGTERM held back (blocked) inside, for starting a process (module
    docstring): one that arrives meanwhile is raised on leaving, in the caller's code.  The
    child inherits the held signals and calls `release_signals` once its handlers are set.
    Inside, no other thread of this process is within `between_forks`."""
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    try:
        with between_forks():
            yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def release_signals() -> None:
    """In a child started under `signals_held`: receive SIGINT/SIGTERM again."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD)


def lead_process_group() -> None:
    """Make this (forked) process the leader of a new process group, so that it and
    every process it starts can be killed together (`kill_group`)."""
    try:
        os.setpgid(0, 0)
    except OSError:  # already a group leader: nothing to do
        pass


def kill_group(process) -> None:
    """Kill a `multiprocessing` process that leads its own group, and the group with it
    (what the user's code started in it); wait for it.  One never started: nothing."""
    if process.pid is None:
        return
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass  # the group is gone (or the process never led one: killed below)
    if process.is_alive():
        process.kill()
    process.join()


def describe_exit(exitcode: int | None, during: str, who: str = "the worker") -> str:
    """What a child's exit code says happened to ``who`` ``during`` something ("the
    run")."""
    if exitcode is None:
        return f"{who} stopped answering during {during}"
    if exitcode < 0:
        try:
            name = f" ({signal.Signals(-exitcode).name})"
        except ValueError:
            name = ""
        oom = "; the system kills with it when memory runs out" \
            if -exitcode == signal.SIGKILL else ""
        return f"{who} was killed by signal {-exitcode}{name} during {during}{oom}"
    return f"{who} exited with status {exitcode} during {during}"


def _safe_repr(value) -> str:
    try:
        return repr(value)
    except Exception:  # noqa: BLE001 - a repr that raises still gets a name
        return f"<{type(value).__name__} object>"


_AT_CHILD_EXIT: list = []


def at_child_exit(fn) -> None:
    """Call ``fn()`` (once, however often registered) when a `contained` child ends: it
    leaves by ``os._exit``, which skips the ``atexit`` handlers, so what a child made for
    itself alone (an unpacked FMU) is removed here."""
    if fn not in _AT_CHILD_EXIT:
        _AT_CHILD_EXIT.append(fn)


def _child(conn, parent: int, fn, args) -> None:
    lead_process_group()
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what a Ctrl-C means
    release_signals()
    try:
        try:
            outcome = ("ok", fn(*args))
        except ConfigError as exc:
            outcome = ("config", exc.path, exc.message)
        except SystemExit as exc:
            outcome = ("fault", f"it called sys.exit({_safe_repr(exc.code)})")
        except BaseException as exc:  # noqa: BLE001 - a KeyboardInterrupt raised by code too
            outcome = ("fault", f"it raised {type(exc).__name__}: {_safe_repr(exc)}")
        for clean in _AT_CHILD_EXIT:  # before the answer: the parent then kills this process
            clean()
        conn.send(outcome)
    finally:
        os._exit(0)  # no atexit handler, no buffered output of the parent's flushed twice


def contained(fn, *args, timeout: float, during: str):
    """``fn(*args)`` in a forked child (module docstring); returns its (picklable) value.
    Raises the `ConfigError` it raised, or `ContainedFault` if the child ended, exited or
    did not answer within ``timeout`` seconds (``during``: what it was doing, for the
    message)."""
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=_child, args=(send, os.getpid(), fn, args), daemon=True,
                        name="flexarm-check")
    try:
        with signals_held():
            child.start()
        send.close()  # the child's death is then end-of-file here
        if not receive.poll(timeout):
            raise ContainedFault(f"no answer after {timeout:g} s during {during} (stopped; "
                                 "--run-timeout sets the limit)")
        try:
            outcome = receive.recv()
        except (EOFError, OSError):
            child.join()
            raise ContainedFault(describe_exit(child.exitcode, during, "the process checking it"))\
                from None
    finally:
        kill_group(child)
        send.close()  # closed above unless the start was interrupted
        receive.close()
    if outcome[0] == "config":
        raise ConfigError(outcome[1], outcome[2])
    if outcome[0] == "fault":
        raise ContainedFault(f"{outcome[1]} during {during}")
    return outcome[1]


def contain_checks(timeout: float | None) -> None:
    """From now on, `checked_apart` runs its checks in a contained child, each given
    ``timeout`` seconds (None: in this process again, as in a run's worker)."""
    global _check_timeout
    _check_timeout = timeout


def checked_apart(fn, *args, key: str, what: str):
    """``fn(*args)``: a check that imports and constructs the plug-in ``what`` (module
    docstring).  A fault of its process is a `ConfigError` on ``key`` saying what
    happened."""
    if _check_timeout is None:
        return fn(*args)
    try:
        return contained(fn, *args, timeout=_check_timeout,
                         during="its import and construction")
    except ContainedFault as exc:
        raise ConfigError(key, f"{what}: {exc}") from None
