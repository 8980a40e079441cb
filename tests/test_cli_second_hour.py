"""A new user's second hour (issue 41): sizes read from headers before any decoding, bounded counts,
a tone curve that exists, a user's own files never overwritten, ``--plan-only`` with the run's
checks and JSON, the ToF sensitivity analysis that runs. Each refusal: exit 2, one line naming the
input, nothing written, no traceback."""

from __future__ import annotations

import json
import struct
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.base.image_files import write_image
from svgs_sim.base.profiles import load_camera
from svgs_sim.cli.main import main
from svgs_sim.svgs.pipeline import MAX_IMAGE_PIXELS, image_header_size, load_image

ROOT = Path(__file__).resolve().parents[1]


def _png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG whose header says ``width`` x ``height`` (8-bit grey) and whose data is one empty
    chunk: a few dozen bytes that would take width x height bytes to decode."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"")) + chunk(b"IEND", b""))
    return path


def _one_error_line(err: str) -> str:
    lines = [x for x in err.splitlines() if "error" in x]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("side", [20000, 40000])
def test_an_image_larger_than_any_phone_is_refused_from_its_header(tmp_path, capsys, side):
    big = _png_header_only(tmp_path / "big.png", side, side)
    assert big.stat().st_size < 200 and image_header_size(big) == (side, side)
    t0 = time.perf_counter()
    rc = main(["solve", str(big), "--camera", "galaxy-nexus"])
    line = _one_error_line(capsys.readouterr().err)
    assert rc == 2 and time.perf_counter() - t0 < 5
    assert f"{side} x {side} px" in line and "not decoded" in line
    assert side * side > MAX_IMAGE_PIXELS


def test_a_photo_of_another_size_than_the_camera_is_refused_before_decoding(tmp_path, capsys):
    small = _png_header_only(tmp_path / "small.png", 640, 480)
    rc = main(["solve", str(small), "--camera", "galaxy-nexus"])
    line = _one_error_line(capsys.readouterr().err)
    assert rc == 2 and "640 x 480 px does not match camera" in line
    cam = load_camera("galaxy-nexus")
    ok = tmp_path / "ok.png"
    write_image(ok, np.zeros((cam.height, cam.width), np.uint8))
    assert load_image(ok, camera=cam).shape == (cam.height, cam.width)


@pytest.mark.parametrize("argv", [
    ["calibrate", "render-board", "--camera", "galaxy-nexus", "--board", "chessboard", "--cols", "100000", "--rows",
     "100000", "--spacing-mm", "25", "--views", "2", "--out", "OUT"],
    ["calibrate", "study", "--camera", "galaxy-nexus", "--cols", "100000", "--out", "OUT", "--plan-only"],
])
def test_a_board_of_absurd_size_is_refused_before_any_allocation(tmp_path, capsys, argv):
    out = tmp_path / "out"
    rc = main([str(out) if a == "OUT" else a for a in argv])
    line = _one_error_line(capsys.readouterr().err)
    assert rc == 2 and "--cols" in line and "100000" in line and not out.exists()


def test_a_tone_curve_of_gamma_zero_is_refused(tmp_path):
    text = (ROOT / "svgs_sim" / "assets" / "cameras" / "galaxy-nexus.toml").read_text()
    assert "gamma = 2.2" in text
    bad = tmp_path / "g0.toml"
    bad.write_text(text.replace("gamma = 2.2", "gamma = 0", 1))
    with pytest.raises(InputError, match=r"gamma = 0.*1 is linear"):
        load_camera(str(bad))


def test_a_users_own_report_is_never_overwritten(tmp_path, capsys):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "report.html").write_text("my report")
    (mine / "summary.csv").write_text("a,b\n")
    for extra in ([], ["--plan-only", "--json"]):
        rc = main(["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "4", "--ranges", "5",
                   "--out", str(mine), "--processes", "0", *extra])
        cap = capsys.readouterr()
        line = _one_error_line(cap.err)
        assert rc == 2 and "report.html, summary.csv but no manifest.json" in line
    assert (mine / "report.html").read_text() == "my report" and sorted(p.name for p in mine.iterdir()) == [
        "report.html", "summary.csv"]


