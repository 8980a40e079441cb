"""The lens' core PSF: the Airy pattern of the f/N aperture convolved with the aberration blur.

Image formation in the physical order: film irradiance at sub-pixel resolution -> lens PSF ->
integration over each pixel's area -> sensor. Two kinds of input reach the lens:

- **points** (:class:`svgs_sim.camera.rendered.PointFlux`): the flash seen through the cubes, as the
  guided estimator's samples, each at its exact film position. :meth:`CorePSF.splat` displaces
  every sample's film point by draws from the PSF (a Monte Carlo convolution, exact in
  expectation, Airy tail included) and counts it in the pixel that contains it: pixel ``i``
  spans ``[i - 1/2, i + 1/2)`` (OpenCV's pixel-centre convention), so the pixel-area
  integration is exact and nothing of the sub-pixel position is lost to the grid.
- **pixel images** (the diffuse light, already integrated over each pixel by the renderer's box
  filter): :meth:`CorePSF.convolve` convolves them with the pixel-integrated PSF sampled at
  integer offsets (:meth:`CorePSF.pixel_kernel`). For content that varies slowly over a pixel
  this is the same integral; at a sharp edge it adds one pixel of box smoothing, symmetric, so
  an edge's position is kept (``tests/test_camera_psf.py``).

The PSF (film coordinates in pixels)::

    PSF = Airy(lambda N / pitch) (x) Gaussian(aberration_sigma_px)
    Airy: I(r) ~ [2 J1(x) / x]^2,  x = pi r / (lambda N / pitch)
    encircled energy EE(x) = 1 - J0(x)^2 - J1(x)^2 (Born & Wolf, Principles of Optics, 8.5)

A monochromatic Airy pattern at ``wavelength_nm`` (the middle of the band unless a colour
channel says otherwise, see :mod:`svgs_sim.camera.phone.cfa`). The Gaussian stands for the lens'
aberrations; defocus is not here: the renderer's thin lens traces it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from svgs_sim.camera.backend import get_backend
from svgs_sim.camera.rendered import bilinear_splat, bilinear_splats

#: Encircled-energy table of the Airy pattern: x = pi r / (lambda N) from 0 to this value.
AIRY_TABLE_X_MAX = 400.0
AIRY_TABLE_STEP = 0.002
#: Monte Carlo convolution: at least this many PSF draws per frame (several per sample when a
#: frame has few samples), so that the draws add a negligible noise to the spots.
MIN_DRAWS = 1 << 20
#: At most this many draws per sample.
MAX_DRAWS_PER_SAMPLE = 64
#: The Airy pattern inside this radius is drawn (Monte Carlo); outside it, where draws would
#: be sparse specks, it is a deterministic kernel on the points' bilinear pixel image, px.
AIRY_DRAWN_RADIUS_PX = 6.0
#: Half-size of that outer kernel, px; it carries the whole Airy energy beyond the drawn
#: radius (the share beyond this half-size, ~0.3 % at f/2.4 and 1.4 um, is folded into it).
AIRY_OUTER_RADIUS_PX = 64
#: Deterministic convolution of the points (:meth:`CorePSF.splat`): nodes per pixel (per
#: axis) of the sub-pixel grid the samples are spread onto.
SPLAT_OVERSAMPLING = 8
#: Half-size of that inner kernel, px: the Airy pattern inside :data:`AIRY_DRAWN_RADIUS_PX`
#: blurred by the aberration Gaussian and a pixel's box reaches 6 + 0.5 + 5 sigma_ab.
INNER_KERNEL_RADIUS_PX = 10
#: The inner kernel is computed on a grid this many times finer than the splat's, then sampled.
KERNEL_SUPERSAMPLING = 4
#: Points whose spots lie closer than this are convolved in one window, px.
CLUSTER_CELL_PX = 32
#: Half-size of the pixel kernel used on pixel images (the diffuse light), px. The Airy
#: tail beyond it (2.4 % of the energy at f/2.4 and 1.4 um) is folded back by normalisation.
PIXEL_KERNEL_RADIUS_PX = 8


@functools.lru_cache(maxsize=4)
def _airy_ee_table():
    from scipy.special import j0, j1

    x = np.arange(0.0, AIRY_TABLE_X_MAX + AIRY_TABLE_STEP / 2, AIRY_TABLE_STEP)
    ee = 1.0 - j0(x) ** 2 - j1(x) ** 2
    ee[0] = 0.0
    ee = np.maximum.accumulate(ee)  # monotone for the inverse (flat only at the dark rings)
    return x, ee


def airy_encircled_energy(r_px, lam_over_d_px: float) -> np.ndarray:
    """Fraction of the Airy pattern's energy within radius ``r_px`` (px)."""
    from scipy.special import j0, j1

    x = np.pi * np.asarray(r_px, float) / lam_over_d_px
    return 1.0 - j0(x) ** 2 - j1(x) ** 2


