"""Input read as written, and physically impossible input refused, before any work (issue 41).

Comma-separated numbers are read item by item at every option that takes them: an empty item
(``5,,10``) or an underscore (``5_0``, which Python's ``float`` reads as 50) is refused, exit 2,
one line naming the option (both ran). A focus inside the lens's focal length is refused the
same way (it rendered and then found no blob)."""

import pytest

from refusal import refused
from svgs_sim.base.errors import InputError, number_items


def test_number_items_reads_what_was_written():
    assert number_items(" 5, 10 ,2.5e1", "--x") == [5.0, 10.0, 25.0]
    assert number_items("-60,0,60", "--x") == [-60.0, 0.0, 60.0]
    for bad, word in (("5,,10", "empty"), ("5,10,", "empty"), ("5_0,10", "underscore"), ("5,ten", "'ten'"),
                      ("1,2", "expected 3")):
        with pytest.raises(InputError, match="--x") as e:
            number_items(bad, "--x", count=3 if bad == "1,2" else None)
        assert word in str(e.value)


def _cases(tmp):
    out = str(tmp / "out")
    for empty, under in (("5,,10", "5_0,10"),):
        yield ["range-sweep", "--camera", "galaxy-nexus", "--ranges", empty, "--out", out], "--ranges"
        yield ["range-sweep", "--camera", "galaxy-nexus", "--ranges", under, "--out", out], "--ranges"
        yield ["campaign", "--camera", "galaxy-nexus", "--ranges", under, "--out", out, "--plan-only"], "--ranges"
        yield (["sun-study", "--camera", "galaxy-nexus", "--ranges", "5", f"--sun-azimuths-deg={empty}",
                "--sun-elevations-deg", "15", "--trials", "1", "--out", out, "--plan-only"], "--sun-azimuths-deg")
        yield (["sun-study", "--camera", "galaxy-nexus", "--ranges", "5", "--sun-azimuths-deg", "0",
                "--sun-elevations-deg", under, "--trials", "1", "--out", out, "--plan-only"], "--sun-elevations-deg")
        yield ["campaign", "--camera", "galaxy-nexus", "--pp-error-px", "1_0,2", "--out", out, "--plan-only"], \
            "--pp-error-px"
        yield ["campaign", "--camera", "galaxy-nexus", "--misalignment-deg", "1,,2,3", "--out", out, "--plan-only"], \
            "--misalignment-deg"
        yield (["render", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit", "--sun-deg", "9_0,45",
                "--out", out], "--sun-deg")
        yield ["approach", "--camera", "galaxy-nexus", "--fps", "2", "--from", "10", "--to", "5", "--duration", "5", "--lateral", "0,,0", "--out", out], "--lateral"
        yield ["calibrate", "study", "--camera", "galaxy-nexus", "--views-list", "5,,10", "--out", out, "--plan-only"], \
            "--views-list"


@pytest.mark.parametrize("k", range(10))
def test_every_number_list_option_refuses_empty_items_and_underscores(k, capsys, tmp_path):
    argv, flag = list(_cases(tmp_path))[k]
    line = refused(argv, capsys, watch=[tmp_path])
    assert flag in line, line


@pytest.mark.parametrize("command", ["render", "render-and-solve"])
def test_a_focus_inside_the_focal_length_is_refused_before_the_render(command, capsys, tmp_path):
    """A thin lens focused at s <= f forms no real image (1/v = 1/f - 1/s <= 0): refused at once,
    naming --focus-m (it rendered for ~12 s and then found no blob). The Galaxy Nexus' f is 3.43 mm."""
    argv = [command, "--camera", "galaxy-nexus", "--range", "5", "--focus-m", "0.003"]
    argv += ["--out", str(tmp_path / "out")] if command == "render" else []
    line = refused(argv, capsys, watch=[tmp_path])
    assert "--focus-m" in line and "focal length" in line


def test_a_float_image_scaled_0_to_1_is_told_its_scale(capsys, tmp_path):
    """A float image whose values lie in 0-1 has nothing above a threshold in counts: the no-blob
    message says the image's brightest value and what to do (it said only "nothing above the
    threshold"); an 8-bit image as dark gets no such hint."""
    import numpy as np

    from svgs_sim.cli.main import main

    img = np.zeros((1944, 2592), np.float32)
    for u, v in ((1200, 900), (1400, 900), (1200, 1000), (1300, 1050)):
        img[v - 3:v + 4, u - 3:u + 4] = 0.95
    np.save(tmp_path / "f.npy", img)
    assert main(["solve", str(tmp_path / "f.npy"), "--camera", "galaxy-nexus"]) == 1
    cap = capsys.readouterr()
    said = cap.out + cap.err
    assert "brightest value is 0.95" in said and "--threshold" in said
    np.save(tmp_path / "u8.npy", np.zeros((1944, 2592), np.uint8))
    assert main(["solve", str(tmp_path / "u8.npy"), "--camera", "galaxy-nexus"]) == 1
    cap = capsys.readouterr()
    assert "no bright blob" in cap.out + cap.err and "brightest value" not in cap.out + cap.err
