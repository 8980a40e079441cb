"""Target identification: labels over the envelope, distractors, failures with reasons."""

import os

import numpy as np
import pytest

from svgs_sim.base.profiles import Camera, Pattern
from svgs_sim.svgs.detect import detect_blobs
from svgs_sim.base.errors import InputError
from svgs_sim.svgs.identify import (GATE_MARGIN_DEG, GATE_MARGIN_LATERAL, GATE_MARGIN_RANGE, Identification, identify,
                                    pattern_gates)
from svgs_sim.svgs.envelope import PAPER_ENVELOPE, Envelope
from svgs_sim.svgs.result import REASONS, Failure
from synth_svgs import random_envelope_pose, synth_frame


def _distractor_points(rng, uv, m, shape_wh, near_fraction, clearance_px=8.0):
    """m random points, ``near_fraction`` of them within one pattern size of the pattern,
    none closer than ``clearance_px`` to a target."""
    lo, hi = uv.min(0), uv.max(0)
    size = max(float(np.max(hi - lo)), 30.0)
    out = []
    while len(out) < m:
        if rng.random() < near_fraction:
            c = rng.uniform(lo - size, hi + size)
        else:
            c = rng.uniform([0, 0], [shape_wh[0] - 1, shape_wh[1] - 1])
        if np.min(np.linalg.norm(uv - c, axis=1)) >= clearance_px:
            out.append(c)
    return np.asarray(out).reshape(-1, 2)


def _point_trials(n, seed, camera, pattern, *, noise_px=0.2, max_distractors=20, near_fraction=0.25):
    """Identify shuffled (targets + distractors) point sets; returns (n_correct, failures)."""
    rng = np.random.default_rng(seed)
    correct, failures = 0, []
    for _ in range(n):
        R, t, sc = random_envelope_pose(rng)
        uv = camera.project_target(pattern.points_m, R, t)
        meas = uv + rng.normal(0.0, noise_px, uv.shape)
        d = _distractor_points(rng, uv, int(rng.integers(0, max_distractors + 1)), (camera.width, camera.height),
                               near_fraction)
        pts = np.concatenate([meas, d])
        perm = rng.permutation(len(pts))
        res = identify(pts[perm], camera, pattern)
        truth = np.argsort(perm)[: pattern.n]
        if res and np.array_equal(res.blob_index, truth):
            correct += 1
        else:
            failures.append((sc, res))
    return correct, failures


# ---------------------------------------------------------------- gates
def test_gates_derived_from_pattern():
    """The gates use the pattern's longest baseline (1-2 for svgs-3u) and put target 4 on
    one side of it only (handedness); target 3 sits near the baseline's midpoint."""
    g = pattern_gates(Pattern.load("svgs-3u"))
    assert (g.a, g.b) == (0, 1) and g.others == (2, 3)
    # w = (z - z1) / (z2 - z1): target 3 near 0.5 + 0j, target 4 at 0.5 - 0.32j (v is down)
    assert g.mean[0] == pytest.approx([0.5, 0.0], abs=0.02)
    assert g.mean[1][0] == pytest.approx(0.5, abs=0.02)
    assert g.mean[1][1] == pytest.approx(-0.0875 / 0.275, abs=0.02)
    # Longest image baseline (normalised units): an independent reference is the projected
    # 1-2 baseline maximised over the envelope box at its near range (scipy, continuous).
    # The gate must cover the real envelope (>= its supremum) and cannot exceed what the
    # inflated envelope it samples can produce (<= that supremum); it samples all box
    # corners, so it is at least the largest corner value.
    env = PAPER_ENVELOPE
    sup_real, _ = _max_baseline(env.range_interval_m[0], env.lateral_fraction,
                                          (env.roll_deg, env.pitch_deg, env.yaw_deg))
    sup_infl, corner_infl = _max_baseline(env.range_interval_m[0] / GATE_MARGIN_RANGE,
                                          env.lateral_fraction + GATE_MARGIN_LATERAL,
                                          np.array([env.roll_deg, env.pitch_deg, env.yaw_deg]) + GATE_MARGIN_DEG)
    assert sup_real <= g.base_max
    assert corner_infl * (1 - 1e-12) <= g.base_max <= sup_infl * (1 + 1e-12)
    assert g.base_min < 0.275 / (40 * 1.25)


