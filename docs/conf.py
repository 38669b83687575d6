"""Sphinx configuration of the vivbench documentation (``make docs``)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
# The examples run during the build: one BLAS thread (tiny solves are slower threaded), no display.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import vivbench  # noqa: E402

project = "vivbench"
author = "the vivbench developers"
copyright = "the vivbench developers"
release = vivbench.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "**.ipynb_checkpoints", "sg_execution_times.rst"]
templates_path = ["_templates"]

# Markdown pages (MyST): $...$ maths, definition lists, anchors for the headings of the
# reference pages so that other pages can link to a section.
myst_enable_extensions = ["dollarmath", "deflist", "colon_fence"]
myst_heading_anchors = 3

# API reference: one page per public name (autosummary over each subpackage's __all__).
autosummary_generate = True
autosummary_imported_members = True
autosummary_ignore_module_all = False
autodoc_default_options = {"members": False}
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# Executed examples.
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples" / "gallery"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "within_subsection_order": "FileNameSortKey",
    "show_memory": False,
    "min_reported_time": 0,
}

html_theme = "pydata_sphinx_theme"
html_title = f"vivbench {release}"
html_static_path: list[str] = []
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
}
suppress_warnings: list[str] = []


def _drop_type_docstring(app, what, name, obj, options, lines):
    """A constant has no docstring of its own: show its value, not the docstring of its type."""
    if what != "data" or callable(obj):
        return
    own = type(obj).__doc__
    if isinstance(own, str) and lines and own.strip().startswith(lines[0].strip()):
        lines.clear()


def setup(app):
    app.connect("autodoc-process-docstring", _drop_type_docstring)
