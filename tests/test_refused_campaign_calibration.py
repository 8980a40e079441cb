"""A refused rendered campaign leaves its folder as it was, even when the refusal comes after its
focal-length calibration (issue 26): ``calibration.json`` is written only once the campaign's
store has taken the run. A folder that did not exist does not exist afterwards; a previous run's
files are untouched (a rerun with other parameters used to overwrite its ``calibration.json``).

The calibration's renders are replaced by projected centroids (``focal_frames_geometric``): the
refusals come before any trial, so nothing here needs Mitsuba.
"""

import dataclasses
import json
from pathlib import Path

import pytest

import svgs_sim.calibration.focal
import svgs_sim.studies.campaign.paper_calibration as paper_calibration
import svgs_sim.studies.campaign.run as campaign_run
from svgs_sim.cli.main import main
from svgs_sim.studies.calibration.focal import focal_frames_geometric
from svgs_sim.studies.campaign import make_config, rendered_paper_calibration
from svgs_sim.studies.store import ResultStore

ARGS = ["campaign", "--camera", "galaxy-nexus", "--trial-kind", "render", "--calibration", "paper", "--trials", "2",
        "--exposures-per-render", "2", "--ranges", "4,8", "--processes", "0", "--no-progress"]


@pytest.fixture(autouse=True)
def _no_compile_notice(monkeypatch):
    import svgs_sim.cli.compile_kernels as ck

    monkeypatch.setattr(ck, "kernels_cached", lambda: True)


@pytest.fixture
def renders(monkeypatch):
    """The calibration's frames, projected instead of rendered; the list of calls."""
    calls = []

    def frames(true, cam, pat, ranges_m, *, exposures=1, seed=0, progress=None, **kw):
        calls.append(list(ranges_m))
        return focal_frames_geometric(true, pat, ranges_m, exposures=exposures, seed=seed)

    monkeypatch.setattr(paper_calibration, "focal_frames_rendered", frames)  # patched where it is looked up
    return calls


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _previous_run(out: Path) -> dict:
    """A folder as a rendered campaign with seed 0 leaves it: its calibration and its store."""
    config = make_config("galaxy-nexus", ranges_m=[4.0, 8.0], trials_per_range=2, exposures_per_render=2,
                         trial_kind="render", calibration="paper")
    config = rendered_paper_calibration(config, out)
    ResultStore(out, config.manifest(), ["trial_id", "seed", "x"])  # writes its manifest
    assert {"calibration.json", "manifest.json"} <= set(_snapshot(out))
    return _snapshot(out)


def _refused(capsys, argv) -> str:
    assert main(argv) == 2
    cap = capsys.readouterr()
    lines = [ln for ln in cap.err.splitlines() if ln.strip() and not ln.startswith("plan: ")]  # the plan first
    assert len(lines) == 1 and "Traceback" not in cap.err and cap.out == "", cap.err
    return lines[0]


@pytest.mark.parametrize("change, stored", [(["--seed", "1"], "seed: 0 -> 1"),
                                            (["--trials", "4"], "trials_per_range: 2 -> 4")])
def test_a_resumed_folder_with_other_parameters_is_refused_untouched_before_the_renders(change, stored, renders,
                                                                                       tmp_path, capsys):
    out = tmp_path / "campaign"
    before = _previous_run(out)
    renders.clear()
    line = _refused(capsys, ARGS + ["--out", str(out)] + change)
    assert "--out" in line and stored in line, line
    assert _snapshot(out) == before  # calibration.json and the store as they were
    assert renders == []  # refused before the calibration's renders


def test_a_refusal_after_the_calibration_leaves_no_folder(renders, monkeypatch, tmp_path, capsys):
    """A calibration 60 % off (forced here) makes every scenario's focal_error_frac invalid: the
    campaign is refused after its calibration, which was kept in the folder before."""
    real = svgs_sim.calibration.focal.estimate_focal

    def off(*a, **kw):
        est = real(*a, **kw)
        return dataclasses.replace(est, f_px=1.6 * est.f_px)

    monkeypatch.setattr(paper_calibration, "estimate_focal", off)
    out = tmp_path / "campaign"
    line = _refused(capsys, ARGS + ["--out", str(out)])
    assert "focal_error_frac" in line and renders, line
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_an_interrupted_campaign_keeps_its_calibration(renders, monkeypatch, tmp_path, capsys):
    """Not a refusal: the calibration's renders are kept for the rerun."""
    def interrupted(*a, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(campaign_run, "run_stored_study", interrupted)
    out = tmp_path / "campaign"
    assert main(ARGS + ["--out", str(out)]) == 130
    capsys.readouterr()
    saved = json.loads((out / "calibration.json").read_text())
    assert saved["key"]["seed"] == 0 and saved["result"]["ranges_used_m"] == [4.0, 8.0]
