"""The ToF pipeline end to end on seeded synthetic frames, and its bad-input handling."""

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.frames import pose_from_scenario, rotation_angle_deg
from svgs_sim.tof import TofPipeline, load_camera, load_target, solve_frame
from synth_tof import synth_frame


@pytest.fixture(scope="module")
def cam():
    return load_camera("tof-epc660")


@pytest.fixture(scope="module")
def tgt():
    return load_target("tof-8")


def _frame(cam, tgt, range_m, angles, seed, **kw):
    R, t = pose_from_scenario(range_m, 0.002, -0.010, *angles)
    kw.setdefault("gray_scale_dn", 800.0 * max(1.0, (range_m / 0.8) ** 2))  # exposure scaled with range
    return synth_frame(cam, tgt, R, t, seed=seed, **kw)


@pytest.fixture(scope="module")
def near(cam, tgt):
    """The paper's near stability range, 697 mm (Table 1 attitude)."""
    return _frame(cam, tgt, 0.697, (-2.5, -0.4, -2.7), seed=11)


@pytest.fixture(scope="module")
def far(cam, tgt):
    """The paper's far stability range, 5712 mm (Table 2 attitude)."""
    return _frame(cam, tgt, 5.712, (-2.1, 3.8, 1.3), seed=12)


@pytest.mark.parametrize("which, pos_tol_m, att_tol_deg", [("near", 0.001, 0.1), ("far", 0.015, 2.0)])
def test_pose_from_synthetic_frames(which, pos_tol_m, att_tol_deg, request, cam, tgt):
    fr = request.getfixturevalue(which)
    res = solve_frame(fr.gray, fr.depth_m, cam, tgt)
    assert res, getattr(res, "message", "")
    assert sorted(res.targets_px) == list(range(1, 9))
    assert np.abs(res.t_cam_target_m - fr.t_cam_target_m).max() < pos_tol_m
    assert rotation_angle_deg(res.R_cam_target, fr.R_cam_target) < att_tol_deg
    # centroids on the projected marker centres, as the paper reports (0.06 px)
    uv = np.array([res.targets_px[k] for k in range(1, 9)])
    assert np.abs(uv - fr.centres_px).max() < 0.1
    assert res.residual_rms_px < 0.1
    assert set(res.timings_s) >= {"active_set", "nlog_filter", "blobs", "centroids", "match", "pose"}


def test_projected_centre_correction_on_rendered_markers(cam, tgt):
    """Noise-free frame, plate tilted 30 deg at 0.6 m: the corrected centres sit on the
    projections of the marker centres; uncorrected (ellipse-centre) ones carry the bias."""
    fr = _frame(cam, tgt, 0.75, (10.0, 25.0, 15.0), seed=13, gray_noise_dn=0.0, depth_noise_m=0.0)
    on = solve_frame(fr.gray, fr.depth_m, cam, tgt)
    off = solve_frame(fr.gray, fr.depth_m, cam, tgt, centre_correction=False)
    ids = np.array(sorted(on.targets_px))
    err_on = np.linalg.norm(np.array([on.targets_px[k] for k in ids]) - fr.centres_px[ids - 1], axis=1)
    err_off = np.linalg.norm(np.array([off.targets_px[k] for k in ids]) - fr.centres_px[ids - 1], axis=1)
    bias = np.linalg.norm(fr.ellipse_centres_px - fr.centres_px, axis=1)[ids - 1]
    big = tgt.diameter_m[ids - 1] > 0.05
    assert bias[big].min() > 0.1  # the bias is real for the 80 mm markers
    assert err_on[big].max() < 0.06
    assert err_off[big].min() > 0.06
    np.testing.assert_allclose(err_off[big], bias[big], atol=0.06)  # uncorrected error = the bias
    assert rotation_angle_deg(on.R_cam_target, fr.R_cam_target) < rotation_angle_deg(off.R_cam_target, fr.R_cam_target)


def test_glint_glued_to_a_marker_is_repaired_by_ellipse_detection(cam, tgt):
    fr = _frame(cam, tgt, 0.875, (0.0, 5.0, -5.0), seed=14)  # marker 6's face at ~0.85 m
    g, d = fr.gray.copy(), fr.depth_m.copy()
    u, v = np.round(fr.centres_px[5]).astype(int)  # marker 6 (80 mm)
    g[v - 2:v + 3, u:u + 30] = g[v, u]
    d[v - 2:v + 3, u:u + 30] = fr.range_m[5]
    res = solve_frame(g, d, cam, tgt)
    assert np.linalg.norm(np.array(res.targets_px[6]) - fr.centres_px[5]) < 0.1
    assert "ellipse" in set(res.candidates.source)
    plain = solve_frame(g, d, cam, tgt, ellipse_supplement=False)
    assert np.linalg.norm(np.array(plain.targets_px[6]) - fr.centres_px[5]) > 1.0


