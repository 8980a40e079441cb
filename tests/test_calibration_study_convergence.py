"""Convergence part of the calibration study: detection over a set, calibration from N views,
errors against the truth (geometric images: calibration.synthesize_views, no render)."""

import numpy as np
import pytest

from svgs_sim.calibration import Board, calibrate, sample_board_poses, synthesize_views
from svgs_sim.studies.calibration import (
    calibration_convergence,
    calibration_errors,
    convergence_summary,
    detect_all,
    parse_number_list,
    true_camera,
)
from svgs_sim.base.profiles import Camera
from svgs_sim.base.errors import InputError

from conftest import REPO


@pytest.fixture(scope="module")
def setup():
    cam = true_camera(Camera.load("galaxy-nexus").scaled(640, 480))
    board = Board("chessboard", 9, 6, 0.1)
    R, t = sample_board_poses(board, cam, 40, seed=0)
    imgs = list(synthesize_views(board, cam, R, t, oversample=3, blur_px=0.6, noise_dn=1.5, seed=1))
    return cam, board, imgs, R, t


@pytest.mark.slow
def test_calibration_errors_against_known_truth(setup):
    cam, board, _, R, t = setup
    obj = [board.object_points()] * 12
    img = [cam.project(board.object_points() @ Rk.T + tk) for Rk, tk in zip(R[:12], t[:12])]
    cal = calibrate(obj, img, (cam.width, cam.height))
    e = calibration_errors(cal, cam)
    assert abs(e["fx_error_pct"]) < 1e-4 and e["pp_error_norm_px"] < 1e-3 and e["map_rms_px"] < 1e-3
    # the same calibration judged against a camera 0.1 % longer and 2 px off
    other = cam.replace(fx=cam.fx * 1.001, cx=cam.cx + 2.0)
    e2 = calibration_errors(cal, other)
    assert e2["fx_error_pct"] == pytest.approx(-0.0999, abs=1e-3)
    assert e2["pp_error_u_px"] == pytest.approx(-2.0, abs=1e-3)
    assert e2["map_rms_px"] > 1.5 > e2["map_rot_rms_px"]  # a rotation absorbs the principal-point error


@pytest.mark.slow
def test_convergence_to_the_truth(setup):
    # acceptance on the geometric set at N = 40: fx, fy within 0.2 %, pp within 1 px,
    # mapping error (after rotation) below 0.1 px; and more views -> smaller errors
    cam, board, imgs, _, _ = setup
    det = detect_all(imgs, board)
    assert len(det) == 40 and det.skipped == []
    rows, cals = calibration_convergence(det, cam, (5, 40), subsets=4, seed=2, board=board)
    s = {r["n_views"]: r for r in convergence_summary(rows)}
    assert s[5]["subsets"] == 4 and s[40]["subsets"] == 1
    assert s[40]["fx_error_pct_max_abs"] < 0.2 and s[40]["fy_error_pct_max_abs"] < 0.2
    assert s[40]["pp_error_norm_px_max"] < 1.0 and s[40]["map_rot_rms_px_max"] < 0.1
    assert s[40]["map_rot_rms_px_max"] < s[5]["map_rot_rms_px_mean"]
    assert set(cals) == {5, 40} and len(cals[40].views) == 40


@pytest.mark.slow
def test_bad_sets_are_clear_errors(setup):
    cam, board, imgs, _, _ = setup
    blank = np.full((480, 640), 128, np.uint8)
    det = detect_all(imgs[:4] + [blank], board, names=[f"v{k}" for k in range(5)])
    assert len(det) == 4 and det.skipped[0][0] == "v4" and det.skipped[0][1].reason == "no_board"
    with pytest.raises(InputError, match=r"found in only 4.*v4"):
        calibration_convergence(det, cam, (3, 5))
    with pytest.raises(InputError, match="at least 3 views"):
        calibration_convergence(det, cam, (2,))
    with pytest.raises(InputError, match="differ in size"):
        detect_all([imgs[0], np.zeros((240, 320), np.uint8)], board)
    with pytest.raises(InputError, match="no board images"):
        detect_all([], board)
    with pytest.raises(InputError, match="but camera"):
        calibration_convergence(det, cam.scaled(320, 240), (3,))
    # the wrong board dimensions: no view has it
    det2 = detect_all(imgs[:3], Board("chessboard", 8, 6, 0.1))
    assert len(det2) == 0 and len(det2.skipped) == 3


def test_parse_number_list():
    assert parse_number_list("5, 10,20", "--views-list", integer=True, minimum=3) == (5, 10, 20)
    assert parse_number_list("1,7.5", "--pose-ranges") == (1.0, 7.5)
    for bad, what in (("5,x", "not a number"), ("2.5", "whole number"), ("", "comma-separated"), ("1,2", "minimum"),
                      ("nan", "not finite")):
        with pytest.raises(InputError, match=what):
            parse_number_list(bad, "--views-list", integer=bad != "nan", minimum=3)


def test_results_stored_under_the_old_column_names_are_read(tmp_path):
    """A convergence store written by the old code (the committed study's store with the header and
    the manifest's columns as they were before the rename: cx_err_px, fx_err_pct, ...) opens under
    the new names (pp_error_u_px, fx_error_pct, ...) with the same values, and resumes."""
    import json
    import shutil

    from svgs_sim.studies.calibration.convergence import RENAMED_COLUMNS, upgrade_stored_columns
    from svgs_sim.studies.calibration.trials import KINDS, SCENARIO_KEYS
    from svgs_sim.studies.store import ResultStore, read_rows

    src = REPO / "docs" / "reports" / "calibration-study-galaxy-nexus" / "trials" / "convergence"
    folder = tmp_path / "convergence"
    folder.mkdir()
    for name in ("manifest.json", "results.csv"):
        shutil.copy(src / name, folder / name)
    back = {v: k for k, v in RENAMED_COLUMNS.items()}  # the old code's names
    lines = (folder / "results.csv").read_text().split("\n")
    lines[0] = ",".join(back.get(c, c) for c in lines[0].split(","))
    (folder / "results.csv").write_text("\n".join(lines))
    man = json.loads((folder / "manifest.json").read_text())
    man["columns"] = [back.get(c, c) for c in man["columns"]]
    (folder / "manifest.json").write_text(json.dumps(man, indent=2))
    old = read_rows(folder / "results.csv")
    assert set(RENAMED_COLUMNS) <= set(old[0])
    assert upgrade_stored_columns(folder) and not upgrade_stored_columns(folder)  # once
    cols = KINDS["convergence"].columns(SCENARIO_KEYS["convergence"])
    new = read_rows(folder / "results.csv", cols)
    assert len(new) == len(old) > 0
    for o, n in zip(old, new):
        assert {RENAMED_COLUMNS.get(k, k): v for k, v in o.items()} == n
    params = json.loads((folder / "manifest.json").read_text())["parameters"]
    with ResultStore(folder, params, cols) as store:  # the stored study, resumable: nothing to redo
        assert store.done_ids == {r["trial_id"] for r in old}
