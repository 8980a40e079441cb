"""Every subcommand refuses bad values before any work: exit 2, one line naming the input, no
traceback, nothing on stdout, within a second and nothing written (issue 14, item 1; issue 26).

The bad values are generated from each command's parser, not from the validation layer's rules:
every integer option gets -1, every float option nan and inf, every comma-separated range list a
duplicate, a range of 1e9 m and a negative one, every output location an existing file and a path
under a file.
"""

import argparse
from pathlib import Path

import numpy as np
import pytest

from svgs_sim.cli.main import build_parser, main
from refusal import refused


def _walk(parser):
    """Every command's parser, groups included (:func:`svgs_sim.cli.main.iter_commands`)."""
    from svgs_sim.cli.main import iter_commands

    return iter_commands(parser)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    import cv2

    d = tmp_path_factory.mktemp("inputs")
    img = d / "img.png"
    cv2.imwrite(str(img), np.zeros((48, 64), np.uint8))
    np.save(d / "gray.npy", np.zeros((240, 320), np.float32))
    np.save(d / "depth.npy", np.ones((240, 320), np.float32))
    return {"img": str(img), "gray": str(d / "gray.npy"), "depth": str(d / "depth.npy")}


def base_argv(cmd, parser, files, out_dir, *, skip=()):
    """A valid invocation of ``cmd`` (its required arguments but those whose dest is in ``skip``),
    writing under ``out_dir``."""
    tof = cmd[0] == "tof"
    values = {"image": files["img"], "images": [files["img"]], "camera": "tof-epc660" if tof else "galaxy-nexus",
              "range_m": "2" if tof else "5", "range": "5", "ranges": "5,10", "gray": [files["gray"]],
              "depth": [files["depth"]], "out": None if out_dir is None else str(out_dir / "out"), "board": "chessboard", "cols": "9",
              "rows": "6", "spacing_mm": "20", "views": "3", "fps": "1", "sun_azimuths_deg": "0,90",
              "sun_elevations_deg": "-30,30", "trials": "1", "model": "sensor_model.json"}
    argv = list(cmd)
    for a in parser._actions:
        if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)) or a.dest in skip:
            continue
        if not (a.required or not a.option_strings):
            continue
        v = values[a.dest]
        vs = v if isinstance(v, list) else [v]
        argv += vs if not a.option_strings else [a.option_strings[0], *vs]
    return argv


def _with(argv, flag, value):
    """``argv`` with ``flag`` set to ``value`` (replacing an existing value)."""
    out = list(argv)
    if flag in out:
        i = out.index(flag)
        del out[i:i + 2]
    return out + [flag, value]


def pytest_generate_tests(metafunc):
    if "bad_case" in metafunc.fixturenames:
        parser = build_parser()
        ids, params = [], []
        for cmd, p in _walk(parser):
            for a in p._actions:
                if not a.option_strings or isinstance(a, argparse._HelpAction):
                    continue
                flag = max(a.option_strings, key=len)
                if a.type is int:
                    vals = ["-1"]
                elif a.type is float:
                    vals = ["nan", "inf"]
                elif a.dest in ("ranges", "focal_ranges", "pose_ranges"):
                    vals = ["5,5", "1e9", "-3"]
                elif a.dest in ("out", "cache"):
                    vals = ["<file>", "<under-file>"]
                else:
                    continue
                for v in vals:
                    params.append((cmd, flag, v))
                    ids.append(f"{' '.join(cmd)} {flag} {v}")
        metafunc.parametrize("bad_case", params, ids=ids)


def test_every_subcommand_refuses_a_bad_value_before_any_work(bad_case, files, tmp_path, capsys):
    cmd, flag, value = bad_case
    parser = dict(_walk(build_parser()))[cmd]
    blocker = tmp_path / "a_file"
    blocker.write_text("keep")
    value = {"<file>": str(blocker), "<under-file>": str(blocker / "under")}.get(value, value)
    argv = _with(base_argv(cmd, parser, files, tmp_path), flag, value)
    # exit 2, one line, no traceback, within a second, nothing written (tests/refusal.py)
    line = refused(argv, capsys, watch=[tmp_path])
    assert "error" in line
    assert blocker.read_text() == "keep"


def test_the_valid_base_invocations_pass_the_layer(files, tmp_path):
    """The base invocations themselves are valid for the layer (so each case tests its one value)."""
    from svgs_sim.cli.validate import check_args

    parser = build_parser()
    for cmd, p in _walk(parser):
        if not any(isinstance(a, argparse._SubParsersAction) for a in p._actions):
            argv = base_argv(cmd, p, files, tmp_path)
            args = parser.parse_args(argv)
            check_args(args, parser)
    assert not (tmp_path / "out").exists()


def test_messages_name_the_input_and_the_envelope(capsys):
    cases = [(["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5,5"], "--ranges", "repeated range"),
             (["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--ranges", "1e9"], "--ranges",
              "spots merge"),
             (["render", "--camera", "galaxy-nexus", "--range", "5", "--spot-samples", "0", "--out", "x"],
              "--spot-samples", "positive"),
             (["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5", "--jitter-deg", "-1"], "--jitter-deg", "0 to 90 deg"),
             (["render-and-solve", "--camera", "tof-epc660", "--range", "5"], "--camera", "time-of-flight"),
             (["tof", "stability", "--range", "40"], "--range", "15")]
    for argv, name, why in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert name in err and why in err, err
    assert not Path("x").exists()
