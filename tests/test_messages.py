"""Messages say what was wrong (issue 26, item 6): the option and its allowed range, no internal
field name or stray unit, the shape of an array, the blobs found, a threshold no pixel can pass,
special files, no library chatter - each an exit code, one line and no traceback.

Absurdly large floats (1e308) are refused by every float option of every command before any work
(they overflowed the solver and the focal calibration): every float option has a physical bound.
"""

import os

import cv2
import numpy as np
import pytest

from svgs_sim.cli.main import build_parser, main
from svgs_sim.cli.validate import ATTITUDES, option_bounds
from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_from_scenario
from svgs_sim.svgs.identify import identify
from synth_svgs import synth_frame
from refusal import refused
from test_cli_validation import _walk, _with, base_argv

#: Float options bounded by the envelope instead of BOUNDS.
RANGES = {"range_m", "range", "from_m", "to_m"}


def _float_options():
    for cmd, p in _walk(build_parser()):
        for a in p._actions:
            if a.option_strings and a.type is float:
                yield cmd, p, a


def test_every_float_option_has_a_physical_bound():
    unbounded = sorted({f"{' '.join(c)} {max(a.option_strings, key=len)}" for c, _, a in _float_options()
                        if option_bounds(a) is None and a.dest not in ATTITUDES and a.dest not in RANGES})
    assert not unbounded, unbounded


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    cv2.imwrite(str(d / "img.png"), np.zeros((48, 64), np.uint8))
    np.save(d / "gray.npy", np.zeros((240, 320), np.float32))
    np.save(d / "depth.npy", np.ones((240, 320), np.float32))
    return {"img": str(d / "img.png"), "gray": str(d / "gray.npy"), "depth": str(d / "depth.npy")}


def _one_error_line(err):
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("usage:", " ", "compiling"))]
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("value", ["1e308", "-1e308"])
def test_absurd_floats_are_refused_before_any_work(value, files, tmp_path, capsys):
    for cmd, p, a in _float_options():
        flag = max(a.option_strings, key=len)
        v = f"{value},{value}" if a.nargs == 2 else value
        argv = _with(base_argv(cmd, p, files, tmp_path), flag, v)
        if a.nargs == 2:
            i = argv.index(flag)
            argv[i + 1:i + 2] = [value, value]
        assert flag in refused(argv, capsys, watch=[tmp_path])  # exit 2, one line, within a second, nothing written
    assert not (tmp_path / "out").exists()


def _err(capsys, argv, rc=2):
    return refused(argv, capsys, code=rc)  # one line, no traceback, within a second


def test_parameter_messages_name_the_option_and_the_range_without_a_unit_1(capsys):
    line = _err(capsys, ["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric",
                         "--focal-error-frac", "-0.6", "--out", "never"])
    assert "--focal-error-frac: expected -0.5 to 0.5, got -0.6" in line and "focal_error_frac" not in line
    line = _err(capsys, ["sensitivity", "--camera", "galaxy-nexus", "--vary", "focal_error_frac=-0.6:0.1",
                         "--vary", "sigma_px=0.1:0.2", "--n", "8", "--out", "never"])
    assert "--vary focal_error_frac LOW: expected -0.5 to 0.5, got -0.6 - " in line and "0.5 1" not in line
    assert not os.path.exists("never")


def test_a_bound_that_accepts_0_does_not_say_positive(capsys):
    line = _err(capsys, ["calibrate", "focal", "--camera", "galaxy-nexus", "--image", "x.png", "--range", "5",
                         "--range-sigma-m", "-1"])
    assert "--range-sigma-m: expected 0 to 10 m" in line and "positive" not in line


def test_remedy_out_of_range_says_the_range(capsys):
    line = _err(capsys, ["exposure-study", "--camera", "galaxy-nexus", "--remedy", "exposure=100", "--out", "never"])
    assert "exposure=VALUE with VALUE > 0 and <= 60 s" in line and "value out of range" not in line


@pytest.fixture(scope="module")
def frame_png(tmp_path_factory, nexus, pattern):
    R, t = pose_from_scenario(5.0, 0.02, 0.01, yaw_deg=5)
    path = tmp_path_factory.mktemp("img") / "frame.png"
    cv2.imwrite(str(path), synth_frame(nexus, pattern, R, t, seed=1, n_distractors=3).image)
    return path


def test_a_stack_of_frames_is_said_as_its_shape(tmp_path, capsys):
    p = tmp_path / "stack.npy"
    np.save(p, np.zeros((2, 1944, 2592), np.uint8))
    line = _err(capsys, ["solve", str(p), "--camera", "galaxy-nexus"])
    assert "shape (2, 1944, 2592)" in line and "1944 x 2 px" not in line


def test_a_threshold_above_full_scale_says_so(frame_png, capsys):
    line = _err(capsys, ["solve", str(frame_png), "--camera", "galaxy-nexus", "--threshold", "258"])
    assert "258 is at or above the largest value of this 8-bit image (255" in line
    assert main(["solve", str(frame_png), "--camera", "galaxy-nexus", "--threshold", "254"]) == 1
    assert "nothing above the threshold 254" in capsys.readouterr().out


@pytest.mark.parametrize("kind", ["devnull", "fifo"])
def test_special_files_are_not_called_empty(kind, tmp_path, capsys):
    if kind == "fifo":
        path = tmp_path / "fifo.png"
        os.mkfifo(path)
    else:
        path = os.devnull
    line = _err(capsys, ["solve", str(path), "--camera", "galaxy-nexus"])
    assert "not a regular file" in line and "empty" not in line
    line = _err(capsys, ["solve", str(path), "--camera", str(path)])
    assert "not a regular file" in line


def test_no_libpng_line_before_the_error(frame_png, tmp_path, capfd):
    b = bytearray(frame_png.read_bytes())
    b[200] ^= 0xFF  # inside the first IDAT chunk: a CRC error
    bad = tmp_path / "crc.png"
    bad.write_bytes(bytes(b))
    assert main(["solve", str(bad), "--camera", "galaxy-nexus"]) == 2
    err = capfd.readouterr().err
    line = _one_error_line(err)
    assert "corrupt" in line
    assert not [ln for ln in err.splitlines() if ln.startswith("libpng")], err


def test_the_blobs_counted_are_the_blobs_found(nexus, pattern):
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.uniform(100, 2400, 40), rng.uniform(100, 1800, 40)])
    fail = identify(pts, nexus, pattern)
    assert not fail and "30 brightest of the 40 blobs found" in fail.message, fail.message
    assert fail.details["n_blobs"] == 40


def test_a_bad_float_to_the_parameters_is_an_input_error():
    from svgs_sim.sim.trials import GEOMETRIC_PARAMETERS as G

    with pytest.raises(InputError, match=r"^k1_error: expected -1 to 1, got 2 - "):
        G["k1_error"].check(2.0)
    with pytest.raises(InputError, match=r"^--x: expected -1000 to 1000 m"):
        G["target_x_m"].check(1e300, "--x")
