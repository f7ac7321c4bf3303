"""MathJax shipped with the site: the theory pages' equations render without a network.

Sphinx loads MathJax from a CDN unless ``mathjax_path`` names a file of the site: offline
the pages then show raw LaTeX (``\\(e = Q - Q_d\\)``).  MathJax's own release comes as
files in the pinned ``django-static-mathjax`` package (the docs extra; its Python module
is an empty ``mathjax/__init__.py`` beside the files, nothing of Django is used).  After
an HTML build this copies into ``_static/mathjax/`` the one combined component the site
loads (`COMPONENT`: TeX input, SVG output — glyphs drawn as paths, no font files), the TeX
extensions it loads on demand (beside it, where its loader looks), and MathJax's licence.
"""
from __future__ import annotations

import importlib.resources
import shutil
from pathlib import Path

#: The MathJax component the pages load, relative to ``_static`` (conf.py's mathjax_path).
COMPONENT = "mathjax/tex-svg.js"


def release() -> Path:
    """The folder of MathJax's ES5 build in the installed package."""
    return Path(str(importlib.resources.files("mathjax"))) / "static" / "mathjax" / "es5"


def copy_mathjax(app, exception) -> None:
    if exception is not None or app.builder.format != "html":
        return
    source = release()
    target = Path(app.outdir) / "_static" / "mathjax"
    target.mkdir(parents=True, exist_ok=True)
    shutil.copy2(source / Path(COMPONENT).name, target / Path(COMPONENT).name)
    shutil.copy2(source.parent / "LICENSE", target / "LICENSE")
    shutil.copytree(source / "input" / "tex" / "extensions",
                    target / "input" / "tex" / "extensions", dirs_exist_ok=True)