def test_sequence_with_temporal_median_and_persistence(cam, tgt):
    frames = [_frame(cam, tgt, 2.0, (3.0, -4.0, 5.0), seed=20 + k) for k in range(3)]
    pipe = TofPipeline(cam, tgt, persistence_window=3, persistence_min_count=2)
    res = [pipe.process(f.gray, f.depth_m) for f in frames]
    assert all(res)
    assert np.abs(res[-1].t_cam_target_m - frames[0].t_cam_target_m).max() < 0.003


def test_bad_input_raises_input_error(near, cam, tgt):
    g, d = near.gray, near.depth_m
    pipe = TofPipeline(cam, tgt)
    with pytest.raises(InputError, match="different sizes"):
        pipe.process(g, d[:200])
    with pytest.raises(InputError, match="no valid pixel"):
        pipe.process(g, np.full_like(d, np.nan))
    with pytest.raises(InputError, match="negative"):
        pipe.process(g, -np.abs(np.nan_to_num(d)))
    bad = g.copy()
    bad[0, 0] = np.nan
    with pytest.raises(InputError, match="gray"):
        pipe.process(bad, d)
    with pytest.raises(InputError, match="camera"):
        pipe.process(g[:, :300], d[:, :300])
    with pytest.raises(InputError, match="2-D"):
        pipe.process(g[0], d[0])
    with pytest.raises(InputError, match="unknown pipeline parameter"):
        TofPipeline(cam, tgt, no_such_setting=1)


def test_failures_carry_reasons(near, cam, tgt):
    g, d = near.gray, near.depth_m
    dark = solve_frame(np.zeros_like(g), d, cam, tgt)
    assert not dark and dark.reason == "no_blobs"
    noisy_dark = solve_frame(5 + np.random.default_rng(3).normal(0, 1, g.shape), d, cam, tgt)
    assert not noisy_dark and noisy_dark.reason == "no_blobs"
    # keep only two markers in the gray image -> fewer than three
    few = np.full_like(g, float(np.median(g)))
    for k in (4, 5):
        u, v = np.round(near.centres_px[k]).astype(int)
        few[v - 15:v + 16, u - 15:u + 16] = g[v - 15:v + 16, u - 15:u + 16]
    r = solve_frame(few, d, cam, tgt)
    assert not r and r.reason == "too_few_blobs" and r.details["n_blobs"] == 2
    # depth missing (NaN) on all markers -> no 3-D points
    nod = d.copy()
    nod[g > 0.2 * g.max()] = np.nan
    r = solve_frame(g, nod, cam, tgt)
    assert not r and r.reason == "too_few_blobs"
    # depth missing on two markers only: still solved from the other six
    part = d.copy()
    for k in (0, 6):
        u, v = np.round(near.centres_px[k]).astype(int)
        part[v - 30:v + 31, u - 30:u + 31] = np.nan
    r = solve_frame(g, part, cam, tgt)
    assert r and 1 not in r.targets_px and 7 not in r.targets_px and len(r.targets_px) == 6


def test_markers_cut_by_the_image_border_are_not_used(cam, tgt):
    """Markers 5 and 6 straddle the left border: their centroids would be biased, so they are
    dropped and the pose comes from the six others."""
    R, t = pose_from_scenario(0.675, -0.1275, 0.0, 0.0, 0.0, 0.0)  # the markers' centroid 0.675 m away
    fr = synth_frame(cam, tgt, R, t, seed=3, gray_scale_dn=1000.0)
    z_face = (tgt.points_m[[4, 5]] @ R.T + t)[:, 2]
    u_left = fr.centres_px[[4, 5], 0] - cam.fx * tgt.radius_m[[4, 5]] / z_face
    assert np.all(u_left < -0.5)  # the two markers really are cut
    res = solve_frame(fr.gray, fr.depth_m, cam, tgt)
    assert sorted(res.targets_px) == [1, 2, 3, 4, 7, 8]
    assert res.candidates.notes.get("dropped_at_border") == 2
    assert np.abs(res.t_cam_target_m - t).max() < 0.001
    assert rotation_angle_deg(res.R_cam_target, R) < 0.1
