"""Output locations are checked by writing, before any work (issue 26, item 1).

As root the permission bits say yes to everything, so a check by ``os.access`` lets ``svgs render
--out /proc/nope`` render for seconds and then fail with a traceback. Every command with an output
option is driven from its parser: the output set to ``/proc/nope`` (a folder the kernel will not
make, even for root) and to a path under a regular file must exit 2 with one line naming the
option and the path, no traceback, nothing on stdout, nothing written, well within a second.
"""

import argparse
import os
import time
from pathlib import Path

import numpy as np
import pytest

from svgs_sim.cli.main import build_parser, main
from svgs_sim.cli.outdir import check_output_folder, output_folder, prepare_output_file, prepare_output_folder
from svgs_sim.base.errors import InputError
from test_cli_validation import base_argv

#: Output options of the commands: the study store of ``tof study`` too.
OUTPUT_DESTS = ("out", "cache", "store")
#: The longest a refused command may take (the bad output is found before any render or trial).
MAX_S = 1.0


def _walk(parser):
    """Every command's parser, groups included (:func:`svgs_sim.cli.main.iter_commands`)."""
    from svgs_sim.cli.main import iter_commands

    return iter_commands(parser)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    import cv2

    from svgs_sim.base.profiles import load_camera

    d = tmp_path_factory.mktemp("inputs")
    cam = load_camera("galaxy-nexus")
    img = d / "img.png"  # the phone's size: solve's own checks pass, the output check is what refuses
    cv2.imwrite(str(img), np.zeros((cam.height, cam.width), np.uint8))
    np.save(d / "gray.npy", np.zeros((240, 320), np.float32))
    np.save(d / "depth.npy", np.ones((240, 320), np.float32))
    return {"img": str(img), "gray": str(d / "gray.npy"), "depth": str(d / "depth.npy")}


def _base_argv(cmd, parser, files):
    """A valid invocation of ``cmd`` (its required arguments) without its output options."""
    return base_argv(cmd, parser, files, None, skip=OUTPUT_DESTS)


def _output_options(parser):
    return [(a, max(a.option_strings, key=len)) for a in parser._actions if a.dest in OUTPUT_DESTS and a.option_strings]


def _cases():
    ids, params = [], []
    for cmd, p in _walk(build_parser()):
        if any(isinstance(a, argparse._SubParsersAction) for a in p._actions):
            continue
        for a, flag in _output_options(p):
            for where in ("/proc/nope", "<under-file>"):
                params.append((cmd, flag, where))
                ids.append(f"{' '.join(cmd)} {flag} {where}")
    return params, ids


PARAMS, IDS = _cases()


def test_every_writing_command_has_a_case():
    cmds = {" ".join(c) for c, _, _ in PARAMS}
    assert {"render", "solve", "render-and-solve", "range-sweep", "exposure-study", "calibrate focal",
            "calibrate board", "calibrate render-board", "calibrate study", "tof render-and-solve", "tof stability",
            "tof study", "campaign", "sensitivity", "merge-range", "approach"} <= cmds


@pytest.mark.parametrize("case", PARAMS, ids=IDS)
def test_an_output_that_cannot_be_made_is_refused_at_once(case, files, tmp_path, capsys, monkeypatch):
    import svgs_sim.cli.compile_kernels as ck

    monkeypatch.setattr(ck, "kernels_cached", lambda: True)  # no first-run notice: the one line is the error
    monkeypatch.chdir(tmp_path)  # default output folders of the other options land here (and must not)
    cmd, flag, where = case
    parser = dict(_walk(build_parser()))[cmd]
    blocker = tmp_path / "a_file"
    blocker.write_text("keep")
    bad = {"<under-file>": str(blocker / "sub" / "dir")}.get(where, where)
    meta = {f: (a.metavar or "").lower() for a, f in _output_options(parser)}
    if meta[flag].endswith(".toml"):
        bad = str(Path(bad) / "cam.toml")
    argv = _base_argv(cmd, parser, files) + [flag, bad]
    for a, other in _output_options(parser):  # the other output options: good folders, not made either
        if other != flag:
            argv += [other, str(tmp_path / "good" / other.strip("-"))]
    before = sorted(p.name for p in tmp_path.iterdir())
    t0 = time.perf_counter()
    rc = main(argv)
    took = time.perf_counter() - t0
    cap = capsys.readouterr()
    assert rc == 2, (argv, cap.err[-400:])
    assert "Traceback" not in cap.err and cap.out == ""
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(lines) == 1, cap.err
    assert f"{flag} {bad!r}" in lines[0] or f"{flag} {str(Path(bad).parent)!r}" in lines[0], lines[0]
    assert took < MAX_S, f"{took:.2f} s before the refusal"
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written
    assert blocker.read_text() == "keep"


# --------------------------------------------------------------------------- the helper itself
def test_proc_is_refused_even_as_root():
    assert os.access("/proc", os.W_OK) or os.geteuid() != 0  # the permission bits would let it through as root
    with pytest.raises(InputError, match=r"^--out '/proc/nope': cannot create the folder \(.+\)$"):
        prepare_output_folder("/proc/nope")
    with pytest.raises(InputError, match=r"^--out '/proc/nope': cannot create the folder"):
        check_output_folder("/proc/nope")
    with pytest.raises(InputError, match=r"^--cache '/proc/nope/a/b': cannot create the folder"):
        prepare_output_folder("/proc/nope/a/b", "--cache")


def test_a_file_and_a_path_under_a_file_are_refused(tmp_path):
    f = tmp_path / "f"
    f.write_text("keep")
    with pytest.raises(InputError, match="exists and is not a folder"):
        prepare_output_folder(f)
    with pytest.raises(InputError, match="cannot create the folder"):
        prepare_output_folder(f / "a" / "b")
    with pytest.raises(InputError, match="is a folder; expected a file name"):
        prepare_output_file(tmp_path)
    assert f.read_text() == "keep" and sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def test_the_folder_is_made_with_its_parents_and_no_probe_is_left(tmp_path):
    out = prepare_output_folder(tmp_path / "a" / "b" / "c")
    assert out.is_dir() and list(out.iterdir()) == []
    check_output_folder(tmp_path / "x" / "y")  # checks, makes nothing
    assert not (tmp_path / "x").exists() and not any(p.name.startswith(".svgs") for p in tmp_path.iterdir())
    prepare_output_file(tmp_path / "p" / "cam.toml")
    assert (tmp_path / "p").is_dir() and not (tmp_path / "p" / "cam.toml").exists()


def test_a_refused_command_removes_the_folders_it_made_but_keeps_what_holds_results(tmp_path):
    with pytest.raises(InputError):
        with output_folder(tmp_path / "new" / "out"):
            raise InputError("refused after the folder was made")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(KeyboardInterrupt):
        with output_folder(tmp_path / "run") as out:
            (out / "results.csv").write_text("trial_id\n0\n")
            raise KeyboardInterrupt
    assert (tmp_path / "run" / "results.csv").is_file()  # rows to resume from are kept
    existing = tmp_path / "existing"
    existing.mkdir()
    with pytest.raises(InputError):
        with output_folder(existing):
            raise InputError("refused")
    assert existing.is_dir()  # a folder that was there before stays
