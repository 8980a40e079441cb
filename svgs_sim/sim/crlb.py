"""The Cramer-Rao bound of a simulated frame: how well its spots can be located, and the pose.

For a rendered frame we know everything the sensor does, so the centroid bound is not
assumed but computed from the noise-free optical image at the exposure used:

- the mean charge of pixel ``i`` is ``mu_i = qe * phi_i * t + dark * t`` (electrons, ``phi`` the
  optical image in photons/s after the lens PSF);
- its variance is ``mu_i + read^2 + q_i^2 / 12``, with ``q_i`` the charge step of one output
  code (the ADC, then the 8-bit tone curve: ``white_e * d(linear)/d(DN)``);
- a saturated pixel (``mu_i`` at or above full well, or at the output white) carries no
  information about the spot's position;
- the Fisher information of spot ``j``'s position is ``sum_i (d mu_i / d x_j)^2 / var_i`` over
  its window, and ``sigma_x = 1 / sqrt(I_x)`` (Kay, Fundamentals of Statistical Signal
  Processing: Estimation Theory, 1993, eq. 3.31 for independent Gaussian samples; the
  Poisson-Gaussian pixel as in Smith et al., Nat. Methods 7, 373 (2010)).

``d mu / d x`` is exact: the deterministic optical image's derivative with respect to a
sub-pixel shift of the point samples (the PSF kernel's spectral derivative,
:meth:`svgs_sim.camera.phone.psf.CorePSF.splat` with ``gradient=True``). The earlier estimate - the
points shifted by +-h px and convolved with the PSF by Monte Carlo with the same draws
(common random numbers) - stays as ``method="monte-carlo"``. The pose bound then is the solver's unit-noise covariance
(``(J^T J)^-1``, :attr:`svgs_sim.svgs.solver.Solution.covariance`) scaled by the mean per-spot centroid
variance (the spots' bounds are within a few tens of per cent of each other).
"""

from __future__ import annotations

import numpy as np

from svgs_sim.camera.rendered import PointFlux
from svgs_sim.sim.closed_loop import render_seed
from svgs_sim.svgs.frames import STATE_KEYS

#: Half-width of the window around a spot over which its Fisher information is summed, px.
WINDOW_HALF_PX = 24
#: Shift for the central difference, px.
SHIFT_PX = 0.25


def _shifted(points, dx, dy):

    return PointFlux(points.u_px + dx, points.v_px + dy, points.rate_ph_s)


#: Margin around a window over which the point samples are convolved, px (the Airy tail beyond
#: reaches the window at ~1e-4 of the peak).
PAD_PX = 16
#: PSF draws per shifted image and colour channel, over all the spots (shared among them by their
#: samples): the bound's Monte Carlo error is about 0.5 % (tests/test_camera_psf.py checks it
#: against GalSim's image to 5 %).
CRLB_DRAWS = 1 << 17


