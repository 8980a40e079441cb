"""Guided estimator of the flash seen through specular chains (the retro spots, glints).

Why: the LED is a ~1 mm disk. Seen through a cube at 40 m its image is 0.04 px wide,
so a camera ray sampled uniformly over a pixel and the aperture reaches it with
probability ~1e-3: brute-force path tracing needs ~1e7 samples per pixel for 1 %
radiometry. Here the camera rays are instead aimed at where the LED's image must be.

Method (an importance-sampled form of the same pixel integral the sensor estimates):
each *strategy* j is a virtual source ``X_j`` (the LED's image through a cube, a cube's
front face, or a mirror sphere - see :func:`svgs_sim.render.predict.virtual_sources`). A sample
draws an aperture point ``a`` uniformly, then a film position ``p`` uniformly in a disk
``B_j(a)`` of radius ``rho_j`` pixels around the image of ``X_j`` through ``a``; the
camera ray through ``(p, a)`` is traced through delta (glass, mirror) bounces only, and
scores the LED's radiance ``L0 cos^(m-1)`` if it then hits an LED disk (analytic
ray-disk test, no geometry in between). Each sample adds, to the pixel containing
``p``, ``L / sum_k N_k [p in B_k(a)] / (pi rho_k^2)`` - the balance heuristic over all
strategies (``N_k`` samples each), so overlapping disks (a glint on top of a retro
spot) are not counted twice. The result is the mean radiance over each pixel and the
aperture, like the sensor's, for every path whose first diffuse-free chain ends on
the LED inside some ``B_j``; ``rho_j`` is twice the LED image radius plus a margin.

Everything else (light that meets a diffuse surface) is rendered by Mitsuba's
``path`` integrator with the LED as a point light (:mod:`svgs_sim.render.scene`); the two parts
are disjoint and add up.
"""

from __future__ import annotations

import numpy as np

from .sampling import to_numpy

#: Ray-spawn offset at a delta bounce, metres (scaled by 1 + |p|).
EPS_M = 1e-6
#: How the guided samples are placed (:class:`SpotEstimator` ``sampler``).
SPOT_SAMPLERS = ("sobol", "kronecker", "independent")
_PHI4 = 1.1673039782614187  # the real root of x^5 = x + 1 (generalised golden ratio, d = 4)
R4_STEP_U32 = tuple(int(round(2.0**32 / _PHI4 ** (k + 1))) & 0xFFFFFFFF for k in range(4))


