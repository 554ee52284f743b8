"""Sphinx configuration of the femodes documentation (build: ``make docs``).

The examples are not executed here: the gallery shows the pictures that
``python examples/make_gallery.py`` wrote to ``examples/images``.
"""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

import femodes  # noqa: E402

project = "femodes"
author = "the femodes developers"
copyright = "2026, the femodes developers"
release = femodes.__version__
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "myst_parser",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]

# numpydoc-style docstrings, read by napoleon
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "description"
# types of documented parameters only (the docstrings already state the return types)
autodoc_typehints_description_target = "documented_params"
autodoc_typehints_format = "short"
autodoc_default_options = {"members": True}
autosummary_generate = False  # the tables link to the autodoc entries on the same page

myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3
# the benchmark notes were written as plain Markdown files: some skip a heading level
# reference lists of the module docstrings name works the text cites elsewhere (ref.citation:
# "Citation [X] is not referenced"); unresolved citations ([ref.ref]) still fail the build
suppress_warnings = ["myst.header", "ref.citation"]

html_theme = "furo"
html_title = f"femodes {release}"
html_static_path = []
