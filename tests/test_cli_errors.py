"""Error messages and exit codes of the ``svgs`` command line (issue 26, deliverable 6).

- the error line names the sub-command that was run (``svgs calibrate focal: error: ...``), for
  argparse's usage errors and for bad input (:class:`svgs_sim.base.errors.InputError`) alike;
- with ``--json``, exit 2 prints exactly one JSON object ``{"ok": false, "error": ...}`` on
  stdout (as ``docs/cli.md`` promises) and the same message on stderr;
- a simulated physical failure (a ToF frame that the ambient light leaves without one valid
  depth pixel) exits 1 with its reason, not 2.

Each case asserts the exit code, one error line, no traceback, the time before exit and that
nothing was written.
"""

from __future__ import annotations

import json
import time

import pytest

from svgs_sim.cli.main import main


def _run(argv, capsys, tmp_path, monkeypatch):
    """(rc, stdout, the error lines of stderr, seconds) of ``svgs ARGV`` run in ``tmp_path``; asserts no
    traceback and nothing written there."""
    monkeypatch.chdir(tmp_path)
    before = sorted(p.name for p in tmp_path.iterdir())
    t0 = time.perf_counter()
    rc = main(argv)
    dt = time.perf_counter() - t0
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err and "Traceback" not in cap.out
    assert sorted(p.name for p in tmp_path.iterdir()) == before, "a refused run wrote files"
    # the error lines: "svgs ...: error: ..." (status lines, progress bars and argparse's usage block are not)
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("svgs")]
    if lines:
        assert cap.err.rstrip("\n").splitlines()[-1] == lines[-1], "the error is not the last line of stderr"
    return rc, cap.out, lines, dt


#: (argv, the prefix the error line must start with, a fragment of the message)
BAD_INPUT = [
    (["calibrate", "focal", "--camera", "galaxy-nexus", "--image", "a.png", "--range", "5", "--image", "b.png"],
     "svgs calibrate focal: error: ", "one --range per --image"),
    (["tof", "stability", "--range", "40"], "svgs tof stability: error: ", "--range"),
    (["solve", "missing.png", "--camera", "galaxy-nexus"], "svgs solve: error: ", "missing.png"),
    (["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5,5"], "svgs range-sweep: error: ", "--ranges"),
    (["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--ranges", "1e9"],
     "svgs campaign: error: ", "--ranges"),
    (["calibrate", "board", "x.png", "--board", "chessboard", "--cols", "9", "--rows", "6", "--spacing-mm", "20",
      "--aspect-ratio", "nan"], "svgs calibrate board: error: ", "--aspect-ratio"),
]

#: argparse usage errors: the sub-command's parser names itself
USAGE = [
    (["calibrate", "focal", "--camera", "galaxy-nexus", "--image", "a.png", "--range", "5", "--bogus"],
     "svgs calibrate focal: error: ", "unrecognized arguments: --bogus"),
    (["tof", "solve", "--gray", "g.npy", "--depth", "d.npy", "--frobnicate", "3"],
     "svgs tof solve: error: ", "unrecognized arguments: --frobnicate 3"),
    (["range-sweep", "--camera", "galaxy-nexus", "--ranges", "5", "--trials", "x"],
     "svgs range-sweep: error: ", "--trials: invalid int value"),
    (["calibrate", "study"], "svgs calibrate study: error: ", "--camera"),
    (["calibrate"], "svgs calibrate: error: ", "METHOD"),
    (["frobnicate"], "svgs: error: ", "invalid choice"),
]


@pytest.mark.parametrize("argv,prefix,fragment", BAD_INPUT + USAGE, ids=[" ".join(c[0][:3]) for c in BAD_INPUT + USAGE])
def test_the_error_line_names_the_sub_command(argv, prefix, fragment, capsys, tmp_path, monkeypatch):
    rc, out, lines, dt = _run(argv, capsys, tmp_path, monkeypatch)
    assert rc == 2
    assert out == ""  # without --json nothing on stdout
    assert len(lines) == 1, lines
    assert lines[0].startswith(prefix) and fragment in lines[0], lines[0]
    assert dt < 10.0, f"{dt:.1f} s before the refusal"