def _window_core_image(phone, cfa: bool, points, dx: float, dy: float, box, seed: int,
                       draws: int = CRLB_DRAWS) -> np.ndarray:
    """The optical image's core (the lens' Airy (x) aberration PSF, with the CFA's channels and
    responses when ``cfa``) of the points shifted by ``(dx, dy)``, over one window
    ``box = (y0, y1, x0, x1)`` of the frame: photons/s per pixel, float64.

    The glare wings and ghosts (a few per cent of the light spread over hundreds of pixels) are
    left out: their derivative inside a spot's window is negligible beside the core's. The same
    ``seed`` for every shift (common random numbers) makes differences of these images exact
    derivatives, not Monte Carlo noise."""
    from svgs_sim.camera.phone.cfa import response_map
    from svgs_sim.camera.phone.optics import core_image, core_share


    y0, y1, x0, x1 = box
    X0, Y0 = x0 - PAD_PX, y0 - PAD_PX
    h, w = (y1 - y0) + 2 * PAD_PX, (x1 - x0) + 2 * PAD_PX
    m = ((points.u_px >= X0 - 0.5) & (points.u_px < X0 + w - 0.5) & (points.v_px >= Y0 - 0.5)
         & (points.v_px < Y0 + h - 0.5))
    local = PointFlux(points.u_px[m] + dx - X0, points.v_px[m] + dy - Y0, points.rate_ph_s[m])
    p = phone.params
    n_draws = max(1, int(round(draws * m.sum() / max(len(points), 1))))
    zeros = np.zeros((h, w), np.float32)
    if not cfa:
        out = core_image(zeros, phone.core_psf(), local, np.random.default_rng(seed), min_draws=n_draws,
                         method="monte-carlo")
    else:
        from svgs_sim.camera.phone import PhoneCamera

        mc = PhoneCamera(phone.camera, phone.params, point_method="monte-carlo")
        out = mc.core_mosaic(zeros, local, seed=seed, origin=(X0, Y0), min_draws=n_draws)
        out *= response_map(p.cfa, (h + 2, w + 2))[(Y0 % 2):(Y0 % 2) + h, (X0 % 2):(X0 % 2) + w]
    out *= core_share(p.glare)
    return out[PAD_PX:PAD_PX + (y1 - y0), PAD_PX:PAD_PX + (x1 - x0)]


def _window_core_gradient(phone, cfa: bool, points, box) -> tuple[np.ndarray, np.ndarray]:
    """The derivatives of the optical image's core over one window ``box = (y0, y1, x0, x1)``
    with respect to a common shift of the points there, ``(d/du, d/dv)``, photons/s per pixel
    per px, float64: exact derivatives of the deterministic image
    (:meth:`svgs_sim.camera.phone.psf.CorePSF.splat` with ``gradient=True``), with the CFA's channels and
    responses when ``cfa``. The points within :data:`PAD_PX` of the window count (their light
    reaches it); the image is made over the window only. The glare wings and ghosts are left
    out, as in :func:`_window_core_image`."""
    from svgs_sim.camera.phone.cfa import response_map
    from svgs_sim.camera.phone.optics import core_share

    y0, y1, x0, x1 = box
    X0, Y0 = x0 - PAD_PX, y0 - PAD_PX
    h, w = (y1 - y0) + 2 * PAD_PX, (x1 - x0) + 2 * PAD_PX
    m = ((points.u_px >= X0 - 0.5) & (points.u_px < X0 + w - 0.5) & (points.v_px >= Y0 - 0.5)
         & (points.v_px < Y0 + h - 0.5))
    local = PointFlux(points.u_px[m] - x0, points.v_px[m] - y0, points.rate_ph_s[m])
    p = phone.params
    hh, ww = y1 - y0, x1 - x0
    if not cfa:
        gu, gv = phone.core_psf().splat(local.u_px, local.v_px, local.rate_ph_s, (hh, ww), gradient=True)[1:]
    else:
        gu, gv = phone.core_mosaic(np.zeros((hh, ww), np.float32), local, origin=(x0, y0), gradient=True,
                                   value=False)
        resp = response_map(p.cfa, (hh + 2, ww + 2))[(y0 % 2):(y0 % 2) + hh, (x0 % 2):(x0 % 2) + ww]
        gu, gv = gu * resp, gv * resp
    f = core_share(p.glare)
    return f * gu, f * gv


#: How the bound's image derivatives are computed: ``"analytic"`` (default; the deterministic
#: image's exact derivatives) or ``"monte-carlo"`` (central differences of Monte Carlo
#: convolutions with common random numbers: the earlier path).
CRLB_METHODS = ("analytic", "monte-carlo")


