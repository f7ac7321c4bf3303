"""Where a law or plant raised, in its own code: the frames of an exception's traceback
that lie in the files of the code's own package (a plug-in author's module and its
helpers), as Python prints them, and the innermost of them as "file:line in function".

A run that raises is recorded as failed (a result, not an exception: `loop`), so the
traceback itself is gone when anyone reads the run; these frames are what a plug-in
author needs of it, stored with the run (`RunResult.traceback`) and printed by
``flexarm run`` and ``flexarm show``.
"""
from __future__ import annotations

import sys
import traceback
from pathlib import Path

__all__ = ["own_frames"]


def _roots(modules) -> tuple[list[Path], dict[Path, Path]]:
    """The folders of the top-level packages of ``modules`` (imported module names) and
    the files of top-level modules, each with the folder its paths are shown relative to
    (the one it was imported from)."""
    folders, files = [], {}
    for name in modules:
        top = sys.modules.get(name.partition(".")[0])
        if top is None or not getattr(top, "__file__", None):
            continue
        path = Path(top.__file__).resolve()
        if getattr(top, "__path__", None):  # a package: every file below its folder
            folders.append(path.parent)
        else:
            files[path] = path.parent
    return folders, files


def own_frames(exc: BaseException, modules) -> tuple[str, str]:
    """The frames of ``exc``'s traceback in the code of ``modules`` (the module names of
    a law's class and of the classes it derives from, or of a scenario's plug-ins).

    Parameters
    ----------
    exc : BaseException
        The exception, with its ``__traceback__``.
    modules : iterable of str
        Module names whose top-level package (or module file) counts as the code's own.

    Returns
    -------
    where : str
        The innermost own frame as ``"mylab/control.py:12 in __call__"`` (the file
        relative to the folder its package was imported from); the innermost frame of
        the traceback if none is the code's own; "" without a traceback.
    frames : str
        Those frames as Python prints them (``File "...", line N, in f`` and the source
        line), the innermost last.

    Examples
    --------
    >>> import json
    >>> try:
    ...     json.loads("{")
    ... except ValueError as exc:
    ...     where, frames = own_frames(exc, ["json"])
    >>> where.startswith("json/decoder.py:")
    True
    """
    stack = traceback.extract_tb(exc.__traceback__)
    if not stack:
        return "", ""
    folders, files = _roots(modules)

    def base(frame) -> Path | None:
        path = Path(frame.filename).resolve()
        if path in files:
            return files[path]
        return next((f.parent for f in folders if path.is_relative_to(f)), None)
    own = [(frame, base(frame)) for frame in stack]
    own = [(frame, root) for frame, root in own if root is not None] or [(stack[-1], None)]
    frame, root = own[-1]
    path = Path(frame.filename)
    shown = path.resolve().relative_to(root).as_posix() if root is not None else path.name
    where = f"{shown}:{frame.lineno} in {frame.name}"
    text = "".join(traceback.StackSummary.from_list([f for f, _ in own]).format())
    return where, text.rstrip("\n")
