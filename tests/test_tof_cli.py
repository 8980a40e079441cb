"""``svgs tof solve`` in-process: file formats, JSON keys and exit codes."""

import json

import cv2
import numpy as np
import pytest

from svgs_sim.cli.main import main
from svgs_sim.svgs.frames import pose_from_scenario
from svgs_sim.tof import load_camera, load_target
from synth_tof import synth_frame

#: The keys ``svgs solve --json`` prints (svgs_sim.cli.main), which ``svgs tof solve --json`` shares.
SOLVE_KEYS = {"ok", "reason", "state", "R_cam_target", "t_cam_target_m", "targets_px", "n_blobs", "residual_rms_px"}
#: The documented JSON state keys, written out: an independent check of svgs_sim.svgs.frames.STATE_KEYS.
STATE_KEYS = {"x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("tof")
    cam, tgt = load_camera(), load_target()
    R, t = pose_from_scenario(1.2, 0.03, -0.02, 4.0, -6.0, 12.0)
    fr = synth_frame(cam, tgt, R, t, seed=4, gray_scale_dn=2000.0)
    np.save(d / "gray.npy", fr.gray)
    np.save(d / "depth.npy", fr.depth_m)
    cv2.imwrite(str(d / "gray.png"), np.clip(fr.gray, 0, 65535).astype(np.uint16))
    cv2.imwrite(str(d / "depth_mm.png"), np.round(np.nan_to_num(fr.depth_m) * 1000).astype(np.uint16))
    cv2.imwrite(str(d / "depth_m.tiff"), np.nan_to_num(fr.depth_m).astype(np.float32))
    np.save(d / "depth_small.npy", fr.depth_m[:100])
    np.save(d / "depth_nan.npy", np.full_like(fr.depth_m, np.nan))
    np.save(d / "dark.npy", np.zeros_like(fr.gray))
    np.save(d / "gray_seq.npy", np.stack([fr.gray, fr.gray]))
    np.save(d / "depth_seq.npy", np.stack([fr.depth_m, fr.depth_m]))
    (d / "junk.png").write_bytes(b"not an image")
    return d, fr


def _run(capsys, *args):
    rc = main(["tof", "solve", *map(str, args)])
    out = capsys.readouterr()
    return rc, out


@pytest.mark.parametrize("gray, depth", [("gray.npy", "depth.npy"), ("gray.png", "depth_mm.png"),
                                         ("gray.png", "depth_m.tiff"), ("gray_seq.npy", "depth_seq.npy")])
def test_solve_formats_json(files, capsys, gray, depth):
    d, fr = files
    rc, out = _run(capsys, "--gray", d / gray, "--depth", d / depth, "--json")
    assert rc == 0, out.err
    js = json.loads(out.out)
    assert SOLVE_KEYS <= set(js) and set(js["state"]) == STATE_KEYS and js["ok"] is True
    assert set(js["targets_px"]) == {str(k) for k in range(1, 9)}
    np.testing.assert_allclose(js["t_cam_target_m"], fr.t_cam_target_m, atol=0.003)  # mm-quantised PNG depth too


def test_solve_text_output(files, capsys):
    d, _ = files
    rc, out = _run(capsys, "--gray", d / "gray.npy", "--depth", d / "depth.npy")
    assert rc == 0 and "SOLVED" in out.out and "marker 8" in out.out


def test_no_solution_exits_1_with_the_reason(files, capsys):
    d, _ = files
    rc, out = _run(capsys, "--gray", d / "dark.npy", "--depth", d / "depth.npy", "--json")
    js = json.loads(out.out)
    assert rc == 1 and js["ok"] is False and js["reason"] == "no_blobs"
    assert SOLVE_KEYS <= set(js) and js["state"] is None
    rc, out = _run(capsys, "--gray", d / "dark.npy", "--depth", d / "depth.npy")
    assert rc == 1 and "NO SOLUTION (no_blobs)" in out.out


@pytest.mark.parametrize("gray, depth, extra, message", [
    ("gray.npy", "depth_small.npy", [], "different sizes"),
    ("gray.npy", "depth_nan.npy", [], "no valid pixel"),
    ("missing.npy", "depth.npy", [], "does not exist"),
    ("junk.png", "depth.npy", [], "corrupt"),
    ("gray.npy", "depth_seq.npy", [], "frame"),
    ("gray.npy", "depth.npy", ["--camera", "no-such-camera"], "unknown camera"),
])
def test_bad_input_exits_2(files, capsys, gray, depth, extra, message):
    d, _ = files
    rc, out = _run(capsys, "--gray", d / gray, "--depth", d / depth, *extra)
    assert rc == 2
    assert message in out.err and "Traceback" not in out.err
