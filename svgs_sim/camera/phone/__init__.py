"""The phone camera model: photon flux -> the image a phone would deliver.

Flux (photons/s/px, from :mod:`render`; the retro spots as sub-pixel point samples) -> lens
PSF (Airy + aberration core, glare wings, ghosts; :mod:`svgs_sim.camera.phone.optics`), integrated over
each pixel -> Bayer mosaic (:mod:`svgs_sim.camera.phone.cfa`) -> exposure (auto or manual) -> sensor
in electrons (shot, dark, DSNU/PRNU, blooming) -> readout (read noise, gain, black level,
ADC) = **raw** (DN) -> ISP (white balance, demosaic, noise reduction, tone curve, sharpening,
8 bits, downscale, JPEG; :mod:`svgs_sim.camera.phone.isp`) = **image** (uint8, the luminance the app
thresholds). No Mitsuba here: it runs on any flux image.

Render once, expose many: :class:`Exposer` holds one noise-free flux, applies the optics and
meters the scene once, and then makes as many exposures (noise draws, exposure or gain
changes) as asked, each from its own seed.

Stages (``stages=``): ``glare`` (optics PSF; off: a perfect lens), ``cfa`` (the profile's
colour filter array; off, or ``[cfa] pattern = "none"``: mono), ``shot``, ``dark``, ``fpn``
(DSNU and PRNU), ``read``, ``bloom`` (off: plain full-well clipping), ``adc`` (quantise and
clip; off: float DN), ``nr`` (the ISP's noise reduction, ``[isp] nr_sigma_px`` > 0), ``tone``
(off: linear), ``sharpen`` (unsharp mask, ``[isp] sharpen_amount`` > 0), ``u8`` (the delivered
image in 8 bits; off: a float32 image on the same 0-255 scale, and no JPEG), ``downscale``,
``chroma`` (a colour JPEG's chroma subsampled as ``[isp] jpeg_subsampling``; off: 4:4:4),
``jpeg``. The optics stages (``glare``, ``cfa``) are fixed per :class:`Exposer`; the others
may change per exposure (:meth:`Exposer.expose`'s ``stages``), and so may the ISP's
parameters and the demosaic (its ``isp`` and ``demosaic``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import Camera, load_camera
from svgs_sim.camera.backend import get_backend
from svgs_sim.camera.phone.cfa import (channel_map, linear_bgr, luminance, natural_response_map, response_map, tone_bgr,
                                      tone_image)
from svgs_sim.camera.phone.isp import (
    ExposureSolver,
    auto_exposure,
    downscale,
    jpeg_roundtrip,
    luma,
    noise_reduction,
    tone_lut,
    unsharp_mask,
)
from svgs_sim.camera.phone.optics import (
    POINT_METHODS,
    apply_psf,
    compose,
    core_image,
    core_psf,
    core_share,
    glare_image,
    wings_coarse,
)
from svgs_sim.camera.phone.params import (
    ALL_STAGES,
    NOISE_STAGES,
    OPTICS_STAGES,
    IspParams,
    PhoneParams,
    check_demosaic,
    check_stages,
)
from svgs_sim.camera.phone.psf import PIXEL_KERNEL_RADIUS_PX, splat_patches, support_box
from svgs_sim.camera.phone.sensor import (DARK_TABLE_MAX_E, bloom, dark_charge_limit, electrons, electrons_dark,
                                         fixed_patterns, readout, tile_max)
from svgs_sim.camera.rendered import PointFlux
from svgs_sim.camera.tonemap import gamma_u8

__all__ = ["PhoneCamera", "Exposer", "Exposure", "DeferredExposure", "PhoneParams", "ALL_STAGES", "NOISE_STAGES", "OPTICS_STAGES",
           "DARK_PIXELS"]

#: How an exposure makes its dark pixels (:meth:`Exposer.expose`): ``exact`` (default), every
#: pixel by the exact path's inversion; ``fast``, the pixels that cannot reach the detection
#: threshold by a table sampler of the same Poisson law (other variates); ``deferred``, only the
#: tiles that can reach it (and the ISP's reach around them) are exposed now, to the exact path's
#: bytes, and the full frame, the exact path's, when the image is read (:class:`DeferredExposure`).
DARK_PIXELS = ("exact", "fast", "deferred")
#: The JPEG's minimum coded unit, px (16 x 16 at 4:2:0; the block grid's period for a crop).
JPEG_MCU_PX = 16
#: A deferred exposure's crops reach this far beyond the tiles they deliver, px: the ISP's
#: reach (:data:`DARK_ISP_REACH_PX`: the demosaic, the JPEG's block and chroma upsampling) rounded
#: up to whole tiles, so the delivered pixels do not see the crop's edge.
DEFERRED_MARGIN_TILES = 2
#: Side of the dark pixels' tiles, px (the 16-px JPEG MCU, a multiple of the 2-px mosaic).
DARK_TILE_PX = 16
#: The tiles within this distance of a point sample of the targets' spots are exact, px (and
#: their neighbours, :data:`DARK_ISP_REACH_PX`).
DARK_WINDOW_PX = 16
#: How far the ISP carries a pixel's value, px of the delivered image: the demosaic's 1 px, a
#: JPEG block's 15 px and the chroma upsampling's 2 px. The tiles this close to a tile that can
#: reach the threshold are exact too (scaled by a downscale's factor).
DARK_ISP_REACH_PX = 18
#: The chance allowed to one dark pixel of reaching the detection threshold: 1e-13, i.e. below
#: 1e-6 over a 5-Mpx frame.
DARK_TAIL_P = 1e-13
#: What the ISP after the pixels may add to a dark region's 8-bit level (the JPEG's quantisation
#: error on a dark, smooth block), 8-bit counts: the dark pixels stay this far below the threshold.
DARK_JPEG_MARGIN_U8 = 8.0
#: Above this fraction of the frame's pixels in tiles that can reach the threshold (a sunlit body
#: or the Earth behind the target) the exposure takes the exact path.
DARK_FALLBACK_FRACTION = 0.25


@dataclass
class Exposure:
    """One exposure of the phone camera.

    Attributes
    ----------
    raw_dn : ndarray, float32, shape (H, W)
        ADC output before the ISP (integers when the ``adc`` stage is on), full resolution.
    image : ndarray, uint8, shape (h, w)
        What the phone delivered (after tone curve, downscale, JPEG).
    exposure_s, iso : float
    gain_dn_per_e : float
        System gain K.
    info : dict
        Auto-exposure result, blooming statistics, stages, seed.
    electrons : ndarray, float32, shape (H, W), optional
        Charge after blooming, before read noise (kept with ``keep_electrons=True``).
    """

    raw_dn: np.ndarray
    image: np.ndarray
    exposure_s: float
    iso: float
    gain_dn_per_e: float
    info: dict = field(default_factory=dict)
    electrons: np.ndarray | None = None

    @property
    def detect_image(self) -> np.ndarray:
        """The image a detector with a numeric threshold reads: :attr:`image`."""
        return self.image


class DeferredExposure(Exposure):
    """An exposure whose dark pixels are made only when asked for (``dark_pixels="deferred"``,
    :meth:`Exposer.expose`).

    :attr:`detect_image` holds, now, the exact path's delivered bytes over the tiles that can
    reach the detection threshold (and the ISP's reach around them), and 0 elsewhere: the same
    blobs as the full image unless a dark pixel reaches the threshold (a chance below
    :data:`DARK_TAIL_P` a pixel). :attr:`image`, :attr:`raw_dn` and :attr:`electrons` are the
    exact path's exposure with the same seed, made on first read (bit for bit).

    Attributes
    ----------
    detect_image : ndarray, uint8, shape (h, w)
    exposure_s, iso, gain_dn_per_e, info
        As :class:`Exposure`; ``info["dark_pixels"]`` says what was deferred.
    """

    def __init__(self, full, detect_image: np.ndarray, exposure_s: float, iso: float, gain_dn_per_e: float,
                 info: dict, keep_electrons: bool):
        self._full_fn = full
        self._full = None
        self._detect = detect_image
        self._keep_electrons = bool(keep_electrons)
        self.exposure_s = exposure_s
        self.iso = iso
        self.gain_dn_per_e = gain_dn_per_e
        self.info = info

    def full(self) -> Exposure:
        """The exact path's exposure (made on the first call, then kept)."""
        if self._full is None:
            self._full = self._full_fn()
            self._full_fn = None
        return self._full

    @property
    def detect_image(self) -> np.ndarray:
        return self._detect

    @property
    def image(self) -> np.ndarray:
        return self.full().image

    @property
    def raw_dn(self) -> np.ndarray:
        return self.full().raw_dn

    @property
    def electrons(self) -> np.ndarray | None:
        return self.full().electrons if self._keep_electrons else None


#: Optical images of backgrounds that stay from frame to frame (:meth:`PhoneCamera.optics`),
#: by unit array and phone model; a few entries at most.
_BACKGROUND_CACHE: dict = {}


class PhoneCamera:
    """A camera profile's sensor, optics and ISP.

    Parameters
    ----------
    camera : svgs.Camera or str
    params : PhoneParams, optional
        Defaults to the profile's ``[sensor]``, ``[glare]``, ``[exposure]``, ``[isp]`` tables.
    point_method : str
        ``"grid"`` (default): the points are convolved with the PSF deterministically;
        ``"monte-carlo"``: by PSF draws (the earlier path, the reference of the tests).
    backend : str or svgs_sim.camera.backend.Backend, optional
        Array backend of the optics' convolutions (:data:`svgs_sim.camera.backend.BACKENDS`; default
        ``$SVGS_ARRAY_BACKEND``, else the CPU).
    """

    def __init__(self, camera, params: PhoneParams | None = None, *, point_method: str = "grid", backend=None):


        self.camera = load_camera(camera)
        self.params = params if params is not None else PhoneParams.from_camera(self.camera)
        if point_method not in POINT_METHODS:
            raise InputError(f"point_method: expected one of {POINT_METHODS}, got {point_method!r}")
        #: How the point samples meet the lens PSF (:data:`svgs_sim.camera.phone.optics.POINT_METHODS`).
        self.point_method = point_method
        try:
            #: The array backend of the optics (:class:`svgs_sim.camera.backend.Backend`).
            self.backend = get_backend(backend)
        except ValueError as exc:
            raise InputError(str(exc)) from None
        self._fpn = None
        self._pattern_bounds = None

    @property
    def shape(self):
        return (self.camera.height, self.camera.width)

    def fixed_patterns(self):
        if self._fpn is None:
            self._fpn = fixed_patterns(self.params.sensor, self.shape)
        return self._fpn

    def pattern_bounds(self) -> tuple[float, float]:
        """The fixed patterns' extremes (kept): the largest PRNU gain and the largest DSNU
        magnitude (e-), for the dark pixels' bound (:meth:`Exposer.dark_tiles`)."""
        if self._pattern_bounds is None:
            prnu, dsnu = self.fixed_patterns()
            self._pattern_bounds = (float(prnu.max()), float(np.abs(dsnu).max()))
        return self._pattern_bounds

    def core_psf(self):
        """The lens' core PSF (:class:`svgs_sim.camera.phone.psf.CorePSF`): Airy (x) aberration."""
        p = self.params
        return core_psf(p.f_number, p.band_nm, p.sensor.pixel_pitch_m, p.glare.aberration_sigma_px)

    def optics(self, flux_ph_s: np.ndarray, points=None, *, seed: int = 0, cfa: bool | None = None,
               background=None, natural=None) -> np.ndarray:
        """The optical image: the lens PSF applied to a flux image (photons/s/px, already
        integrated over pixels) and to point samples at sub-pixel positions
        (:class:`svgs_sim.camera.rendered.PointFlux`), integrated over pixels. ``seed`` seeds the
        Monte Carlo convolution of the points.

        With the colour filter array (``cfa``: default, the profile's ``[cfa]``), each pixel
        gets its channel's image (Airy pattern at the channel's wavelength) times its
        channel's response: the mosaic the pixels see. Returns float32 (H, W).

        ``background = (scale, unit)``: light ``scale * unit`` (photons/s/px, ``unit`` an
        (H, W) array that stays the same from frame to frame, e.g. the lab's light per unit
        radiance) added to ``flux_ph_s``. The optics are linear: the optical image of ``unit``
        is made once and kept (for that very array), then scaled.

        ``natural = (flux, weights)``: the part of ``flux_ph_s`` that is light of another colour
        than the flash (the sun's and the Earth's; float32 (H, W)) and its channel weights
        (shape (3,), :func:`svgs_sim.camera.phone.cfa.light_weights`): through the colour filter
        array, each pixel of colour ``c`` takes that part times ``weights[c]``. Without the
        array (a mono sensor) it changes nothing."""
        p = self.params
        pp = (self.camera.cx, self.camera.cy)
        use_cfa = p.cfa.enabled if cfa is None else (bool(cfa) and p.cfa.enabled)
        bg = None
        if background is not None:
            scale, unit = background
            scale = float(scale)
            if scale != 0.0:
                bg = self._background_optics(unit, use_cfa)
        if not use_cfa:
            out = apply_psf(flux_ph_s, p.glare, self.core_psf(), pp, points=points, rng=np.random.default_rng(seed),
                            method=self.point_method, backend=self.backend)
            if bg is not None:
                out += (scale * bg).astype(np.float32)
            return out
        nat = _natural_excess(natural)
        out = self.core_mosaic(flux_ph_s, points, seed=seed, natural=nat)
        resp_nat = None if nat is None else natural_response_map(p.cfa, nat[1], self.shape)
        if not p.glare.ghosts:  # core, wings, background and response in one pass
            eta = p.glare.veiling_fraction
            wc, s = (wings_coarse(flux_ph_s, p.glare, points, self.backend) if eta > 0 else (np.zeros((1, 1)), 1))
            extra = None
            if nat is not None and eta > 0:  # the wings of the natural light's extra colour
                extra = (wings_coarse(nat[0], p.glare, None, self.backend)[0], resp_nat)
            return compose(out, core_share(p.glare), wc, s, max(eta, 0.0), response_map(p.cfa, self.shape),
                           None if bg is None else (scale, bg), extra=extra)
        out *= core_share(p.glare)
        g = glare_image(flux_ph_s, p.glare, pp, points, self.backend)
        if g is not None:
            out += g
        if bg is not None:
            out += scale * bg
        out *= response_map(p.cfa, self.shape)
        if nat is not None:
            g = glare_image(nat[0], p.glare, pp, None, self.backend)
            if g is not None:
                out += g * resp_nat
        return out.astype(np.float32)

    def _background_optics(self, unit, use_cfa: bool) -> np.ndarray:
        """The optical image of a background that stays (before the CFA's responses), kept per
        array and phone model (shared by the phones of isolated frames: the lab's factor is one
        array per camera): float64 (H, W), read-only."""
        cache = _BACKGROUND_CACHE
        key = (id(unit), bool(use_cfa), self.params, self.camera.cx, self.camera.cy, self.backend.name,
               self.point_method)
        hit = cache.get(key)
        if hit is None or hit[0] is not unit:
            u = np.ascontiguousarray(unit, np.float32)  # checked by the caller (check_background)
            p = self.params
            pp = (self.camera.cx, self.camera.cy)
            if use_cfa:
                img = self.core_mosaic(u)
                img *= core_share(p.glare)
                g = glare_image(u, p.glare, pp, backend=self.backend)
                if g is not None:
                    img += g
            else:
                img = apply_psf(u, p.glare, self.core_psf(), pp, backend=self.backend).astype(np.float64)
            img.setflags(write=False)
            if len(cache) >= 4:
                cache.clear()
            hit = (unit, img)
            cache[key] = hit
        return hit[1]

    def core_mosaic(self, flux_ph_s: np.ndarray, points=None, *, seed: int = 0, origin=(0, 0),
                    min_draws: int | None = None, gradient: bool = False, value: bool = True, natural=None):
        """The lens' core PSF through the colour filter array: each pixel gets its channel's
        image (the Airy pattern at the channel's wavelength (x) the aberration Gaussian) of the
        flux and the points, unit share, before the channel responses (float64, the flux's shape).

        ``origin``: the frame pixel ``(x0, y0)`` of the flux's top-left pixel, when it is a
        window of the frame (the mosaic's phase); ``min_draws``: the points' PSF draws per
        channel (:func:`svgs_sim.camera.phone.optics.core_image`). ``seed`` seeds the three channels'
        Monte Carlo convolutions (``point_method="monte-carlo"``). ``gradient``: the points only
        (the flux must be zero), with the grid method: a tuple ``(image, d_du, d_dv)``, the
        derivatives with respect to a common shift of the points (for the Cramer-Rao bound);
        with ``value=False`` as well, only ``(d_du, d_dv)``. ``natural = (flux, excess)``: channel
        ``c``'s image is of ``flux_ph_s + excess[c] * flux`` (light of another colour,
        :meth:`optics`)."""
        p = self.params
        H, W = np.shape(flux_ph_s)
        x0, y0 = int(origin[0]) % 2, int(origin[1]) % 2
        chan = channel_map(p.cfa.pattern, (H + 2, W + 2))[y0:y0 + H, x0:x0 + W]  # the mosaic repeats every 2 px
        cores = [core_psf(p.f_number, p.band_nm, p.sensor.pixel_pitch_m, p.glare.aberration_sigma_px,
                          wavelength_nm=p.cfa.wavelength_nm[c]) for c in range(3)]
        has_points = points is not None and len(points) > 0
        if self.point_method == "monte-carlo" and not gradient:
            out = np.zeros((H, W))
            seeds = np.random.SeedSequence(int(seed)).spawn(3)
            for c, core in enumerate(cores):
                fc = flux_ph_s if natural is None else flux_ph_s + np.float32(natural[1][c]) * natural[0]
                img = core_image(fc, core, points, np.random.default_rng(seeds[c]), min_draws=min_draws,
                                 method="monte-carlo", backend=self.backend)
                np.copyto(out, img, where=chan == c)
            return out
        if gradient and np.any(flux_ph_s):
            raise ValueError("core_mosaic: gradient=True takes the points only (the flux must be zero)")
        n_out = (3 if value else 2) if gradient else 1
        outs = [np.zeros((H, W)) for _ in range(n_out)]
        f = np.ascontiguousarray(flux_ph_s, np.float32)
        box = None if gradient else support_box(f, PIXEL_KERNEL_RADIUS_PX)
        if box is not None:  # the pixel images: over their support only
            y0, y1, x0, x1 = box
            sub, sel = outs[0][y0:y1, x0:x1], chan[y0:y1, x0:x1]
            win = np.ascontiguousarray(f[y0:y1, x0:x1])
            for c, core in enumerate(cores):
                wc = win if natural is None else win + np.float32(natural[1][c]) * natural[0][y0:y1, x0:x1]
                np.copyto(sub, core.convolve(wc, backend=self.backend), where=sel == c)
        if has_points:
            # each spot's three channel images at once, each pixel taking its channel's
            for ys, xs, patches in splat_patches(cores, points.u_px, points.v_px, points.rate_ph_s, (H, W),
                                                 gradient=gradient, value=value or not gradient):
                h, w = patches[0][0].shape
                sel = chan[ys:ys + h, xs:xs + w]
                for k, out in enumerate(outs):
                    out[ys:ys + h, xs:xs + w] += np.choose(sel, [patches[c][k] for c in range(3)])
        return tuple(outs) if gradient else outs[0]

    def uses_cfa(self, stages) -> bool:
        """Whether exposures with these stages go through the colour filter array."""
        return self.params.cfa.enabled and "cfa" in stages

    def check_points(self, points):
        """Validate point samples (None passes)."""
        if points is None:
            return None

        if not isinstance(points, PointFlux):
            raise InputError(f"points: expected a svgs_sim.camera.rendered.PointFlux, got {type(points).__name__}")
        if len(points) and not (np.all(np.isfinite(points.u_px)) and np.all(np.isfinite(points.v_px))
                                and np.all(np.isfinite(points.rate_ph_s)) and points.rate_ph_s.min() >= 0):
            raise InputError("points: expected finite positions and finite, non-negative photons per second")
        return points

    def check_background(self, background):
        """Validate ``(scale, unit)`` of a background (None passes); the unit image is checked
        once per array."""
        if background is None:
            return None
        try:
            scale, unit = background
            scale = float(scale)
        except (TypeError, ValueError):
            raise InputError("background: expected (scale, unit image)") from None
        if not np.isfinite(scale) or scale < 0:
            raise InputError(f"background: expected a finite, non-negative scale, got {scale!r}")
        checked = self.__dict__.setdefault("_checked_backgrounds", {})
        if checked.get(id(unit)) is not unit:
            self.check_flux(unit)
            if len(checked) >= 4:
                checked.clear()
            checked[id(unit)] = unit
        return scale, unit

    def check_natural(self, natural):
        """Validate ``(flux, weights)`` of light of another colour (None passes; :meth:`optics`)."""
        if natural is None:
            return None
        try:
            flux, weights = natural
            weights = np.asarray(weights, np.float64)
        except (TypeError, ValueError):
            raise InputError("natural: expected (flux image, channel weights)") from None
        if weights.shape != (3,) or not np.all(np.isfinite(weights)) or weights.min() < 0:
            raise InputError(f"natural: expected three finite, non-negative channel weights, got {weights!r}")
        return self.check_flux(flux), weights

    def check_flux(self, flux_ph_s) -> np.ndarray:
        f = np.asarray(flux_ph_s)
        if f.shape != self.shape:
            raise InputError(f"flux: shape {f.shape} does not match camera {self.camera.name!r} {self.shape}")
        if not np.issubdtype(f.dtype, np.number) or not np.all(np.isfinite(f)) or f.min() < 0:
            raise InputError("flux: expected finite, non-negative photons per second per pixel")
        return f.astype(np.float32, copy=False)

    def exposer(self, flux_ph_s, *, points=None, stages=ALL_STAGES, optics_seed: int = 0,
                background=None, natural=None) -> "Exposer":
        return Exposer(self, flux_ph_s, points=points, stages=stages, optics_seed=optics_seed, background=background,
                       natural=natural)

    def expose(self, flux_ph_s, *, points=None, seed: int = 0, exposure_s=None, iso=None, stages=ALL_STAGES,
               keep_electrons=False):
        """One exposure of a flux image (convenience for ``exposer(flux).expose(...)``)."""
        return self.exposer(flux_ph_s, points=points, stages=stages, optics_seed=seed).expose(
            seed=seed, exposure_s=exposure_s, iso=iso, keep_electrons=keep_electrons)


def _natural_excess(natural):
    """``(flux, weights - 1)`` of light of another colour, or None when there is none or its
    weights are the flash's (the flash-only path keeps its bytes)."""
    if natural is None:
        return None
    flux, weights = natural
    excess = np.asarray(weights, np.float64) - 1.0
    if not np.any(excess) or not np.any(flux):
        return None
    return np.ascontiguousarray(flux, np.float32), excess


def lit_crops(lit: np.ndarray, margin_tiles: int) -> list:
    """The crops of a deferred exposure, in tiles: the lit tiles grouped so that crops reaching
    ``margin_tiles`` beyond them do not overlap.

    Parameters
    ----------
    lit : ndarray, bool, shape (th, tw)
        The tiles to deliver.
    margin_tiles : int

    Returns
    -------
    list of ((r0, r1, c0, c1), (i0, i1, j0, j1))
        Per crop, its tile box (half-open, clipped to the grid) and the box of its lit tiles.
    """
    from scipy import ndimage

    if not lit.any():
        return []
    k = 2 * int(margin_tiles) + 1
    grown = ndimage.binary_dilation(lit, np.ones((k, k), bool))
    labels, _ = ndimage.label(grown, np.ones((3, 3), bool))
    out = []
    for lab, sl in enumerate(ndimage.find_objects(labels), start=1):
        rows, cols = np.nonzero(lit[sl] & (labels[sl] == lab))
        if rows.size == 0:
            continue
        inner = (sl[0].start + rows.min(), sl[0].start + rows.max() + 1, sl[1].start + cols.min(),
                 sl[1].start + cols.max() + 1)
        out.append(((sl[0].start, sl[0].stop, sl[1].start, sl[1].stop), inner))
    return out


class Exposer:
    """Render once, expose many: optics and metering done once for a flux image.

    Parameters
    ----------
    phone : PhoneCamera
    flux_ph_s : ndarray, shape (H, W)
        Noise-free photon flux, photons per second per pixel (before the lens PSF), of the
        light already integrated over pixels (the diffuse part of a render).
    points : svgs_sim.camera.rendered.PointFlux, optional
        Light at exact sub-pixel film positions (a render's retro spots), not in ``flux_ph_s``.
    stages : sequence of str
        Pipeline stages that are on (see the module docstring).
    optics_seed : int
        Seed of the Monte Carlo convolution of the points with the PSF.
    background : (float, ndarray (H, W)), optional
        ``(scale, unit)``: light ``scale * unit`` photons/s/px added to ``flux_ph_s``, whose
        optical image the phone keeps for that ``unit`` array (:meth:`PhoneCamera.optics`).
    """

    def __init__(self, phone: PhoneCamera, flux_ph_s, *, points=None, stages=ALL_STAGES, optics_seed: int = 0,
                 background=None, natural=None):
        self.phone = phone
        self.stages = check_stages(stages)
        f = phone.check_flux(flux_ph_s)
        pts = phone.check_points(points)
        bg = phone.check_background(background)
        nat = phone.check_natural(natural)
        self.cfa = phone.uses_cfa(self.stages)
        #: The point samples of the targets' spots (their tiles keep the exact path, :meth:`expose`).
        self.points = pts
        self._flux_tiles = None
        self._windows = None
        if "glare" in self.stages:
            self.flux_optics = phone.optics(f, pts, seed=optics_seed, cfa=self.cfa, background=bg, natural=nat)
        else:  # a perfect lens: each point counts in its own pixel
            self.flux_optics = f.copy() if pts is None else (f + pts.binned(f.shape)).astype(np.float32)
            if bg is not None:
                self.flux_optics += np.float32(bg[0]) * bg[1]
            if self.cfa:
                self.flux_optics *= response_map(phone.params.cfa, f.shape)
                ex = _natural_excess(nat)
                if ex is not None:
                    self.flux_optics += ex[0] * natural_response_map(phone.params.cfa, ex[1], f.shape)
        self._solver = None
        p = phone.params
        self._lut = tone_lut(p.sensor, p.isp.gamma, "tone" in self.stages)

    def auto_exposure(self):
        """(exposure_s, iso, info) chosen by the phone's auto-exposure for this scene."""
        p = self.phone.params
        if self._solver is None:
            self._solver = ExposureSolver.from_flux(self.flux_optics, p.sensor, p.exposure.metering)
        return auto_exposure(self.flux_optics, p.sensor, p.exposure, self._solver)

    @property
    def meter(self) -> ExposureSolver:
        """The phone's meter on this scene (:class:`svgs_sim.camera.phone.isp.ExposureSolver`): the metered
        level against the exposure product, from the noise-free signal."""
        if self._solver is None:
            self.auto_exposure()
        return self._solver

    def metered_level(self, exposure_s: float, iso: float) -> float:
        """What the phone's meter reads on this scene at given settings: the weighted linear
        level (0..1, full-well clipping included) of the noise-free signal."""
        return self.meter.level(float(exposure_s) * float(iso) / self.phone.params.sensor.base_iso)

    def settings(self, exposure_s=None, iso=None):
        """Resolve the exposure: explicit values, the profile's manual values, or auto-exposure."""
        p = self.phone.params
        info = {}
        if exposure_s is None and iso is None and p.exposure.mode == "auto":
            exposure_s, iso, info = self.auto_exposure()
            info["mode"] = "auto"
        else:
            exposure_s = p.exposure.exposure_s if exposure_s is None else exposure_s
            iso = p.exposure.iso if iso is None else iso
            info["mode"] = "manual"
        for name, v in (("exposure_s", exposure_s), ("iso", iso)):
            try:
                fv = float(v)
            except (TypeError, ValueError):
                raise InputError(f"{name}: expected a number, got {v!r}") from None
            if not np.isfinite(fv) or fv <= 0:
                raise InputError(f"{name}: impossible exposure setting {v!r} (must be a positive finite number)")
        if float(exposure_s) > 60.0:
            raise InputError(f"exposure_s: impossible exposure of {exposure_s} s for a phone camera (> 60 s)")
        return float(exposure_s), float(iso), info

    def expose(self, *, seed: int = 0, exposure_s=None, iso=None, keep_electrons=False, stages=None, isp=None,
               demosaic=None, dark_pixels: str = "exact", threshold_u8: float | None = None) -> Exposure:
        """One exposure with its own noise draw.

        Parameters
        ----------
        seed : int
            Seeds shot, dark and read noise (fixed patterns come from the camera's serial).
        exposure_s, iso : float, optional
            Override the profile's exposure (manual or auto).
        keep_electrons : bool
            Keep the charge image (after blooming) in the result.
        stages : sequence of str, optional
            The stages of this exposure (default the exposer's); the optics stages
            (``glare``, ``cfa``) must be the exposer's, since its optical image is made.
        isp : svgs_sim.camera.phone.params.IspParams, optional
            The ISP of this exposure (JPEG quality, chroma sampling and block grid, noise
            reduction, sharpening, tone, downscale) instead of the profile's ``[isp]``.
        demosaic : str, optional
            The demosaic of this exposure (:data:`svgs_sim.camera.phone.params.DEMOSAIC_METHODS`) instead
            of the profile's ``[cfa] demosaic``.
        dark_pixels : {"exact", "fast", "deferred"}
            ``fast``: the pixels that cannot reach ``threshold_u8`` draw their shot noise from a
            cheaper sampler of the same law (:meth:`_electrons`); not the same bytes as ``exact``.
            ``deferred``: only the tiles that can reach it are exposed now (a
            :class:`DeferredExposure`: the exact path's bytes there, the full frame on reading
            its image; :meth:`_deferred`).
        threshold_u8 : float, optional
            The detector's threshold on the delivered 8-bit image (``fast`` only; without it,
            the exact path).

        Returns
        -------
        Exposure
        """
        p = self.phone.params
        sp = p.sensor
        st = self.stages
        if stages is not None:
            st = check_stages(stages)
            if tuple(s for s in OPTICS_STAGES if s in st) != tuple(s for s in OPTICS_STAGES if s in self.stages):
                raise InputError(f"stages: the optics stages ({', '.join(OPTICS_STAGES)}) are fixed by the exposer "
                                 f"({', '.join(s for s in OPTICS_STAGES if s in self.stages) or 'none'})")
        if isp is None:
            isp = p.isp
        elif not isinstance(isp, IspParams):
            raise InputError(f"isp: expected a svgs_sim.camera.phone.params.IspParams, got {type(isp).__name__}")
        method = p.cfa.demosaic if demosaic is None else check_demosaic(demosaic)
        t, iso, info = self.settings(exposure_s, iso)
        if dark_pixels == "deferred":
            ex = self._deferred(seed, t, iso, st, isp, method, threshold_u8, info, keep_electrons)
            if ex is not None:
                return ex
        e = self._electrons(t, iso, seed, st, isp, method, dark_pixels, threshold_u8, info)
        raw, img = self._develop(e, seed, iso, st, isp, method, info)
        info.update({"seed": int(seed), "stages": list(st), "demosaic": method if self.cfa else None})
        return Exposure(raw, img, t, iso, sp.gain_dn_per_e(iso), info, e if keep_electrons else None)

    def _develop(self, e, seed: int, iso: float, st, isp, method: str, info: dict, origin=(0, 0),
                 full_width: int | None = None):
        """The charge ``e`` (e-, float32 (H, W), modified in place) through blooming, the readout
        and the ISP: ``(raw_dn, image)``. ``origin`` and ``full_width`` place a crop in the frame
        (:func:`svgs_sim.camera.phone.sensor.readout`); ``info["bloom"]`` gets the blooming's statistics."""
        p = self.phone.params
        sp = p.sensor
        if "bloom" in st:
            info["bloom"] = bloom(e, sp.full_well_e, sp.anti_blooming_drain, sp.bloom_direction)
        else:
            np.minimum(e, sp.full_well_e, out=e)
        g = isp.gamma if "tone" in st else 0.0
        same_lut = isp.gamma == p.isp.gamma and ("tone" in st) == ("tone" in self.stages)
        lut = self._lut if same_lut else tone_lut(sp, isp.gamma, "tone" in st)
        nr = "nr" in st and isp.nr_sigma_px > 0
        sharpen = "sharpen" in st and isp.sharpen_amount > 0
        colour = self.cfa and isp.jpeg_subsampling != "gray"
        legacy = not (nr or sharpen or colour)  # the luminance image through the one-pass paths
        raw, img = readout(e, sp, iso, seed, read="read" in st, adc="adc" in st,
                           lut=None if (self.cfa or not legacy) else lut, origin=origin, full_width=full_width)
        if legacy:
            if self.cfa:  # white balance, demosaic, luminance; then the tone curve
                if "adc" in st:
                    img = tone_image(raw, p.cfa, sp.black_level_dn, sp.white_dn, lut, method)
                else:
                    img = gamma_u8(luminance(raw, p.cfa, sp.black_level_dn, sp.white_dn, method), g)
            if "u8" not in st:  # the same tone curve, not quantised: float32 on the 0-255 scale
                lin = (luminance(raw, p.cfa, sp.black_level_dn, sp.white_dn, method) if self.cfa
                       else np.clip((raw - sp.black_level_dn) / (sp.white_dn - sp.black_level_dn), 0, 1))
                img = (255.0 * (np.asarray(lin, np.float64) ** (1.0 / g) if g > 0 else lin)).astype(np.float32)
            elif img is None:
                img = gamma_u8(np.clip((raw - sp.black_level_dn) / (sp.white_dn - sp.black_level_dn), 0, 1), g)
        else:
            img = self._isp_image(raw, isp, method, g, nr=nr, sharpen=sharpen, colour=colour, u8="u8" in st)
        if "downscale" in st and isp.output_width > 0:
            img = downscale(img, isp.output_width, isp.output_height)
        if "jpeg" in st and "u8" in st and isp.jpeg_quality > 0:
            sub = (isp.jpeg_subsampling if "chroma" in st else "4:4:4") if colour else "gray"
            ox, oy = isp.jpeg_grid_offset_px  # a crop's pixels on the frame's block grid
            grid = ((int(ox) + int(origin[1])) % JPEG_MCU_PX, (int(oy) + int(origin[0])) % JPEG_MCU_PX)
            img = jpeg_roundtrip(img, isp.jpeg_quality, sub, grid)
        if img.ndim == 3:  # the app reads the colour picture's luma
            img = luma(img)
        return raw, img

    def _deferred(self, seed: int, exposure_s: float, iso: float, st, isp, method: str, threshold_u8, info: dict,
                  keep_electrons: bool):
        """The :class:`DeferredExposure` of :meth:`expose`, or None for the exact path (``info["dark_pixels"]``
        says why): no numeric threshold, a bright frame or an ISP outside the dark tiles' bound
        (:meth:`dark_tiles`), a downscale, a float image (no ``u8`` stage), or blooming that fills a
        pixel beyond the delivered tiles.

        The lit tiles (not dark) are grouped into crops, each reaching
        :data:`DEFERRED_MARGIN_TILES` tiles beyond them; each crop goes through the exact path's
        charge, blooming, readout, ISP and JPEG with the frame's counters and block grid, and its
        lit tiles are copied into the detection image."""
        dark, why = self.dark_tiles(exposure_s, iso, st, isp, method, threshold_u8)
        if dark is not None and "downscale" in st and isp.output_width > 0:
            dark, why = None, {"path": "exact", "reason": "downscaled image"}
        elif dark is not None and "u8" not in st:  # the threshold is on the delivered 8-bit image
            dark, why = None, {"path": "exact", "reason": "no 8-bit image"}
        if dark is None:
            info["dark_pixels"] = why
            return None
        sp = self.phone.params.sensor
        H, W = self.flux_optics.shape
        prnu, dsnu = self.phone.fixed_patterns()
        detect = np.zeros((H, W), np.uint8)
        crops = lit_crops(~dark, DEFERRED_MARGIN_TILES)
        blooms, lit_px = [], 0
        for crop, inner in crops:
            crop_info = {}
            (r0, r1, c0, c1), (i0, i1, j0, j1) = (tuple(DARK_TILE_PX * np.asarray(b)) for b in (crop, inner))
            r1, c1, i1, j1 = min(r1, H), min(c1, W), min(i1, H), min(j1, W)
            lit_px += (r1 - r0) * (c1 - c0)
            e = electrons(self.flux_optics[r0:r1, c0:c1], sp, exposure_s, prnu[r0:r1, c0:c1], dsnu[r0:r1, c0:c1], seed,
                          shot="shot" in st, dark="dark" in st, fpn="fpn" in st, origin=(r0, c0), full_width=W)
            before = e.copy() if "bloom" in st else None
            _, img = self._develop(e, seed, iso, st, isp, method, crop_info, origin=(r0, c0), full_width=W)
            if before is not None and crop_info["bloom"]["regions"]:
                moved = e != np.minimum(before, sp.full_well_e)  # the pixels blooming filled
                moved[i0 - r0:i1 - r0, j0 - c0:j1 - c0] = False
                if moved.any() or crop_info["bloom"]["lost_e"] > 0:  # beyond the delivered tiles (or off the crop)
                    info["dark_pixels"] = {**why, "path": "exact", "reason": "blooming beyond the lit tiles"}
                    return None
            detect[i0:i1, j0:j1] = img[i0 - r0:i1 - r0, j0 - c0:j1 - c0]
            blooms.append(crop_info.get("bloom"))
        if "bloom" in st:  # the crops' blooming (regions that spill into no other crop: the frame's)
            info["bloom"] = {k: sum(b[k] for b in blooms) for k in ("drained_e", "lost_e", "regions", "bloomed_px")}
        info["dark_pixels"] = {**why, "path": "deferred", "crops": len(crops), "exposed_fraction": lit_px / (H * W)}
        info.update({"seed": int(seed), "stages": list(st), "demosaic": method if self.cfa else None})

        def full():
            return self.expose(seed=seed, exposure_s=exposure_s, iso=iso, keep_electrons=keep_electrons, stages=st,
                               isp=isp, demosaic=method)

        return DeferredExposure(full, detect, exposure_s, iso, sp.gain_dn_per_e(iso), info, keep_electrons)

    def _electrons(self, exposure_s: float, iso: float, seed: int, st, isp, method: str, dark_pixels: str,
                   threshold_u8, info: dict) -> np.ndarray:
        """The charge image (e-, float32 (H, W)) before blooming: every pixel by
        :func:`svgs_sim.camera.phone.sensor.electrons`, or with ``dark_pixels="fast"`` the dark
        tiles' pixels (:meth:`dark_tiles`) by :func:`svgs_sim.camera.phone.sensor.electrons_dark`
        (the same law; the other pixels to the bit as the exact path). ``info["dark_pixels"]``
        says which path was taken and why."""
        if dark_pixels not in DARK_PIXELS:
            raise InputError(f"dark_pixels: expected one of {DARK_PIXELS}, got {dark_pixels!r}")
        sp = self.phone.params.sensor
        prnu, dsnu = self.phone.fixed_patterns()
        if dark_pixels == "fast":
            dark, why = self.dark_tiles(exposure_s, iso, st, isp, method, threshold_u8)
            info["dark_pixels"] = why
            if dark is not None:
                return electrons_dark(self.flux_optics, sp, exposure_s, prnu, dsnu, seed, dark, DARK_TILE_PX,
                                      fpn="fpn" in st)
        return electrons(self.flux_optics, sp, exposure_s, prnu, dsnu, seed, shot="shot" in st, dark="dark" in st,
                         fpn="fpn" in st)

    def dark_reach_e(self, iso: float, st, isp, threshold_u8: float) -> float:
        """The charge (e-) below which a pixel cannot bring the delivered image to
        ``threshold_u8 - DARK_JPEG_MARGIN_U8``: raw DN ``black + K e`` (rounded), white-balanced
        by the weakest channel response (the bilinear demosaic and the luminance are averages, so
        no output exceeds the largest white-balanced input), then the tone curve.

        Parameters
        ----------
        iso : float
        st : tuple of str
            The exposure's stages.
        isp : IspParams
        threshold_u8 : float
            The detector's threshold, 8-bit counts.

        Returns
        -------
        float
            e- (0 when the margin leaves nothing).
        """
        p = self.phone.params
        sp = p.sensor
        x = (float(threshold_u8) - DARK_JPEG_MARGIN_U8) / 255.0
        if x <= 0:
            return 0.0
        lin = x ** isp.gamma if ("tone" in st and isp.gamma > 0) else x
        resp = min(p.cfa.response) if self.cfa else 1.0
        dn_above = lin * (sp.white_dn - sp.black_level_dn) * resp
        return max((dn_above - 0.5) / sp.gain_dn_per_e(iso), 0.0)

    def dark_tiles(self, exposure_s: float, iso: float, st, isp, method: str, threshold_u8):
        """The dark tiles of an exposure (``DARK_TILE_PX`` square): those whose pixels, and the
        pixels of the tiles within :data:`DARK_ISP_REACH_PX` (times a downscale's factor), cannot reach the
        threshold (expected charge below :func:`svgs_sim.camera.phone.sensor.dark_charge_limit` of
        :meth:`dark_reach_e`, chance :data:`DARK_TAIL_P` a pixel) and lie away from the spots'
        point samples (:data:`DARK_WINDOW_PX`).

        Returns
        -------
        dark : ndarray, bool, shape (ceil(H / DARK_TILE_PX), ceil(W / DARK_TILE_PX)), or None
            None: the exact path (no threshold, an ISP the bound does not hold for, or more
            than :data:`DARK_FALLBACK_FRACTION` of the frame can reach the threshold).
        why : dict
            ``path`` ("fast" or "exact"), ``reason``, and when computed ``mu_dark_e`` (e-),
            ``reach_fraction`` (of the tiles).
        """
        sp = self.phone.params.sensor
        if threshold_u8 is None or isinstance(threshold_u8, str) or not np.isfinite(float(threshold_u8)):
            return None, {"path": "exact", "reason": "no numeric threshold"}
        if not ("shot" in st and "dark" in st) or ("nr" in st and isp.nr_sigma_px > 0) or (
                "sharpen" in st and isp.sharpen_amount > 0) or (self.cfa and method != "bilinear"):
            return None, {"path": "exact", "reason": "stages or ISP outside the bound"}
        prnu_max, dsnu_max = self.phone.pattern_bounds() if "fpn" in st else (1.0, 0.0)
        mu_dark = dark_charge_limit(self.dark_reach_e(iso, st, isp, float(threshold_u8)), sp, dsnu_max, DARK_TAIL_P)
        if self._flux_tiles is None:
            self._flux_tiles = tile_max(self.flux_optics, DARK_TILE_PX)
        mu = sp.qe * exposure_s * self._flux_tiles * prnu_max + sp.dark_current_e_s * exposure_s
        reach = (mu >= min(mu_dark, DARK_TABLE_MAX_E)) | self._window_tiles(mu.shape)
        f = max(1.0, self.phone.shape[1] / isp.output_width) if ("downscale" in st and isp.output_width > 0) else 1.0
        r = max(1, int(np.ceil((DARK_ISP_REACH_PX * f + 1) / DARK_TILE_PX)))
        grown = np.pad(reach, r)
        dil = np.zeros_like(reach)
        for a in range(2 * r + 1):
            for b in range(2 * r + 1):
                dil |= grown[a:a + reach.shape[0], b:b + reach.shape[1]]
        why = {"mu_dark_e": float(mu_dark), "reach_fraction": float(dil.mean())}
        if dil.mean() > DARK_FALLBACK_FRACTION:
            return None, {"path": "exact", "reason": "bright frame (fallback)", **why}
        return ~dil, {"path": "fast", "reason": "", **why}

    def _window_tiles(self, shape) -> np.ndarray:
        """The tiles within :data:`DARK_WINDOW_PX` of a point sample of the spots (kept): bool,
        ``shape`` (tiles)."""
        if self._windows is None:
            win = np.zeros(shape, bool)
            if self.points is not None and len(self.points):
                # each point's tile, and the tiles k = DARK_WINDOW_PX / DARK_TILE_PX away (clipped to the
                # frame): the points' tiles (one far beyond the frame as the k-th outside it)
                # marked on a grid padded by k, dilated by k, cut back
                k = -(-DARK_WINDOW_PX // DARK_TILE_PX)
                i = np.clip(np.floor(self.points.v_px / DARK_TILE_PX), -k, shape[0] - 1 + k).astype(np.intp) + k
                j = np.clip(np.floor(self.points.u_px / DARK_TILE_PX), -k, shape[1] - 1 + k).astype(np.intp) + k
                base = np.zeros((shape[0] + 2 * k, shape[1] + 2 * k), bool)
                base[i, j] = True
                grown = np.zeros_like(base)
                n0, n1 = base.shape
                for a in range(-k, k + 1):
                    for b in range(-k, k + 1):
                        grown[max(a, 0):n0 + min(a, 0), max(b, 0):n1 + min(b, 0)] |= \
                            base[max(-a, 0):n0 + min(-a, 0), max(-b, 0):n1 + min(-b, 0)]
                win = grown[k:k + shape[0], k:k + shape[1]]
            self._windows = win
        return self._windows

    def _isp_image(self, raw, isp, method: str, gamma: float, *, nr: bool, sharpen: bool, colour: bool,
                   u8: bool) -> np.ndarray:
        """The ISP's image with noise reduction, sharpening or a colour output: linear image
        (demosaiced and white-balanced with the mosaic) -> noise reduction -> [luminance, unless
        ``colour``] -> tone curve -> sharpening of the luminance -> 8 bits (unless ``u8`` is off).

        Returns
        -------
        ndarray, shape (H, W) or (H, W, 3) (``colour``: BGR); uint8, or float32 on the 0-255 scale
        """
        p = self.phone.params
        sp = p.sensor
        black, white = sp.black_level_dn, sp.white_dn
        if colour and not nr:
            if u8 and not sharpen:  # rounded in the tables: the same numbers in one pass
                return tone_bgr(raw, p.cfa, black, white, gamma, method, u8=True)
            toned = tone_bgr(raw, p.cfa, black, white, gamma, method)
        else:
            if self.cfa:
                lin = linear_bgr(raw, p.cfa, black, white, method)
            else:
                lin = np.clip((raw - black) / (white - black), 0, 1).astype(np.float32)
            if nr:
                lin = np.clip(noise_reduction(lin, isp.nr_sigma_px, isp.nr_range), 0.0, 1.0)
            if self.cfa and not colour:
                lin = luma(lin)
            lin64 = np.asarray(lin, np.float64)
            toned = (255.0 * (lin64 ** (1.0 / gamma) if gamma > 0 else lin64)).astype(np.float32)
        if sharpen:  # the luminance sharpened; a colour image's chroma kept (the same step on B, G and R)
            y = luma(toned) if toned.ndim == 3 else toned
            d = unsharp_mask(y, isp.sharpen_amount, isp.sharpen_sigma_px) - y
            toned = toned + (d[..., None] if toned.ndim == 3 else d)
        np.clip(toned, 0.0, 255.0, out=toned)
        return np.rint(toned).astype(np.uint8) if u8 else toned.astype(np.float32)
