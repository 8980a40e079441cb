"""Geometric-optics predictions the renders are tested against (numpy only).

Retro return (``shared/notes/physics.md`` section 1-2). A perfect corner cube maps the
incoming ray line to its point reflection through the (apparent) vertex V, so the
flash S seen through the cube is a virtual source at ``S' = 2V - S``; back at the
phone the return irradiance inside the footprint is

- hollow, mirror reflectance r: ``E = r^3 I / |S' - C|^2``,
- solid uncoated glass, normal incidence: ``E = I / |S' - C|^2 * (T^2 / (1 - R_F) + R_F)``
  (``R_F = ((n-1)/(n+1))^2``, ``T = 1 - R_F``): the retro pass ``T^2``, light that goes
  round the cube again after an internal reflection at the front face
  (``T^2 R_F / (1 - R_F)``) and the front-face glint ``R_F``. Lossless: the sum is 1.
  Away from normal incidence the last two leave along the *specular* direction and
  form a separate weak spot (or miss the lens).

``I`` is the flash's radiant intensity towards the cube, ``C`` the lens centre. The
footprint is the cube aperture scaled by 2 about S (a disk ~2D across, centred on the
flash): the lens sees the return only if it lies inside.

Spot position: the light reaching the lens centre C left the cube along the ray that,
traced backwards, is the retro-reflection of a ray from S. :func:`spot_direction_cam`
solves for it exactly (refraction at the front face included); the spot's centroid is
the projection of that direction. For a hollow cube it is the projection of
``2V - S``: relative to the projection of V the spot moves by about ``-f * s / (2 Z)``
for a flash offset ``s`` at range ``Z`` - the flash-to-lens shift.
"""

from __future__ import annotations

import numpy as np

from .geometry import Reflector


def fresnel_normal(n: float) -> float:
    """Normal-incidence Fresnel reflectance of an uncoated surface of index ``n``."""
    return ((n - 1.0) / (n + 1.0)) ** 2


def retro_factor(refl: Reflector, band_nm=(400.0, 700.0)) -> float:
    """Fraction of ``I / |S'-C|^2`` a cube returns at normal incidence (see module doc)."""
    if refl.kind == "hollow":
        return float(refl.mirror_reflectance ** 3)
    rf = fresnel_normal(refl.index(band_nm))
    t = 1.0 - rf
    return float(t * t / (1.0 - rf) + rf)


def retro_pass_factor(refl: Reflector, band_nm=(400.0, 700.0)) -> float:
    """Fraction returned along the retro path only (no front-face glint or second round)."""
    if refl.kind == "hollow":
        return float(refl.mirror_reflectance ** 3)
    t = 1.0 - fresnel_normal(refl.index(band_nm))
    return float(t * t)


def _refract(d, n_out, eta):
    """Refract unit direction ``d`` at a surface whose normal ``n_out`` points against ``d``.

    ``eta`` = n_incident / n_transmitted. Returns the unit transmitted direction.
    """
    cosi = -float(d @ n_out)
    k = 1.0 - eta * eta * (1.0 - cosi * cosi)
    if k < 0:
        return None
    return eta * d + (eta * cosi - np.sqrt(k)) * n_out


def retro_exit_ray(P, S, V_phys, F, axis, n_glass):
    """Trace a ray from ``S`` entering the cube at ``P`` (on the front plane) through a
    perfect cube. All vectors in one frame (3,).

    Returns
    -------
    Q : ndarray (3,)
        Exit point on the front plane.
    d_out : ndarray (3,)
        Exit direction (= minus the incoming direction for a perfect cube).
    """
    d = P - S
    d = d / np.linalg.norm(d)
    di = _refract(d, axis, 1.0 / n_glass) if n_glass != 1.0 else d
    if di is None:
        return None, None
    X = 2.0 * V_phys - P  # point-reflection of the inside line through the vertex
    s = float((F - X) @ axis) / float(-di @ axis)
    Q = X - s * di
    return Q, -d


