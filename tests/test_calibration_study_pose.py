"""Pose error caused by calibration error (svgs_sim.studies.calibration.pose, centroid level).

Expected values from first-order geometry: a focal length too long by e makes the solver put
the target e times farther (Z_L off by e R); a principal point off by d px tilts the camera
by atan(d / f) and leaves the position where it was; exact intrinsics reproduce the truth.
"""

import numpy as np
import pytest

from svgs_sim.assets.papers import svgs_2014_rows
from svgs_sim.studies.calibration import (
    error_cases,
    pose_error_study,
    pose_errors_batch,
    power_law_exponent,
    study_poses,
    table4_comparison,
    true_camera,
)
from svgs_sim.base.profiles import Camera
from svgs_sim.svgs.frames import pose_from_scenario


@pytest.fixture(scope="module")
def cams():
    nominal = Camera.load("galaxy-nexus")
    return nominal, true_camera(nominal, (15.0, -15.0), (0.03, 0, 0, 0, 0))


def _facing(ranges):
    R, t = zip(*(pose_from_scenario(r) for r in ranges))
    return np.array(R), np.array(t)


def test_focal_error_scales_the_range(cams, pattern):
    _, cam = cams
    ranges = [2.0, 10.0, 30.0]
    R, t = _facing(ranges)
    wrong = cam.replace(fx=cam.fx * 1.01, fy=cam.fy * 1.01)
    res = pose_errors_batch(cam, wrong, pattern, R, t)
    assert res["ok"].all()
    dz = res["d_state"][:, 2]
    assert dz / np.array(ranges) == pytest.approx([0.01] * 3, rel=0.03)
    assert np.all(np.abs(res["d_state"][:, :2]) < 1e-3 * np.array(ranges)[:, None])
    assert np.all(res["rot_err_deg"] < 0.05)


def test_principal_point_error_is_an_attitude_bias(cams, pattern):
    _, cam = cams
    ranges = [3.0, 20.0]
    R, t = _facing(ranges)
    res = pose_errors_batch(cam, cam.replace(cx=cam.cx + 20.0), pattern, R, t)
    expected = np.degrees(np.arctan(20.0 / cam.fx))  # 0.47 deg for f = 2450 px
    assert res["rot_err_deg"] == pytest.approx([expected] * 2, rel=0.05)
    # the camera's position in the target frame barely moves (< 0.2 % of the range)
    assert np.all(res["pos_err_norm_m"] < 2e-3 * np.array(ranges))


def test_exact_intrinsics_reproduce_the_truth_and_noise_is_shared(cams, pattern):
    _, cam = cams
    rr, R, t = study_poses([1.0, 8.0, 40.0], 6, seed=3)
    res = pose_errors_batch(cam, cam, pattern, R, t)
    assert res["ok"].all()
    assert np.max(np.abs(res["d_state"][:, :3])) < 1e-6 * 40
    assert np.nanmax(res["rot_err_deg"]) < 1e-5
    a = pose_errors_batch(cam, cam, pattern, R, t, noise_px=0.2, seed=9)
    b = pose_errors_batch(cam, cam, pattern, R, t, noise_px=0.2, seed=9)
    assert np.array_equal(a["d_state"], b["d_state"])  # seeded: the same draws for every case
    # noise errors grow faster than linearly with range (the spacing shrinks as 1/R)
    far, near = a["pos_err_norm_m"][rr == 40.0].mean(), a["pos_err_norm_m"][rr == 1.0].mean()
    assert far / near > 40.0


def test_pose_error_study_rows(cams, pattern):
    nominal, cam = cams
    cases = error_cases(cam, focal_pct=(1.0,), pp_px=(20.0,), k1=(0.05,))
    cases["nominal (focal-only style)"] = nominal
    rows = pose_error_study(cam, cases, pattern, [5.0, 30.0], poses_per_range=8, seed=1)
    by = {(r["case"], r["range_m"]): r for r in rows}
    assert by[("exact", 5.0)]["pos_err_norm_m"] < 1e-6
    # a focal error's position bias grows linearly, its attitude bias does not
    f5, f30 = by[("focal +1 %", 5.0)], by[("focal +1 %", 30.0)]
    assert f30["pos_err_norm_m"] / f5["pos_err_norm_m"] == pytest.approx(6.0, rel=0.1)
    assert f5["mean_z_m"] == pytest.approx(0.05, rel=0.05)
    p5, p30 = by[("principal point +20 px (u)", 5.0)], by[("principal point +20 px (u)", 30.0)]
    assert p30["rot_err_deg"] == pytest.approx(p5["rot_err_deg"], rel=0.1)
    # the nominal camera (principal point and distortion ignored) is off by about the 21 px offset
    n5 = by[("nominal (focal-only style)", 5.0)]
    assert n5["rot_err_deg"] == pytest.approx(np.degrees(np.hypot(15, 15) / cam.fx), rel=0.15)
    assert all(r["n_failed"] == 0 and r["n_poses"] == 8 for r in rows)


def test_power_law_exponent():
    r = np.array([5.0, 10.0, 20.0, 30.0])
    assert power_law_exponent(r, 0.003 * r**1.7) == pytest.approx(1.7)
    assert np.isnan(power_law_exponent([5.0], [1.0]))
    assert np.isnan(power_law_exponent(r, np.zeros(4)))


def test_table4_comparison_reads_the_paper():
    paper = svgs_2014_rows("galaxy-nexus", "mean_error")
    assert [p["range_m"] for p in paper] == [5, 10, 15, 20, 30]
    assert paper[-1]["y_m"] == 1.53  # Table 4, 30 m, Y
    rows = [{"case": "c", "range_m": float(r), "noise_px": 0.0, **{k: 0.01 * r for k in
            ("x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg")}} for r in (5, 10, 15, 20, 30)]
    t4 = table4_comparison(rows)
    assert t4["exponents"]["c"]["x_m"] == pytest.approx(1.0)
    # the paper's Z error is 1.2-1.6 % of the range: growth exponent about 1
    assert 0.9 < t4["exponents"]["paper Table 4"]["z_m"] < 1.1
    assert min(t4["z_over_range_pct"]) > 1.1 and max(t4["z_over_range_pct"]) < 1.7
    assert len(t4["rows"]) == 5 * 6 and t4["rows"][0]["c"] == pytest.approx(0.05)


def test_true_camera_checks(cams):
    nominal, cam = cams
    assert (cam.cx - nominal.cx, cam.cy - nominal.cy) == (15.0, -15.0) and cam.dist[0] == 0.03
    from svgs_sim.base.errors import InputError

    with pytest.raises(InputError, match="outside"):
        true_camera(nominal, (5000.0, 0.0))
    with pytest.raises(InputError, match="5 finite"):
        true_camera(nominal, (0.0, 0.0), (0.1, 0.2))