@pytest.mark.parametrize("argv,prefix,fragment", BAD_INPUT + USAGE[:3],
                         ids=[" ".join(c[0][:3]) for c in BAD_INPUT + USAGE[:3]])
def test_json_exit_2_prints_one_object(argv, prefix, fragment, capsys, tmp_path, monkeypatch):
    """With --json: one JSON object on stdout, {"ok": false, "error": MESSAGE}, and the same MESSAGE on stderr."""
    rc, out, lines, dt = _run(argv + ["--json"], capsys, tmp_path, monkeypatch)
    assert rc == 2
    assert len(out.splitlines()) == 1, out
    obj = json.loads(out)
    assert obj == {"ok": False, "error": obj["error"]} and fragment in obj["error"]
    assert len(lines) == 1 and lines[0] == prefix + obj["error"], (lines, obj)
    assert dt < 10.0


def test_a_multi_line_message_is_printed_on_one_line(capsys):
    from svgs_sim.cli.main import report_error

    report_error("svgs solve", "first\n  second", as_json=True)
    cap = capsys.readouterr()
    assert cap.err == "svgs solve: error: first second\n"
    assert json.loads(cap.out) == {"ok": False, "error": "first second"}


@pytest.mark.render
def test_a_saturated_simulated_frame_is_a_simulation_failure():
    """1e12 lux saturates every pixel of the simulated ToF frame: the closed loop raises
    SimulationFailure (reason 'saturated'), not InputError. (The CLI bounds --ambient-lux to
    natural light, 2e5 lux, so this is the library's path.)"""
    from svgs_sim.sim import tof_closed_loop as tcl
    from svgs_sim.base.errors import InputError, SimulationFailure

    tr = tcl.render(tcl.TofScenario(range_m=1.0, spp=4, ambient_lux=1e12))
    frame = next(tcl.expose(tr, 1))
    with pytest.raises(SimulationFailure) as exc:
        tcl.solve(tr, 0, frame, tcl.pipeline(tr))
    assert exc.value.reason == "saturated" and not isinstance(exc.value, InputError)
    assert "pixels saturated" in str(exc.value) and "1e+12 lux" in str(exc.value)


@pytest.mark.render
@pytest.mark.parametrize("as_json", [False, True])
def test_a_simulation_failure_is_exit_1_with_its_reason(as_json, capsys, tmp_path, monkeypatch):
    """The CLI turns the closed loop's SimulationFailure into exit 1 and one line with the reason
    (with --json, {"ok": false, "reason": ...}): the sensor is made to saturate every frame by
    running the stability command's sensor at 1e12 lux (the command line refuses that value)."""
    from svgs_sim.sim import tof_closed_loop as tcl

    real = tcl.make_sensor

    def saturating(scenario, camera=None):
        import dataclasses

        return real(dataclasses.replace(scenario, ambient_lux=1e12), camera)

    monkeypatch.setattr(tcl, "make_sensor", saturating)
    argv = ["tof", "stability", "--range", "1", "--frames", "1", "--spp", "4"]
    rc, out, lines, dt = _run(argv + (["--json"] if as_json else []), capsys, tmp_path, monkeypatch)
    assert rc == 1, lines
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith("svgs tof stability: no solution (saturated): ") and "error" not in line
    assert "pixels saturated" in line, line
    if as_json:
        obj = json.loads(out)
        assert obj["ok"] is False and obj["reason"] == "saturated" and obj["error"] in line
    else:
        assert out == ""
    assert dt < 60.0


def test_real_frames_without_valid_depth_stay_bad_input(capsys, tmp_path, monkeypatch):
    """A user's depth file with no valid pixel is bad input (exit 2), unlike a simulated frame."""
    import numpy as np

    np.save(tmp_path / "g.npy", np.ones((240, 320), np.float32))
    np.save(tmp_path / "d.npy", np.full((240, 320), np.nan, np.float32))
    rc, out, lines, _ = _run(["tof", "solve", "--gray", "g.npy", "--depth", "d.npy"], capsys, tmp_path, monkeypatch)
    assert rc == 2 and len(lines) == 1
    assert lines[0].startswith("svgs tof solve: error: ") and "no valid pixel" in lines[0]
