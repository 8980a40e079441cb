"""Issue 26, deliverable 7: nothing a user gives is silently ignored.

Each case asserts the exit code (or the exception), the one line that says it, and that no
traceback was printed. The references are independent of the code under test: Pillow's
``ImageOps.exif_transpose`` for EXIF orientation, the pinhole model for the pattern images,
the profile's own numbers for the resize.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from refusal import refused
from svgs_sim.svgs.frames import pose_from_scenario

REPO = Path(__file__).resolve().parents[1]


def _run(argv, capsys):
    from svgs_sim.cli.main import main

    code = main(argv)
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    return code, cap.out, cap.err


def _save_with_orientation(path, array, orientation, **kw):
    from PIL import Image

    im = Image.fromarray(array)
    exif = im.getexif()
    exif[0x0112] = orientation
    im.save(path, exif=exif.tobytes(), **kw)


# ------------------------------------------------------------------------ EXIF orientation
@pytest.mark.parametrize("orientation", range(1, 9))
@pytest.mark.parametrize("colour", [False, True])
def test_exif_orientation_is_applied_as_pillow_does(tmp_path, capsys, orientation, colour):
    from PIL import Image, ImageOps

    from svgs_sim.svgs.pipeline import load_image

    rng = np.random.default_rng(orientation)
    a = rng.integers(0, 256, (30, 50, 3) if colour else (30, 50), dtype=np.uint8)
    p = tmp_path / "photo.png"  # lossless: the pixels must move exactly as a viewer moves them
    _save_with_orientation(p, a, orientation)
    got = load_image(p)
    with Image.open(p) as im:
        ref = np.asarray(ImageOps.exif_transpose(im))
    assert got.shape == ref.shape and np.array_equal(got, ref)
    err = capsys.readouterr().err.strip().splitlines()
    if orientation == 1:
        assert err == []
    else:  # one line naming the orientation and the size used
        assert len(err) == 1 and f"EXIF orientation {orientation}" in err[0]
        assert f"{ref.shape[1]} x {ref.shape[0]} px" in err[0]


def test_jpeg_photo_held_on_its_side_is_solved_upright_and_said(tmp_path, capsys, nexus, pattern):
    """A phone held on its side stores the picture rotated with EXIF orientation 6. The upright
    picture is what the camera profile describes: it solves, and the rotation is said."""
    from synth_svgs import synth_frame

    R, t = pose_from_scenario(5.0, 0.05, -0.03, yaw_deg=4.0)
    upright = synth_frame(nexus, pattern, R, t, sigma_px=1.5, seed=3).image
    stored = np.ascontiguousarray(np.rot90(upright, 1))  # orientation 6: the viewer turns it 90 deg clockwise
    p = tmp_path / "side.jpg"
    _save_with_orientation(p, stored, 6, quality=95)
    code, out, err = _run(["solve", str(p), "--camera", "galaxy-nexus", "--json"], capsys)
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if "EXIF" in ln]
    assert len(lines) == 1 and "orientation 6" in lines[0] and "rotated 90 deg clockwise" in lines[0]
    d = json.loads(out)
    assert d["ok"] and abs(d["state"]["z_m"]) == pytest.approx(5.0, rel=0.01)  # the range it was made at


# ------------------------------------------------------------------------ trajectory columns
def test_trajectory_with_state_and_stand_columns_is_refused(tmp_path, capsys):
    f = tmp_path / "both.csv"
    f.write_text("t_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg,rail_m,stage_m\n"
                 "0,0,0,10,0,0,0,10,0\n4,0,0,6,0,0,0,6,0\n")
    out_dir = tmp_path / "run"
    lines = [refused(["approach", "--trajectory", str(f), "--fps", "2", "--out", str(out_dir)], capsys,
                     watch=[tmp_path])]
    assert lines[0].startswith("svgs approach: error: --trajectory")
    assert "x_m, y_m, z_m" in lines[0] and "rail_m, stage_m" in lines[0]  # both sets named
    assert not out_dir.exists()


# ------------------------------------------------------------------------ frame count
def test_approach_of_one_frame_is_refused_with_the_rate_that_gives_two(tmp_path, capsys):
    out_dir = tmp_path / "run"
    lines = [refused(["approach", "--from", "10", "--to", "5", "--duration", "3", "--fps", "1e-9",
                      "--out", str(out_dir)], capsys, watch=[tmp_path])]
    assert "--fps" in lines[0] and "gives 1 frame" in lines[0] and "at least 2" in lines[0]
    assert not out_dir.exists()
    # the rate it names gives two frames over the 3 s: floor(3 s x fps) + 1 >= 2
    import re

    from svgs_sim.sim.approach import Trajectory

    fps = float(re.search(r"give --fps ([0-9.e+-]+) or more", lines[0]).group(1))
    assert 3.0 * fps >= 1.0
    assert len(Trajectory.straight(10.0, 5.0, 3.0).frame_times(fps)) == 2


# ------------------------------------------------------------------------ same image twice
@pytest.fixture(scope="module")
def focal_images(tmp_path_factory):
    import cv2

    from svgs_sim.base.profiles import Camera, Pattern
    from synth_svgs import synth_frame

    cam, pat = Camera.load("galaxy-nexus"), Pattern.load("svgs-3u")
    folder = tmp_path_factory.mktemp("focal")
    paths = []
    for k, r in enumerate((2.0, 4.0, 7.0)):
        R, t = pose_from_scenario(r, 0.02 * r, -0.01 * r, yaw_deg=3.0 * k)
        p = folder / f"range{r:g}m.png"
        cv2.imwrite(str(p), synth_frame(cam, pat, R, t, sigma_px=1.5, seed=10 + k).image)
        paths.append(p)
    return paths


def test_focal_refuses_the_same_image_twice_even_under_another_name(tmp_path, capsys, focal_images):
    import shutil

    copy = tmp_path / "copy_of_range2m.png"
    shutil.copy(focal_images[0], copy)
    base = ["calibrate", "focal", "--camera", "galaxy-nexus"]
    ok = base + sum((["--image", str(p), "--range", str(r)] for p, r in zip(focal_images, (2, 4, 7))), [])
    code, out, err = _run(ok + ["--json"], capsys)
    assert code == 0, err
    for extra in (["--image", str(focal_images[0]), "--range", "2"], ["--image", str(copy), "--range", "3"]):
        lines = [refused(ok + extra, capsys, watch=[tmp_path])]
        assert lines[0].startswith("svgs calibrate focal: error: --image")
        assert "range2m.png" in lines[0] and "same picture" in lines[0]


@pytest.mark.slow  # a few seconds each (make test runs it; make test-fast does not)
def test_board_calibration_refuses_a_view_given_twice(tmp_path, capsys):
    import cv2

    from svgs_sim.calibration import Board, sample_board_poses, synthesize_views
    from svgs_sim.base.profiles import Camera

    cam = Camera(name="synthetic", width=640, height=480, fx=600.0, fy=600.0, cx=319.5, cy=239.5)
    board = Board("chessboard", 9, 6, 0.025)
    R, t = sample_board_poses(board, cam, 4, seed=11)
    paths = []
    for k, img in enumerate(synthesize_views(board, cam, R, t, blur_px=0.6, noise_dn=1.5, seed=12)):
        paths.append(tmp_path / f"v{k}.png")
        cv2.imwrite(str(paths[-1]), img)
    blank = np.full((480, 640), 128, np.uint8)  # no board: skipped and listed, so twice does no harm
    for n in ("blank1.png", "blank2.png"):
        cv2.imwrite(str(tmp_path / n), blank)
    base = ["calibrate", "board", "--board", "chessboard", "--cols", "9", "--rows", "6", "--spacing-mm", "25",
            "--min-views", "3", "--json"]
    code, out, err = _run(base + [str(p) for p in paths] + [str(tmp_path / "blank1.png"), str(tmp_path / "blank2.png")],
                          capsys)
    assert code == 0, err
    lines = [refused(base + [str(p) for p in paths] + [str(paths[1])], capsys, watch=[tmp_path], json_out=True)]
    assert lines[0].startswith("svgs calibrate board: error: images:")
    assert "v1.png" in lines[0] and "same picture" in lines[0]


# ------------------------------------------------------------------------ non-square boards
def test_resize_to_another_shape_warns_with_the_focal_lengths(capsys):
    from argparse import Namespace

    from svgs_sim.cli.calibrate_study import _camera
    from svgs_sim.base.profiles import Camera

    prof = Camera.load("galaxy-nexus")
    cam = _camera(Namespace(camera="galaxy-nexus", width=640, height=100, calibrate_command="render-board"))
    err = capsys.readouterr().err.strip().splitlines()
    fx, fy = prof.fx * 640 / prof.width, prof.fy * 100 / prof.height  # the scaling, from the profile's numbers
    assert (cam.fx, cam.fy) == pytest.approx((fx, fy))
    assert len(err) == 1 and err[0].startswith("svgs calibrate render-board: warning:")
    assert f"fx {fx:.1f} px" in err[0] and f"fy {fy:.1f} px" in err[0]
    h = round(prof.height * 640 / prof.width)
    assert f"--height {h}" in err[0]
    _camera(Namespace(camera="galaxy-nexus", width=640, height=480, calibrate_command="render-board"))  # same shape
    assert capsys.readouterr().err == ""


def test_non_square_calibration_result_is_warned():
    from svgs_sim.calibration.intrinsics import Calibration

    std = {k: 0.0 for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")}
    K = np.array([[605.0, 0, 319.5], [0, 126.0, 49.5], [0, 0, 1]])
    cal = Calibration(K, np.zeros(5), (640, 100), 0.1, np.full(12, 0.1), std, np.zeros((12, 3)), np.zeros((12, 3)),
                      [f"v{k}" for k in range(12)], np.full(12, 54))
    w = [s for s in cal.warnings if "non-square" in s]
    assert len(w) == 1 and "fx 605.0 px" in w[0] and "fy 126.0 px" in w[0]
    square = Calibration(np.array([[605.0, 0, 319.5], [0, 604.0, 239.5], [0, 0, 1]]), np.zeros(5), (640, 480), 0.1,
                         np.full(12, 0.1), std, np.zeros((12, 3)), np.zeros((12, 3)), [f"v{k}" for k in range(12)],
                         np.full(12, 54))
    assert not [s for s in square.warnings if "non-square" in s]


# ------------------------------------------------------------------------ GPU variant
def test_variant_fallback_decision_is_named():
    from svgs_sim.render.variant import decide, fallback_line, is_fallback

    avail = ["scalar_rgb", "llvm_ad_mono", "cuda_ad_mono"]
    name, _, note = decide("cuda", cuda_ok=False, llvm_version=(19, 1, 0), available=avail)
    assert name == "llvm_ad_mono" and is_fallback("cuda", name)
    assert "no CUDA device" in note and "llvm_ad_mono" in note
    assert not is_fallback("cuda", "cuda_ad_mono") and not is_fallback("llvm", "llvm_ad_mono")
    assert not is_fallback(None, "llvm_ad_mono") and is_fallback(None, "scalar_rgb")
    line = fallback_line("cuda", name, note)
    assert "cuda" in line and "llvm_ad_mono" in line and "\n" not in line


@pytest.mark.render
def test_cuda_request_without_a_gpu_is_said_once_on_stderr():
    script = ("from svgs_sim.render.variant import select_variant\n"
              "a = select_variant(); b = select_variant()\n"
              "print(a.name, a.backend)\n")
    env = dict(os.environ, SVGS_MI_VARIANT="cuda")
    p = subprocess.run([sys.executable, "-c", script], env=env, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr[-2000:]
    name, backend = p.stdout.split()
    lines = [ln for ln in p.stderr.splitlines() if "SVGS_MI_VARIANT" in ln]
    if backend == "cuda":  # a machine with a GPU: the request is met, nothing to say
        assert lines == []
    else:
        assert len(lines) == 1 and lines[0].startswith("svgs: note: SVGS_MI_VARIANT=cuda")
        assert "no CUDA device" in lines[0] and name in lines[0]
