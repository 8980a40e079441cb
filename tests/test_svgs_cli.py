"""`svgs solve` end to end, in-process (exit codes, JSON keys, bad input)."""

import json

import cv2
import numpy as np
import pytest

from svgs_sim.cli.main import main
from svgs_sim.svgs.frames import pose_from_scenario, pose_to_state
from synth_svgs import synth_frame

KEYS = {"ok", "reason", "state", "R_cam_target", "t_cam_target_m", "targets_px", "n_blobs", "residual_rms_px"}


@pytest.fixture(scope="module")
def example_png(tmp_path_factory, nexus, pattern):
    R, t = pose_from_scenario(8.0, 0.4, -0.3, 12, -8, 25)
    fr = synth_frame(nexus, pattern, R, t, seed=3, n_distractors=6)
    path = tmp_path_factory.mktemp("img") / "frame.png"
    cv2.imwrite(str(path), fr.image)
    return path, pose_to_state(R, t)


def test_solve_json(example_png, capsys):
    path, truth = example_png
    assert main(["solve", str(path), "--camera", "galaxy-nexus", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert KEYS <= set(out)
    assert out["ok"] is True and out["reason"] is None
    s = out["state"]
    got = np.array([s["x_m"], s["y_m"], s["z_m"], *np.radians([s["roll_deg"], s["pitch_deg"], s["yaw_deg"]])])
    assert np.abs(got[:3] - truth[:3]).max() < 0.05
    assert np.degrees(np.abs(got[3:] - truth[3:])).max() < 0.5
    assert set(out["targets_px"]) == {"1", "2", "3", "4"}
    assert out["n_blobs"] >= 4 and out["residual_rms_px"] < 0.5
    R = np.array(out["R_cam_target"])
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-9)


def test_solve_out_writes_the_overlay_and_the_solution(example_png, capsys, tmp_path):
    """Issue 14 item 6: what the detector found and where the solution puts the targets."""
    path, _ = example_png
    out = tmp_path / "run"
    assert main(["solve", str(path), "--camera", "galaxy-nexus", "--out", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["outputs"]["overlay"] == str(out / "overlay.png")
    saved = json.loads((out / "solution.json").read_text())
    assert saved["state"] == d["state"]
    img = cv2.imread(str(out / "overlay.png"))
    assert img is not None and img.ndim == 3 and max(img.shape[:2]) >= 900
    # the four labels and the reprojection crosses are drawn
    assert np.all(img == (0, 255, 255), axis=2).sum() > 100  # labels (yellow)
    assert np.all(img == (60, 60, 255), axis=2).sum() > 20  # reprojected solution (red)


def test_solve_readable(example_png, capsys):
    path, _ = example_png
    assert main(["solve", str(path), "--camera", "galaxy-nexus"]) == 0
    assert "SOLVED" in capsys.readouterr().out


def test_no_solution_exit_1(tmp_path, capsys):
    img = np.zeros((1944, 2592), np.uint8)
    cv2.circle(img, (1000, 900), 3, 255, -1)  # one spot: not the pattern
    p = tmp_path / "one.png"
    cv2.imwrite(str(p), img)
    assert main(["solve", str(p), "--camera", "galaxy-nexus", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is False and out["reason"] in ("too_few_blobs", "merged_spots")
    assert out["message"]


def write(tmp_path, name, data: bytes):
    p = tmp_path / name
    p.write_bytes(data)
    return str(p)


@pytest.mark.parametrize(
    "make_args, match",
    [
        (lambda d, png: ["solve", str(d / "missing.png"), "--camera", "galaxy-nexus"], "does not exist"),
        (lambda d, png: ["solve", write(d, "empty.png", b""), "--camera", "galaxy-nexus"], "empty"),
        (lambda d, png: ["solve", write(d, "bad.png", b"not an image at all" * 50), "--camera", "galaxy-nexus"], "corrupt"),
        (lambda d, png: ["solve", png, "--camera", "htc-amaze-4g"], "does not match camera"),
        (lambda d, png: ["solve", png, "--camera", "no-such-phone"], "unknown camera profile"),
        (lambda d, png: ["solve", png, "--camera", write(d, "nan.toml", b"[intrinsics]\nwidth=2592\nheight=1944\nfx=nan\nfy=1\ncx=1\ncy=1\n")], "fx"),
        (lambda d, png: ["solve", png, "--camera", "galaxy-nexus", "--pattern", "nope"], "unknown target pattern"),
        (lambda d, png: ["solve", png, "--camera", "galaxy-nexus", "--threshold", "-3"], "threshold"),
        (lambda d, png: ["solve", png, "--camera", "galaxy-nexus", "--sigma-px", "0"], "sigma-px"),
    ],
)
def test_bad_input_exit_2(tmp_path, example_png, capsys, make_args, match):
    path, _ = example_png
    assert main(make_args(tmp_path, str(path))) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err


def test_usage_error_exit_2(capsys):
    assert main(["solve"]) == 2
    assert main(["no-such-command"]) == 2
