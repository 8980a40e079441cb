"""Output that cannot be written exits 3 (``io_error``), with one line and nothing lost (issue 41).

The mechanisms: every command's stdout goes through :class:`svgs_sim.cli.stdout_guard.GuardedStdout`
(a closed stdout, a broken pipe or a full disk behind a redirection never stops a command half-way:
it writes its files, then exits 3), every ``OSError`` a command's writing raises ends in one line
naming the path and exit 3 (``{"ok": false, "reason": "io_error", ...}`` under ``--json``), and
images and videos are written through Python's file calls (:mod:`svgs_sim.base.image_files`), so a
path that is not valid UTF-8 never reaches OpenCV's C string (it ended the process with SIGSEGV).
As root permission bits prove nothing: the failures are made with ``/dev/full``, a closed
descriptor, a pipe whose reader is gone and fault injection.
"""

from __future__ import annotations

import builtins
import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from svgs_sim.base.image_files import read_image, write_image
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.cli.exit_codes import EXIT_IO_ERROR
from svgs_sim.cli.main import main
from svgs_sim.cli.stdout_guard import GuardedStdout

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    """A synthetic Galaxy Nexus frame of the target at 5 m, head-on (solves)."""
    from synth_svgs import synth_frame

    d = tmp_path_factory.mktemp("photo")
    f = synth_frame(load_camera("galaxy-nexus"), load_pattern("svgs-3u"), np.eye(3), np.array([0.0, 0.0, 5.0]), seed=1)
    write_image(d / "img.png", f.image)
    return d / "img.png"


def _svgs(args, shell_tail: str = "", cwd=None):
    """``svgs ARGS`` as a program, its stdout redirected by ``shell_tail`` (bash)."""
    cmd = " ".join(["exec", sys.executable, "-m", "svgs_sim.cli.main", *[f"'{a}'" for a in args]]) + " " + shell_tail
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(["bash", "-c", cmd], capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


def _one_line_io_error(stderr: str) -> None:
    lines = [x for x in stderr.splitlines() if "error" in x]  # progress lines ("plan: ...") aside
    assert len(lines) == 1, stderr
    assert lines[0].startswith("svgs ") and "io_error" in lines[0] and "Traceback" not in stderr


@pytest.mark.parametrize("tail", ["1>&-", "> /dev/full", "| head -c 0 > /dev/null; exit ${PIPESTATUS[0]}"],
                         ids=["closed", "dev-full", "broken-pipe"])
def test_solve_json_with_stdout_lost_exits_3_and_keeps_its_files(photo, tmp_path, tail):
    out = tmp_path / "out"
    r = _svgs(["solve", str(photo), "--camera", "galaxy-nexus", "--out", str(out), "--json"], tail)
    assert r.returncode == EXIT_IO_ERROR, r.stderr
    _one_line_io_error(r.stderr)
    assert (out / "solution.json").is_file() and (out / "overlay.png").is_file()


def test_a_study_piped_into_a_reader_that_stops_writes_its_summary(tmp_path):
    out = tmp_path / "camp"
    r = _svgs(["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "4", "--ranges", "5,10",
               "--out", str(out), "--no-progress", "--processes", "1"], "| head -c 0 > /dev/null; exit ${PIPESTATUS[0]}")
    assert r.returncode == EXIT_IO_ERROR, r.stderr
    _one_line_io_error(r.stderr)
    s = json.loads((out / "summary.json").read_text())
    assert [x["trials"] for x in s["ranges"]] == [4, 4]


def test_a_path_that_is_not_utf8_is_written_not_a_native_crash(photo, tmp_path):
    out = os.path.join(os.fsencode(tmp_path), b"bad\xff")
    r = subprocess.run([sys.executable, "-m", "svgs_sim.cli.main", "solve", str(photo), "--camera", "galaxy-nexus",
                        "--out", out], capture_output=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
    assert r.returncode == 0, r.stderr  # was -11 (SIGSEGV in cv2.imwrite)
    assert os.path.isfile(os.path.join(out, b"overlay.png"))
    assert read_image(os.fsdecode(os.path.join(out, b"overlay.png"))) is not None


def test_a_disk_that_fills_during_the_work_exits_3_with_one_line_and_json(photo, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    real_open = builtins.open

    def full_open(file, mode="r", *a, **k):
        if any(m in mode for m in "wax") and str(out) in os.fsdecode(file):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), os.fsdecode(file))
        return real_open(file, mode, *a, **k)

    monkeypatch.setattr(builtins, "open", full_open)
    rc = main(["solve", str(photo), "--camera", "galaxy-nexus", "--out", str(out), "--json"])
    monkeypatch.setattr(builtins, "open", real_open)
    cap = capsys.readouterr()
    assert rc == EXIT_IO_ERROR
    _one_line_io_error(cap.err)
    assert "No space left on device" in cap.err and str(out) in cap.err
    obj = json.loads(cap.out.strip().splitlines()[-1])
    assert obj["ok"] is False and obj["reason"] == "io_error"


def test_a_path_the_system_refuses_exits_3_in_one_short_line(photo, tmp_path, capsys):
    rc = main(["solve", str(photo), "--camera", "galaxy-nexus", "--out", str(tmp_path / ("a" * 300))])
    err = capsys.readouterr().err
    assert rc == EXIT_IO_ERROR
    _one_line_io_error(err)
    assert "File name too long" in err and len(err) < 400


def test_the_guard_marks_every_lost_reader_and_passes_the_rest():
    class Dead:
        def write(self, s):
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")

        def flush(self):
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")

    g = GuardedStdout(Dead())
    assert g.write("x") == 1 and g.broken and g.error.errno == errno.EPIPE
    assert GuardedStdout(None).broken
    import io

    buf = io.StringIO()
    g = GuardedStdout(buf)
    print("ok", file=g)
    assert not g.broken and buf.getvalue() == "ok\n"
