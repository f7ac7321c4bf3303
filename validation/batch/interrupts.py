"""What SIGINT/SIGTERM mean to a command: `signals_interrupt` makes the first one raise
`Interrupted` in the main thread (the command keeps what finished and exits with
`exit_status`: 130 or 143) and a second one end this process and its workers at once.

`Interrupted` is a `KeyboardInterrupt`.  A signal handler's exception can be raised
inside C code, and CPython's C code lets only a KeyboardInterrupt through in places: its
compiler clears any other error raised while it folds a constant such as ``2**31`` (the
integer power checks for signals), so a Ctrl-C landing while a module is compiled on its
first import was lost (seen about once in 15 reports on a fresh clone).  Code that
catches KeyboardInterrupt to call it a run's or a plug-in's failure re-raises
`Interrupted` first.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from contextlib import contextmanager

__all__ = ["Interrupted", "signals_interrupt", "exit_status"]


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; ``signum`` says which (a BaseException, so that no
    ``except Exception`` in a run swallows it)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


#: Signals received while `signals_interrupt` is in force (shared by nested uses).
_received: list[int] = []


def _on_signal(signum, frame):
    if _received:  # the second signal: end the workers and this process now
        for child in multiprocessing.active_children():
            child.kill()
        os._exit(exit_status(signum))
    _received.append(signum)
    raise Interrupted(signum)


@contextmanager
def signals_interrupt():
    """SIGINT/SIGTERM raise `Interrupted` in the main thread; a second one exits now.
    Nested uses share the first one's state (a second signal is a second signal)."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is _on_signal):
        yield
        return
    _received.clear()
    previous = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def exit_status(signum: int) -> int:
    """The shell's convention: 128 + the signal number (130 for SIGINT, 143 SIGTERM)."""
    return 128 + signum
