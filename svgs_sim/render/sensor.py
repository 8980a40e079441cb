"""A Mitsuba sensor that is exactly the OpenCV camera of a profile, with a thin lens.

Why a custom sensor instead of ``thinlens`` + ``hdrfilm`` crop:

- it maps film positions to rays with the profile's ``fx, fy, cx, cy`` and Brown-Conrady
  distortion (inverted by a fixed-point iteration, as OpenCV's ``undistortPoints``), so
  ``targets_px`` from :meth:`svgs_sim.svgs.Camera.project_target` is where the image of a point
  lands, with no resampling step;
- it renders any set of equally-sized **windows** of the full frame as one film (a
  vertical mosaic of ``n`` windows of ``w x h`` pixels): the window origins live in
  opaque Dr.Jit arrays, so moving windows between frames recompiles nothing
  (mitsuba3 #399), and crop offsets never meet the principal point (mitsuba3 #236);
- the pose lives in opaque arrays too (:class:`CameraModel`, shared with the spot
  estimator of :mod:`svgs_sim.render.spots`), updated in place between frames.

Pixel convention: OpenCV's (pixel centres at integer coordinates); the film's
continuous coordinate ``p`` maps to ``u = p - 0.5``. Ray weight is 1: pixel values are
mean radiance over the pixel and the lens aperture.

Only usable after :func:`svgs_sim.render.variant.select_variant` (it subclasses ``mi.Sensor``).
"""

from __future__ import annotations

import numpy as np

PLUGIN_NAME = "svgs_opencv_thinlens"
_CLASSES: dict = {}


class CameraModel:
    """Camera parameters as (opaque) Dr.Jit values, and the film -> ray map.

    Parameters
    ----------
    camera : svgs.Camera
    aperture_radius_m, focus_distance_m : float
    undistort_iterations : int
        Fixed-point iterations of the distortion inversion (as OpenCV).
    """

    def __init__(self, camera, aperture_radius_m, focus_distance_m, undistort_iterations=20):
        import drjit as dr
        import mitsuba as mi

        self.mi, self.dr = mi, dr
        self.jit = dr.is_jit_v(mi.Float)
        self.has_dist = bool(camera.has_distortion)
        self.iters = int(undistort_iterations)
        self.values = [float(x) for x in camera.dist] + [camera.fx, camera.fy, camera.cx, camera.cy,
                                                         float(aperture_radius_m), float(focus_distance_m)]
        if self.jit:
            self._k = mi.Float(self.values)
            dr.make_opaque(self._k)
        self.set_pose(np.eye(3), np.zeros(3))

    def get(self, i):
        if self.jit:
            return self.dr.gather(self.mi.Float, self._k, self.mi.UInt32(i))
        return self.values[i]

    def set_pose(self, R_world_cam, p_world_cam_m):
        """Camera-to-world rotation (3, 3) and lens centre in the world frame (3,), m."""
        mi, dr = self.mi, self.dr
        self.R_np = np.asarray(R_world_cam, float).copy()
        self.p_np = np.asarray(p_world_cam_m, float).copy()
        self.R = mi.Matrix3f(self.R_np.tolist())
        self.p = mi.Point3f(*self.p_np.tolist())
        if self.jit:
            dr.make_opaque(self.R, self.p)

    def undistort(self, u, v):
        """OpenCV pixel coordinates -> undistorted normalised coordinates (x, y)."""
        fx, fy, cx, cy = (self.get(i) for i in (5, 6, 7, 8))
        xd = (u - cx) / fx
        yd = (v - cy) / fy
        x, y = xd, yd
        if self.has_dist:
            k1, k2, p1, p2, k3 = (self.get(i) for i in range(5))
            for _ in range(self.iters):
                r2 = x * x + y * y
                icdist = 1.0 / (1.0 + ((k3 * r2 + k2) * r2 + k1) * r2)
                dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
                dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
                x = (xd - dx) * icdist
                y = (yd - dy) * icdist
        return x, y

    def distort_to_pixels(self, x, y):
        """Undistorted normalised coordinates -> OpenCV pixel coordinates (u, v)."""
        fx, fy, cx, cy = (self.get(i) for i in (5, 6, 7, 8))
        if self.has_dist:
            k1, k2, p1, p2, k3 = (self.get(i) for i in range(5))
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
            yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        else:
            xd, yd = x, y
        return fx * xd + cx, fy * yd + cy

    def aperture_point(self, sample):
        """Uniform point on the aperture disk (camera frame, z = 0) from a 2D sample."""
        mi = self.mi
        a = mi.warp.square_to_uniform_disk_concentric(sample) * self.get(9)
        return mi.Vector3f(a.x, a.y, 0.0)

    def ray(self, u, v, a_cam):
        """World-space ray through pixel coordinates (u, v) and aperture point ``a_cam``."""
        mi, dr = self.mi, self.dr
        x, y = self.undistort(u, v)
        fd = self.get(10)
        focus = mi.Vector3f(x * fd, y * fd, fd)
        d_cam = dr.normalize(focus - a_cam)
        ray = mi.Ray3f()
        ray.o = mi.Point3f(self.R @ a_cam) + self.p
        ray.d = self.R @ d_cam
        return ray

    def image_of(self, X_cam, a_cam):
        """Pixel (u, v) where a point ``X_cam`` (camera frame) is imaged through aperture
        point ``a_cam`` by the thin lens (the ray a -> X meets the focus plane)."""
        fd = self.get(10)
        s = fd / X_cam.z
        xf = a_cam.x + (X_cam.x - a_cam.x) * s
        yf = a_cam.y + (X_cam.y - a_cam.y) * s
        return self.distort_to_pixels(xf / fd, yf / fd)


