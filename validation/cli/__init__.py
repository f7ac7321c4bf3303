"""The ``flexarm`` command line: a thin layer over the library.

Bad input ends with one line on stderr and exit status 2, before anything is written;
exit status 1 when something a command was asked for is missing because a run failed
(the one rule, command by command: docs/guide/execution.rst, "Exit statuses");
SIGINT/SIGTERM exit 130/143 after keeping what finished (at once, while the program is
still starting); a full disk is one line naming the folder, exit 1.  Never a traceback,
and never status 0 because code a command ran (a plug-in) called ``sys.exit``.

`main` runs a command; `parser` declares every command's arguments; the commands live
by what they work on: `modes`, `one_run` (run, show), `campaigns` (campaign,
reproduce-paper), `verdicts` (stability, validity, attribute, verify, baseline),
`results` (report, export, repair), `calibrate` (calibrate, export --signals), with
what they share in `common` and what the verdict commands print in `summaries`.
"""
from __future__ import annotations

import os
import signal
import sys


def _is_the_program() -> bool:
    """Whether this process is the ``flexarm`` program (its console script, or ``python
    -m validation.cli``), not a library or test importing this package."""
    argv = getattr(sys, "orig_argv", sys.argv)
    return os.path.basename(sys.argv[0]) == "flexarm" or any(
        a == "-m" and b == __name__ for a, b in zip(argv, argv[1:]))


def _stop_while_starting(signum, frame):
    print("flexarm: interrupted", file=sys.stderr)
    os._exit(128 + signum)


# A Ctrl-C while the program imports its libraries (numpy, numba, Exudyn: a second or
# two, nothing written yet) ends it at once, without a traceback.  Only when this package
# is the program: importing it (tests, notebooks) leaves the handlers alone.
if _is_the_program():
    for _signal in (signal.SIGINT, signal.SIGTERM):
        signal.signal(_signal, _stop_while_starting)

from ..run.threads import prefer_one_thread  # noqa: E402

prefer_one_thread()  # before numpy is imported; a user's setting wins

import argparse  # noqa: E402
import errno  # noqa: E402
import sqlite3  # noqa: E402

from .system import missing_library  # noqa: E402

try:
    from ..batch.interrupts import Interrupted, exit_status, signals_interrupt  # noqa: E402
    from ..batch.store.folder import StoreError  # noqa: E402
    from ..run.processes import CHECK_TIMEOUT, contain_checks  # noqa: E402
    from ..run.config import short_repr  # noqa: E402
    from .common import EXIT_FAILED, EXIT_USAGE  # noqa: E402
    from .parser import build_parser  # noqa: E402
except ImportError as _exc:  # a system library missing: one line naming the fix
    if not (_is_the_program() and missing_library(_exc)):
        raise
    print(f"flexarm: error: {missing_library(_exc)}", file=sys.stderr)
    sys.exit(2)

__all__ = ["main", "build_parser"]


def main(argv: list[str] | None = None) -> int:
    try:
        with signals_interrupt():  # SIGINT/SIGTERM raise Interrupted from here on
            args = build_parser().parse_args(argv)
            if getattr(args, "tier", "") is None:
                args.tier = "full" if args.campaign else "short"
            # Plug-ins named "package.module:Class" are found like `python -m` finds
            # modules: the current directory first (spawned workers inherit this path).
            # Commands that import no plug-in (those that read a results folder, and
            # write only into it: show, report, export, repair, baseline add) locate its
            # files for the code fingerprint on the same path, with the current directory
            # last: a module shipped inside a results folder read from there cannot stand
            # in for a library the command imports.
            if os.getcwd() not in sys.path:
                if getattr(args, "imports_no_plugin", False):
                    sys.path.append(os.getcwd())
                else:
                    sys.path.insert(0, os.getcwd())
            # A plug-in's import and constructor run apart from the command when a
            # scenario is checked: whatever they do, the command ends with a message.
            contain_checks(getattr(args, "run_timeout", None) or CHECK_TIMEOUT)
            return _command(args)
    except Interrupted as exc:
        print("flexarm: interrupted", file=sys.stderr)
        return exit_status(exc.signum)


def _command(args: argparse.Namespace) -> int:
    """Run the command: every error one line on stderr, and its exit status."""
    try:
        return args.func(args)
    except (ValueError, StoreError) as exc:  # ConfigError, StoreError: bad input
        return _error(exc, EXIT_USAGE)
    except ImportError as exc:  # a module imported when first needed
        if missing_library(exc) is None:
            raise
        return _error(missing_library(exc), EXIT_USAGE)
    except RecursionError:  # a structure the checks did not bound
        return _error("input nested too deeply", EXIT_USAGE)
    except SystemExit as exc:  # flexarm's own code never exits from inside a command
        return _error(f"sys.exit({short_repr(exc.code)}) was called by code this command ran "
                      "(a plug-in's?); stopped", EXIT_FAILED)
    except Interrupted:  # a Ctrl-C (a KeyboardInterrupt too): `main` says so
        raise
    except KeyboardInterrupt:  # a Ctrl-C raises Interrupted: this one was raised by code
        return _error("KeyboardInterrupt raised by code this command ran (a plug-in's?), "
                      "not by a Ctrl-C; stopped", EXIT_FAILED)
    except sqlite3.Error as exc:  # the store turns its own into StoreError: a last resort
        where = getattr(args, "out", None) or getattr(args, "results", None) or "the index"
        return _error(f"{where}: the index cannot be used ({exc})", EXIT_FAILED)
    except OSError as exc:
        where = exc.filename or getattr(args, "out", None) or getattr(args, "results", None) \
            or "the results folder"
        reason = "no space left on the device" if exc.errno == errno.ENOSPC else \
            (exc.strerror or str(exc))
        return _error(f"{where}: {reason}", EXIT_FAILED)


def _error(message, status: int) -> int:
    print(f"flexarm: error: {message}", file=sys.stderr)
    return status