def _max_baseline(range_m, lateral_fraction, max_angles_deg, n_starts=6):
    """(sup, largest corner value) of |z2 - z1| (pinhole, normalised) over the attitude and
    lateral-offset box at ``range_m``: L-BFGS-B from the best corner and random starts."""
    import itertools

    from scipy.optimize import minimize

    from svgs_sim.svgs.frames import D_CAM_PHOTO, rotation_from_angles

    P = Pattern.load("svgs-3u").points_m[:2]
    am = np.deg2rad(max_angles_deg)

    def neg_base(f):
        R = D_CAM_PHOTO @ rotation_from_angles(*(f[2:] * am))
        t = D_CAM_PHOTO @ np.array([f[0] * lateral_fraction * range_m, f[1] * lateral_fraction * range_m, -range_m])
        pc = P @ R.T + t
        return -float(np.linalg.norm(pc[1, :2] / pc[1, 2] - pc[0, :2] / pc[0, 2]))

    corners = [np.array(c) for c in itertools.product([-1.0, 1.0], repeat=5)]
    corner = max(-neg_base(c) for c in corners)
    starts = [max(corners, key=lambda c: -neg_base(c))] + list(np.random.default_rng(0).uniform(-1, 1, (n_starts, 5)))
    sup = max(-minimize(neg_base, x0, bounds=[(-1, 1)] * 5).fun for x0 in starts)
    return max(sup, corner), corner


# ---------------------------------------------------------------- points
def test_noise_free_points_over_the_envelope(nexus, pattern):
    rng = np.random.default_rng(0)
    for _ in range(150):
        R, t, sc = random_envelope_pose(rng)
        uv = nexus.project_target(pattern.points_m, R, t)
        perm = rng.permutation(4)
        res = identify(uv[perm], nexus, pattern)
        assert res, (sc, res)
        assert np.array_equal(res.blob_index, np.argsort(perm))
        assert np.allclose(res.points_px, uv)
        assert res.residual_rms_px < 1e-6
        assert res.solution.residual_rms_px == pytest.approx(res.residual_rms_px)
        assert np.allclose(res.solution.t_cam_target_m, t, atol=1e-6)


@pytest.mark.slow
def test_points_with_distractors_identified_99_percent(nexus, pattern):
    """0-20 distractor points (a quarter of them near the pattern), 0.2 px centroid noise,
    random envelope poses. Bare points carry no photometry; a distractor sitting where
    target 3 could be (its position mostly sets roll and pitch) is then ambiguous."""
    n = 400
    correct, failures = _point_trials(n, 1, nexus, pattern)
    reasons = [f[1].reason if not f[1] else "wrong" for f in failures]
    assert correct >= 0.99 * n, f"{correct}/{n} correct; failures: {reasons}"
    for _, res in failures:
        if not res:
            assert res.reason in REASONS and res.message


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SVGS_LONG_TESTS"),
                    reason="long form of the test above (more trials, the same acceptance): set SVGS_LONG_TESTS=1")
def test_points_with_distractors_identified_99_percent_long(nexus, pattern):
    n = 2000
    correct, _ = _point_trials(n, 2, nexus, pattern)
    assert correct >= 0.99 * n


def test_many_blobs_capped_and_verified_few(nexus, pattern):
    """25 blobs: the candidate sets are pruned before solving; few are solved."""
    rng = np.random.default_rng(4)
    R, t, _ = random_envelope_pose(rng, range_interval_m=(5.0, 5.0))
    uv = nexus.project_target(pattern.points_m, R, t)
    d = _distractor_points(rng, uv, 21, (nexus.width, nexus.height), 0.5)
    res = identify(np.concatenate([uv, d]), nexus, pattern)
    assert res and np.array_equal(res.blob_index, [0, 1, 2, 3])
    assert res.n_blobs == 25 and res.n_verified <= 6 and res.n_candidates >= res.n_verified


def test_other_pattern_with_five_targets(nexus):
    """The checks come from the pattern file: a five-target layout works as well."""
    pat = Pattern(name="five", ids=np.array([1, 2, 3, 4, 5]),
                  points_m=np.array([[0, 0.2, 0], [0, -0.15, 0], [0, 0, 0.06], [0.1, 0.02, 0], [-0.08, -0.05, 0.02]]))
    rng = np.random.default_rng(6)
    for _ in range(60):
        R, t, sc = random_envelope_pose(rng, range_interval_m=(1.0, 20.0))
        uv = nexus.project_target(pat.points_m, R, t) + rng.normal(0, 0.1, (5, 2))
        pts = np.concatenate([uv, rng.uniform([0, 0], [nexus.width - 1, nexus.height - 1], (8, 2))])
        perm = rng.permutation(len(pts))
        res = identify(pts[perm], nexus, pat)
        assert res and np.array_equal(res.blob_index, np.argsort(perm)[:5]), sc


