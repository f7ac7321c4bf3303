"""Sphinx configuration of the flexarm-validation documentation site (``make docs``).

Pages that state what the code defines — the configuration keys, the command line, the
signal names, the metric keys, the claims, the findings of a stored paper reproduction —
are generated at build time by the local extension in ``_ext/`` from the code itself, so
they cannot drift from it.  The examples gallery runs every example during the build.
"""
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
# The gallery's campaigns fork workers from this process: one BLAS thread each, as the
# command line does (validation.run.threads), before numpy is imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")

project = "flexarm-validation"
author = "the flexarm-validation authors"
copyright = "the flexarm-validation authors (MIT licence)"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "flexarm_docs",
]

exclude_patterns = ["_build", "_generated", "examples/README.rst",
                    "auto_examples/*.ipynb", "auto_examples/*.py", "**.zip", "**.md5"]
templates_path = ["_templates"]
html_static_path = ["_static"]
html_css_files = ["flexarm.css"]
html_theme = "furo"
html_title = "flexarm-validation"
html_theme_options = {"navigation_with_keys": True}

# Every cross-reference must resolve (make docs runs with -n -W).  There is no network at
# build time, so no intersphinx: references to other libraries' types are left as text.
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(numpy|np|scipy|control|exudyn|exu|matplotlib|pathlib|numba|rtamt|"
               r"dask|distributed|typing|collections|types|enum|argparse)(\..*)?"),
    (r"py:class", r"(optional|default .*|array_like|ndarray|callable|Path|path-like)"),
]

# Types live in the docstrings (numpydoc), not in the signatures: one place to read them.
autodoc_typehints = "none"
autodoc_member_order = "bysource"
autodoc_default_options = {"members": True}
autosummary_generate = True
autosummary_imported_members = True
numpydoc_show_class_members = False  # members are documented by autodoc, once
numpydoc_xref_param_type = False

sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",       # every example runs during the build
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": False,    # list every failing example, then fail (-W)
    "only_warn_on_example_error": False,
    "matplotlib_animations": False,
    "capture_repr": (),
    "show_memory": False,
    "min_reported_time": 1,
    # Its pages of computation times load jQuery and DataTables from CDNs: the site
    # works offline without them (the build's log states the times).
    "write_computation_times": False,
}

pygments_style = "sphinx"

# The site works offline: MathJax is shipped with it (flexarm_docs.mathjax copies the
# pinned release into _static), never loaded from a CDN.
from flexarm_docs.mathjax import COMPONENT  # noqa: E402

mathjax_path = COMPONENT
# Docutils' "smart quotes" turn "--" into an en dash, and so "--set" in prose or in a help
# text into "–set", which a reader copies and the shell refuses: quotes and ellipses only.
smartquotes_action = "qe"
