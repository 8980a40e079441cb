"""Pictures and lines that answer the first question (issue 26): the overlay's error table, the
one line on an error far above its bound and its why (the head-on glint or a bias), the approach's
half-open range bins, a rate a person can read, a Windows results file, and the ToF study's
default folder."""

from __future__ import annotations

import math

import numpy as np
import pytest

from svgs_sim.svgs.frames import STATE_KEYS, pose_from_scenario
from svgs_sim.base.profiles import Camera, Pattern


def test_overlay_notes_panel_is_drawn_below_the_picture():
    from svgs_sim.svgs.overlay import render_overlay

    img = np.zeros((120, 160), np.uint8)
    img[60:63, 80:83] = 255
    kw = {"blobs_px": [[81.0, 61.0]], "targets_px": {"1": [81.0, 61.0]}, "title": "t", "size_px": 300}
    plain = render_overlay(img, **kw)
    notes = ["component\ttruth\terror", "x_m\t+0.0000\t-0.1170", "a line long enough to be wrapped " * 4]
    pic = render_overlay(img, notes=notes, **kw)
    assert pic.shape[1] == plain.shape[1]
    assert np.array_equal(pic[:plain.shape[0]], plain)  # the picture above is untouched
    panel = pic[plain.shape[0]:]
    # 18 px a line: two table rows and the long line wrapped onto more than one
    assert panel.shape[0] >= 18 * 4 + 10
    rows_with_ink = np.flatnonzero(panel.max(axis=(1, 2)) > 0)
    assert rows_with_ink.size and rows_with_ink.max() > 18 * 3  # the wrapped text reaches the fourth line


def test_bound_note_names_the_components_far_above_and_the_glint():
    from svgs_sim.studies.diagnosis import bound_note

    crlb = {k: 1e-3 for k in STATE_KEYS}
    within = {k: 2e-3 for k in STATE_KEYS}  # 2 sigma: noise, nothing said
    assert bound_note(within, crlb) is None
    errors = dict(within, x_m=-0.117, pitch_deg=-1.39)  # the head-on Galaxy Nexus at 5 m
    glint = bound_note(errors, crlb, ("3",))
    assert "x_m 117x" in glint and "pitch_deg 1390x" in glint
    assert glint.index("pitch_deg") < glint.index("x_m")  # largest first
    assert "head-on glint" in glint and "target 3" in glint and "examples/head_on_glint.py" in glint
    bias = bound_note(errors, crlb, ())
    assert "not the head-on glint" in bias and "centroid or calibration" in bias
    assert "\n" not in glint and "\n" not in bias  # one line


def test_bound_note_ignores_unknown_or_zero_bounds():
    from svgs_sim.studies.diagnosis import bound_note

    errors = {k: 1.0 for k in STATE_KEYS}
    assert bound_note(errors, {k: None for k in STATE_KEYS}) is None
    assert bound_note(errors, {k: 0.0 for k in STATE_KEYS}) is None
    assert bound_note(errors, {k: float("nan") for k in STATE_KEYS}) is None


def _hand_head_on_glint(camera, pattern, range_m):
    """Head-on, the front face is perpendicular to the line of sight: the flash's mirror image in
    the face lies at (s, 2 z_face) for an LED at lateral offset s, and the line from it to the
    lens crosses the face's plane at s / 2 whatever z_face. The glint reaches the lens when that
    point is on the face: within its radius (+ the renderer's 3 mm footprint margin,
    svgs_sim.render.predict.virtual_sources) of the face's centre."""
    led = np.asarray(camera.flash.led_offsets_m, float)
    R, t = pose_from_scenario(range_m)
    centres = pattern.points_m @ R.T + t  # the faces' centres are on the cubes' axes, laterally at the points
    radius_m = 0.5 * 0.0127  # svgs-3u's reflector: Edmund N-BK7 corner cubes, 12.7 mm across
    out = set()
    for i, c in enumerate(centres):
        for s in led:
            if math.hypot(0.5 * s[0] - c[0], 0.5 * s[1] - c[1]) <= radius_m + 0.003:
                out.add(str(int(pattern.ids[i])))
    return tuple(sorted(out))


@pytest.mark.parametrize("range_m", [1.0, 5.0, 20.0])
def test_front_glint_head_on_matches_the_mirror_geometry(range_m):
    from svgs_sim.studies.diagnosis import front_glint_targets

    cam, pat = Camera.load("galaxy-nexus"), Pattern.load("svgs-3u")
    expected = _hand_head_on_glint(cam, pat, range_m)
    assert expected, "the svgs-3u pattern has a target on the boresight"
    R, t = pose_from_scenario(range_m)
    assert front_glint_targets(cam, pat, R, t) == expected


def test_front_glint_gone_when_tilted_far_off_facing():
    """Tilted by 2 deg at 20 m the mirror image moves ~2 x 2 deg x 20 m = 1.4 m sideways: the line
    to the lens crosses the face's plane ~0.7 m from any face (faces 12.7 mm wide)."""
    from svgs_sim.studies.diagnosis import front_glint_targets

    cam = Camera.load("galaxy-nexus")
    R, t = pose_from_scenario(20.0, pitch_deg=2.0)
    assert front_glint_targets(cam, "svgs-3u", R, t) == ()
    R, t = pose_from_scenario(20.0, yaw_deg=0.0, roll_deg=2.0)
    assert front_glint_targets(cam, "svgs-3u", R, t) == ()