def test_mirror_image_is_not_the_pattern(nexus, pattern):
    """Handedness: the mirror image of the pattern (u flipped) is not accepted."""
    rng = np.random.default_rng(9)
    n_rejected = 0
    for _ in range(40):
        R, t, _ = random_envelope_pose(rng, range_interval_m=(1.0, 10.0))
        uv = nexus.project_target(pattern.points_m, R, t)
        mirrored = uv.copy()
        mirrored[:, 0] = 2 * nexus.cx - mirrored[:, 0]
        res = identify(mirrored, nexus, pattern)
        n_rejected += (not res) or not np.array_equal(res.blob_index, [0, 1, 2, 3])
        if not res:
            assert res.reason == "no_consistent_set"
    assert n_rejected == 40


def test_verify_off_uses_geometry_only(nexus, pattern):
    R, t = random_envelope_pose(np.random.default_rng(3))[:2]
    uv = nexus.project_target(pattern.points_m, R, t)
    res = identify(uv[::-1], nexus, pattern, verify=False)
    assert res and np.array_equal(res.blob_index, [3, 2, 1, 0])
    assert res.solution is None and np.isnan(res.residual_rms_px) and res.n_verified == 0


def test_narrow_envelope_rejects_poses_outside_it(nexus, pattern):
    """Gates follow the envelope: a 30 m pose is not found with a 1-5 m envelope."""
    from svgs_sim.svgs.frames import pose_from_scenario

    uv = nexus.project_target(pattern.points_m, *pose_from_scenario(30.0))
    assert identify(uv, nexus, pattern)
    res = identify(uv, nexus, pattern, envelope=Envelope(range_interval_m=(1.0, 5.0)))
    assert not res and res.reason == "no_consistent_set"
    assert PAPER_ENVELOPE.range_interval_m == (1.0, 40.0)


# ---------------------------------------------------------------- images (acceptance)
def _image_trials(n, seed, camera, pattern, *, dtype="uint8", colour=False, max_distractors=20):
    """Synthetic frames over the envelope with 0-20 distractors (spots, glints, hot pixels;
    half near the pattern). Spot sigma 1-2 px, kept resolvable: at most 1/6 of the closest
    target pair's separation and not under 0.8 px (else the pose is redrawn)."""
    rng = np.random.default_rng(seed)
    correct, failures, errs = 0, [], []
    for _ in range(n):
        while True:
            R, t, sc = random_envelope_pose(rng)
            uv = camera.project_target(pattern.points_m, R, t)
            dmin = min(np.linalg.norm(uv[i] - uv[j]) for i in range(4) for j in range(i))
            sigma = min(rng.uniform(1.0, 2.0), dmin / 6.0)
            if sigma >= 0.8:
                break
        m = int(rng.integers(0, max_distractors + 1))
        peak = rng.uniform(80, 250) * (257 if dtype == "uint16" else 1)
        f = synth_frame(camera, pattern, R, t, sigma_px=sigma, peak=peak, n_distractors=m, dtype=dtype, colour=colour,
                        read_noise=1.5 * (257 if dtype == "uint16" else 1), seed=rng)
        res = identify(detect_blobs(f.image, threshold="auto", centroid="window"), camera, pattern)
        if res:
            e = np.linalg.norm(res.points_px - f.targets_px, axis=1)
            if e.max() < 1.0:
                correct += 1
                errs.append(e.max())
                continue
        failures.append((sc, m, res))
    return correct, failures, np.array(errs)


@pytest.mark.slow
def test_images_with_distractors_identified_99_percent(nexus, pattern):
    """Acceptance: detect + identify on synthetic 5 MP frames with 0-20 distractors:
    >= 99 % correct, every failure with a reason."""
    n = 200
    correct, failures, errs = _image_trials(n, 10, nexus, pattern)
    assert correct >= 0.99 * n, [(sc, m, getattr(r, "reason", "wrong")) for sc, m, r in failures]
    for _, _, res in failures:
        if not res:
            assert res.reason in REASONS and res.message
    # identified targets are the true spots (to noise level, incl. close neighbours at 40 m)
    assert np.median(errs) < 0.1


def test_images_16bit_and_colour(nexus, pattern):
    for dtype, colour in (("uint16", False), ("uint8", True)):
        correct, failures, _ = _image_trials(15, 20, nexus, pattern, dtype=dtype, colour=colour)
        assert correct == 15, failures


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SVGS_LONG_TESTS"),
                    reason="long form of the test above (more trials, the same acceptance): set SVGS_LONG_TESTS=1")
def test_images_with_distractors_identified_99_percent_long(nexus, pattern):
    n = 1000
    correct, failures, _ = _image_trials(n, 11, nexus, pattern)
    assert correct >= 0.99 * n