def test_plan_only_prints_the_plan_as_json_and_runs_nothing(tmp_path, capsys):
    out = tmp_path / "sweep"
    rc = main(["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5,10", "--out", str(out), "--plan-only", "--json"])
    cap = capsys.readouterr()
    obj = json.loads(cap.out)
    assert rc == 0 and obj["ok"] and obj["plan_only"] and obj["plan"]["trials"] > 0 and obj["plan"]["kind"] == "render"
    assert not (out / "results.csv").exists()


def test_the_tof_sensitivity_analysis_takes_a_tof_camera_and_builds_its_trials(capsys):
    from svgs_sim.studies.sensitivity import make_config, sensitivity_trials

    cfg = make_config("tof-epc660", ["range_m=1:3", "ambient_lux=100:10000"], method="morris", n=2, trial_kind="tof")
    trials, _ = sensitivity_trials(cfg)  # was KeyError: 'render_seed'
    assert len(trials) == 6 and cfg.pattern == "tof-8"
    for t in trials:
        assert int(t.seed) == int(t.scenario.scenario.seed)  # a ToF trial's seed is its render seed
    with pytest.raises(InputError, match="needs a time-of-flight camera"):
        make_config("galaxy-nexus", ["range_m=1:3", "ambient_lux=100:10000"], method="morris", n=2, trial_kind="tof")
    rc = main(["sensitivity", "--camera", "tof-epc660", "--trial-kind", "tof", "--vary", "range_m=1:3", "--vary",
               "ambient_lux=100:10000", "--n", "2", "--method", "morris", "--plan-only"])
    assert rc == 0
    rc = main(["sensitivity", "--camera", "galaxy-nexus", "--trial-kind", "tof", "--vary", "range_m=1:3", "--vary",
               "ambient_lux=100:10000", "--n", "2", "--method", "morris", "--plan-only"])
    assert rc == 2 and "time-of-flight camera profile" in _one_error_line(capsys.readouterr().err)


def test_the_kernel_cache_is_looked_for_where_numba_keeps_it(monkeypatch, tmp_path):
    """The user-wide folder numba uses when the package's own is read-only, computed by numba's own
    locator: the first-compile notice printed on every run when the cache was there."""
    from numba.core.caching import _CacheLocator

    import svgs_sim.svgs._lm_kernel as k
    from svgs_sim.cli.compile_kernels import numba_cache_folders

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    src = Path(k.__file__).resolve()
    inside, user = numba_cache_folders(src)
    assert inside == src.parent / "__pycache__"
    assert user == tmp_path / "numba" / _CacheLocator.get_suitable_cache_subpath(str(src))


def test_a_message_names_the_option_not_the_api_argument(tmp_path, capsys):
    """The stand refuses ``misalignment_deg`` (its Python argument); the CLI user typed
    --misalignment-deg, and that is what the one line names, for any option whose dest leads a message."""
    from svgs_sim.cli.main import build_parser, iter_commands, named_by_option

    rc = main(["campaign", "--camera", "galaxy-nexus", "--misalignment-deg", "0,0,99", "--trial-kind", "geometric",
               "--out", str(tmp_path / "c"), "--plan-only"])
    line = _one_error_line(capsys.readouterr().err)
    assert rc == 2 and "--misalignment-deg: expected" in line and "misalignment_deg" not in line
    for words, p in iter_commands(build_parser()):
        for a in p._actions:
            if a.option_strings and a.dest != "help":
                assert named_by_option(p, f"{a.dest}: expected x").startswith(max(a.option_strings, key=len))
    assert named_by_option(build_parser(), "no key here: x") == "no key here: x"


def test_plan_only_refuses_a_folder_holding_another_studys_store(tmp_path, capsys):
    """The run refuses a folder whose store has other parameters; --plan-only now says so too."""
    out = tmp_path / "c"
    base = ["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "4", "--out", str(out),
            "--processes", "0", "--no-progress"]
    assert main([*base, "--ranges", "5"]) == 0
    capsys.readouterr()
    rc = main([*base, "--ranges", "10", "--plan-only"])
    line = _one_error_line(capsys.readouterr().err)
    assert rc == 2 and "different parameters" in line
    assert main([*base, "--ranges", "5", "--plan-only"]) == 0  # its own store: the plan