def spot_direction_cam(S_cam, V_phys_cam, axis_cam, refl: Reflector, band_nm=(400.0, 700.0), C_cam=None,
                       iterations=20) -> np.ndarray:
    """Direction (unit, camera frame) along which the lens centre sees the flash through a cube.

    Parameters
    ----------
    S_cam : ndarray, shape (3,)
        LED centre, camera frame (m).
    V_phys_cam : ndarray, shape (3,)
        Physical vertex of the cube, camera frame (m).
    axis_cam : ndarray, shape (3,)
        Cube axis (out of the front face), camera frame.
    refl : Reflector
    C_cam : ndarray, shape (3,), optional
        Lens centre (default origin).

    Returns
    -------
    ndarray, shape (3,)
        Unit vector from ``C`` towards the apparent source (point it through the camera
        model to get the spot's pixel).
    """
    C = np.zeros(3) if C_cam is None else np.asarray(C_cam, float)
    S = np.asarray(S_cam, float)
    V = np.asarray(V_phys_cam, float)
    a = np.asarray(axis_cam, float)
    a = a / np.linalg.norm(a)
    n = refl.index(band_nm)
    F = V + refl.height_m * a
    # plane basis
    e1 = np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)

    def miss(uv):
        P = F + uv[0] * e1 + uv[1] * e2
        Q, dout = retro_exit_ray(P, S, V, F, a, n)
        # closest approach of the exit ray to C, in the plane basis of the exit direction
        w = C - Q
        r = w - (w @ dout) * dout
        return np.array([r @ e1, r @ e2]), Q

    uv = np.zeros(2)
    for _ in range(iterations):
        f0, _q = miss(uv)
        if np.max(np.abs(f0)) < 1e-13:
            break
        J = np.empty((2, 2))
        h = 1e-7
        for j in range(2):
            du = np.zeros(2)
            du[j] = h
            J[:, j] = (miss(uv + du)[0] - f0) / h
        uv = uv - np.linalg.solve(J, f0)
    _, Q = miss(uv)
    d = Q - C
    return d / np.linalg.norm(d)


def virtual_source_cam(S_cam, V_ref_cam) -> np.ndarray:
    """``2V - S``: the flash's image through a perfect (hollow, or paraxial solid) cube."""
    return 2.0 * np.asarray(V_ref_cam, float) - np.asarray(S_cam, float)


def retro_irradiance_w_m2(intensity_w_sr, S_cam, V_ref_cam, refl: Reflector, band_nm=(400.0, 700.0),
                          C_cam=None, retro_only=False) -> float:
    """Return irradiance at the lens (normal to the line of sight), W/m^2.

    ``factor * I / |2V - S - C|^2`` with the factor of :func:`retro_factor` (or
    :func:`retro_pass_factor` when ``retro_only``). Valid when the lens is inside the
    return footprint.
    """
    C = np.zeros(3) if C_cam is None else np.asarray(C_cam, float)
    dist = np.linalg.norm(virtual_source_cam(S_cam, V_ref_cam) - C)
    f = retro_pass_factor(refl, band_nm) if retro_only else retro_factor(refl, band_nm)
    return float(f * intensity_w_sr / dist ** 2)