class SpotEstimator:
    """Traces the guided samples for one scene (strategy layout fixed at construction).

    Parameters
    ----------
    scene : mi.Scene
    model : svgs_sim.render.sensor.CameraModel
    n_strategies : int
        Fixed number of strategy slots (inactive ones get 0 samples).
    n_leds : int
    led_radius_m : float
    led_radiance_w_m2_sr : float
        On-axis radiance ``L0`` of each LED disk.
    cos_exponent : float
        LED profile ``I = I0 cos^m``, i.e. ``L = L0 cos^(m-1)``.
    max_depth : int
        Delta bounces followed at most.
    width, height : int
        Frame size (pixels).
    sampler : {"kronecker", "sobol", "independent"}
        How each strategy's samples draw their aperture point and film-disk offset (the four
        dimensions that place a sample on the film). ``"kronecker"`` (the renderer's default):
        the 4-D Kronecker (R4) sequence ``j alpha mod 1`` with a Cranley-Patterson shift per
        strategy hashed from the seed; ``"sobol"``: a scrambled (0, 2)-sequence per pair of
        dimensions (Mitsuba's ``radical_inverse_2`` / ``sobol_2``, the disk pair's index
        shuffled by a Kensler permutation); ``"independent"``: a PCG32 stream per lane (before
        issue 23). The same estimator and expectation in all three; the delta bounces' choices
        (Fresnel reflection or refraction) draw from PCG32 in each. A spot's centroid scatter
        across seeds at 10 m, 2^14 samples (``tools/render_noise.py``): 0.00035 px (kronecker),
        0.00059 (sobol), 0.00082 (independent).
    """

    def __init__(self, scene, model, n_strategies, n_leds, led_radius_m, led_radiance_w_m2_sr, cos_exponent,
                 max_depth, width, height, sampler: str = "kronecker"):
        import drjit as dr
        import mitsuba as mi

        self.mi, self.dr = mi, dr
        self.jit = dr.is_jit_v(mi.Float)
        self.scene, self.model = scene, model
        self.K = int(n_strategies)
        self.n_leds = int(n_leds)
        self.r_led = float(led_radius_m)
        self.L0 = float(led_radiance_w_m2_sr)
        self.m = float(cos_exponent)
        self.max_depth = int(max_depth)
        self.W, self.H = int(width), int(height)
        if sampler not in SPOT_SAMPLERS:
            raise ValueError(f"sampler: expected one of {SPOT_SAMPLERS}, got {sampler!r}")
        self.sampler = sampler

    def _arr(self, values):
        mi, dr = self.mi, self.dr
        a = mi.Float(np.asarray(values, np.float64).astype(np.float32).tolist())
        dr.make_opaque(a)
        return a

    def render(self, sources_cam, radii_px, counts, led_centres_world, led_normal_world, seed: int) -> np.ndarray:
        """Estimate the specular-chain radiance image.

        Parameters
        ----------
        sources_cam : ndarray, shape (K, 3)
            Virtual source of each strategy, camera frame, m (z > 0).
        radii_px : ndarray, shape (K,)
            Sampling disk radius of each strategy, pixels.
        counts : ndarray of int, shape (K,)
            Samples per strategy (0 = inactive).
        led_centres_world : ndarray, shape (n_leds, 3)
        led_normal_world : ndarray, shape (3,)
        seed : int

        Returns
        -------
        img : ndarray, shape (H, W), float64
            Mean radiance per pixel (W m^-2 sr^-1): the samples binned into the pixels that
            contain them.
        samples : tuple of ndarray, each shape (M,)
            ``(u_px, v_px, radiance)`` of every scoring sample inside the frame: its film
            position and what it adds to its pixel's mean radiance (``img`` is their sum per
            pixel). The camera model convolves these with the lens PSF before pixel
            integration, so their sub-pixel position survives.
        """
        counts = np.asarray(counts, np.int64)
        total = int(counts.sum())
        img = np.zeros((self.H, self.W))
        if total == 0:
            return img, (np.zeros(0), np.zeros(0), np.zeros(0))
        if not self.jit:
            return self._render_scalar(sources_cam, radii_px, counts, led_centres_world, led_normal_world, seed)
        strat, sx, sy, sz, rr, dens = self._upload_strategies(sources_cam, radii_px, counts)
        lc, ln = self._upload_leds(led_centres_world, led_normal_world)
        rng = self._lane_rng(total, seed)
        film = self._film_samples(rng, counts, strat, seed)
        a, u, v, denom = self._sample_film(film, strat, sx, sy, sz, rr, dens)
        result = self._trace_to_leds(self.model.ray(u, v, a), rng, lc, ln)
        return self._splat(u, v, result, denom)

    def _upload_strategies(self, sources_cam, radii_px, counts):
        """The strategies as opaque Dr.Jit arrays and each lane's strategy index.

        Returns
        -------
        strat : mi.UInt32, shape (sum(counts),)
        sx, sy, sz, rr, dens : mi.Float, shape (K,)
            Virtual sources (camera frame, m), disk radii (px), sample densities
            ``N_k / (pi rho_k^2)`` (per px^2).
        """
        mi = self.mi
        src = np.asarray(sources_cam, float)
        rad = np.asarray(radii_px, float)
        sx, sy, sz = self._arr(src[:, 0]), self._arr(src[:, 1]), self._arr(src[:, 2])
        rr = self._arr(rad)
        dens = self._arr(np.where(rad > 0, counts / (np.pi * np.maximum(rad, 1e-30) ** 2), 0.0))
        strat = mi.UInt32(np.repeat(np.arange(self.K, dtype=np.uint32), counts))
        return strat, sx, sy, sz, rr, dens

    def _upload_leds(self, led_centres_world, led_normal_world):
        """LED disk centres (list of mi.Point3f) and their common normal (mi.Vector3f), opaque."""
        mi, dr = self.mi, self.dr
        leds = np.asarray(led_centres_world, float)
        lc = [mi.Point3f(*p.tolist()) for p in leds]
        ln = mi.Vector3f(*np.asarray(led_normal_world, float).tolist())
        dr.make_opaque(ln, *lc)
        return lc, ln

    def _lane_rng(self, total: int, seed: int):
        """One PCG32 stream per lane, decorrelated: Mitsuba's independent-sampler hashing
        (PCG streams that differ only by consecutive increments are correlated); opaque
        seeds so that a new seed does not mean a new kernel."""
        mi, dr = self.mi, self.dr
        ss = np.random.SeedSequence(int(seed)).generate_state(2, dtype=np.uint64)
        lane = dr.arange(mi.UInt32, total)
        s0 = dr.opaque(mi.UInt32, int(ss[0] & 0xFFFFFFFF))
        s1 = dr.opaque(mi.UInt32, int(ss[1] & 0xFFFFFFFF))
        v0, v1 = mi.sample_tea_32(s0, lane)
        w0, w1 = mi.sample_tea_32(s1, lane)
        return mi.PCG32(size=total, initstate=mi.UInt64(v0) << 32 | mi.UInt64(v1), initseq=mi.UInt64(w0) << 32 | mi.UInt64(w1))

    def _film_samples(self, rng, counts, strat, seed: int):
        """The four uniform numbers of each lane that place it on the film: ``(aperture
        pair, disk pair)`` as two mi.Point2f (see ``sampler``)."""
        mi, dr = self.mi, self.dr
        if self.sampler == "independent":
            ap = mi.Point2f(rng.next_float32(), rng.next_float32())
            return ap, mi.Point2f(rng.next_float32(), rng.next_float32())
        # the lane's index within its strategy: lane - the strategy's first lane
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.uint32)
        first = mi.UInt32(starts.tolist())
        dr.make_opaque(first)
        lane = dr.arange(mi.UInt32, int(counts.sum()))
        j = lane - dr.gather(mi.UInt32, first, strat)
        ss = np.random.SeedSequence([int(seed), 0x50B01]).generate_state(2, dtype=np.uint32)
        k0 = dr.opaque(mi.UInt32, int(ss[0]))
        k1 = dr.opaque(mi.UInt32, int(ss[1]))
        s0, s1 = mi.sample_tea_32(strat, k0)
        s2, s3 = mi.sample_tea_32(strat, k1)
        if self.sampler == "kronecker":
            # the 4-D Kronecker (R4) sequence j * alpha mod 1, alpha_k = phi_4^-k, with a
            # Cranley-Patterson shift per strategy, in 32-bit fixed point
            sh = (s0, s1, s2, s3)
            x = [mi.Float(j * R4_STEP_U32[k] + sh[k]) * (2.0**-32) for k in range(4)]
            one = 1.0 - 2.0**-24
            x = [dr.minimum(c, one) for c in x]
            return mi.Point2f(x[0], x[1]), mi.Point2f(x[2], x[3])
        n = int(counts[counts > 0][0])  # the Kensler permutation's length: one for all strategies
        if np.any(counts[counts > 0] != n):
            raise ValueError("sampler 'sobol': every active strategy needs the same number of samples")
        jp = mi.permute_kensler(j, n, s2)
        ap = mi.Point2f(mi.radical_inverse_2(j, s0), mi.sobol_2(j, s1))
        dk = mi.Point2f(mi.radical_inverse_2(jp, s3), mi.sobol_2(jp, s3 ^ 0x9E3779B9))
        return ap, dk

    def _sample_film(self, film, strat, sx, sy, sz, rr, dens):
        """Per lane: an aperture point, a film position in its strategy's disk and the
        balance-heuristic density over all strategies. ``film``: the lanes' ``(aperture pair,
        disk pair)`` of uniform numbers (:meth:`_film_samples`).

        Returns
        -------
        a : mi.Point3f
            Aperture point.
        u, v : mi.Float
            Film position, px.
        denom : mi.Float
            ``sum_k N_k [p in B_k(a)] / (pi rho_k^2)``.
        """
        mi, dr = self.mi, self.dr
        model = self.model
        a = model.aperture_point(film[0])
        Xj = mi.Vector3f(dr.gather(mi.Float, sx, strat), dr.gather(mi.Float, sy, strat), dr.gather(mi.Float, sz, strat))
        uc, vc = model.image_of(Xj, a)
        disk = mi.warp.square_to_uniform_disk_concentric(film[1])
        rj = dr.gather(mi.Float, rr, strat)
        u = uc + disk.x * rj
        v = vc + disk.y * rj
        # balance heuristic over all strategies
        denom = mi.Float(0.0)
        for k in range(self.K):
            Xk = mi.Vector3f(dr.gather(mi.Float, sx, mi.UInt32(k)), dr.gather(mi.Float, sy, mi.UInt32(k)),
                             dr.gather(mi.Float, sz, mi.UInt32(k)))
            uk, vk = model.image_of(Xk, a)
            rk = dr.gather(mi.Float, rr, mi.UInt32(k))
            inside = dr.square(u - uk) + dr.square(v - vk) <= dr.square(rk)
            denom += dr.select(inside, dr.gather(mi.Float, dens, mi.UInt32(k)), 0.0)
        return a, u, v, denom

    def _trace_to_leds(self, ray, rng, lc, ln):
        """Follow delta (glass, mirror) bounces until a ray meets an LED disk first (scoring
        ``L0 cos^(m-1)`` times the path throughput) or anything else; symbolic loop, finished
        lanes stop. Returns the score per lane (mi.Float)."""
        mi, dr = self.mi, self.dr
        ctx = mi.BSDFContext()
        r2 = self.r_led * self.r_led
        L0, m_1 = self.L0, self.m - 1.0

        def cond(ray, beta, result, active, depth, rng):
            return active & (depth <= self.max_depth)

        def body(ray, beta, result, active, depth, rng):
            t_led = mi.Float(dr.inf)
            cos_led = mi.Float(0.0)
            dn = dr.dot(ray.d, ln)
            for c in lc:
                t = dr.dot(c - ray.o, ln) / dn
                hit = (dn < 0) & (t > 1e-6) & (dr.squared_norm(ray.o + ray.d * t - c) <= r2)
                closer = hit & (t < t_led)
                t_led = dr.select(closer, t, t_led)
                cos_led = dr.select(closer, -dn, cos_led)
            si = self.scene.ray_intersect(ray, active)
            led_first = active & (t_led < si.t)
            emit = L0 * dr.power(cos_led, m_1) if m_1 != 0.0 else mi.Float(L0)
            result = dr.select(led_first, result + beta * emit, result)
            active = active & ~led_first & si.is_valid()
            bsdf = si.bsdf(ray)
            active = active & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta)
            bs, w = bsdf.sample(ctx, si, rng.next_float32(active), mi.Point2f(rng.next_float32(active), rng.next_float32(active)), active)
            beta = dr.select(active, beta * w[0], beta)
            active = active & (beta > 0)
            # spawn with a small offset: Mitsuba's spawn_ray moves the origin by
            # (1 + |p|) * 8.9e-5 m, which loses the paths that meet a cube face within
            # ~0.1 mm of an inner edge (a few % of a retro return); the world here is
            # the target frame (|p| < 1 m), where 1e-6 m is ~70 float32 ulps
            wo = si.to_world(bs.wo)
            eps = dr.mulsign(EPS_M * (1.0 + dr.max(dr.abs(si.p))), dr.dot(si.n, wo))
            new = mi.Ray3f(dr.fma(si.n, eps, si.p), wo)
            ray = dr.select(active, new, ray)
            return ray, beta, result, active, depth + 1, rng

        ray, beta, result, active, depth, rng = dr.while_loop(
            (ray, mi.Float(1.0), mi.Float(0.0), mi.Bool(True), mi.UInt32(0), rng), cond, body)
        return result

    def _splat(self, u, v, result, denom):
        """Each lane's ``result / denom`` added to the pixel containing ``(u, v)``: the
        radiance image, float64 (H, W), and the scoring samples ``(u, v, value)``."""
        mi, dr = self.mi, self.dr
        val = result / denom
        ui = mi.Int32(dr.floor(u + 0.5))
        vi = mi.Int32(dr.floor(v + 0.5))
        ok = (ui >= 0) & (ui < self.W) & (vi >= 0) & (vi < self.H) & (result > 0) & (denom > 0)
        idx = dr.select(ok, mi.UInt32(vi) * self.W + mi.UInt32(ui), 0)
        val = dr.select(ok, val, 0.0)
        dr.eval(idx, val, u, v)
        idx_np = to_numpy(idx, np.int64)
        val_np = to_numpy(val, np.float64)
        nz = val_np > 0
        img = np.zeros((self.H, self.W))
        if np.any(nz):  # binned over the samples' box only
            iy, ix = np.divmod(idx_np[nz], self.W)
            y0, x0 = int(iy.min()), int(ix.min())
            h, w = int(iy.max()) - y0 + 1, int(ix.max()) - x0 + 1
            img[y0:y0 + h, x0:x0 + w] = np.bincount((iy - y0) * w + (ix - x0), weights=val_np[nz],
                                                    minlength=h * w).reshape(h, w)
        samples = (to_numpy(u, np.float64)[nz], to_numpy(v, np.float64)[nz], val_np[nz])
        return img, samples

    def _render_scalar(self, sources_cam, radii_px, counts, led_centres_world, led_normal_world, seed):
        """Same estimator, one sample at a time (scalar variants; slow)."""
        mi = self.mi
        rng = np.random.default_rng(seed)
        src = np.asarray(sources_cam, float)
        rad = np.asarray(radii_px, float)
        dens = np.where(rad > 0, counts / (np.pi * np.maximum(rad, 1e-30) ** 2), 0.0)
        leds = np.asarray(led_centres_world, float)
        ln = np.asarray(led_normal_world, float)
        img = np.zeros((self.H, self.W))
        su, sv, sval = [], [], []
        model = self.model
        ctx = mi.BSDFContext()

        def image_np(X, a):
            u, v = model.image_of(mi.ScalarVector3f(*X), mi.ScalarVector3f(a[0], a[1], 0.0))
            return float(u), float(v)

        for k in range(self.K):
            for _ in range(int(counts[k])):
                r1 = rng.random(4)
                a2 = mi.warp.square_to_uniform_disk_concentric(mi.ScalarPoint2f(r1[0], r1[1])) * model.get(9)
                a = (float(a2[0]), float(a2[1]))
                uc, vc = image_np(src[k], a)
                dd = mi.warp.square_to_uniform_disk_concentric(mi.ScalarPoint2f(r1[2], r1[3]))
                u, v = uc + float(dd[0]) * rad[k], vc + float(dd[1]) * rad[k]
                den = 0.0
                for j in range(self.K):
                    if dens[j] > 0:
                        uj, vj = image_np(src[j], a)
                        if (u - uj) ** 2 + (v - vj) ** 2 <= rad[j] ** 2:
                            den += dens[j]
                ray = model.ray(u, v, mi.ScalarVector3f(a[0], a[1], 0.0))
                score = self._scalar_trace(ray, rng, leds, ln, ctx)
                if score is not None:
                    ui, vi = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
                    if 0 <= ui < self.W and 0 <= vi < self.H and den > 0 and score > 0:
                        img[vi, ui] += score / den
                        su.append(u)
                        sv.append(v)
                        sval.append(score / den)
        return img, (np.asarray(su, float), np.asarray(sv, float), np.asarray(sval, float))

    def _scalar_trace(self, ray, rng, leds, ln, ctx):
        """One scalar ray through delta bounces: ``beta L0 cos^(m-1)`` if it meets an LED disk
        first, None if it escapes, meets a non-delta surface or loses its throughput."""
        mi = self.mi
        beta = 1.0
        for _depth in range(self.max_depth + 1):
            o = to_numpy(ray.o)
            d = to_numpy(ray.d)
            dn = float(d @ ln)
            t_led, cos_led = np.inf, 0.0
            for c in leds:
                if dn < 0:
                    t = float((c - o) @ ln) / dn
                    if t > 1e-6 and np.sum((o + d * t - c) ** 2) <= self.r_led ** 2 and t < t_led:
                        t_led, cos_led = t, -dn
            si = self.scene.ray_intersect(ray)
            if t_led < float(si.t):
                return beta * self.L0 * cos_led ** (self.m - 1.0)
            if not si.is_valid():
                return None
            bsdf = si.bsdf()
            if not mi.has_flag(bsdf.flags(), mi.BSDFFlags.Delta):
                return None
            r2 = rng.random(3)
            bs, w = bsdf.sample(ctx, si, float(r2[0]), mi.ScalarPoint2f(r2[1], r2[2]))
            beta *= float(np.mean(to_numpy(w)))
            if beta <= 0:
                return None
            wo = si.to_world(bs.wo)
            eps = EPS_M * (1.0 + float(np.max(np.abs(to_numpy(si.p)))))
            eps = eps if float(np.dot(to_numpy(si.n), to_numpy(wo))) >= 0 else -eps
            ray = mi.Ray3f(si.p + si.n * eps, wo)
        return None
