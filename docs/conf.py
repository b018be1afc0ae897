"""Sphinx configuration of dynid's documentation.

Build (warnings are errors):  sphinx-build -W -b html docs docs/_build/html
The gallery's scripts (examples/) run during the build; ``-D plot_gallery=0`` renders them without
running them (no output, no figures), for a quick check of the text.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from sphinx.util.nodes import make_refnode

# One BLAS / OpenMP thread (several copies load in one process: casadi, pinocchio, numpy) and no
# display, as in the tests; set before anything imports numpy.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(DOCS))  # _gallery.py, named in sphinx_gallery_conf

import dynid  # noqa: E402  (light: every public name is imported on first use)

project = "dynid"
author = "the dynid authors"
copyright = "the dynid authors, BSD-3-Clause"
version = release = dynid.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
templates_path = ["_templates"]
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", ".gitignore"]

# Markdown (MyST): ::: fences, definition lists, anchors on headings so that pages link to sections.
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3

# The API reference: numpydoc-style docstrings, read by napoleon.
autosummary_generate = True
autodoc_member_order = "bysource"
# Types are in the numpydoc sections (with shapes and units); signatures stay readable without them.
autodoc_typehints = "none"
autodoc_preserve_defaults = True
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = False
napoleon_use_param = False
napoleon_use_keyword = False
# "Attributes" read like "Parameters": types as text, not cross-references ("shape (m, n)" is no object).
napoleon_custom_sections = [("Attributes", "params_style")]

# The gallery: examples/NN_*.py, run during the build and rendered with their output and figures.
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/\d\d_",
    "ignore_pattern": r"__init__\.py|/_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "show_memory": False,
    "min_reported_time": 1,
    "capture_repr": (),
    "backreferences_dir": None,
    # each script writes into docs/_build/gallery-output/<script>, its first argument
    "reset_argv": "_gallery.example_output",
}

html_theme = "furo"
html_title = f"dynid {release}"
html_static_path: list[str] = []
html_show_sourcelink = False
html_theme_options = {"navigation_with_keys": True}


def _drop_object_base(app, name, obj, options, bases):
    """``Bases: object`` says nothing: show a class's bases only when it has real ones."""
    bases[:] = [base for base in bases if base is not object]


def _resolve_by_name(app, env, node, contnode):
    """Docstrings name objects relative to the module that defines them (``:class:`ThreeLayerModel```
    in ``dynid.identify.model``), while the reference documents them where users import them
    (``dynid.identify.ThreeLayerModel``).  A Python reference Sphinx cannot resolve is linked to the
    documented object of the same name when exactly one has it; otherwise it stays plain text."""
    if node.get("refdomain") != "py":
        return None
    name = node.get("reftarget", "").rstrip("()").rsplit(".", 1)[-1]
    matches = [
        (fullname, entry)
        for fullname, entry in env.get_domain("py").objects.items()
        if fullname.rsplit(".", 1)[-1] == name and not entry.aliased
    ]
    if len(matches) != 1:
        return None
    fullname, entry = matches[0]
    return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, fullname)


def setup(app):
    app.connect("autodoc-process-bases", _drop_object_base)
    app.connect("missing-reference", _resolve_by_name)
