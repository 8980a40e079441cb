"""Sunlight through the colour filter array: its own channel weights, against the optics' linearity
(an image of two lights equals the sum of each through a camera with that light's responses), the
flash-only path's bytes, and the weights' sensitivity to the filters' assumed edges."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from svgs_sim.base.profiles import load_camera
from svgs_sim.camera.phone import Exposer, PhoneCamera
from svgs_sim.camera.phone.cfa import light_weights
from svgs_sim.camera.phone.params import CfaParams

WEIGHTS = np.array([1.24, 0.71, 1.02])  # about the sun's against the flash (a fixed input here)


@pytest.fixture(scope="module")
def phone():
    return PhoneCamera(load_camera("galaxy-nexus"))


def _scene(shape):
    f = np.full(shape, 50.0, np.float32)
    f[800:1200, 1000:1600] += 2e5  # a sunlit body
    sun = np.zeros(shape, np.float32)
    sun[800:1200, 1000:1600] = 1.5e5
    return f, sun


def test_two_lights_sum_as_each_through_its_own_channel_responses(phone):
    """Linearity, glare and all: optics(flash + sun, sun's weights) = optics_flash(flash) +
    optics_sun(sun), the second through a camera whose channel responses are the flash's times the
    sun's weights."""
    f, sun = _scene(phone.shape)
    got = phone.optics(f, natural=(sun, WEIGHTS))
    p2 = dataclasses.replace(phone.params, cfa=dataclasses.replace(
        phone.params.cfa, response=tuple(np.asarray(phone.params.cfa.response) * WEIGHTS)))
    ref = phone.optics(f - sun) + PhoneCamera(phone.camera, params=p2).optics(sun)
    assert np.max(np.abs(got - ref)) <= 1e-6 * np.max(ref)


def test_the_flash_only_path_and_the_flashs_own_colour_keep_their_bytes(phone):
    f, sun = _scene(phone.shape)
    plain = Exposer(phone, f).flux_optics
    assert np.array_equal(Exposer(phone, f, natural=(sun, np.ones(3))).flux_optics, plain)
    assert np.array_equal(Exposer(phone, f, natural=(np.zeros_like(sun), WEIGHTS)).flux_optics, plain)
    # a mono sensor (no colour filters) takes no weights
    assert np.array_equal(Exposer(phone, f, natural=(sun, WEIGHTS), stages=("glare",)).flux_optics,
                          Exposer(phone, f, stages=("glare",)).flux_optics)


def test_without_the_lens_each_pixel_takes_its_channels_weight(phone):
    f, sun = _scene(phone.shape)
    got = Exposer(phone, f, natural=(sun, WEIGHTS), stages=("cfa",)).flux_optics
    from svgs_sim.camera.phone.cfa import channel_map

    chan = channel_map(phone.params.cfa.pattern, phone.shape)
    resp = np.asarray(phone.params.cfa.response)[chan]
    want = resp * ((f - sun) + WEIGHTS[chan] * sun)
    assert np.allclose(got, want, rtol=1e-6)


def test_a_light_of_the_flashs_spectrum_weighs_one_and_bad_input_is_refused(phone):
    from svgs_sim.base.errors import InputError

    wl = np.arange(400.0, 700.1, 1.0)
    n = np.exp(-0.5 * ((wl - 550.0) / 60.0) ** 2)
    assert light_weights(CfaParams(pattern="RGGB"), wl, 3.0 * n, n) == pytest.approx([1.0, 1.0, 1.0], abs=1e-12)
    # monochromatic red light: red up, blue down
    red = np.exp(-0.5 * ((wl - 650.0) / 5.0) ** 2)
    w = light_weights(CfaParams(pattern="RGGB"), wl, red, n)
    assert w[0] > 2.0 and w[2] < 0.01
    with pytest.raises(InputError, match="natural"):
        Exposer(phone, np.zeros(phone.shape, np.float32), natural=(np.zeros(phone.shape, np.float32), [1.0, 2.0]))


def test_the_suns_weights_move_under_3_percent_with_the_filters_edges():
    pytest.importorskip("pvlib", reason="the orbit extra")
    from svgs_sim.render.sun import photon_spectra

    spectra = photon_spectra((400.0, 700.0), "white-led")
    cfa = CfaParams(pattern="RGGB")
    nominal = light_weights(cfa, *spectra)
    for edge in (5.0, 15.0):
        assert light_weights(cfa, *spectra, edge_nm=edge) == pytest.approx(nominal, rel=0.03)
