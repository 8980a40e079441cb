"""The geometric trial: numbers (noise-free exactness, CRLB efficiency, calibration bias),
render grouping, failures, registry and scenario validation."""

import numpy as np
import pytest

from svgs_sim.studies.seeding import trial_seed
from svgs_sim.sim.trials import (GEOMETRIC, geometric_group, geometric_render_key, geometric_scenario, geometric_trial,
                        get_trial_kind)
from svgs_sim.svgs.frames import STATE_KEYS
from svgs_sim.base.errors import InputError


def test_noise_free_trial_recovers_the_pose_exactly():
    s = geometric_scenario(camera="galaxy-nexus", range_m=12.0, target_x_m=0.3, target_y_m=-0.2, roll_deg=20.0, pitch_deg=-15.0,
                           yaw_deg=40.0, sigma_px=0.0)
    r = geometric_trial(s, 1)
    assert r["ok"] and r["reason"] is None
    assert r["pos_err_norm_m"] < 1e-6 and r["rot_err_deg"] < 1e-6 and r["residual_rms_px"] < 1e-6
    assert all(r[f"crlb_{k}"] == 0.0 for k in STATE_KEYS)
    # truth in the paper convention: the camera's distance to the target origin is |(x, y, range)|
    dist = np.linalg.norm([r["true_x_m"], r["true_y_m"], r["true_z_m"]])
    assert dist == pytest.approx(np.sqrt(12.0**2 + 0.3**2 + 0.2**2), rel=1e-12) and r["true_z_m"] > 0
    assert (r["true_roll_deg"], r["true_pitch_deg"], r["true_yaw_deg"]) == pytest.approx((20.0, -15.0, 40.0))


def test_centroid_noise_scatter_matches_the_cramer_rao_bound():
    """Normalised errors err / CRLB over many noise draws have unit standard deviation and zero mean."""
    s = geometric_scenario(camera="galaxy-nexus", range_m=15.0, roll_deg=10.0, pitch_deg=-20.0, yaw_deg=30.0,
                           sigma_px=0.2)
    rows = [geometric_trial(s, trial_seed(7, i)) for i in range(400)]
    assert all(r["ok"] for r in rows)
    for k in STATE_KEYS:
        z = np.array([r[f"err_{k}"] / r[f"crlb_{k}"] for r in rows])
        # std of a 400-sample std: 1/sqrt(800) = 0.035; allow ~4 sigma
        assert abs(np.std(z) - 1.0) < 0.15, (k, np.std(z))
        assert abs(np.mean(z)) < 0.2, (k, np.mean(z))


def test_focal_length_error_scales_the_range_estimate():
    """A solver focal length (1 + e) too long makes the target look (1 + e) farther away."""
    e = 0.03
    errs = []
    for i in range(20):
        rng = np.random.default_rng(i)
        s = geometric_scenario(camera="htc-amaze-4g", range_m=4.0, roll_deg=rng.uniform(-25, 25),
                               pitch_deg=rng.uniform(-25, 25), yaw_deg=rng.uniform(-45, 45), sigma_px=0.0,
                               focal_error_frac=e)
        r = geometric_trial(s, 0)
        assert r["ok"]
        dist_true = np.linalg.norm([r[f"true_{k}"] for k in ("x_m", "y_m", "z_m")])
        dist_est = np.linalg.norm([r[f"est_{k}"] for k in ("x_m", "y_m", "z_m")])
        errs.append(dist_est / dist_true - 1.0)
    assert np.mean(errs) == pytest.approx(e, rel=0.1)


def test_principal_point_error_tilts_the_attitude():
    """Shifting cx by du rotates the estimated line of sight by about du / fx radians."""
    s = geometric_scenario(camera="galaxy-nexus", range_m=10.0, sigma_px=0.0, pp_error_u_px=24.5)
    r = geometric_trial(s, 0)
    assert r["ok"]
    assert r["rot_err_deg"] == pytest.approx(np.degrees(24.5 / 2450.0), rel=0.05)


