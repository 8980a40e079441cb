"""A refused run leaves nothing behind (issue 26, item 2).

A campaign or calibration study refused for a bad value must not leave a results store (or
trials folder) in its ``--out``: otherwise the corrected rerun into the same folder is refused
for "different parameters". The store itself removes what it made when it closes without a
stored row, so a refusal found after it was made leaves nothing either.
"""

import json

import pytest

from svgs_sim.cli.main import main
from refusal import refused
from svgs_sim.studies.store import ResultStore
from svgs_sim.base.errors import InputError

CAMPAIGN = ["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "4",
            "--exposures-per-render", "2", "--ranges", "5,10", "--processes", "0", "--no-progress"]
STUDY = ["calibrate", "study", "--camera", "galaxy-nexus", "--width", "640", "--height", "480", "--geometric",
         "--views-list", "4,8", "--subsets", "2", "--focal-ranges", "1,3,5,10", "--focal-exposures", "2",
         "--pose-ranges", "2,5,10,20,30", "--poses-per-range", "4", "--processes", "0", "--no-progress"]


@pytest.fixture(autouse=True)
def _no_compile_notice(monkeypatch):
    import svgs_sim.cli.compile_kernels as ck

    monkeypatch.setattr(ck, "kernels_cached", lambda: True)


@pytest.mark.slow  # a few seconds each (make test runs it; make test-fast does not)
@pytest.mark.parametrize("bad, rerun", [(["--ranges", "5,5"], True), (["--ranges", "1e9"], False),
                                        (["--misalignment-deg", "0,0,11"], False),
                                        (["--misalignment-deg", "1,2"], False), (["--sigma-px", "-1"], False)])
def test_a_refused_campaign_leaves_nothing_and_the_corrected_rerun_runs(bad, rerun, tmp_path, capsys):
    """Each refusal leaves no folder; the corrected rerun into it runs (shown once: with no folder
    left, the rerun after any refusal is a fresh run)."""
    out = tmp_path / "campaign"
    argv = CAMPAIGN + ["--out", str(out)]
    refused(argv + bad, capsys, watch=[tmp_path])  # exit 2, one line, within a second, nothing written
    assert not out.exists()
    if not rerun:
        return
    assert main(argv) == 0, capsys.readouterr().err  # the same folder: not refused for other parameters
    capsys.readouterr()
    assert json.loads((out / "manifest.json").read_text())["parameters"]["ranges_m"] == [5.0, 10.0]


def test_a_refused_calibration_study_leaves_no_trials_and_names_no_function(tmp_path, capsys):
    out = tmp_path / "study"
    line = refused(STUDY + ["--true-dist", "5,0,0,0,0", "--out", str(out)], capsys, watch=[tmp_path])
    assert "--true-dist" in line and "sample_board_poses" not in line
    assert not out.exists()


def test_a_refused_calibration_study_keeps_an_existing_folder_as_it_was(tmp_path, capsys):
    out = tmp_path / "study"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    refused(STUDY + ["--true-dist", "5,0,0,0,0", "--out", str(out)], capsys, watch=[out])
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


@pytest.mark.slow
def test_the_corrected_calibration_study_runs_into_the_refused_folder(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(STUDY + ["--true-dist", "5,0,0,0,0", "--out", str(out)]) == 2
    assert main(STUDY + ["--out", str(out)]) == 0, capsys.readouterr().err
    assert (out / "summary.json").is_file()


@pytest.mark.slow
def test_a_calibration_study_refused_after_its_trials_started_leaves_nothing(tmp_path, capsys):
    """Refused once the board set is drawn and detected (a fine 40 x 30 board is not found in every
    view): the trials folder this run made is removed with its stores and detection cache."""
    out = tmp_path / "study"
    argv = [a for a in STUDY if a not in ("--pose-ranges", "2,5,10,20,30", "--width", "640", "--height", "480")]
    argv += ["--pose-ranges", "2,5", "--width", "320", "--height", "240"]
    # refused after the board set was drawn and detected: a few seconds of work by design (at
    # 320 x 240 px no view resolves the board; 640 x 480 finds it in 7 of 8 after 15 s of OpenCV)
    line = refused(argv + ["--board", "chessboard", "--cols", "40", "--rows", "30", "--spacing-mm", "5",
                           "--out", str(out)], capsys, watch=[tmp_path], within_s=60.0,
                   after_work=True)
    assert "--views-list: 8 views asked but the board was found in only 0" in line
    assert "a calibration needs 3: a board with fewer, larger squares, or a larger image" in line
    assert not out.exists()


# --------------------------------------------------------------------------- the store
COLS = ["trial_id", "seed", "x"]


def test_a_store_closed_without_a_row_removes_what_it_made(tmp_path):
    d = tmp_path / "a" / "study"
    with ResultStore(d, {"trials": 10}, COLS):
        pass  # refused or stopped before the first trial finished
    assert not (tmp_path / "a").exists()
    with ResultStore(d, {"trials": 20}, COLS) as st:  # the corrected parameters are not refused
        st.append([{"trial_id": 0, "seed": 1, "x": 0.5}])
    with pytest.raises(InputError, match="different parameters"):
        ResultStore(d, {"trials": 10}, COLS)  # a store with a row is kept, and guards its rows


def test_a_store_keeps_a_folder_with_anything_else_in_it(tmp_path):
    with ResultStore(tmp_path, {"trials": 10}, COLS):
        (tmp_path / "calibration.json").write_text("{}")
    assert {p.name for p in tmp_path.iterdir()} >= {"manifest.json", "results.csv", "calibration.json"}


def test_a_resumed_store_without_new_rows_is_kept(tmp_path):
    with ResultStore(tmp_path, {"trials": 10}, COLS) as st:
        st.append([{"trial_id": 0, "seed": 1, "x": 0.5}])
    with ResultStore(tmp_path, {"trials": 10}, COLS) as st:
        assert st.done_ids == {0}
    with ResultStore(tmp_path, {"trials": 10}, COLS).open() as st:  # opened by hand, closed by the context
        pass
    assert ResultStore(tmp_path, {"trials": 10}, COLS).read_rows()[0]["x"] == 0.5
    # a store made earlier (its manifest already there) is never removed by a later run
    empty = tmp_path / "empty"
    ResultStore(empty, {"trials": 10}, COLS)  # made, never opened (an earlier run)
    with ResultStore(empty, {"trials": 10}, COLS):
        pass
    assert (empty / "manifest.json").is_file()
