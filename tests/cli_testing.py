"""The ``flexarm`` command as the tests start it.

`flexarm` runs a command in a child forked from the test process: the child has the
libraries and kernels the test process loaded already, so a command costs what it does,
not a new interpreter's start (about 0.5 s of imports for a command reading a folder,
1.5 s for a run: numba, scipy.signal, Exudyn, the kernels from the cache), and whatever
it imports, changes or leaks stays in the child.  It is what the program does from
`validation.cli.main` on: the arguments, the exit status, stdout and stderr (warnings
printed as a new interpreter prints them), a child's own workers.

`program` starts the program itself, ``python -m validation.cli``: for what only a new
interpreter shows (what a command imports, the environment read at import, signals while
it starts).
"""
from __future__ import annotations

import atexit
import functools
import io
import os
import select
import signal
import subprocess
import sys
import tempfile
import traceback
import warnings

__all__ = ["flexarm", "program"]


def program(cwd, *args, timeout: float = 600) -> subprocess.CompletedProcess:
    """``python -m validation.cli *args`` in ``cwd``, run to its end."""
    return subprocess.run([sys.executable, "-m", "validation.cli", *map(str, args)],
                          cwd=cwd, capture_output=True, text=True, timeout=timeout)


def flexarm(cwd, *args, timeout: float = 600) -> subprocess.CompletedProcess:
    """``flexarm *args`` in ``cwd`` (None: this process's), in a child forked from this
    process, run to its end: its exit status (negative: the signal that ended it), stdout
    and stderr, as `subprocess.run` gives them.  Past ``timeout`` seconds the child is killed and
    `subprocess.TimeoutExpired` raised."""
    _load()
    args = [str(a) for a in args]
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            _child(cwd, args, out.fileno(), err.fileno())
        status = _wait(pid, timeout, args)
        text = []
        for f in (out, err):
            f.seek(0)
            text.append(f.read().decode("utf-8", "replace"))
    return subprocess.CompletedProcess(["flexarm", *args], status, *text)


@functools.cache
def _load() -> None:
    """Load, once in this process, what every child would otherwise load for itself: the
    command line's libraries, those of a run and of a figure, the default runs' kernels,
    the code's fingerprint (the project's files do not change while the tests run)."""
    import validation.cli  # noqa: F401
    import validation.report.figures  # noqa: F401
    from validation.batch.fingerprint import code_fingerprint
    from validation.batch.worker import warm_up
    warm_up()
    code_fingerprint()


def _wait(pid: int, timeout: float, args) -> int:
    """The exit status of child ``pid`` (`subprocess`'s convention), killed past
    ``timeout``."""
    ended = os.pidfd_open(pid)
    try:
        if not select.select([ended], [], [], timeout)[0]:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise subprocess.TimeoutExpired(["flexarm", *args], timeout)
    finally:
        os.close(ended)
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])


def _child(cwd, args: list[str], out: int, err: int) -> None:
    """In the forked child: become ``flexarm *args`` in ``cwd`` — no stdin, stdout and
    stderr into ``out`` and ``err``, the signal handlers, warning filters and exit
    handlers of a new interpreter — run it, and exit with its status."""
    status = 1
    try:
        atexit._clear()  # the test process's, not the command's
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_DFL)
        nothing = os.open(os.devnull, os.O_RDONLY)
        for fd, into in ((nothing, 0), (out, 1), (err, 2)):
            os.dup2(fd, into)
        sys.stdin = open(0, closefd=False)
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), write_through=True)
        sys.stderr = io.TextIOWrapper(io.FileIO(2, "w", closefd=False), write_through=True,
                                      errors="backslashreplace")
        warnings.resetwarnings()  # a new interpreter's filters, printed to stderr
        for category in (DeprecationWarning, PendingDeprecationWarning, ImportWarning,
                         ResourceWarning):
            warnings.simplefilter("ignore", category)
        warnings.filterwarnings("default", category=DeprecationWarning, module="__main__")
        warnings.showwarning = _print_warning
        if cwd is not None:
            os.chdir(cwd)
        sys.argv = ["flexarm", *args]
        from validation.cli import main
        status = main(args)
        atexit._run_exitfuncs()
    except SystemExit as exc:  # as the interpreter exits with it (a message: printed, 1)
        if exc.code is not None and not isinstance(exc.code, int):
            print(exc.code, file=sys.stderr)
        status = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    except BaseException:  # an uncaught exception: its traceback, status 1
        traceback.print_exc()
        status = 1
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except BaseException:  # noqa: S110 — the status still goes back
                pass
        os._exit(status)


def _print_warning(message, category, filename, lineno, file=None, line=None) -> None:
    sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))