# ---------------------------------------------------------------- failures
def test_failure_reasons(nexus, pattern):
    empty = identify(np.zeros((0, 2)), nexus, pattern)
    assert isinstance(empty, Failure) and not empty and empty.reason == "no_blobs"
    three = identify([[100.0, 100.0], [200.0, 120.0], [150.0, 300.0]], nexus, pattern)
    assert not three and three.reason == "too_few_blobs" and "3" in three.message
    rng = np.random.default_rng(0)
    random_pts = rng.uniform([0, 0], [nexus.width, nexus.height], (6, 2))
    none = identify(random_pts, nexus, pattern)
    assert not none and none.reason == "no_consistent_set"
    assert none.details["n_blobs"] == 6
    for f in (empty, three, none):
        assert f.reason in REASONS and f.message and f.to_json()["ok"] is False


def _merged_frame(camera, pattern, range_m, sigma_px):
    from svgs_sim.svgs.frames import pose_from_scenario

    R, t = pose_from_scenario(range_m, 0.0, 0.0, 10.0, -10.0, 5.0)
    return synth_frame(camera, pattern, R, t, sigma_px=sigma_px, peak=600.0, read_noise=1.0, seed=1)


def test_merged_spots_into_one_blob(nexus, pattern):
    """Far away with a wide PSF (the Amaze 4G beyond 6.5 m): one saturated blob."""
    f = _merged_frame(nexus, pattern, 40.0, 4.0)
    blobs = detect_blobs(f.image, threshold="auto", centroid="window")
    assert len(blobs) == 1 and blobs.saturated_fraction[0] > 0
    res = identify(blobs, nexus, pattern)
    assert not res and res.reason == "merged_spots"
    assert "merged" in res.message
    assert res.details["n_blobs"] == 1


def test_two_spots_merged_leave_three_blobs(nexus, pattern):
    """Targets 3 and 4 are the closest pair; with a moderate PSF only they merge."""
    from svgs_sim.svgs.frames import pose_from_scenario

    R, t = pose_from_scenario(30.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    uv = nexus.project_target(pattern.points_m, R, t)
    d = np.linalg.norm(uv[:, None] - uv[None], axis=-1) + np.eye(4) * 1e9
    assert np.unravel_index(np.argmin(d), d.shape) in ((2, 3), (3, 2))
    f = synth_frame(nexus, pattern, R, t, sigma_px=2.0, peak=200.0, read_noise=1.0, seed=3)
    blobs = detect_blobs(f.image, threshold="auto", centroid="window")
    assert len(blobs) == 3
    res = identify(blobs, nexus, pattern)
    assert not res and res.reason == "merged_spots"
    # bare points cannot tell: too_few_blobs
    res_pts = identify(blobs.centroid_px, nexus, pattern)
    assert not res_pts and res_pts.reason == "too_few_blobs"


def test_three_separate_spots_are_too_few_not_merged(nexus, pattern):
    from svgs_sim.svgs.frames import pose_from_scenario

    R, t = pose_from_scenario(3.0)
    f = synth_frame(nexus, pattern.__class__(name="three-of-four", ids=pattern.ids, points_m=pattern.points_m), R, t,
                    sigma_px=1.5, peak=150.0, seed=2)
    img = f.image.copy()
    u, v = np.round(f.targets_px[3]).astype(int)
    img[v - 10: v + 11, u - 10: u + 11] = np.median(img)  # target 4 hidden
    res = identify(detect_blobs(img, threshold="auto", centroid="window"), nexus, pattern)
    assert not res and res.reason == "too_few_blobs"


def test_identification_object(nexus, pattern):
    R, t = random_envelope_pose(np.random.default_rng(1))[:2]
    uv = nexus.project_target(pattern.points_m, R, t)
    res = identify(uv, nexus, pattern)
    assert isinstance(res, Identification) and bool(res)
    assert list(res.targets_px) == [1, 2, 3, 4]
    j = res.to_json()
    assert j["ok"] is True and j["n_blobs"] == 4 and len(j["targets_px"]) == 4


# ---------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "bad, match",
    [
        (np.zeros((5, 3)), "blobs_or_points"),
        (np.zeros((2, 5, 2)), "blobs_or_points"),
        (np.array([[1.0, np.nan]] * 5), "blobs_or_points"),
        ("abc", "blobs_or_points"),
    ],
)
def test_bad_points_raise_input_error(nexus, pattern, bad, match):
    with pytest.raises(InputError, match=match):
        identify(bad, nexus, pattern)


