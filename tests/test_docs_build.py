"""The documentation builds without a warning (``make docs``: Sphinx with ``-W``).

Three bounded builds with Sphinx's ``dummy`` builder (every page read, every reference
resolved, nothing written), each in a subprocess:

- the pages of docs/ (MyST Markdown) and their links: a link to a page that is not there, a
  page missing from the index, a heading a ``#anchor`` names that is gone - seconds;
- the gallery of docs/gallery/ executed (one Mitsuba render at preview size; ``render``);
- the API reference from the numpydoc docstrings of every module (``slow``: about 45 s of CPU).

Skipped, with the reason, where the docs extra (``pip install -e ".[docs]"``) is not installed.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
NEEDED = ("sphinx", "myst_parser", "numpydoc", "sphinx_gallery", "pydata_sphinx_theme")
MISSING = [name for name in NEEDED if importlib.util.find_spec(name) is None]
pytestmark = pytest.mark.skipif(
    bool(MISSING), reason=f"the docs extra is not installed ({', '.join(MISSING)}): pip install -e '.[docs]'")


def _build(tmp_path, *, gallery: bool, api: bool, timeout_s: float):
    env = {**os.environ, "SVGS_DOCS_GALLERY": "1" if gallery else "0", "SVGS_DOCS_API": "1" if api else "0"}
    cmd = [sys.executable, "-m", "sphinx", "-b", "dummy", "-W", "--keep-going", "-q", "-E",
           "-d", str(tmp_path / "doctrees"), str(DOCS), str(tmp_path / "out")]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout_s)
    assert proc.returncode == 0, f"sphinx warnings or errors:\n{proc.stderr[-6000:]}"
    return proc


@pytest.mark.slow  # a few seconds each (make test runs it; make test-fast does not)
def test_pages_and_links(tmp_path):
    _build(tmp_path, gallery=False, api=False, timeout_s=120)


@pytest.mark.slow  # a few seconds each (make test runs it; make test-fast does not)
def test_a_broken_link_fails_the_build(tmp_path):
    """The check can fail: a page linking to a page that does not exist is a build error."""
    import shutil

    repo = tmp_path / "repo"  # the pages link to files beside docs/ (CONTRIBUTING.md, examples/)
    repo.mkdir()
    for item in ROOT.iterdir():
        if item.is_file():
            shutil.copy(item, repo / item.name)  # copied: an include resolves links from where it is
        elif item.name not in {"docs", ".git", ".venv"}:
            (repo / item.name).symlink_to(item)
    docs = repo / "docs"
    shutil.copytree(DOCS, docs, ignore=shutil.ignore_patterns("_build", "generated", "auto_gallery", "frames",
                                                              "sg_execution_times.rst"))
    page = docs / "frames.md"
    page.write_text(page.read_text() + "\nSee [the missing page](no-such-page.md).\n")
    env = {**os.environ, "SVGS_DOCS_GALLERY": "0", "SVGS_DOCS_API": "0"}
    cmd = [sys.executable, "-m", "sphinx", "-b", "dummy", "-W", "--keep-going", "-q", "-E", str(docs),
           str(tmp_path / "out")]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    warnings = [line for line in proc.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert len(warnings) == 1 and "no-such-page" in warnings[0], proc.stderr[-3000:]


@pytest.mark.render
@pytest.mark.slow
def test_gallery_runs(tmp_path):
    _build(tmp_path, gallery=True, api=False, timeout_s=300)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SVGS_LONG_TESTS"),
                    reason="long form (~40 s, the API reference of every module): set SVGS_LONG_TESTS=1")
def test_api_reference(tmp_path):
    _build(tmp_path, gallery=False, api=True, timeout_s=400)
