"""The README's and the docs' result numbers are written from the committed reports' data
(svgs_sim.studies.report_text): a number typed by hand, or a report regenerated without its prose,
fails here."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from svgs_sim.assets.papers import svgs_2014_results
from svgs_sim.studies.report_text import BLOCK_RE, BLOCKS, PAGES, fill, main, stale

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def block_texts():
    """Every passage written once from the committed data (the writers take seconds each)."""
    return {name: writer(ROOT) for name, writer in BLOCKS.items()}


@pytest.fixture
def written_once(block_texts, monkeypatch):
    """The passages' writers give the texts written once from the repository's data (the copies
    of the root below read the same data through their links)."""
    for name, text in block_texts.items():
        monkeypatch.setitem(BLOCKS, name, lambda root, _text=text: _text)


def test_every_generated_passage_matches_the_committed_data(written_once):
    diffs = stale(ROOT)
    assert not diffs, ("generated passages differ from the reports' data; run python -m svgs_sim.studies.report_text:\n"
                       + "".join(diffs))


def test_every_page_passage_has_a_writer_and_every_writer_is_used():
    used = set()
    for p in PAGES:
        used |= {m.group("name") for m in BLOCK_RE.finditer((ROOT / p).read_text(encoding="utf-8"))}
    assert used == set(BLOCKS)


def _copy_root(tmp_path: Path) -> Path:
    for p in PAGES:
        if p.startswith("docs/reports/"):  # read through the link below
            continue
        (tmp_path / p).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / p, tmp_path / p)
    for data in ("reports", "figures"):  # read only: the test never writes the figure (--check, fill)
        (tmp_path / "docs" / data).symlink_to(ROOT / "docs" / data, target_is_directory=True)
    return tmp_path


def test_an_edited_committed_number_fails_the_check(tmp_path, capsys, written_once):
    root = _copy_root(tmp_path)
    readme = root / "README.md"
    text = readme.read_text(encoding="utf-8")
    m = next(m for m in BLOCK_RE.finditer(text) if m.group("name") == "merge-range")
    body = m.group("body")
    i = next(k for k, ch in enumerate(body) if ch.isdigit())
    edited = body[:i] + str((int(body[i]) + 1) % 10) + body[i + 1:]
    readme.write_text(text[:m.start("body")] + edited + text[m.end("body"):], encoding="utf-8")
    diffs = stale(root, pages=("README.md",))
    assert len(diffs) == 1 and "README.md" in diffs[0] and edited.strip() in diffs[0]
    assert main(["--check", "--root", str(root)]) == 1  # the command, over every page
    assert "README.md" in capsys.readouterr().out
    # written from the data again, the page is the committed one
    assert fill(readme.read_text(encoding="utf-8"), root) == (ROOT / "README.md").read_text(encoding="utf-8")


def test_an_unknown_passage_is_refused():
    with pytest.raises(KeyError, match="no-such"):
        fill("<!-- generated: no-such -->\n<!-- /generated: no-such -->", ROOT)


def test_the_root_must_hold_the_pages(tmp_path, capsys):
    assert main(["--check", "--root", str(tmp_path)]) == 2
    assert "README.md" in capsys.readouterr().err


@pytest.mark.parametrize("phone", ["galaxy-nexus", "htc-amaze-4g"])
def test_the_std_count_agrees_with_a_recount_from_results_csv(phone):
    """An independent recount: the std of the signed error of the baseline's reported trials (solved,
    or refused only by the consistency test) per range and component, from results.csv with the csv
    module, against the paper's Tables 3 and 5 read from its own file; the count within 2x must be
    the one the README and docs print."""
    folder = ROOT / "docs" / "reports" / f"campaign-{phone}"
    with open(folder / "results.csv", newline="", encoding="utf-8") as fh:
        rows = [r for r in csv.DictReader(fh) if r["variant"] == "baseline"
                and (r["ok"] == "1" or (r["reason"] == "inconsistent" and r["err_x_m"] != ""))]
    paper = svgs_2014_results()
    within = cells = 0
    for (ph, stat, r), vals in paper.items():
        if ph != phone or stat != "std":
            continue
        sel = [x for x in rows if float(x["nominal_range_m"]) == r]
        for c, p in vals.items():
            s = np.std([float(x[f"err_{c}"]) for x in sel], ddof=1)
            cells += 1
            within += 0.5 <= s / p <= 2.0
    counts = json.loads((folder / "honest_count.json").read_text())["counts"]
    std = next(iter(counts.values()))["by_statistic"]["std"]
    assert (std["within_2x"], std["predicted"]) == (within, cells)
    name = {"galaxy-nexus": "Galaxy Nexus", "htc-amaze-4g": "HTC Amaze 4G"}[phone]
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert f"{name}: {within} of {cells} standard-deviation cells within 2x" in readme