def mirror_point(X, plane_point, normal) -> np.ndarray:
    """Mirror image of point ``X`` through a plane."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    X = np.asarray(X, float)
    return X - 2.0 * ((X - plane_point) @ n) * n


def _line_hits_disk(A, B, centre, normal, radius) -> bool:
    """Does the segment/line A->B cross the plane (centre, normal) within ``radius``?"""
    d = B - A
    dn = float(d @ normal)
    if abs(dn) < 1e-15:
        return False
    s = float((centre - A) @ normal) / dn
    P = A + s * d
    return bool(np.linalg.norm(P - centre) <= radius)


def sphere_glint(S, C, O, radius, iterations=30):
    """Glint point of a mirror sphere (centre O) reflecting S towards C, and the LED's image.

    Returns
    -------
    G : ndarray (3,)
        Point on the sphere where the normal bisects the directions to S and C.
    image_distance : float
        Depth of the virtual image behind the surface along the line of sight (convex
        mirror, focal length R/2): ``R/2 * dS / (dS + R/2)`` for a source at ``dS``.
    magnification : float
        Image size / source size.
    """
    S, C, O = (np.asarray(x, float) for x in (S, C, O))
    n = (S - O) / np.linalg.norm(S - O) + (C - O) / np.linalg.norm(C - O)
    n /= np.linalg.norm(n)
    for _ in range(iterations):
        G = O + radius * n
        n_new = (S - G) / np.linalg.norm(S - G) + (C - G) / np.linalg.norm(C - G)
        n_new /= np.linalg.norm(n_new)
        if np.linalg.norm(n_new - n) < 1e-14:
            n = n_new
            break
        n = n_new
    G = O + radius * n
    dS = np.linalg.norm(S - G)
    f = 0.5 * radius
    di = f * dS / (dS + f)
    return G, di, di / dS


def virtual_sources(camera, flash, refl: Reflector, band_nm, vertices_cam, axes_cam, glints_cam=(),
                    margin_px=0.02, image_factor=1.5, footprint_margin_m=0.003):
    """Sampling strategies of the guided spot estimator (see :mod:`svgs_sim.render.spots`).

    Slots, in order: for each cube i and LED l, ``[retro, specular front face, specular
    second round]``; then for each mirror sphere g and LED l, ``[glint]``.

    Parameters
    ----------
    camera : svgs.Camera
    flash : svgs_sim.render.optics.Flash
    refl : Reflector
    band_nm : tuple
    vertices_cam : ndarray, shape (N, 3)
        Physical cube vertices, camera frame (m).
    axes_cam : ndarray, shape (N, 3)
        Cube axes, camera frame.
    glints_cam : sequence of (centre (3,), radius)
        Mirror spheres, camera frame (m).
    margin_px : float
        Added to the sampling-disk radius, pixels.
    image_factor : float
        Sampling-disk radius in units of the LED image radius.
    footprint_margin_m : float
        A specular strategy is active when the line from its virtual source to the lens
        crosses the cube's front plane within ``radius + footprint_margin_m``.

    Returns
    -------
    sources : ndarray, shape (K, 3)
    radii_px : ndarray, shape (K,)
    active : ndarray of bool, shape (K,)
    labels : list of str
    """
    C = np.zeros(3)
    r_led = 0.5 * flash.emitter_diameter_m
    fmax = max(camera.fx, camera.fy)
    src, rad, act, lab = [], [], [], []

    def add(X, img_radius_m, on, label):
        X = np.asarray(X, float)
        dist = np.linalg.norm(X - C)
        ok = bool(on and X[2] > 1e-6)
        src.append(X if ok else np.array([0.0, 0.0, 1.0]))
        rad.append(image_factor * fmax * img_radius_m / max(dist, 1e-9) + margin_px)
        act.append(ok)
        lab.append(label)

    for i, (V, a) in enumerate(zip(np.asarray(vertices_cam, float), np.asarray(axes_cam, float))):
        a = a / np.linalg.norm(a)
        F = V + refl.height_m * a
        V_ref = F - refl.reference_depth_m(band_nm) * a
        for li, S in enumerate(flash.led_offsets_m):
            facing = float((S - F) @ a) > 0
            d = spot_direction_cam(S, V, a, refl, band_nm) if facing else np.array([0.0, 0.0, 1.0])
            dist = np.linalg.norm(virtual_source_cam(S, V_ref) - C)
            add(C + d * dist, r_led, facing, f"cube{i}:led{li}:retro")
            for kind, plane_pt in (("front", F), ("second", F - 2.0 * refl.reference_depth_m(band_nm) * a)):
                on = facing and refl.kind == "solid"
                X = mirror_point(S, plane_pt, a)
                on = on and _line_hits_disk(X, C, F, a, refl.radius_m + footprint_margin_m)
                add(X, r_led, on, f"cube{i}:led{li}:{kind}")
    for g, (O, R) in enumerate(glints_cam):
        for li, S in enumerate(flash.led_offsets_m):
            G, di, mag = sphere_glint(S, C, O, R)
            los = (G - C) / np.linalg.norm(G - C)
            add(G + di * los, r_led * mag, True, f"glint{g}:led{li}")
    return np.array(src), np.array(rad), np.array(act, bool), lab


def thin_lens_image_px(camera, focus_distance_m, X_cam, a_cam) -> np.ndarray:
    """Pixel where the ray from aperture point ``a_cam`` through ``X_cam`` meets the focus
    plane, projected through the profile (distortion included).

    Parameters
    ----------
    camera : svgs.Camera
    focus_distance_m : float
    X_cam : ndarray, shape (..., 3)
    a_cam : ndarray, shape (..., 3)
        Points on the aperture (z = 0), broadcast against ``X_cam``.

    Returns
    -------
    ndarray, shape (..., 2)
    """
    X = np.asarray(X_cam, float)
    a = np.asarray(a_cam, float)
    s = focus_distance_m / X[..., 2]
    xf = a[..., 0] + (X[..., 0] - a[..., 0]) * s
    yf = a[..., 1] + (X[..., 1] - a[..., 1]) * s
    return camera.normalized_to_pixels(np.stack([xf, yf], -1) / focus_distance_m)


def _disk_points(n):
    """``2 * (n // 2)`` quasi-uniform points on the unit disk: a Fibonacci spiral and its
    point reflection (so that their centroid is exactly the centre), shape (m, 2)."""
    h = max(1, n // 2)
    k = np.arange(h) + 0.5
    r = np.sqrt(k / h)
    th = k * np.pi * (3.0 - np.sqrt(5.0))
    p = np.stack([r * np.cos(th), r * np.sin(th)], -1)
    return np.concatenate([p, -p])


def binned_spot(camera, aperture_radius_m, focus_distance_m, X_cam, source_radius_m, n_aperture=4000, n_source=64):
    """Geometric-optics image of a small disk source seen through a thin lens, binned
    into the profile's pixels (no vignetting assumed).

    The image of every source point through every aperture point (a defocus disk of
    source images) is accumulated into pixels with OpenCV's convention (pixel ``i``
    covers ``[i - 0.5, i + 0.5)``). Its intensity-weighted centroid is what a pixel
    centroid of an ideal render converges to - including the pixel-phase ("pixel
    locking") bias of a spot only a few pixels wide.

    Parameters
    ----------
    camera : svgs.Camera
    aperture_radius_m, focus_distance_m : float
    X_cam : ndarray, shape (3,)
        Centre of the (virtual) source, camera frame, m.
    source_radius_m : float
        Radius of the source disk (taken perpendicular to the line of sight), m.

    Returns
    -------
    centroid_px : ndarray, shape (2,)
        Centroid of the binned image.
    chief_px : ndarray, shape (2,)
        Projection of ``X_cam`` (the chief ray), for comparison.
    """
    X = np.asarray(X_cam, float)
    los = X / np.linalg.norm(X)
    e1 = np.cross(los, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(los, e1)
    ap = _disk_points(n_aperture) * aperture_radius_m
    a = np.concatenate([ap, np.zeros((n_aperture, 1))], 1)
    src = _disk_points(n_source) * source_radius_m
    pts = X + src[:, 0:1] * e1 + src[:, 1:2] * e2  # (ns, 3)
    uv = thin_lens_image_px(camera, focus_distance_m, pts[:, None, :], a[None, :, :]).reshape(-1, 2)
    iu = np.floor(uv[:, 0] + 0.5)
    iv = np.floor(uv[:, 1] + 0.5)
    return np.array([iu.mean(), iv.mean()]), camera.project(X)


def predicted_spots_px(camera, flash, refl: Reflector, optics, target, R_cam_target, t_cam_target_m) -> np.ndarray:
    """Geometric-optics spot centre of every target, averaged over the LEDs.

    Parameters
    ----------
    camera : svgs.Camera
    flash : svgs_sim.render.optics.Flash
    refl : Reflector
    optics : svgs_sim.render.optics.Optics
        Its ``band_nm``.
    target : svgs_sim.render.geometry target handle
        ``cube_vertex_m`` (N, 3) and ``cube_axis`` (N, 3) in the target frame.
    R_cam_target : array_like, shape (3, 3)
    t_cam_target_m : array_like, shape (3,)

    Returns
    -------
    ndarray, shape (N, 2)
        Pixels (OpenCV convention), distortion included.
    """
    R, t = np.asarray(R_cam_target, float), np.asarray(t_cam_target_m, float)
    V = target.cube_vertex_m @ R.T + t
    A = target.cube_axis @ R.T
    out = np.zeros((V.shape[0], 2))
    for i in range(V.shape[0]):
        uv = []
        for S in flash.led_offsets_m:
            d = spot_direction_cam(S, V[i], A[i], refl, optics.band_nm)
            uv.append(camera.project(d if d[2] > 0 else np.array([d[0], d[1], 1e-12])))
        out[i] = np.mean(uv, axis=0)
    return out


def predicted_centroids_px(camera, flash, refl: Reflector, optics, target, R_cam_target, t_cam_target_m) -> np.ndarray:
    """Geometric-optics pixel centroid of every retro spot, binned into pixels.

    The flash image through each cube (virtual source at ``2V - S`` along the exact
    chief-ray direction, see :func:`spot_direction_cam`), defocused by the thin lens and
    accumulated into pixels (:func:`binned_spot`), averaged over the LEDs. Valid when the
    lens lies inside every return footprint and no glint overlaps the spot.

    Parameters
    ----------
    camera, flash, refl, optics, target, R_cam_target, t_cam_target_m
        As :func:`predicted_spots_px` (``optics``: ``band_nm``, ``aperture_radius_m``,
        ``focus_distance_m``; ``target``: also ``reference_m`` (N, 3)).

    Returns
    -------
    ndarray, shape (N, 2)
    """
    R, t = np.asarray(R_cam_target, float), np.asarray(t_cam_target_m, float)
    V = target.cube_vertex_m @ R.T + t
    A = target.cube_axis @ R.T
    Vref = target.reference_m @ R.T + t
    out = np.zeros((V.shape[0], 2))
    for i in range(V.shape[0]):
        acc = []
        for S in flash.led_offsets_m:
            d = spot_direction_cam(S, V[i], A[i], refl, optics.band_nm)
            X = d * np.linalg.norm(virtual_source_cam(S, Vref[i]))
            c, _ = binned_spot(camera, optics.aperture_radius_m, optics.focus_distance_m, X,
                               0.5 * flash.emitter_diameter_m)
            acc.append(c)
        out[i] = np.mean(acc, axis=0)
    return out