#: Inverse encircled energy tabulated at this many uniform steps of EE in [0, INVERSE_EE_MAX].
INVERSE_EE_STEPS = 1 << 16
INVERSE_EE_MAX = 0.998


@functools.lru_cache(maxsize=1)
def _inverse_ee_table():
    x_t, ee_t = _airy_ee_table()
    u = np.linspace(0.0, INVERSE_EE_MAX, INVERSE_EE_STEPS + 1)
    return np.interp(u, ee_t, x_t)


def sample_airy_radius_px(u, lam_over_d_px: float) -> np.ndarray:
    """Radii (px) of Airy-distributed points from uniform numbers ``u`` in [0, 1).

    Inverts the encircled energy ``EE(x) = 1 - J0^2 - J1^2`` by a table at uniform steps of EE
    (linear interpolation, O(1) per draw) up to EE = 0.998; beyond it the asymptote
    ``1 - EE(x) = 2 / (pi x)`` (x > 318, where it holds to 0.3 %).
    """
    inv = _inverse_ee_table()
    u = np.asarray(u, float)
    t = np.minimum(u, INVERSE_EE_MAX) * (INVERSE_EE_STEPS / INVERSE_EE_MAX)
    i = np.minimum(t.astype(np.int64), INVERSE_EE_STEPS - 1)
    f = t - i
    x = inv[i] * (1.0 - f) + inv[i + 1] * f
    tail = u > INVERSE_EE_MAX
    if np.any(tail):
        x[tail] = 2.0 / (np.pi * np.maximum(1.0 - u[tail], 1e-300))
    return x * lam_over_d_px / np.pi


