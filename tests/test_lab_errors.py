"""The lab's error sources (issue 24): the air's turbulence against the analytic angle-of-arrival
variance, the stand's errors against the stand's own geometry, the campaign's draws."""

import numpy as np
import pytest

from svgs_sim.sim.turbulence import aoa_variance_rad2, draw_tilts, image_shifts_px, tilt_covariance
from svgs_sim.base.errors import InputError


def test_single_spot_variance_is_the_spherical_wave_formula():
    """Path integral of the layers against the closed form 2.91 * 3/8 * C_n^2 L D^-1/3
    (Andrews & Phillips; the 3/8 is the integral of (z/L)^(5/3))."""
    L, D, cn2 = 30.0, 1.43e-3, 1e-12
    cov = tilt_covariance([[0.0, 0.0, L]], D, cn2, n_layers=2000)
    expected = 2.91 * 3.0 / 8.0 * cn2 * L * D ** (-1.0 / 3.0)
    assert cov[0, 0] == pytest.approx(expected, rel=1e-4) and cov[1, 1] == pytest.approx(expected, rel=1e-4)
    assert cov[0, 1] == pytest.approx(0.0, abs=1e-30)
    assert aoa_variance_rad2(cn2, L, D) == pytest.approx(expected, rel=1e-12)
    assert aoa_variance_rad2(cn2, L, D, wave="plane") == pytest.approx(expected * 8 / 3, rel=1e-12)
    # 1.43 mm aperture, 30 m, 1e-12: 17 urad per axis (the order of the literature's examples)
    assert np.sqrt(expected) == pytest.approx(1.6e-5, rel=0.1)


def test_two_spots_are_nearly_independent_and_the_correlation_follows_the_dimm_coefficients():
    """Two spots 27.5 cm apart at 30 m: their tilts' differential variance against the direct
    path integral of Sarazin & Roddier's correlations 0.541 (D/d)^(1/3) (along the baseline) and
    0.810 (D/d)^(1/3) (across), d the cones' separation in each layer."""
    L, D, cn2, b = 30.0, 1.27e-3, 1e-12, 0.275
    cov = tilt_covariance([[-b / 2, 0.0, L], [b / 2, 0.0, L]], D, cn2, n_layers=4000)
    var = cov[0, 0]
    # the differential over the single spot's rms (an independent quadrature of the same model)
    u = (np.arange(200000) + 0.5) / 200000
    w = (1 - u) ** (5 / 3)
    r = (b / D) * u / (1 - u)
    for axis, c in ((0, 0.0968 / 0.179), (1, 0.145 / 0.179)):
        rho = np.minimum(1.0, c * r ** (-1 / 3))
        ratio = np.sqrt(2 * (w * (1 - rho)).sum() / w.sum())
        diff = cov[axis, axis] + cov[2 + axis, 2 + axis] - 2 * cov[axis, 2 + axis]
        assert np.sqrt(diff / var) == pytest.approx(ratio, rel=2e-3)
    # along the baseline about 1.30 x, across about 1.23 x the single spot's rms
    d_l = np.sqrt((2 * var - 2 * cov[0, 2]) / var)
    d_t = np.sqrt((2 * var - 2 * cov[1, 3]) / var)
    assert 1.25 < d_l < 1.35 and 1.18 < d_t < 1.28 and d_l > d_t
    assert np.all(np.linalg.eigvalsh(cov) >= -1e-25)


def test_draws_have_the_covariance():
    """20000 frozen draws: their sample covariance against the model's (the sample variance's
    relative standard error is sqrt(2 / n) = 1 %: 5 % is 5 sigma)."""
    P = [[-0.1375, 0.0, 20.0], [0.1375, 0.0, 20.0], [0.0, 0.1, 20.0], [0.0, -0.05, 20.0]]
    cov = tilt_covariance(P, 1.43e-3, 3e-12)
    rng = np.random.default_rng(5)
    draws = np.array([draw_tilts(cov, rng).ravel() for _ in range(20000)])
    sample = np.cov(draws.T)
    d = np.sqrt(np.diag(cov))
    assert np.allclose(np.diag(sample) / np.diag(cov), 1.0, atol=0.05)
    assert np.allclose(sample / np.outer(d, d), cov / np.outer(d, d), atol=0.05)
    # seeded: the same seed, the same draw
    a = image_shifts_px(P, 2450.0, 1.43e-3, 1e-12, np.random.default_rng(1))
    b = image_shifts_px(P, 2450.0, 1.43e-3, 1e-12, np.random.default_rng(1))
    assert a.shape == (4, 2) and np.array_equal(a, b)


def test_bad_turbulence_input_is_named():
    with pytest.raises(InputError, match="cn2_m23"):
        aoa_variance_rad2(-1.0, 10.0, 1e-3)
    with pytest.raises(InputError, match="aperture_m"):
        tilt_covariance([[0, 0, 5.0]], 0.0, 1e-13)
    with pytest.raises(InputError, match="points_cam_m"):
        tilt_covariance([[0, 0, -5.0]], 1e-3, 1e-13)
    assert not tilt_covariance([[0, 0, 5.0], [0.1, 0, 5.0]], 1e-3, 0.0).any()


