"""What every renderer hands to a camera model: one result type for the SVGS and ToF renders.

A renderer (:mod:`render`, the only Mitsuba code) turns a pose into noise-free per-pixel
means - numpy arrays - plus a JSON-serialisable truth record; a camera model
(:mod:`svgs_sim.camera.phone`, :mod:`svgs_sim.camera.amcw`) then draws noisy frames from them (render once,
expose many). :class:`RenderedFrame` is the part both results share; the SVGS renderer's
:class:`svgs_sim.render.api.RenderResult` and the ToF renderer's :class:`svgs_sim.camera.amcw.RenderedTof` add
their own arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(kw_only=True)
class RenderedFrame:
    """Base of a rendered frame (keyword-only fields, after the subclass's own).

    Attributes
    ----------
    truth : dict
        Pose (``R_cam_target``, ``t_cam_target_m``, ``state``), projections and every
        physical and render parameter used (JSON-serialisable).
    timings_s : dict
        Wall-clock seconds of the render's stages.

    Subclasses provide ``flux`` (ndarray, shape (H, W)): photons per second reaching each
    pixel (noise-free expectation) of the light the renderer modelled.
    """

    truth: dict = field(default_factory=dict)
    timings_s: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple:
        """Frame shape (H, W)."""
        return tuple(np.shape(self.flux))

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """``(R_cam_target (3, 3), t_cam_target_m (3,))`` from the truth record."""
        return np.asarray(self.truth["R_cam_target"], float), np.asarray(self.truth["t_cam_target_m"], float)


def bilinear_splat(u_px, v_px, weight, x0: int, y0: int, width: int, height: int, *,
                   derivative: str | None = None) -> np.ndarray:
    """Weights at sub-pixel positions spread bilinearly over their four nearest pixel centres,
    on the box of pixels ``[x0, x0 + width) x [y0, y0 + height)`` (what falls outside is
    dropped). Each sample's first moment is kept exactly.

    ``derivative="u"`` (or ``"v"``): the derivative of that splat with respect to a common
    shift of all the samples along u (v), per px.

    Returns
    -------
    ndarray, float64, shape (height, width)
    """
    return bilinear_splats(u_px, v_px, weight, x0, y0, width, height, derivatives=(derivative,))[0]


def bilinear_splats(u_px, v_px, weight, x0: int, y0: int, width: int, height: int, *,
                    derivatives=(None,)) -> list:
    """:func:`bilinear_splat` for several ``derivative`` values (None, "u", "v") of the same
    samples at once: the samples' pixel indices are found once.

    Returns
    -------
    list of ndarray, float64, shape (height, width)
        One per entry of ``derivatives``.
    """
    u_px = np.asarray(u_px, np.float64)
    v_px = np.asarray(v_px, np.float64)
    weight = np.asarray(weight, np.float64)
    u0 = np.floor(u_px)
    v0 = np.floor(v_px)
    fu = u_px - u0
    fv = v_px - v0
    xi = (u0 - x0).astype(np.int64)
    yi = (v0 - y0).astype(np.int64)
    base = yi * width + xi
    n = height * width
    inside = bool(xi.size == 0 or (xi.min() >= 0 and xi.max() + 1 < width and yi.min() >= 0
                                   and yi.max() + 1 < height))
    offsets = (0, 1, width, width + 1)  # corners (0, 0), (1, 0), (0, 1), (1, 1)
    idx = np.concatenate([base + o for o in offsets])
    ok = None
    if not inside:
        ok = np.concatenate([(xi + du >= 0) & (xi + du < width) & (yi + dv >= 0) & (yi + dv < height)
                             for du, dv in ((0, 0), (1, 0), (0, 1), (1, 1))])
        idx = idx[ok]
    gu, gv = 1.0 - fu, 1.0 - fv
    outs = []
    for derivative in derivatives:
        if derivative is None:
            a, b = weight * gu, weight * fu
            corners = (a * gv, b * gv, a * fv, b * fv)
        elif derivative == "u":
            a, b = weight * gv, weight * fv
            corners = (-a, a, -b, b)
        elif derivative == "v":
            a, b = weight * gu, weight * fu
            corners = (-a, -b, a, b)
        else:
            raise ValueError(f"derivative: expected None, 'u' or 'v', got {derivative!r}")
        wts = np.concatenate(corners)
        if ok is not None:
            wts = wts[ok]
        outs.append(np.bincount(idx, weights=wts, minlength=n).reshape(height, width))
    return outs


@dataclass(frozen=True)
class PointFlux:
    """Light that reaches the film at exact sub-pixel positions: the samples of the flash
    seen through the cubes (the guided estimator's, :mod:`svgs_sim.render.spots`), before the lens PSF.

    The camera model convolves them with its PSF and integrates over pixels
    (:meth:`svgs_sim.camera.phone.psf.CorePSF.splat`), so their sub-pixel position survives. Their
    sum binned into pixels is part of a render's ``flux``.

    Attributes
    ----------
    u_px, v_px : ndarray, float64, shape (M,)
        Film position of each sample, px (OpenCV convention: pixel centres at integers).
    rate_ph_s : ndarray, float64, shape (M,)
        Photons per second each sample carries into the aperture, in the camera band.
    """

    u_px: np.ndarray
    v_px: np.ndarray
    rate_ph_s: np.ndarray

    def __post_init__(self):
        for name in ("u_px", "v_px", "rate_ph_s"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), np.float64).ravel())
        n = {self.u_px.size, self.v_px.size, self.rate_ph_s.size}
        if len(n) != 1:
            raise ValueError(f"PointFlux: u_px, v_px and rate_ph_s differ in length ({sorted(n)})")

    def __len__(self) -> int:
        return int(self.u_px.size)

    @property
    def total_ph_s(self) -> float:
        return float(self.rate_ph_s.sum())

    def scaled(self, factor: float) -> "PointFlux":
        """The same samples with every rate times ``factor`` (a neutral-density filter)."""
        return PointFlux(self.u_px, self.v_px, self.rate_ph_s * float(factor))

    def moved(self, velocity_px_s, exposure_s: float, readout_time_s: float, height_px: int,
              rng: np.random.Generator) -> "PointFlux":
        """The samples as a moving scene exposes them: motion blur and rolling shutter.

        Each sample is a photon bundle arriving at a uniformly random time within its row's
        exposure; row ``v`` starts exposing ``(v - (H - 1) / 2) / H * readout_time_s`` after
        the centre row (a rolling shutter reading top to bottom). Times are taken from the
        frame's timestamp, the exposure midpoint of the centre row, so a global shutter
        (``readout_time_s = 0``) gives a smear centred on the sample's position at the
        timestamp. First order in the motion: the image velocity of each sample is constant
        over the frame time.

        Parameters
        ----------
        velocity_px_s : array_like, shape (M, 2) or (2,)
            Image velocity ``(du/dt, dv/dt)`` of each sample, px/s.
        exposure_s, readout_time_s : float
            Exposure time per row and the frame's top-to-bottom readout time, s.
        height_px : int
            Rows of the frame.
        rng : numpy.random.Generator
            Draws the arrival times.

        Returns
        -------
        PointFlux
        """
        vel = np.broadcast_to(np.asarray(velocity_px_s, float), (len(self), 2))
        H = float(height_px)
        tau = (self.v_px - 0.5 * (H - 1.0)) / H * float(readout_time_s) + (rng.random(len(self)) - 0.5) * float(exposure_s)
        return PointFlux(self.u_px + vel[:, 0] * tau, self.v_px + vel[:, 1] * tau, self.rate_ph_s)

    def binned(self, shape) -> np.ndarray:
        """Sum of the rates in the pixel containing each sample (a perfect lens), float64 (H, W)."""
        H, W = int(shape[0]), int(shape[1])
        ui = np.floor(self.u_px + 0.5)
        vi = np.floor(self.v_px + 0.5)
        ok = (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
        idx = (vi[ok] * W + ui[ok]).astype(np.int64)
        return np.bincount(idx, weights=self.rate_ph_s[ok], minlength=H * W).reshape(H, W)

    def bilinear(self, shape) -> np.ndarray:
        """The rates spread bilinearly over the four nearest pixel centres (keeps each sample's
        first moment exactly), float64 (H, W): input to smooth kernels such as the glare wings."""
        return bilinear_splat(self.u_px, self.v_px, self.rate_ph_s, 0, 0, int(shape[1]), int(shape[0]))

    def save(self, path) -> None:
        """Write an ``.npz`` with ``u_px``, ``v_px``, ``rate_ph_s``."""
        np.savez_compressed(path, u_px=self.u_px, v_px=self.v_px, rate_ph_s=self.rate_ph_s)

    @classmethod
    def load(cls, path) -> "PointFlux":
        with np.load(path) as z:
            return cls(z["u_px"], z["v_px"], z["rate_ph_s"])