def test_group_gives_the_rows_of_single_trials():
    base = dict(camera="galaxy-nexus", range_m=8.0, roll_deg=5.0, pitch_deg=3.0, yaw_deg=-20.0)
    scens = [geometric_scenario(**base, sigma_px=sg, focal_error_frac=fe) for sg, fe in
             ((0.1, 0.0), (0.3, 0.0), (0.1, 0.01), (0.5, -0.02))]
    assert len({geometric_render_key(s) for s in scens}) == 1
    seeds = [trial_seed(3, i) for i in range(4)]
    assert geometric_group(scens, seeds) == [geometric_trial(s, sd) for s, sd in zip(scens, seeds)]


def test_failures_are_values_with_reasons():
    out = geometric_trial(geometric_scenario(camera="galaxy-nexus", range_m=5.0, target_x_m=20.0), 0)
    assert not out["ok"] and out["reason"] == "too_few_blobs" and out["pos_err_norm_m"] is None
    r = geometric_trial(geometric_scenario(camera="htc-amaze-4g", range_m=30.0), 0)
    merged = geometric_trial(geometric_scenario(camera="htc-amaze-4g", range_m=30.0,
                                                merge_px=r["min_separation_px"] + 1), 0)
    assert not merged["ok"] and merged["reason"] == "merged_spots"


def test_bad_scenarios_are_input_errors():
    with pytest.raises(InputError, match="range_m: expected a value > 0 and <= 1000 m"):
        geometric_scenario(camera="galaxy-nexus", range_m=0.0)
    with pytest.raises(InputError, match="sigma_px: expected 0 to 100 px"):
        geometric_scenario(camera="galaxy-nexus", sigma_px=-0.1)
    with pytest.raises(InputError, match="no parameter 'exposure_s'"):
        geometric_scenario(camera="galaxy-nexus", exposure_s=0.01)
    with pytest.raises(InputError, match="unknown camera"):
        geometric_scenario(camera="no-such-phone")
    with pytest.raises(InputError, match="known: .*geometric"):
        get_trial_kind("no-such-kind")
    assert get_trial_kind("geometric") is GEOMETRIC


def test_one_rendered_trial_kind_for_every_study():
    """``render`` is the rendered kind of the campaign, sensitivity, range sweep and exposure study;
    its defaults are the campaign's render (seed 0, pattern as it is, no ND, default spp, the app's threshold)."""
    from svgs_sim.sim.render_trial import (
        RENDER,
        render_key,
        render_trial_scenario,
        threshold_parameter,
    )
    from svgs_sim.sim.trials import KIND_MODULES, build_scenario, known_trial_kinds

    assert KIND_MODULES == ("svgs_sim.sim.render_trial", "svgs_sim.sim.tof_trial") and "closed-loop" not in known_trial_kinds()
    assert get_trial_kind("render") is RENDER
    s = build_scenario(RENDER, {"camera": "galaxy-nexus", "range_m": 8.0})
    assert (s["render_seed"], s["pattern_scale"], s["target_scale"], s["spp"], s["roi_spp"], s["threshold"]) == \
        (0.0, 1.0, 1.0, -1.0, -1.0, 0.0)
    assert render_trial_scenario(camera="galaxy-nexus", range_m=8.0) == s
    assert render_key({**s, "target_scale": 0.01, "threshold": -1.0, "focal_error_frac": 0.02}) == render_key(s)
    assert render_key({**s, "pattern_scale": 1.5}) != render_key(s)
    assert [threshold_parameter(t) for t in (None, "app", "auto", "otsu", "12", 0)] == [0.0, 0.0, -2.0, -1.0, 12.0, 0.0]
    with pytest.raises(InputError, match="threshold"):
        threshold_parameter("high")
    with pytest.raises(InputError, match="render_seed: expected an integer"):
        render_trial_scenario(camera="galaxy-nexus", render_seed=1.5)
    with pytest.raises(InputError, match="roi_spp"):
        render_trial_scenario(camera="galaxy-nexus", roi_spp=0)