def test_stand_errors_move_the_actual_pose_by_the_stands_own_geometry():
    """Each gimbal angle alone is the same angle of the paper's truth state (svgs_sim.sim.stand), so an
    error of the gimbal's yaw is that much yaw; the rail's error moves the camera along the rail."""
    from svgs_sim.sim.closed_loop import Scenario
    from svgs_sim.svgs.frames import pose_to_state

    sc = Scenario(camera="galaxy-nexus", rail_m=10.0, mount="stand", yaw_deg=10.0,
                  stand_error=(0.0, 0.0, 0.03, 0.0, -0.015))
    cmd, act = pose_to_state(*sc.commanded_pose()), pose_to_state(*sc.pose())
    assert np.rad2deg(act[5] - cmd[5]) == pytest.approx(0.03, abs=1e-9)
    p_cmd = -sc.commanded_pose()[0].T @ sc.commanded_pose()[1]
    p_act = -sc.pose()[0].T @ sc.pose()[1]
    assert np.linalg.norm(p_act - p_cmd) == pytest.approx(0.015, rel=1e-6)
    assert np.linalg.norm(p_act) < np.linalg.norm(p_cmd)  # the camera nearer the target
    # the truth with the rail's error only: the actual position, the commanded attitude
    R, t = sc.truth_pose(False, False, True)
    assert np.allclose(-R.T @ t, p_act) and np.allclose(R, sc.commanded_pose()[0])
    with pytest.raises(InputError, match="stand_error"):
        Scenario(camera="galaxy-nexus", stand_error=(0.0, 0.0, 0.01, 0.0, 0.0))  # no stand, no gimbal
    with pytest.raises(InputError, match="stand_error"):
        Scenario(camera="galaxy-nexus", mount="stand", stand_error=(0.0, 0.0, 9.0, 0.0, 0.0))


def test_campaign_draws_the_stands_errors_within_the_lab_accuracies_and_records_the_rangefinder():
    from svgs_sim.sim.lab import lab_errors
    from svgs_sim.studies.campaign import campaign_trials, make_config, rangefinder_readings

    lab = lab_errors()
    cfg = make_config("galaxy-nexus", ranges_m=(5.0, 10.0), trials_per_range=40, exposures_per_render=4,
                      trial_kind="geometric", calibration="exact")
    assert "turbulence_cn2_m23" not in cfg.lab_errors  # the geometric kind has no spots to move
    trials = campaign_trials(cfg)
    readings = rangefinder_readings(cfg)
    for tr in trials:
        sc = tr.scenario
        ri = [5.0, 10.0].index(sc["nominal_range_m"])
        assert sc["rail_m"] == readings[ri] and sc["rail_m"] + sc["rail_err_m"] == pytest.approx(sc["nominal_range_m"])
        for a in ("roll", "pitch", "yaw"):
            assert abs(sc[f"stand_err_{a}_deg"]) <= lab["gimbal_accuracy_deg"]
        assert abs(sc["stand_err_stage_m"]) <= lab["stage_accuracy_m"]
    # one draw per setting: the exposures of a setting share it, settings differ
    by_pose = {}
    for tr in trials:
        by_pose.setdefault((tr.scenario["nominal_range_m"], tr.scenario["pose_index"]), set()).add(
            tr.scenario["stand_err_yaw_deg"])
    assert all(len(v) == 1 for v in by_pose.values()) and len({next(iter(v)) for v in by_pose.values()}) == 20
    # across settings the yaw errors fill +/- the accuracy (uniform: std a / sqrt(3))
    yaw = np.array([next(iter(v)) for v in by_pose.values()])
    assert 0.3 * lab["gimbal_accuracy_deg"] < yaw.std() < 0.9 * lab["gimbal_accuracy_deg"]
    still = make_config("galaxy-nexus", ranges_m=(5.0,), trials_per_range=4, trial_kind="geometric",
                        calibration="exact", lab_errors=False)
    assert still.lab_errors == {} and all(t.scenario["rail_err_m"] == 0 for t in campaign_trials(still))


@pytest.mark.render
def test_rendered_spots_move_by_the_angle_of_arrival():
    """The render trial through turbulent air: the centroids' scatter over exposures grows in
    quadrature by the analytic image motion (f_px * sigma_a). 10 exposures x 8 coordinates; the
    excess variance's relative standard error about 20 %: the check is within a factor 1.6."""
    from svgs_sim.sim.render_trial import render_trial, render_trial_scenario

    cn2 = 1e-11
    def scatter(c):
        sc = render_trial_scenario(camera="galaxy-nexus", rail_m=30.0, stand=1.0, turbulence_cn2=c)
        rows = np.array([[render_trial(sc, s)[f"cen_{a}_px_{k}"] for k in range(4) for a in ("du", "dv")]
                         for s in range(10)])
        return rows.var(axis=0, ddof=1).mean()
    excess = scatter(cn2) - scatter(0.0)
    expected = aoa_variance_rad2(cn2, 30.0, 3.43e-3 / 2.4) * (3.43e-3 / 1.4e-6) ** 2
    assert expected / 1.6 < excess < expected * 1.6