def _row(frame, range_m, err=1e-3, crlb=1e-3):
    r = {"frame": frame, "t_s": float(frame), "range_m": range_m, "ok": 1, "reason": ""}
    for k in STATE_KEYS:
        r[f"true_{k}"] = range_m if k == "z_m" else 0.0
        r[f"err_{k}"] = err
        r[f"crlb_{k}"] = crlb
    for k in ("render", "optics", "expose", "solve", "crlb"):
        r[f"{k}_s"] = 0.1
    return r


def test_approach_bins_are_half_open_and_labelled_so():
    from svgs_sim.studies.approach import bin_label, summarise

    cfg = {"camera": "galaxy-nexus", "pattern": "svgs-3u", "preview": False, "fps": 1.0, "seed": 0,
           "trajectory": {"source": "test"}}
    rows = [_row(0, 5.0), _row(1, 4.99), _row(2, 2.0)]
    bins = {tuple(b["range_m"]): b["frames"] for b in summarise(rows, cfg)["rms_by_range"]}
    assert bins == {(2.0, 5.0): 2, (5.0, 10.0): 1}  # the 5.0 m frame is not in [2, 5)
    assert bin_label(2.0, 5.0) == "[2, 5)" and bin_label(40.0, None) == "[40, inf)"


def test_approach_report_line_on_errors_far_above_the_bound(tmp_path):
    from svgs_sim.studies.approach import bound_line, summarise

    cfg = {"camera": "galaxy-nexus", "pattern": "svgs-3u", "preview": False, "fps": 1.0, "seed": 0,
           "trajectory": {"source": "test"}}
    rows = [_row(0, 5.0), _row(1, 4.0)]
    assert bound_line(summarise(rows, cfg)) is None
    rows[1]["err_pitch_deg"] = 0.5  # 500x, head-on (the rows' truth is head-on): the glint
    s = summarise(rows, cfg)
    assert s["far_above_bound"]["frames"] == [1] and s["far_above_bound"]["glint_frames"] == [1]
    line = bound_line(s)
    assert "1 of 2 solved frames" in line and "pitch_deg 500x" in line and "head-on glint" in line


def test_slow_studies_print_seconds_per_trial():
    from svgs_sim.studies.execution import RunStats

    def stats(n, s):
        return RunStats(n_trials=n, n_already_done=0, n_run=n, n_tasks=1, n_render_groups=1, elapsed_s=s,
                        executor="in-process")

    assert stats(3, 36.0).rate_text == "12 s/trial"
    assert stats(100, 4.0).rate_text == "25 trials/s"
    assert stats(0, 1.0).rate_text == "no trial run"


def test_results_file_with_windows_line_endings_is_read(tmp_path):
    from svgs_sim.studies.store import ResultStore, read_rows

    cols = ("trial_id", "value")
    with ResultStore(tmp_path, {"p": 1}, cols, trial_ids=range(3)) as store:
        store.append([{"trial_id": 0, "value": 1.5}, {"trial_id": 1, "value": 2.5}])
    path = tmp_path / "results.csv"
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))  # saved by a Windows editor
    assert [r["value"] for r in read_rows(path, cols)] == [1.5, 2.5]
    with ResultStore(tmp_path, {"p": 1}, cols, trial_ids=range(3)) as store:
        assert store.done_ids == {0, 1}
        store.append([{"trial_id": 2, "value": 3.5}])
        assert [r["value"] for r in store.read_rows()] == [1.5, 2.5, 3.5]
    assert b"\r" not in path.read_bytes()


def test_tof_study_default_folder_never_overwrites_a_report(tmp_path, monkeypatch, capsys):
    from svgs_sim.cli.tof_stability import DEFAULT_STUDY_OUT, default_study_out

    monkeypatch.chdir(tmp_path)
    assert DEFAULT_STUDY_OUT != "docs/reports"
    assert default_study_out() == DEFAULT_STUDY_OUT
    (tmp_path / DEFAULT_STUDY_OUT).mkdir()
    assert default_study_out() == DEFAULT_STUDY_OUT  # unfinished: resumed
    (tmp_path / DEFAULT_STUDY_OUT / "tof_stability.md").write_text("# done\n")
    assert default_study_out() == f"{DEFAULT_STUDY_OUT}-2"
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{DEFAULT_STUDY_OUT}-2" in err


def test_render_and_solve_notes_name_the_glint_the_renderer_sampled():
    from svgs_sim.cli.sim import bound_line, error_notes

    crlb = {"crlb_std": {k: 1e-3 for k in STATE_KEYS}}
    row = {"ok": True, "truth_state": {k: 0.0 for k in STATE_KEYS},
           "pos_err_vec_m": [-0.117, 0.0005, 0.0], "att_err_vec_deg": [0.0, -1.39, 0.0]}
    # the renderer's record: strategy labels cube<index>:led<index>:<kind>, index into the pattern's ids
    truth = {"render": {"spot_strategies": [{"label": "cube0:led0:retro", "samples": 16384},
                                            {"label": "cube2:led0:front", "samples": 16384}]}}
    pat = Pattern.load("svgs-3u")
    line = bound_line(row, crlb, truth, pat)
    assert f"target {int(pat.ids[2])}" in line and "head-on glint" in line
    notes = error_notes(row, crlb, truth, pat)
    assert len(notes) == 1 + len(STATE_KEYS) + 1 and notes[-1] == line
    assert notes[1].split("\t") == ["x_m", "+0.0000", "-0.1170", "0.0010", "-117.0"]
    no_glint = {"render": {"spot_strategies": [{"label": "cube2:led0:retro", "samples": 16384}]}}
    assert "not the head-on glint" in bound_line(row, crlb, no_glint, pat)
    assert error_notes({"ok": False}, crlb, truth, pat) == []