def test_bad_options_raise_input_error(nexus, pattern):
    pts = np.zeros((4, 2))
    with pytest.raises(InputError, match="tolerance_px"):
        identify(pts, nexus, pattern, tolerance_px=-1)
    with pytest.raises(InputError, match="max_verify"):
        identify(pts, nexus, pattern, max_verify=0)
    with pytest.raises(Exception, match="camera"):
        identify(pts, "no-such-camera", pattern)


def test_camera_with_distortion(pattern):
    """Centroids are undistorted before the geometric gates."""
    cam = Camera.load("galaxy-nexus").replace(dist=np.array([-0.25, 0.1, 0.001, -0.001, 0.0]))
    rng = np.random.default_rng(12)
    for _ in range(40):
        R, t, _ = random_envelope_pose(rng)
        uv = cam.project_target(pattern.points_m, R, t)
        d = rng.uniform([0, 0], [cam.width - 1, cam.height - 1], (6, 2))
        res = identify(np.concatenate([uv, d]), cam, pattern)
        assert res and np.array_equal(res.blob_index, [0, 1, 2, 3])


@pytest.mark.parametrize("camera, ranges", [("galaxy-nexus", (5.0, 30.0)), ("htc-amaze-4g", (1.0, 6.5))])
def test_every_stand_attitude_in_view_is_identified_among_distractors(camera, ranges):
    """The paper's stand turns the phone (roll/pitch +/-25 deg, yaw +/-45 deg about the line of
    sight): the target can sit anywhere in the field of view. Every setting that keeps it in
    view is identified, with the right labels, beside four distractor spots far from it."""
    from svgs_sim.sim.stand import TestStand, sample_in_view

    cam, pat = Camera.load(camera), Pattern.load("svgs-3u")
    stand = TestStand()
    rng = np.random.default_rng(7)
    for r in ranges:
        settings, _ = sample_in_view(np.random.default_rng(int(r * 10)), cam, pat, r, 40)
        for s in settings:
            uv = cam.project_target(pat.points_m, *stand.pose(r, **s)) + 0.1 * rng.standard_normal((4, 2))
            span = np.ptp(uv, axis=0).max()
            far = []
            while len(far) < 4:  # distractors at least two pattern spans from every target
                p = rng.uniform([0, 0], [cam.width - 1, cam.height - 1])
                if np.min(np.linalg.norm(uv - p, axis=1)) > 2 * span:
                    far.append(p)
            res = identify(np.vstack([uv, far]), cam, pat)
            assert res, (r, s, res.reason)
            assert np.allclose(res.points_px, uv), (r, s)


@pytest.mark.parametrize("camera, ranges", [("galaxy-nexus", (5.0, 7.6, 15.0, 30.0)), ("htc-amaze-4g", (1.0, 3.0, 6.5))])
def test_the_envelope_edges_are_identified_among_distractors(camera, ranges):
    """Issue 14 item 7: the corners and edge midpoints of the envelope (roll/pitch -25, 0, +25 deg,
    yaw -45, 0, +45 deg), both as the stand's gimbal settings and as the truth state's angles
    (a target yawed 44-45 deg at 7.6 m failed before issue 12 widened the lateral gate), with four
    distractor spots far from the pattern: every pose that keeps the targets in view is identified
    with the right labels."""
    import itertools

    from svgs_sim.sim.stand import TestStand, targets_in_view
    from svgs_sim.svgs.frames import pose_from_scenario

    cam, pat = Camera.load(camera), Pattern.load("svgs-3u")
    stand = TestStand()
    rng = np.random.default_rng(11)
    tried = 0
    for r in ranges:
        for roll, pitch, yaw in itertools.product((-25.0, 0.0, 25.0), (-25.0, 0.0, 25.0), (-45.0, -44.0, 0.0, 45.0)):
            for R, t in (stand.pose(r, roll_deg=roll, pitch_deg=pitch, yaw_deg=yaw),
                         pose_from_scenario(r, 0.0, 0.0, roll, pitch, yaw)):
                if not targets_in_view(cam, pat, R, t, 0.02):
                    continue
                tried += 1
                uv = cam.project_target(pat.points_m, R, t) + 0.1 * rng.standard_normal((4, 2))
                span = np.ptp(uv, axis=0).max()
                far = []
                while len(far) < 4:
                    p = rng.uniform([0, 0], [cam.width - 1, cam.height - 1])
                    if np.min(np.linalg.norm(uv - p, axis=1)) > 2 * span:
                        far.append(p)
                res = identify(np.vstack([uv, far]), cam, pat)
                assert res, (r, roll, pitch, yaw, res.reason)
                assert np.allclose(res.points_px, uv), (r, roll, pitch, yaw)
    assert tried > 40 * len(ranges) // 2
