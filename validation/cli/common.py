"""What the commands share: exit statuses, results folders, the runner of a command's
runs, and how a command ends."""
from __future__ import annotations

import functools
import shutil
import sys
import tempfile
from pathlib import Path

from ..batch.executor import check_runner, make_runner
from ..batch.interrupts import exit_status
from ..batch.store.folder import ResultStore, StoreError


EXIT_USAGE = 2
EXIT_FAILED = 1


def open_output(out: str | Path) -> ResultStore:
    """Create (or open) a results folder; one line naming it if that is impossible."""
    store = ResultStore(out)
    try:
        store.prepare()
    except StoreError as exc:
        raise StoreError(f"--out {exc}") from None
    try:  # a file of this process's own (commands may share the folder), gone at close
        with tempfile.TemporaryFile(dir=store.out):
            pass
    except OSError as exc:
        raise StoreError(f"--out {out}: not writable ({exc.strerror or exc})") from None
    return store


def runner_for(args, scenarios, *folders: Path):
    """The runner of a command's runs: its options checked, then the results ``folders``
    created or opened (bad input writes nothing), then, for local workers, the kernels the
    runs of ``scenarios`` use compiled here with progress on stderr (workers fork with
    them), or the Dask scheduler reached; if that fails, the folders created are
    removed."""
    executor = getattr(args, "executor", "local")
    options = dict(force=args.force_workers, run_timeout=args.run_timeout,
                   memory_limit=args.memory_limit)
    check_runner(executor, args.workers, getattr(args, "scheduler", None), **options)
    created = [(Path(f), _first_missing(Path(f))) for f in folders if not Path(f).exists()]
    try:
        for folder in folders:
            open_output(folder)
        return make_runner(executor, args.workers, getattr(args, "scheduler", None),
                           **options, scenarios=list(scenarios) or None, progress=sys.stderr)
    except BaseException:
        # Refused (an unreachable scheduler) or stopped before any run: the folders this
        # command created go again, as long as they hold no run.
        for folder, top in reversed(created):  # with the parents it made (deep/new/out)
            if not any(ResultStore(folder).runs_dir.glob("*.npz")):
                shutil.rmtree(top, ignore_errors=True)
        raise


def _first_missing(path: Path) -> Path:
    """The outermost folder of ``path`` (itself included) that does not exist yet: what
    creating it makes."""
    path = path.absolute()
    while not path.parent.exists() and path.parent != path:
        path = path.parent
    return path


def finish(summary, name: str, out) -> int:
    print(summary.line(name, out))
    if summary.interrupted:
        print(f"flexarm: interrupted ({summary.done} finished runs kept): rerun the same "
              "command to resume", file=sys.stderr)
        return exit_status(summary.interrupted)
    return EXIT_FAILED if summary.any_failed else 0


def mesh_checks(runner, out: Path, run_ids: set, *, progress: bool,
                beyond: frozenset = frozenset()) -> int:
    """Run the mesh checks of the truth-plant runs ``run_ids`` stored in ``out`` but those
    in ``beyond`` (beyond every stability limit: `claims.beyond_every_limit`): level 1
    and the other formulation, then level 2 of the runs whose verdict it could still
    change (`claims.finer_runs`).  A non-zero exit status if interrupted or a check
    failed."""
    from ..batch.store.resimulate import every_signal
    from ..verdicts.claims import finer_runs
    from ..verdicts.mesh import FIRST_STAGE, MESH_SWEEP, run_checks
    store = ResultStore(out)
    wanted = set(run_ids) - set(beyond)
    rows = [r for r in store.rows() if r.run_id in wanted]
    summary = run_checks(rows, out, runner=runner, progress=progress, levels=FIRST_STAGE)
    if not summary.interrupted:
        finer = [r for r in finer_runs(store.rows(), functools.partial(every_signal, store))
                 if r.run_id in wanted]
        summary = summary + run_checks(finer, out, runner=runner, progress=progress,
                                       levels=(2,))
    if summary.planned:
        print(summary.line(MESH_SWEEP, out))
    if summary.interrupted:
        return finish(summary, MESH_SWEEP, out)
    return EXIT_FAILED if summary.any_failed else 0
