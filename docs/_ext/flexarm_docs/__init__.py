"""Sphinx extension: the pages that state what the code defines, generated from the code.

At ``builder-inited`` each generator writes one reStructuredText file into
``docs/_generated/``, which the pages ``.. include::``: the configuration keys
(`configref`), the command line (`cliref`), the signal names and metric keys
(`signalref`), the paper's claims (`claimsref`), the built-in laws (`lawsref`), the arm files' fields and the shipped arms (`armref`) and the findings of a stored
``flexarm reproduce-paper`` (`findings`).  Nothing in them is typed by hand.  MathJax is
copied into the built site (`mathjax`): the site needs no network.
"""
from __future__ import annotations

from pathlib import Path

from .rst import escape_bars
from . import armref, claimsref, cliref, configref, findings, lawsref, signalref
from .mathjax import copy_mathjax

#: File name in docs/_generated → the function returning its text (given the docs folder).
GENERATORS = {
    "configuration.rst": configref.render,
    "cli.rst": cliref.render,
    "signals.rst": signalref.render_signals,
    "metrics.rst": signalref.render_metrics,
    "claims.rst": claimsref.render,
    "laws.rst": lawsref.render,
    "arms.rst": armref.render,
    "findings.rst": findings.render,
}


def generate(app) -> None:
    docs = Path(app.srcdir)
    out = docs / "_generated"
    out.mkdir(exist_ok=True)
    for name, render in GENERATORS.items():
        text = render(docs)
        path = out / name
        # Rewritten only when it changed, so Sphinx rebuilds only the pages that include it.
        if not path.exists() or path.read_text() != text:
            path.write_text(text)


def escape_docstring_bars(app, what, name, obj, options, lines) -> None:
    """Docstrings write magnitudes as |x| (`rst.escape_bars`)."""
    lines[:] = [escape_bars(line) for line in lines]


def setup(app):
    app.connect("builder-inited", generate)
    app.connect("autodoc-process-docstring", escape_docstring_bars)
    app.connect("build-finished", copy_mathjax)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
