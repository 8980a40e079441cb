"""Physical bounds of the numbers a user gives - one table for every layer.

The command line (:func:`svgs_sim.cli.validate.check_args`, its ``BOUNDS``) and the study parameters
(:class:`svgs_sim.sim.trials.Parameter`, against which every scenario and a sensitivity study's
``--vary``/``--fixed`` are checked) take the same bounds for the same quantity: both read them
here, so an option and the parameter of the same name cannot drift apart. The lowest layer holds
them (like :mod:`svgs_sim.base.constants`) so that the CLI, the studies and the trial kinds can all import
them.

The bounds lie far beyond any phone, lab or ToF camera the simulator models; they keep absurd
numbers (1e308, a trillion samples per pixel) from overflowing the solver and the calibrations
or from starting a render that would never end. Ranges and attitudes are bounded by the
sensor's envelope instead (:func:`svgs_sim.svgs.envelope.range_envelope_m`,
:data:`svgs_sim.svgs.envelope.ATTITUDE_LIMITS_DEG`); :data:`RANGE_LIMIT_M` only caps it for any profile.
"""

from __future__ import annotations

from svgs_sim.base.errors import InputError

#: Largest range along the boresight any scenario takes, m. The envelope of the bundled phones
#: ends below 200 m (:func:`svgs_sim.svgs.envelope.range_envelope_m`: the 3U pattern then spans
#: ``MIN_SPAN_PX`` pixels); this leaves room for a profile with a 5x longer lens or a 5x wider
#: pattern. The camera's own envelope is checked on top of it wherever a camera is known.
RANGE_LIMIT_M = 1000.0

#: Largest lateral offset of the target origin from the boresight, m: far outside the field of
#: view at any range of the envelope.
LATERAL_LIMIT_M = 1000.0

#: Most samples per pixel of a render (``--spp``, ``--roi-spp``, the ``spp`` parameters): the
#: Monte Carlo error falls as 1/sqrt(spp), so at 2**24 samples it is 2.4e-4 of a pixel's
#: radiance, far below any sensor's shot noise; a full frame at that many samples takes
#: thousands of hours (:data:`svgs_sim.cli.render.RENDER_SAMPLES_PER_S`), so more is never meant.
MAX_SPP = 2**24

#: Largest seed (``--seed``, the ``render_seed`` parameter, a study seed): the renderers' samplers
#: take 32-bit seeds, and a results store holds a seed in a float64 column (exact below 2**53).
MAX_SEED = 2**32 - 1

#: Physical bounds of the numeric inputs by quantity (the CLI's argument names): name ->
#: ``(low, high, unit)``, inclusive (the CLI reads a low of 0 as exclusive for its positive
#: quantities, ``svgs_sim.cli.validate.POSITIVE``).
INPUT_BOUNDS = {
    "sigma_px": (0.0, 100.0, "px"), "consistency_sigma_px": (1e-3, 100.0, "px"),
    "centroid_sigma_px": (1e-3, 100.0, "px"), "range_sigma_m": (0.0, 10.0, "m"),
    "target_x_m": (-LATERAL_LIMIT_M, LATERAL_LIMIT_M, "m"), "target_y_m": (-LATERAL_LIMIT_M, LATERAL_LIMIT_M, "m"),
    "focus_m": (0.0, 10000.0, "m"), "backdrop_m": (0.0, 1000.0, "m"),
    "ambient": (0.0, 10000.0, "W m^-2 sr^-1"), "exposure_s": (0.0, 60.0, "s"), "iso": (1.0, 1e6, ""),
    "stage_m": (-1.0, 1.0, "m"), "jitter_deg": (0.0, 90.0, "deg"), "jitter_m": (0.0, 10.0, "m"),
    "spacing_mm": (0.0, 1000.0, "mm"), "marker_mm": (0.0, 1000.0, "mm"), "aspect_ratio": (0.1, 10.0, ""),
    "principal_point": (-1e5, 1e5, "px"), "exposure_fill": (0.0, 1.0, "of full well"),
    "true_pp_offset_px": (-1000.0, 1000.0, "px"), "ambient_lux": (0.0, 2e5, "lux"),
    "integration_time_s": (0.0, 1.0, "s"), "modulation_frequency_hz": (0.0, 1e9, "Hz"),
    "focal_error_frac": (-0.5, 0.5, ""), "k1_error": (-1.0, 1.0, ""), "merge_px": (0.0, 1000.0, "px"),
    "duration_s": (0.0, 1e6, "s"), "fps": (0.0, 1000.0, "Hz"), "attitude_deg": (0.0, 45.0, "deg"),
}

#: Whole-number inputs with an upper bound (the CLI's argument names): name -> ``(low, high,
#: unit)``, inclusive.
#: The most features per row or column of a calibration board (a printed board has tens).
MAX_BOARD_FEATURES = 200
#: The longest side of a rendered image, px.
MAX_IMAGE_SIDE_PX = 16384
INT_BOUNDS = {
    "spp": (1, MAX_SPP, "samples per pixel"), "roi_spp": (1, MAX_SPP, "samples per pixel"),
    "seed": (0, MAX_SEED, ""),
    # a calibration board's features per row and column: OpenCV's detectors and a printed board
    # (a 100000 x 100000 board asked for 149 GiB before anything was checked)
    "cols": (1, MAX_BOARD_FEATURES, "features"), "rows": (1, MAX_BOARD_FEATURES, "features"),
    # a rendered image's size, px: beyond the largest phone sensor (200 MP, 16384 px a side)
    "width": (16, MAX_IMAGE_SIDE_PX, "px"), "height": (16, MAX_IMAGE_SIDE_PX, "px"),
}


def bounds(name: str) -> dict:
    """``{"lower": low, "upper": high}`` of the quantity ``name`` of :data:`INPUT_BOUNDS` (the
    keyword arguments of :class:`svgs_sim.sim.trials.Parameter`)."""
    low, high, _ = INPUT_BOUNDS[name]
    return {"lower": low, "upper": high}


def check_focus_beyond_focal_length(focus_distance_m: float, focal_length_m: float, name: str) -> None:
    """:class:`InputError` naming ``name`` unless the lens is focused beyond its focal length: a
    thin lens focused at ``s <= f`` forms no real image (1/v = 1/f - 1/s <= 0), so nothing could be
    rendered in focus (it rendered for seconds and then found no blob)."""
    if not float(focus_distance_m) > float(focal_length_m):
        raise InputError(f"{name}: {focus_distance_m:g} m is not beyond the lens's focal length "
                         f"({focal_length_m:g} m): a thin lens focused there forms no real image")