def centroid_crlb_px(frame, exposer, exposure, spots_px, *, window_half_px: int = WINDOW_HALF_PX,
                     draws: int = CRLB_DRAWS, method: str = "analytic") -> np.ndarray:
    """Per-spot Cramer-Rao bound of the centroid, px (1 sigma per axis).

    Parameters
    ----------
    frame : svgs_sim.sim.closed_loop.Frame
        With ``points`` (guided render).
    exposer : svgs_sim.camera.phone.Exposer
        The exposer the exposure came from (its noise-free optical image is reused).
    exposure : svgs_sim.camera.phone.Exposure
        Gives the exposure time and ISO.
    spots_px : ndarray, shape (N, 2)
        Where the spots are (solved or true targets), full-resolution px.
    draws : int
        PSF draws per shifted image and channel (:data:`CRLB_DRAWS`; the Monte Carlo error of
        the bound goes as ``1 / sqrt(draws)``), ``method="monte-carlo"`` only.
    method : str
        One of :data:`CRLB_METHODS`.

    Returns
    -------
    ndarray, shape (N, 2)
        ``(sigma_u, sigma_v)`` per spot, px; inf where a spot carries no information
        (entirely saturated or outside the frame).
    """
    if method not in CRLB_METHODS:
        raise ValueError(f"method: expected one of {CRLB_METHODS}, got {method!r}")
    phone = exposer.phone
    p = phone.params
    sp = p.sensor
    t = float(exposure.exposure_s)
    H, W = phone.shape
    gain = sp.gain_dn_per_e(exposure.iso)
    white_e = (sp.white_dn - sp.black_level_dn) / gain
    full = min(sp.full_well_e, white_e)
    g = p.isp.gamma if p.isp.gamma > 0 else 1.0

    def noise(sl):
        """Mean charge, variance and the unsaturated mask of a window."""
        mu = sp.qe * exposer.flux_optics[sl].astype(np.float64) * t + sp.dark_current_e_s * t
        # 8-bit output step in electrons (tone curve out = lin^(1/gamma)), and the ADC step
        lin = np.clip(mu / white_e, 1e-6, 1.0)
        q_out = white_e * g / 255.0 * lin ** (1.0 - 1.0 / g)
        return mu, mu + sp.read_noise_e**2 + (q_out**2 + (1.0 / gain) ** 2) / 12.0, mu < 0.98 * full

    out = np.full((len(spots_px), 2), np.inf)
    pts = frame.points
    if pts is None or len(pts) == 0:
        return out
    seed = render_seed(frame.truth)
    k = sp.qe * t  # photons/s -> electrons
    for j, box in enumerate(_windows(spots_px, window_half_px, (H, W))):
        if box is None:
            continue
        y0, y1, x0, x1 = box
        sl = (slice(y0, y1), slice(x0, x1))
        if method == "analytic":
            gu, gv = _cached_gradient(exposer, pts, (y0, y1, x0, x1))
            dmu_dx, dmu_dy = k * gu, k * gv
        else:
            d = [_window_core_image(phone, exposer.cfa, pts, dx, dy, (y0, y1, x0, x1), seed, draws)
                 for dx, dy in ((SHIFT_PX, 0.0), (-SHIFT_PX, 0.0), (0.0, SHIFT_PX), (0.0, -SHIFT_PX))]
            dmu_dx = k * (d[0] - d[1]) / (2 * SHIFT_PX)
            dmu_dy = k * (d[2] - d[3]) / (2 * SHIFT_PX)
        _, var_w, ok = noise(sl)
        ix = float(np.sum((dmu_dx**2 / var_w)[ok]))
        iy = float(np.sum((dmu_dy**2 / var_w)[ok]))
        out[j] = (1.0 / np.sqrt(ix) if ix > 0 else np.inf, 1.0 / np.sqrt(iy) if iy > 0 else np.inf)
    return out


def _windows(spots_px, window_half_px: int, shape) -> list:
    """Each spot's window ``(y0, y1, x0, x1)`` in the frame (None: not finite, or outside)."""
    H, W = shape
    w = int(window_half_px)
    out = []
    for u, v in np.asarray(spots_px, float).reshape(-1, 2):
        box = None
        if np.isfinite(u) and np.isfinite(v):
            x0, x1 = max(0, int(round(u)) - w), min(W, int(round(u)) + w + 1)
            y0, y1 = max(0, int(round(v)) - w), min(H, int(round(v)) + w + 1)
            box = (y0, y1, x0, x1) if x1 > x0 and y1 > y0 else None
        out.append(box)
    return out


