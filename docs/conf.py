"""Sphinx configuration: the docs/ pages (Markdown, MyST), an API reference from the numpydoc
docstrings (autosummary over every package) and a gallery of small examples executed at build
time (sphinx-gallery over docs/gallery/).

Build: ``make docs`` (HTML in docs/_build/html). ``SVGS_DOCS_GALLERY=0`` leaves the gallery out
(the bounded build of tests/test_docs_build.py).
"""

from __future__ import annotations

import os
import re
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

project = "svgs-sim"
author = "svgs-sim contributors"
copyright = "svgs-sim contributors, Apache-2.0"
import svgs_sim  # noqa: E402

release = version = svgs_sim.__version__

GALLERY = os.environ.get("SVGS_DOCS_GALLERY", "1") != "0"
# SVGS_DOCS_API=0 leaves the API reference out (the pages and their links only: seconds)
API = os.environ.get("SVGS_DOCS_API", "1") != "0"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "numpydoc",
    "sphinx.ext.mathjax",
]
if GALLERY:
    extensions.append("sphinx_gallery.gen_gallery")

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = [
    "_build",
    "gallery",  # the gallery's sources; sphinx-gallery writes the pages into auto_gallery/
    "reports/**/frames",
]
# the parts left out, and their entries in index.md's tables of contents
LEFT_OUT = [part for part, on in (("auto_gallery", GALLERY), ("api", API)) if not on]
exclude_patterns += LEFT_OUT
if not GALLERY:
    exclude_patterns.append("sg_execution_times.rst")  # a gallery build's timing page

# MyST: the pages are plain GitHub Markdown; headings get anchors for the pages' #links
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath"]

# API reference: one page per module (autosummary :recursive:, docs/api/)
# (docs/_templates/autosummary/module.rst: automodule with its members on one page, the
# submodules below it, ``__main__`` modules left out: importing one runs it)
templates_path = ["_templates"]
autosummary_generate = True
autosummary_imported_members = False
# a package documents what it defines; what it re-exports is documented where it is defined
autodoc_default_options = {"members": True, "ignore-module-all": True}
# an inherited docstring (concurrent.futures.Executor.submit's ``fn(*args, **kwargs)``) is
# not this project's numpydoc
autodoc_inherit_docstrings = False
autodoc_member_order = "bysource"
# The optional Basilisk extra (svgs_sim.sim.basilisk_svgs): its pages build without it installed.
autodoc_mock_imports = ["Basilisk"]
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()

nitpicky = False

html_theme = "pydata_sphinx_theme"
html_title = "svgs-sim"
html_theme_options = {"navigation_with_keys": False, "show_toc_level": 2, "secondary_sidebar_items": ["page-toc"]}

#: The reports that are HTML pages of their own (self-contained), copied into the site beside the
#: pages that link them (docs/reports.md).
HTML_REPORTS = sorted((ROOT / "docs" / "reports").glob("*/report.html"))

if GALLERY:
    sphinx_gallery_conf = {
        "examples_dirs": "gallery",
        "gallery_dirs": "auto_gallery",
        # every script in docs/gallery/ runs (each a few seconds); the minutes-long
        # examples/*.py are not gallery sources and never run here
        "filename_pattern": r"/plot_",
        "ignore_pattern": r"__init__\.py",
        "download_all_examples": False,
        "plot_gallery": "True",
        "abort_on_example_error": True,
        "within_subsection_order": "FileNameSortKey",
        "remove_config_comments": True,
    }


# The pages are written for GitHub; what GitHub shows without a word needs one for Sphinx.
PAGE_TITLES = {
    # written by tools/centroid_table.py and studies/exposure_study.py: tables without a heading
    "centroid_rules": "Centroid rules: the table",
    "reports/exposure-study-htc-amaze-4g/summary": "Exposure study, HTC Amaze 4G: success rate per remedy and range",
}
OUTSIDE_LINKS = {
    # pages outside docs/ that the pages link to, each included by a page of docs/
    "](../CONTRIBUTING.md": "](contributing.md",
}


def _source_read(app, docname, source):
    text = source[0]
    if docname == root_doc:
        text = "\n".join(line for line in text.splitlines()
                         if line.strip() not in {f"{part}/index" for part in LEFT_OUT})
    first = next((line for line in text.splitlines() if line.strip()), "")
    title = PAGE_TITLES.get(docname) or (docname if docname.startswith("reports/") else None)
    if title and docname != root_doc and not first.startswith("#"):
        text = f"# {title}\n\n" + text
    for old, new in OUTSIDE_LINKS.items():
        text = text.replace(old, new)
    source[0] = text


_BARS = re.compile(r"(?<![\\|\w])\|(?=[^\s|])([^|`]*?[^\s|\\])\|(?![|\w])")


def _escape_bars(lines):
    """``|e|`` in a docstring is an absolute value, not an RST substitution: escape its bars.

    Table rows and rules and ````literals```` are left as written.
    """
    for i, line in enumerate(lines):
        bare = line.strip()
        if "|" not in line or (bare.startswith("|") and bare.endswith("|")) or bare.startswith(("+-", "+=")):
            continue  # a table's row or rule
        parts = line.split("``")
        for k in range(0, len(parts), 2):
            parts[k] = _BARS.sub(r"\\|\1\\|", parts[k])
        lines[i] = "``".join(parts)


def _process_docstring(app, what, name, obj, options, lines):
    _escape_bars(lines)


def _copy_html_reports(app, exception):
    """The self-contained HTML reports into the site (``reports/<name>/report.html``)."""
    if exception is not None or app.builder.format != "html":
        return
    for src in HTML_REPORTS:
        dst = Path(app.outdir) / "reports" / src.parent.name / "report.html"
        dst.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst)


def setup(app):
    app.connect("build-finished", _copy_html_reports)
    app.connect("source-read", _source_read)
    app.connect("autodoc-process-docstring", _process_docstring)
