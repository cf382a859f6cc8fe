"""Sphinx configuration of the methodgen documentation.

Build (from the repository root): ``python -m pip install -e ".[docs]"`` then
``python -m sphinx -W --keep-going -b html docs docs/_build/html``.

Choices, and why: Sphinx reads the numpydoc docstrings the package already has (napoleon) and
the pages as Markdown (MyST), so the guides stay readable on GitHub too; the tutorials are
plain Python scripts executed by sphinx-gallery at every build (no Jupyter kernel needed; each
page offers the script and a notebook for download), so an example that stops working fails
the build.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

# The tutorials build modules: keep them in the build folder, not in the user's cache, so a
# docs build is reproducible and never reads modules a previous version of methodgen left.
os.environ.setdefault("METHODGEN_CACHE", str(HERE / "_build" / "methodgen-cache"))
os.environ.setdefault("MPLBACKEND", "Agg")

import methodgen  # noqa: E402

project = "methodgen"
author = "The methodgen developers"
copyright = "2026, the methodgen developers"
release = methodgen.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx_gallery.gen_gallery",
    "methodgen_cli",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "tutorials/*.py", "tutorials/README.rst", "Thumbs.db", ".DS_Store"]
root_doc = "index"

myst_enable_extensions = ["dollarmath", "deflist"]
myst_heading_anchors = 3

napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"   # the numpydoc "Parameters" sections say the types

sphinx_gallery_conf = {
    "examples_dirs": ["tutorials"],
    "gallery_dirs": ["auto_tutorials"],
    "filename_pattern": r"/tut_",       # execute every tutorial
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "plot_gallery": "True",
    "matplotlib_animations": False,
    "show_memory": False,
}

html_theme = "furo"
html_title = f"methodgen {release}"
html_static_path: list[str] = []
suppress_warnings = ["config.cache"]   # sphinx-gallery's dict config cannot be pickled