def _cached_gradient(exposer, pts, box) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_window_core_gradient` of a window, kept on the exposer: the derivatives depend on
    the render and the window only (a campaign's several exposures per stand setting)."""
    cache = exposer.__dict__.setdefault("_crlb_gradients", {})
    key = (id(pts),) + tuple(int(b) for b in box)
    if key not in cache:
        cache[key] = (pts, _window_core_gradient(exposer.phone, exposer.cfa, pts, box))
    return cache[key][1]


def frame_windows(exposer, row, *, window_half_px: int = WINDOW_HALF_PX) -> list:
    """The windows ``(y0, y1, x0, x1)`` whose image derivatives :func:`frame_crlb` uses for a
    solved frame (around its solved spots; none outside the frame), in its order; [] when the
    frame is unsolved."""
    sol = row.get("_solution")
    if not row.get("ok") or sol is None:
        return []
    return [b for b in _windows(_solved_spots(sol)[1], window_half_px, exposer.phone.shape) if b is not None]


def _solved_spots(solution) -> tuple[list, np.ndarray]:
    """The solved targets' ids and image places ``(N, 2)`` px, in the solution's order."""
    ids = list(solution.targets_px)
    return ids, np.array([solution.targets_px[i] for i in ids], float)


def window_gradients(frame, exposer, boxes) -> None:
    """The bound's image derivatives of ``boxes`` (:func:`frame_windows`) computed and kept on the
    exposer, where :func:`frame_crlb` finds them (another thread may compute some while this one
    computes the others). The numbers do not change."""
    if frame.points is None or len(frame.points) == 0:
        return
    for box in boxes:
        _cached_gradient(exposer, frame.points, box)


def pose_crlb(solution, centroid_sigma_px: float) -> dict:
    """1-sigma Cramer-Rao bound of each state component (m, deg) for a centroid noise.

    Parameters
    ----------
    solution : svgs_sim.svgs.solver.Solution
    centroid_sigma_px : float
        Centroid noise per axis, px.

    Returns
    -------
    dict
        :data:`svgs_sim.svgs.frames.STATE_KEYS` -> bound (m or deg).
    """
    unit = np.asarray(solution.covariance, float) / float(solution.sigma_px) ** 2
    std = np.sqrt(np.maximum(np.diag(unit), 0.0)) * float(centroid_sigma_px)
    std = np.concatenate([std[:3], np.degrees(std[3:])])
    return {k: float(v) for k, v in zip(STATE_KEYS, std)}


def frame_crlb(frame, exposer, row, *, draws: int = CRLB_DRAWS) -> dict | None:
    """The bound of one solved frame: ``centroid_sigma_px`` (per spot and the RMS used) and
    ``crlb_std`` per state component. None when the frame is unsolved or has no points.
    ``draws``: see :func:`centroid_crlb_px`."""
    sol = row.get("_solution")
    if not row.get("ok") or sol is None or frame.points is None:
        return None
    ids, spots = _solved_spots(sol)
    sig = centroid_crlb_px(frame, exposer, row["_exposure"], spots, draws=draws)
    finite = np.isfinite(sig)
    if not np.all(finite):
        return {"centroid_sigma_px": None, "per_spot_sigma_px": {str(i): s.tolist() for i, s in zip(ids, sig)},
                "crlb_std": None, "note": "a spot carries no position information (saturated throughout)"}
    rms = float(np.sqrt(np.mean(sig**2)))
    return {"centroid_sigma_px": rms, "per_spot_sigma_px": {str(i): [float(a), float(b)] for i, (a, b) in zip(ids, sig)},
            "crlb_std": pose_crlb(sol, rms)}
