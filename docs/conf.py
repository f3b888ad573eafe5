"""Sphinx configuration of the workbench's documentation (``make docs``).

The API reference is generated from the numpydoc docstrings, the gallery from
the scripts in ``docs/examples`` (run at build time, figures included), and the
page of measured figures from ``results/benchmarks.json`` by the local extension
in ``docs/_ext``. Environment variables:

``VEHID_DOCS_QUICK=1``
    The gallery's scripts run on shortened records (the docs test sets it).
``VEHID_BENCHMARKS_JSON``
    The figures file to render instead of ``results/benchmarks.json``.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

import matplotlib

# Figures are drawn to files; a display is neither needed nor wanted.
matplotlib.use("Agg")

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
import public_api  # noqa: E402  (the extensions' folder is on the path from here on)

project = "vehid"
author = "the vehid authors"
copyright = "2026, the vehid authors"
release = "0.1.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "benchmark_tables",
    "api_pages",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "examples/README.rst", "**/GALLERY_HEADER.rst"]

# The README's and notes' relative links point at repository files (code,
# SOURCE.md files); they are rendered as text rather than as broken links.
myst_heading_anchors = 3
suppress_warnings = ["myst.xref_missing"]

autosummary_generate = True
autosummary_imported_members = True
autodoc_default_options = {"members": True, "inherited-members": False, "show-inheritance": False}
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
# Every docstring the reference shows is validated, by the checks the docstring test
# applies to the public API (docs/_ext/public_api.py): under -W a failure stops the build.
numpydoc_validation_checks = set(public_api.VALIDATION_CHECKS)
numpydoc_validation_overrides = {"PR01": [public_api.ATTRIBUTES_SECTION]}
numpydoc_validation_exclude = {"^" + re.escape(name) + "$" for name in public_api.data_names()}

quick = os.environ.get("VEHID_DOCS_QUICK", "0") == "1"
sphinx_gallery_conf = {
    "examples_dirs": str(DOCS / "examples"),
    "gallery_dirs": str(DOCS / "auto_examples"),
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    # Each script is timed and listed; none should stop the build silently.
    "abort_on_example_error": True,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "show_memory": False,
    "show_signature": False,
}

benchmarks_json = os.environ.get("VEHID_BENCHMARKS_JSON", str(DOCS.parent / "results" / "benchmarks.json"))

html_theme = "pydata_sphinx_theme"
html_title = "vehid"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    # The sidebar lists the current section only: with a page per API name, a
    # full tree on every page made the sidebar a fifth of the build's time.
    "collapse_navigation": True,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": [],
}
templates_path = ["_templates"]
html_static_path: list[str] = []
html_show_sourcelink = False


def setup(app):
    # numpydoc looks for a signature in every callable's docstring, parsing the whole
    # docstring once more per object; the workbench's docstrings never begin with a
    # signature, and the search took a tenth of the build.
    for listener in list(app.events.listeners.get("autodoc-process-signature", [])):
        if getattr(listener.handler, "__module__", "") == "numpydoc.numpydoc":
            app.disconnect(listener.id)
