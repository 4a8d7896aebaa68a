"""Sphinx configuration of the ema_casadi documentation (``make docs``).

Built offline: no intersphinx inventories are fetched, the gallery examples run on
this machine. ``make docs`` passes ``-W`` (every warning is an error).
"""

from __future__ import annotations

import os
import re
import shutil
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # the gallery draws off screen

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

import ema_casadi  # noqa: E402

sys.path.insert(0, str(HERE))
import _api  # noqa: E402

# the API reference, generated from the package; the stubs are made anew at every build
# (a module that moved or went leaves no stale page behind)
shutil.rmtree(HERE / "api" / "generated", ignore_errors=True)
_api.write(HERE / "api" / "index.md")

project = "ema_casadi"
author = "the ema_casadi authors"
copyright = "the ema_casadi authors, MIT licence"
release = version = ema_casadi.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",  # MathJax served from the site itself: the pages read offline
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "sphinxarg.ext",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "auto_examples/*.ipynb", "auto_examples/*.py", "auto_examples/*.zip",
                    "auto_examples/*.json", "auto_examples/*.md5", "**/sg_execution_times.rst"]

# --- MyST -------------------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist", "attrs_block"]
myst_heading_anchors = 3

# --- API reference ------------------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": True, "inherited-members": False, "show-inheritance": False}
autodoc_typehints = "none"  # the numpydoc sections carry the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# --- gallery ------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"__init__\.py|/_",
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": True,
    "plot_gallery": os.environ.get("EMA_DOCS_GALLERY", "True"),
    "download_all_examples": False,
    "remove_config_comments": True,
    "show_memory": False,
    "min_reported_time": 1,
    "reset_modules": ("matplotlib",),
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
}

# --- HTML ---------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"ema_casadi {version}"
html_theme_options = {
    "navigation_depth": 2,
    "show_toc_level": 2,
    "footer_start": ["copyright"],
    "footer_end": [],
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path: list[str] = []
html_show_sourcelink = False


# --- pages other work may or may not have added --------------------------------------
def _optional_pages(app, docname, source):
    """Fill the placeholders of ``index`` and ``changelog``: pages and files that are
    included when they exist (the architecture page, the root CHANGELOG.md)."""
    text = source[0]
    if docname == "index":
        extra = [name for name in ("architecture",) if (HERE / f"{name}.md").exists()]
        text = text.replace("%OPTIONAL_PAGES%", "\n".join(extra))
    if docname == "changelog":
        if (ROOT / "CHANGELOG.md").exists():
            inc = "```{include} ../CHANGELOG.md\n:relative-docs: docs/\n:relative-images:\n```"
        else:
            inc = "# Changelog\n\nNo release has been recorded yet."
        text = text.replace("%CHANGELOG%", inc)
    source[0] = text


# --- docstrings: |x| is an absolute value, not a reStructuredText substitution --------
_LITERAL = re.compile(r"(``.*?``|`[^`]*`)")
_BARS = re.compile(r"(?<![\\|])\|(?=[^\s|])([^|\n]*?[^\s\\|])\|(?!\|)")


def _escape_bars(app, what, name, obj, options, lines):
    """Escape ``|...|`` outside literals in a docstring, so ``|v|`` reads as written
    (docutils would take it for a substitution reference and fail the build)."""
    for i, line in enumerate(lines):
        stripped = line.lstrip()
        if "|" not in line or stripped.startswith(("| ", "+-", "+=")) or stripped == "|":
            continue  # a line block or a grid table
        parts = _LITERAL.split(line)
        lines[i] = "".join(p if k % 2 else _BARS.sub(r"\\|\1\\|", p) for k, p in enumerate(parts))


def _setup_docstrings(app):
    app.connect("autodoc-process-docstring", _escape_bars, priority=100)  # before numpydoc (500)


def setup(app):
    app.connect("source-read", _optional_pages)
    _setup_docstrings(app)