def sensor_class():
    """The sensor class for the current variant (registered as :data:`PLUGIN_NAME`)."""
    import drjit as dr
    import mitsuba as mi

    if mi.variant() in _CLASSES:
        return _CLASSES[mi.variant()]
    jit = dr.is_jit_v(mi.Float)

    class OpenCVThinLens(mi.Sensor):
        """OpenCV pinhole + distortion geometry, thin-lens aperture, window mosaic."""

        def __init__(self, props):
            super().__init__(props)
            self.m_needs_sample_3 = True
            self.role = str(props.get("svgs_role", ""))
            self.model = None
            self.set_windows(np.zeros((1, 2)), self.film().size()[1])

        def set_model(self, model: CameraModel):
            self.model = model

        def set_windows(self, origins_px, window_height):
            """Origins (film coords of the top-left corner) of the stacked windows, shape (n, 2)."""
            o = np.asarray(origins_px, float).reshape(-1, 2)
            self._n_windows = o.shape[0]
            self._win_h = float(window_height)
            if jit:
                self._ox = mi.Float(o[:, 0].tolist())
                self._oy = mi.Float(o[:, 1].tolist())
                dr.make_opaque(self._ox, self._oy)
            else:
                self._ox, self._oy = o[:, 0].tolist(), o[:, 1].tolist()

        def _ray(self, time, sample2, sample3):
            fs = self.film().size()
            px = sample2.x * float(fs[0])
            py = sample2.y * float(fs[1])
            if jit:
                w = dr.minimum(mi.UInt32(dr.floor(py / self._win_h)), self._n_windows - 1)
                ox = dr.gather(mi.Float, self._ox, w)
                oy = dr.gather(mi.Float, self._oy, w)
                py = py - mi.Float(w) * self._win_h
            else:
                w = min(int(py // self._win_h), self._n_windows - 1)
                ox, oy = self._ox[w], self._oy[w]
                py = py - w * self._win_h
            ray = self.model.ray(ox + px - 0.5, oy + py - 0.5, self.model.aperture_point(sample3))
            ray.time = time
            return ray

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            return self._ray(time, sample2, sample3), mi.Spectrum(1.0)

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            rd = mi.RayDifferential3f(self._ray(time, sample2, sample3))
            rd.has_differentials = False
            return rd, mi.Spectrum(1.0)

        def bbox(self):
            p = self.model.p_np if self.model is not None else np.zeros(3)
            return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(*p.tolist()))

        def to_string(self):
            return f"OpenCVThinLens[role={self.role}, windows={self._n_windows}]"

    mi.register_sensor(PLUGIN_NAME, lambda props: OpenCVThinLens(props))
    _CLASSES[mi.variant()] = OpenCVThinLens
    return OpenCVThinLens
