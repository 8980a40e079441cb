"""The closed-form environment (svgs_sim.render.environment) against the path tracer's own full-frame
pass of the same natural-light scene: the Earth's lit disk, its limb and the sun's disk, as the
renderer drew them before the shortcut (``Renderer._radiance`` over the full frame, 64 samples per
pixel). The path tracer samples Mitsuba's environment map (bilinear texels, 0.09 deg) and the
sun's disk geometry with jittered pixel samples; the shortcut evaluates the sphere and the disk."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.render
pytest.importorskip("pvlib", reason="the orbit extra (pip install -e '.[orbit]')")


def _wide_camera():
    from svgs_sim.base.profiles import Camera

    W, H, f = 320, 240, 260.0  # a 63 x 49 deg field
    return Camera(name="test-env", width=W, height=H, fx=f, fy=f, cx=(W - 1) / 2, cy=(H - 1) / 2,
                  tables={"optics": {"focal_length_m": 0.00343, "f_number": 2.4, "focus_distance_m": 3.0,
                                     "band_nm": [400.0, 700.0]},
                          "flash": {"led_offsets_m": [[0.008, 0.0, 0.0]], "emitter_diameter_m": 0.0012,
                                    "radiant_intensity_w_sr": 0.03, "cos_exponent": 1.0}})


def test_the_closed_form_environment_is_the_path_tracers():
    from svgs_sim.base.profiles import Pattern
    from svgs_sim.render.api import Renderer
    from svgs_sim.render.sun import sun_direction_target

    far = Pattern(name="far", ids=np.arange(1, 5),  # the cubes far outside the field: only the environment
                  points_m=np.array([[30.0, 30.0, 0.05], [40.0, 30.0, 0.05], [30.0, 40.0, 0.05], [40.0, 40.0, 0.1]]))
    # the camera 3 m in front on +z looking down -z; the Earth's centre 55 deg off the boresight toward
    # -x (its limb, 70 deg from the centre, crosses the frame), the sun 25 deg off it toward +x (80 deg
    # from the Earth's centre: not eclipsed, a gibbous Earth)
    earth = sun_direction_target(180.0, -35.0)
    sun = sun_direction_target(0.0, -65.0)
    r = Renderer(_wide_camera(), far, scene_options={"body": "none", "sun_direction_target": tuple(sun),
                                                    "earth_direction_target": tuple(earth), "altitude_m": 400e3,
                                                    "earth_albedo": 0.3}, spp=4, roi_spp=4, spot_samples=16)
    R, t = np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 3.0])
    assert r._earth_in_view(R) and r._sun_in_view(R) and not r.options.eclipsed
    r._set_pose(R, t)
    ref = r._radiance(r._sun["full"], 64, 11, r._sun["scene"])  # the path tracer, full frame
    got = r._environment(R, t)
    L_sun = r._sun["light"]["radiance_w_m2_sr"]
    sun_px = ref > 0.5 * L_sun
    # the sun's disk: its power (the image's sum over the disk and its edge) and where it lies
    box = np.zeros_like(sun_px)
    ys, xs = np.nonzero(sun_px)
    box[ys.min() - 3:ys.max() + 4, xs.min() - 3:xs.max() + 4] = True
    assert got[box].sum() == pytest.approx(ref[box].sum(), rel=0.02)
    cy = lambda img: (np.where(box, img, 0) * np.arange(img.shape[0])[:, None]).sum() / np.where(box, img, 0).sum()
    cx = lambda img: (np.where(box, img, 0) * np.arange(img.shape[1])[None, :]).sum() / np.where(box, img, 0).sum()
    assert cx(got) == pytest.approx(cx(ref), abs=0.1) and cy(got) == pytest.approx(cy(ref), abs=0.1)
    # the Earth away from the sun: the lit disk's mean and its area (the limb) agree
    earth_ref, earth_got = np.where(box, 0, ref), np.where(box, 0, got)
    lit = earth_ref > 0
    assert lit.mean() > 0.05  # a crescent: the sun lights the Earth's far side (phase angle 100 deg)
    # (the path tracer reads the map's bilinear texels: 1.3 % above the sphere's exact pixel means here,
    # where the crescent's radiance bends fast near the limb; the shortcut is 0.3 % below them)
    assert earth_got[lit].mean() == pytest.approx(earth_ref[lit].mean(), rel=0.02)
    # the crescent's area between the limb and the terminator (the map's texels widen it by ~2 %)
    bright = 0.1 * earth_ref[lit].mean()
    assert (earth_got > bright).sum() == pytest.approx((earth_ref > bright).sum(), rel=0.03)
    # pixel by pixel inside the disk, away from the limb (within the texels' bilinear interpolation)
    inner = lit & (np.abs(np.diff(np.pad(lit.astype(int), 2), axis=1)[2:-2, 1:-2]) == 0)
    assert np.median(np.abs(earth_got[inner] / earth_ref[inner] - 1)) < 0.03
