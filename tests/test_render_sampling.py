"""The spp rule and the Dr.Jit exit (svgs_sim.render.sampling), and the shared rendered-frame type."""

import importlib.util

import numpy as np
import pytest

from svgs_sim.base.errors import InputError

needs_mitsuba = pytest.mark.skipif(importlib.util.find_spec("mitsuba") is None, reason="Mitsuba is not installed")


@needs_mitsuba
@pytest.mark.render
def test_spp_rule_is_what_ldsampler_renders():
    # the reference is Mitsuba's own ldsampler: check_spp must record the count it renders
    from svgs_sim.render.sampling import check_spp
    from svgs_sim.render.variant import select_variant

    select_variant()
    import mitsuba as mi

    for n in (1, 2, 3, 4, 5, 8, 15, 16, 17, 63, 64, 65, 200, 256):
        rendered = mi.load_dict({"type": "ldsampler", "sample_count": n}).sample_count()
        assert check_spp(n) == rendered, n


def test_spp_rule_values_and_errors():
    from svgs_sim.render.sampling import check_spp

    assert [check_spp(n) for n in (1, 4, 5, 16, 17)] == [4, 4, 16, 16, 64]
    assert check_spp(0, allow_zero=True) == 0
    # the ToF integrator: powers of two from 1
    assert [check_spp(n, base=2) for n in (1, 2, 3, 64, 65, 128)] == [1, 2, 4, 64, 128, 128]
    for bad in (0, -4, 2.5, "x", None):
        with pytest.raises(InputError, match="spp"):
            check_spp(bad)


def test_rendered_frames_share_one_type():
    from svgs_sim.camera.amcw import RenderedTof
    from svgs_sim.camera.rendered import RenderedFrame
    from svgs_sim.render.api import RenderResult

    ones = np.ones((3, 5))
    R, t = np.eye(3), np.array([0.1, 0.2, 3.0])
    truth = {"R_cam_target": R.tolist(), "t_cam_target_m": t.tolist()}
    svgs = RenderResult(flux=2.0 * ones, radiance=ones, truth=truth, timings_s={"roi_s": 0.1})
    tof = RenderedTof(ones, ones + 0j, ones, 7.0 * ones, ones, ones, 1e7, truth=truth)
    for r in (svgs, tof):
        assert isinstance(r, RenderedFrame)
        assert r.shape == (3, 5)
        Rr, tr = r.pose()
        assert np.array_equal(Rr, R) and np.array_equal(tr, t)
    assert np.all(tof.flux == 7.0)  # radiance x photons per radiance
    assert tof.timings_s == {}