@dataclass(frozen=True)
class CorePSF:
    """Airy pattern (x) aberration Gaussian, in pixels.

    Attributes
    ----------
    lam_over_d_px : float
        ``lambda N / pitch``: wavelength times f-number over the pixel pitch, px (the Airy
        pattern's first dark ring is at 1.22 of it).
    aberration_sigma_px : float
        Standard deviation of the aberration Gaussian, px.
    """

    lam_over_d_px: float
    aberration_sigma_px: float

    @classmethod
    def from_optics(cls, f_number: float, wavelength_nm: float, pixel_pitch_m: float,
                    aberration_sigma_px: float) -> "CorePSF":
        """The PSF of an f/N lens at one wavelength on pixels of a given pitch."""
        return cls(float(wavelength_nm) * 1e-9 * float(f_number) / float(pixel_pitch_m), float(aberration_sigma_px))

    @property
    def sigma_equivalent_px(self) -> float:
        """Standard deviation of the Gaussian that best fits the core (0.42 lambda N for the
        Airy disk, in quadrature with the aberration), px: for summaries and the CRLB."""
        return math.hypot(0.42 * self.lam_over_d_px, self.aberration_sigma_px)

    # ------------------------------------------------------------------ points
    @property
    def drawn_energy(self) -> float:
        """Share of the Airy pattern's energy inside :data:`AIRY_DRAWN_RADIUS_PX`."""
        return float(airy_encircled_energy(AIRY_DRAWN_RADIUS_PX, self.lam_over_d_px))

    def sample_offsets_px(self, n: int, rng: np.random.Generator, *, inner: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """``n`` displacements (dx, dy) px drawn from the PSF (``inner``: from its Airy part
        inside :data:`AIRY_DRAWN_RADIUS_PX` only, renormalised)."""
        u = rng.random(n)
        if inner:
            u *= self.drawn_energy
        r = sample_airy_radius_px(u, self.lam_over_d_px)
        phi = rng.random(n) * (2.0 * np.pi)
        dx = r * np.cos(phi)
        dy = r * np.sin(phi)
        if self.aberration_sigma_px > 0:
            dx += rng.normal(0.0, self.aberration_sigma_px, n)
            dy += rng.normal(0.0, self.aberration_sigma_px, n)
        return dx, dy

    def splat_monte_carlo(self, u_px, v_px, weight, shape, rng: np.random.Generator, *,
                          min_draws: int = MIN_DRAWS) -> np.ndarray:
        """Monte Carlo convolution of point samples with the PSF, integrated over pixels (the
        earlier path; :meth:`splat` computes its expectation deterministically).

        Parameters
        ----------
        u_px, v_px : ndarray, shape (M,)
            Film positions of the samples, px (pixel centres at integers).
        weight : ndarray, shape (M,)
            What each sample carries (photons/s, say).
        shape : (H, W)
        rng : numpy.random.Generator
        min_draws : int
            At least this many PSF draws in all (``ceil(min_draws / M)`` per sample, at most
            :data:`MAX_DRAWS_PER_SAMPLE`).

        Returns
        -------
        ndarray, float64, shape (H, W)
            Sum of the weights landing in each pixel (what leaves the frame is lost).

        Notes
        -----
        The Airy pattern inside :data:`AIRY_DRAWN_RADIUS_PX` (about 97 % of its energy) and the
        aberration Gaussian are drawn; the Airy tail beyond it is added deterministically
        (:meth:`outer_kernel` on the points spread bilinearly over pixel centres, which keeps
        their first moment), so the faint tail is smooth rather than a sprinkle of draws.
        """
        H, W = int(shape[0]), int(shape[1])
        u = np.asarray(u_px, float).ravel()
        v = np.asarray(v_px, float).ravel()
        w = np.asarray(weight, float).ravel()
        out = np.zeros(H * W)
        M = u.size
        if M == 0:
            return out.reshape(H, W)
        e_in = self.drawn_energy
        self._add_outer(out.reshape(H, W), u, v, w * (1.0 - e_in))
        w = w * e_in
        k = int(min(MAX_DRAWS_PER_SAMPLE, max(1, math.ceil(min_draws / M))))
        # draw in chunks to bound memory
        chunk = max(1, (1 << 21) // k)
        for s in range(0, M, chunk):
            uu, vv, ww = u[s:s + chunk], v[s:s + chunk], w[s:s + chunk]
            n = uu.size * k
            dx, dy = self.sample_offsets_px(n, rng, inner=True)
            x = np.repeat(uu, k) + dx
            y = np.repeat(vv, k) + dy
            xi = np.floor(x + 0.5).astype(np.int64)
            yi = np.floor(y + 0.5).astype(np.int64)
            ok = (xi >= 0) & (xi < W) & (yi >= 0) & (yi < H)
            xi, yi = xi[ok], yi[ok]
            if xi.size == 0:
                continue
            # accumulate over the bounding box only (most frames: a few small spots)
            x0, x1, y0, y1 = int(xi.min()), int(xi.max()) + 1, int(yi.min()), int(yi.max()) + 1
            bw = x1 - x0
            box = np.bincount((yi - y0) * bw + (xi - x0), weights=np.repeat(ww / k, k)[ok],
                              minlength=(y1 - y0) * bw)
            out2 = out.reshape(H, W)
            out2[y0:y1, x0:x1] += box.reshape(y1 - y0, bw)
        return out.reshape(H, W)

    def splat(self, u_px, v_px, weight, shape, rng=None, *, gradient: bool = False, min_draws=None):
        """Point samples convolved with the PSF and integrated over pixels, deterministically.

        The exact expectation of :meth:`splat_monte_carlo` without its noise. The points of each
        spot are spread bilinearly onto a grid of :data:`SPLAT_OVERSAMPLING` nodes per pixel
        (a splat that keeps every sample's energy and first moment exactly), convolved by FFT
        with the pixel-integrated PSF sampled at that spacing (:func:`fine_kernel`: the Airy
        pattern inside :data:`AIRY_DRAWN_RADIUS_PX` (x) the aberration Gaussian (x) the pixel's
        box, computed in the frequency domain), and read at the pixel centres. The Airy tail
        beyond that radius is added as before (:meth:`outer_kernel` on the points' bilinear
        pixel image). Because pixel boxes tile the film, a pixel-integrated kernel sums to the
        same energy for any sub-pixel phase: the flux is exact and the centroid moves with the
        points; the bilinear splat adds ``f (1 - f) / q^2`` px^2 of variance per sample (on
        average ``1 / (6 q^2)``, 0.0026 px^2 at q = 8, 1.5 % of the Airy core's variance).

        Parameters
        ----------
        u_px, v_px : ndarray, shape (M,)
            Film positions of the samples, px (pixel centres at integers).
        weight : ndarray, shape (M,)
            What each sample carries (photons/s, say).
        shape : (H, W)
        rng : ignored
            Accepted for the Monte Carlo path's signature (no random draws here).
        gradient : bool
            Also return the image's derivatives with respect to a common shift of all the
            points, ``d image / d u`` and ``d image / d v`` (per px): exact, from the kernel's
            spectral derivative (inner part) and the bilinear weights' derivative (outer tail).
        min_draws : ignored

        Returns
        -------
        ndarray, float64, shape (H, W)
            Sum of the weights landing in each pixel (what leaves the frame is lost); with
            ``gradient``, a tuple ``(image, d_du, d_dv)`` of three such arrays.
        """
        H, W = int(shape[0]), int(shape[1])
        outs = [np.zeros((H, W)) for _ in range(3 if gradient else 1)]
        for ys, xs, patches in splat_patches([self], u_px, v_px, weight, (H, W), gradient=gradient):
            for out, patch in zip(outs, patches[0]):
                out[ys:ys + patch.shape[0], xs:xs + patch.shape[1]] += patch
        return tuple(outs) if gradient else outs[0]

    def outer_kernel(self) -> np.ndarray:
        """The Airy pattern beyond :data:`AIRY_DRAWN_RADIUS_PX`, convolved with the aberration
        Gaussian and integrated over a pixel, at integer offsets; unit sum.
        Shape (2 R + 1, 2 R + 1), R = :data:`AIRY_OUTER_RADIUS_PX`."""
        return _outer_kernel(self.lam_over_d_px, self.aberration_sigma_px).copy()

    def _add_outer(self, out, u, v, w, grads=None) -> None:
        """Add the outer Airy tail of points ``(u, v)`` carrying ``w`` into ``out`` (H, W);
        ``grads = (d_du, d_dv)``: also add its derivatives with respect to a common shift of
        the points (the bilinear weights' derivatives, convolved with the same kernel)."""
        from scipy.signal import fftconvolve

        H, W = out.shape
        R = AIRY_OUTER_RADIUS_PX
        u0 = np.floor(u)
        v0 = np.floor(v)
        ok = (u0 >= -R) & (u0 < W + R) & (v0 >= -R) & (v0 < H + R)
        if not np.any(ok):
            return
        u, v, w, u0, v0 = u[ok], v[ok], w[ok], u0[ok], v0[ok]
        x0, y0 = int(u0.min()), int(v0.min())
        bw, bh = int(u0.max()) - x0 + 2, int(v0.max()) - y0 + 2
        boxes = [bilinear_splat(u, v, w, x0, y0, bw, bh)]
        targets = [out]
        if grads is not None:
            boxes += [bilinear_splat(u, v, w, x0, y0, bw, bh, derivative=axis) for axis in ("u", "v")]
            targets += list(grads)
        k = _outer_kernel(self.lam_over_d_px, self.aberration_sigma_px)
        X0, Y0 = x0 - R, y0 - R
        for box, tgt in zip(boxes, targets):
            conv = fftconvolve(box, k, mode="full")  # origin at (x0 - R, y0 - R)
            ys, xs = max(0, Y0), max(0, X0)
            ye, xe = min(H, Y0 + conv.shape[0]), min(W, X0 + conv.shape[1])
            if ye > ys and xe > xs:
                tgt[ys:ye, xs:xe] += conv[ys - Y0:ye - Y0, xs - X0:xe - X0]

    # ------------------------------------------------------------------ pixel images
    def pixel_kernel(self, radius_px: int = PIXEL_KERNEL_RADIUS_PX, *, normalise: bool = True) -> np.ndarray:
        """The PSF integrated over a pixel, at integer offsets: the energy a point at the centre
        of pixel (0, 0) puts into pixel (i, j).

        Computed in the frequency domain, exactly up to the periodic wrap of a 128 px grid:
        ``OTF_Airy(nu) exp(-2 pi^2 sigma^2 nu^2) sinc(nu_x) sinc(nu_y)`` (the Airy OTF of a
        circular pupil, cut off at ``1 / (lambda N)``).

        Returns
        -------
        ndarray, float64, shape (2 radius_px + 1, 2 radius_px + 1)
            Sums to 1 when ``normalise`` (the tail beyond ``radius_px`` folded back), else to
            the energy inside.
        """
        return _pixel_kernel(self.lam_over_d_px, self.aberration_sigma_px, int(radius_px), bool(normalise)).copy()

    def convolve(self, image, radius_px: int = PIXEL_KERNEL_RADIUS_PX, *, backend=None) -> np.ndarray:
        """Convolve a pixel image (already integrated over pixels) with :meth:`pixel_kernel`.
        float32 (H, W); zero outside the frame. ``backend``: the array backend
        (:func:`svgs_sim.camera.backend.get_backend`; default the CPU's OpenCV)."""

        be = get_backend(backend)
        k = self.pixel_kernel(radius_px).astype(np.float32)
        f = np.ascontiguousarray(image, np.float32)
        H, W = f.shape
        box = support_box(f, int(radius_px))
        if box is None:
            return np.zeros((H, W), np.float32)
        y0, y1, x0, x1 = box
        if (y1 - y0) * (x1 - x0) > 0.5 * H * W:
            return be.filter_same(f, k)
        # light in a small part of the frame (a rendered target without the lab's light): the
        # convolution over its support and a kernel's radius around it, zero elsewhere (exact)
        out = np.zeros((H, W), np.float32)
        out[y0:y1, x0:x1] = be.filter_same(f[y0:y1, x0:x1], k)
        return out


@functools.lru_cache(maxsize=16)
def _pixel_kernel(lam_over_d_px: float, sigma_px: float, radius: int, normalise: bool) -> np.ndarray:
    L, q = 128, 4  # period (px) and oversampling of the frequency grid
    n = L * q
    nu = np.fft.fftfreq(n, d=1.0 / q)  # cycles per pixel
    nx, ny = np.meshgrid(nu, nu)
    rho = np.hypot(nx, ny)
    s = np.clip(rho * lam_over_d_px, 0.0, 1.0)
    otf = (2.0 / np.pi) * (np.arccos(s) - s * np.sqrt(1.0 - s * s))
    otf *= np.exp(-2.0 * np.pi**2 * sigma_px**2 * rho**2) * np.sinc(nx) * np.sinc(ny)
    f = np.real(np.fft.ifft2(otf)) * q * q  # the pixel-integrated PSF at 1/q px spacing
    f = np.fft.fftshift(f)[::q, ::q]  # integer offsets; centre at L/2
    c = L // 2
    k = f[c - radius:c + radius + 1, c - radius:c + radius + 1]
    k = np.maximum(k, 0.0)
    return k / k.sum() if normalise else k


@functools.lru_cache(maxsize=16)
def _outer_kernel(lam_over_d_px: float, sigma_px: float) -> np.ndarray:
    from scipy.ndimage import convolve1d, gaussian_filter
    from scipy.special import j1

    R, q = AIRY_OUTER_RADIUS_PX, 8
    n = (2 * (R + 3)) * q + 1  # fine grid, odd, centred on the pixel centre
    c = n // 2
    y, x = (np.mgrid[:n, :n] - c) / q
    r = np.hypot(x, y)
    z = np.pi * np.maximum(r, 1e-12) / lam_over_d_px
    psf = (np.pi / (4.0 * lam_over_d_px**2)) * (2.0 * j1(z) / z) ** 2 / (q * q)  # energy per fine cell
    psf[r < AIRY_DRAWN_RADIUS_PX] = 0.0
    if sigma_px > 0:
        psf = gaussian_filter(psf, sigma_px * q, mode="constant", truncate=5.0)
    box = np.ones(q + 1)
    box[0] = box[-1] = 0.5  # a centred pixel-wide box on an even number of fine cells
    for axis in (0, 1):  # integrate over a pixel's area
        psf = convolve1d(psf, box, axis=axis, mode="constant")
    k = psf[c % q::q, c % q::q]
    m = k.shape[0] // 2
    k = k[m - R:m + R + 1, m - R:m + R + 1]
    return k / k.sum()


@functools.lru_cache(maxsize=64)
def _outer_kernel_cropped(lam_over_d_px: float, sigma_px: float, radius: int) -> np.ndarray:
    """:func:`_outer_kernel` cut to ``radius`` px (the part that can reach a small frame)."""
    R = AIRY_OUTER_RADIUS_PX
    k = np.ascontiguousarray(_outer_kernel(lam_over_d_px, sigma_px)[R - radius:R + radius + 1, R - radius:R + radius + 1])
    k.setflags(write=False)
    return k


@functools.lru_cache(maxsize=16)
def fine_kernel(lam_over_d_px: float, sigma_px: float) -> tuple:
    """The inner PSF (the Airy pattern inside :data:`AIRY_DRAWN_RADIUS_PX`, renormalised, (x)
    the aberration Gaussian) integrated over a pixel, sampled at ``1 / q`` px
    (q = :data:`SPLAT_OVERSAMPLING`), and its derivatives with respect to the point's position.

    The Airy pattern is sampled on a grid ``KERNEL_SUPERSAMPLING`` times finer; the Gaussian
    and the pixel's box are applied exactly in the frequency domain
    (``exp(-2 pi^2 sigma^2 nu^2) sinc(nu_x) sinc(nu_y)``), and so are the derivatives
    (``2 pi i nu``). Each of the ``q^2`` sub-pixel phases is normalised to unit sum over the
    integer offsets (the flux is exact at every phase).

    Returns
    -------
    (K, dK_du, dK_dv) : ndarrays, float64, shape (2 R q - 1, 2 R q - 1)
        ``K[c + i, c + j]`` is the energy a unit point at the origin puts into a pixel centred
        at ``(j / q, i / q)``, ``c = R q - 1``, R = :data:`INNER_KERNEL_RADIUS_PX`; ``dK_du``,
        ``dK_dv``: its derivatives with respect to the point's position (``-dK/dx``,
        ``-dK/dy``); read-only.
    """
    from scipy.special import j1

    q, s, R = SPLAT_OVERSAMPLING, KERNEL_SUPERSAMPLING, INNER_KERNEL_RADIUS_PX
    n = 2 * R * q * s
    h = 1.0 / (q * s)
    x = (np.arange(n) - n // 2) * h
    X, Y = np.meshgrid(x, x)
    r = np.hypot(X, Y)
    z = np.pi * np.maximum(r, 1e-12) / lam_over_d_px
    psf = (2.0 * j1(z) / z) ** 2
    psf[r >= AIRY_DRAWN_RADIUS_PX] = 0.0
    psf /= psf.sum() * h * h  # unit energy (the inner share is applied by the caller)
    nu = np.fft.fftfreq(n, d=h)
    nx, ny = np.meshgrid(nu, nu)
    F = np.fft.fft2(np.fft.ifftshift(psf))
    F *= np.exp(-2.0 * np.pi**2 * sigma_px**2 * (nx * nx + ny * ny)) * np.sinc(nx) * np.sinc(ny)
    out = []
    for D in (1.0, -2j * np.pi * nx, -2j * np.pi * ny):  # d/du of K(X - u) = -dK/dx
        k = np.fft.fftshift(np.real(np.fft.ifft2(F * D)))[s::s, s::s]  # positions -R + 1/q .. R - 1/q
        out.append(k)
    K = out[0]
    c = R * q - 1
    norm = np.zeros((q, q))
    for py in range(q):
        for px in range(q):
            norm[py, px] = K[(c + py) % q::q, (c + px) % q::q].sum()
    # index i of the kernel belongs to phase (i - c) mod q
    iy = (np.arange(K.shape[0]) - c) % q
    scale = norm[np.ix_(iy, iy)]
    res = tuple(np.ascontiguousarray(k / scale) for k in out)
    for k in res:
        k.setflags(write=False)
    return res


def support_box(image, margin_px: int):
    """The smallest box holding every non-zero pixel of ``image``, grown by ``margin_px`` and
    clipped to the frame: ``(y0, y1, x0, x1)``, or None for an all-zero image."""
    H, W = image.shape
    rows = np.flatnonzero(image.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(image[rows[0]:rows[-1] + 1].any(axis=0))
    m = int(margin_px)
    return (max(0, int(rows[0]) - m), min(H, int(rows[-1]) + m + 1), max(0, int(cols[0]) - m),
            min(W, int(cols[-1]) + m + 1))


def splat_patches(cores, u_px, v_px, weight, shape, *, gradient: bool = False, value: bool = True):
    """The deterministic point convolution of :meth:`CorePSF.splat`, for several PSFs at once
    (the colour channels' Airy patterns), spot by spot.

    What does not depend on the PSF is done once per spot: the spot's samples spread on the
    pixel grid (for the outer Airy tail) and on the sub-pixel grid (for the inner kernel), and
    their Fourier transforms; each PSF then costs one spectrum product and one inverse
    transform per output image.

    Parameters
    ----------
    cores : sequence of CorePSF
    u_px, v_px, weight : ndarray, shape (M,)
        The samples (see :meth:`CorePSF.splat`).
    shape : (H, W)
    gradient : bool
        Also the derivatives with respect to a common shift of the points.
    value : bool
        With ``gradient``, ``False`` leaves the image out (the derivatives only).

    Yields
    ------
    ys, xs : int
        Frame pixel of the patch's top-left corner.
    patches : list (one per core) of list of ndarray, float64, shape (h, w)
        ``[image]``, ``[image, d_du, d_dv]`` or ``[d_du, d_dv]`` of that PSF over the patch
        (inside the frame).

    Notes
    -----
    This function is long (~90 lines) because the two convolutions of one spot (the outer
    tail on the pixel grid, the inner kernel on the sub-pixel grid) write into one patch
    and share its origin, box and FFT sizes; they are kept together, in the order the
    comments mark, so the index arithmetic that places one inside the other is read in
    one place.
    """
    import scipy.fft as sfft

    H, W = int(shape[0]), int(shape[1])
    u = np.asarray(u_px, float).ravel()
    v = np.asarray(v_px, float).ravel()
    w = np.asarray(weight, float).ravel()
    if u.size == 0:
        return
    q, Rk, R = SPLAT_OVERSAMPLING, INNER_KERNEL_RADIUS_PX, AIRY_OUTER_RADIUS_PX
    which = [0, 1, 2] if gradient else [0]
    if gradient and not value:
        which = [1, 2]
    derivs = tuple((None, "u", "v")[i] for i in which)
    inner = [[fine_kernel(c.lam_over_d_px, c.aberration_sigma_px)[i] for i in which] for c in cores]
    outer = [_outer_kernel(c.lam_over_d_px, c.aberration_sigma_px) for c in cores]
    e_in = [c.drawn_energy for c in cores]
    for idx in point_clusters(u, v, H, W, R):
        uu, vv, ww = u[idx], v[idx], w[idx]
        # the outer tail: the samples' bilinear pixel image (and its shift derivatives) with
        # the outer kernel; the patch is that convolution's support
        x0, y0 = int(np.floor(uu.min())), int(np.floor(vv.min()))
        bw, bh = int(np.floor(uu.max())) - x0 + 2, int(np.floor(vv.max())) - y0 + 2
        boxes = bilinear_splats(uu, vv, ww, x0, y0, bw, bh, derivatives=derivs)
        # the outer kernel's reach that can land in the frame (a frame smaller than the kernel:
        # a window of the bound); what lies beyond would fall outside it - exact, not renormalised
        reach = max(x0 + bw - 1, W - 1 - x0, y0 + bh - 1, H - 1 - y0)
        Ro = int(min(R, max(reach, Rk)))
        ks_o = outer if Ro == R else [_outer_kernel_cropped(c.lam_over_d_px, c.aberration_sigma_px, Ro) for c in cores]
        sh_o = (bh + 2 * Ro, bw + 2 * Ro)
        fs_o = (ladder_len(sh_o[0]), ladder_len(sh_o[1]))
        Fb = [sfft.rfft2(b, fs_o) for b in boxes]
        PX, PY = x0 - Ro, y0 - Ro  # frame pixel of the patch's (0, 0)
        patches = [[sfft.irfft2(F * _kernel_spectrum(k, fs_o), fs_o)[:sh_o[0], :sh_o[1]] * (1.0 - e)
                    for F in Fb] for k, e in zip(ks_o, e_in)]
        # the inner part on the sub-pixel grid; pixel X of the full convolution sits at fine
        # index (X - X0) q + c, c = Rk q - 1: the first at X0 - Rk + 1, index q - 1
        X0, Y0 = int(np.floor(uu.min())) - 1, int(np.floor(vv.min())) - 1
        nx = int((np.floor(uu.max()) + 2 - X0) * q) + 1
        ny = int((np.floor(vv.max()) + 2 - Y0) * q) + 1
        B = bilinear_splats((uu - X0) * q, (vv - Y0) * q, ww, 0, 0, nx, ny)[0]
        kshape = inner[0][0].shape
        sh_i = (ny + kshape[0] - 1, nx + kshape[1] - 1)
        # only every q-th node of the fine convolution is read (the pixel centres): fold the
        # spectrum onto the coarse frequencies and invert at pixel resolution (exact: the
        # linear convolution fits the FFT grid, which is a multiple of q)
        fs_i = (q * ladder_len(-(-sh_i[0] // q)), q * ladder_len(-(-sh_i[1] // q)))
        FB = sfft.fft2(B, fs_i)
        n_y, n_x = -(-(sh_i[0] - (q - 1)) // q), -(-(sh_i[1] - (q - 1)) // q)
        iy, ix = (Y0 - Rk + 1) - PY, (X0 - Rk + 1) - PX  # the inner block's place in the patch (>= 0)
        for ch, ks, e in zip(patches, inner, e_in):
            for img, K in zip(ch, ks):
                Z = (FB * _decimating_spectrum(K, fs_i, q)).reshape(q, fs_i[0] // q, q, fs_i[1] // q).sum(axis=(0, 2))
                conv = sfft.ifft2(Z).real[:n_y, :n_x]
                img[iy:iy + n_y, ix:ix + n_x] += (e / (q * q)) * conv
        ys, xs = max(0, PY), max(0, PX)
        ye, xe = min(H, PY + sh_o[0]), min(W, PX + sh_o[1])
        if ye > ys and xe > xs:
            yield ys, xs, [[img[ys - PY:ye - PY, xs - PX:xe - PX] for img in ch] for ch in patches]


def _ladder() -> np.ndarray:
    """The FFT sizes of :func:`ladder_len`: every 2^a 3^b from 8 to 2^16, sorted."""
    sizes = sorted({2 ** a * 3 ** b for a in range(17) for b in range(11) if 8 <= 2 ** a * 3 ** b <= 1 << 16})
    return np.array(sizes, np.int64)


_LADDER = _ladder()


def ladder_len(n: int) -> int:
    """The smallest FFT size ``2^a 3^b`` (at least 8) not below ``n``.

    The splats' FFT grids are padded to these sizes, which lie 12-33 % apart, instead of the
    densest fast sizes: a spot that grows or shrinks a little from one frame to the next keeps its
    grid, so the kernels' spectra (:func:`_cached_spectrum`, ~4 ms each) are reused across the
    frames of a stream instead of made again for each. Any grid at least the linear
    convolution's size gives the same convolution (to rounding)."""
    n = int(n)
    if n > _LADDER[-1]:
        import scipy.fft as sfft

        return int(sfft.next_fast_len(n, real=True))
    return int(_LADDER[np.searchsorted(_LADDER, n)])


def point_clusters(u, v, H: int, W: int, margin_px: int) -> list:
    """Indices of the points grouped by spot: points within :data:`CLUSTER_CELL_PX` of each
    other share a window; points farther than ``margin_px`` outside the frame are dropped.

    Returns
    -------
    list of ndarray of int
    """
    from scipy import ndimage

    ok = (u >= -margin_px) & (u < W + margin_px) & (v >= -margin_px) & (v < H + margin_px)
    sel = np.flatnonzero(ok)
    if sel.size == 0:
        return []
    cs = CLUSTER_CELL_PX
    cx = np.floor(u[sel] / cs).astype(np.int64)
    cy = np.floor(v[sel] / cs).astype(np.int64)
    cx -= cx.min() - 1
    cy -= cy.min() - 1
    occ = np.zeros((int(cy.max()) + 2, int(cx.max()) + 2), bool)
    occ[cy, cx] = True
    lab, n = ndimage.label(ndimage.binary_dilation(occ, np.ones((3, 3), bool)), np.ones((3, 3), int))
    lp = lab[cy, cx]
    order = np.argsort(lp, kind="stable")
    bounds = np.searchsorted(lp[order], np.arange(1, n + 2))
    return [sel[order[bounds[i]:bounds[i + 1]]] for i in range(n) if bounds[i + 1] > bounds[i]]


_SPECTRA: dict = {}


def _cached_spectrum(k: np.ndarray, key: tuple, make) -> np.ndarray:
    """A kernel's spectrum ``make(k)``, kept by the kernel array and ``key`` (the kernels are
    cached arrays; their spectra are reused for every spot and frame)."""
    full = (id(k),) + key
    hit = _SPECTRA.get(full)
    if hit is None or hit[0] is not k:
        if len(_SPECTRA) > 256:
            _SPECTRA.clear()
        hit = (k, make(k))
        _SPECTRA[full] = hit
    return hit[1]


def _kernel_spectrum(k: np.ndarray, fs: tuple) -> np.ndarray:
    """The real-FFT spectrum of kernel ``k`` on an ``fs`` grid."""
    import scipy.fft as sfft

    return _cached_spectrum(k, ("rfft", fs), lambda a: sfft.rfft2(a, fs))


def _decimating_spectrum(k: np.ndarray, fs: tuple, q: int) -> np.ndarray:
    """The full 2-D spectrum of kernel ``k`` on an ``fs`` grid times the phase ramp that
    reads the convolution at offset ``q - 1``: multiplied by a signal's spectrum and folded
    q-fold per axis, it gives ``q^2 x`` the convolution sampled at ``q - 1 + q m``."""
    import scipy.fft as sfft

    def make(a):
        ry = np.exp(2j * np.pi * np.arange(fs[0]) * (q - 1) / fs[0])
        rx = np.exp(2j * np.pi * np.arange(fs[1]) * (q - 1) / fs[1])
        return sfft.fft2(a, fs) * ry[:, None] * rx[None, :]

    return _cached_spectrum(k, ("decimating", fs, q), make)
