"""The corner cubes' acceptance as the renderer computes it: the largest incidence (deg) at which a
pattern's cubes still return the flash's light to a camera's lens, over tilt directions and the
cubes' clocking about the face normal.

Method: the target sits on the boresight with no body; it is tilted by ``theta`` about an axis
in the image plane at angle ``phi`` (0: the image's x axis; the shipped phones' LEDs sit beside the
lens along x) after a turn ``psi`` about its own face normal (which clocks the cubes against the
flash offset). The frame is rendered with the guided spot estimator only (``spp=0``: no diffuse
background) and its total flux compared with the head-on frame's. For each (phi, psi) the largest
``theta`` whose return is at least ``fraction`` of head-on is found by bisection; the acceptance
is the largest over all directions. Two effects bound it, both in the renderer: the return
footprint (the cube's effective aperture mirrored about the LED) shrinking until the lens,
8-9 mm from the LED, falls outside it, and the loss of total internal reflection in the glass.
``tools/reflector_acceptance.py`` runs it for the shipped phones; the pattern file's
``[reflector] acceptance_deg`` is the result (:func:`svgs_sim.svgs.envelope.physical_envelope`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from svgs_sim.svgs.frames import D_CAM_PHOTO

from .api import Renderer


def pose(theta_deg: float, phi_deg: float, psi_deg: float, range_m: float):
    """``R_cam_target`` (3, 3), ``t_cam_target_m`` (3,) (OpenCV camera frame): the target on the
    boresight at ``range_m``, its normal at ``theta_deg`` from the line of sight."""
    tilt = Rotation.from_rotvec(np.radians(theta_deg) * np.array([np.cos(np.radians(phi_deg)),
                                                                  np.sin(np.radians(phi_deg)), 0.0]))
    spin = Rotation.from_rotvec(np.radians(psi_deg) * np.array([0.0, 0.0, 1.0]))
    R = D_CAM_PHOTO @ (tilt * spin).as_matrix()
    return R, D_CAM_PHOTO @ np.array([0.0, 0.0, -range_m])


def return_flux(renderer, theta_deg: float, phi_deg: float, psi_deg: float, range_m: float = 5.0, *,
                spots_only: bool = False) -> float:
    """Total flux (photons/s) of the cubes' return in a frame of ``renderer`` (a
    :class:`svgs_sim.render.api.Renderer` with no body) at the pose of :func:`pose`, with no
    diffuse background (``spp=0``). ``spots_only``: the spot estimator's light alone
    (:meth:`~svgs_sim.render.api.Renderer.spot_flux`, the same samples), without the spots'
    windows' diffuse light (with no body: 4e-7 of the head-on return, the acceptance's
    threshold is 1e-3), in about half the time."""
    R, t = pose(theta_deg, phi_deg, psi_deg, range_m)
    if spots_only:
        return renderer.spot_flux(R, t, seed=1)
    return float(renderer.render(R, t, seed=1, spp=0, check_fov=False).flux.sum())


def acceptance(camera, pattern="svgs-3u", *, range_m: float = 5.0, fraction: float = 1e-3,
               phis=range(0, 360, 15), psis=range(0, 120, 20), tol_deg: float = 0.2) -> dict:
    """The largest incidence (deg) at which ``camera`` sees light from ``pattern``'s cubes.

    Parameters
    ----------
    camera : Camera or str
    pattern : Pattern or str
    range_m : float
        Range along the boresight, m.
    fraction : float
        "Returns light": a total flux at least this fraction of the head-on frame's.
    phis, psis : iterable of float
        Tilt directions and clockings (deg) to search.
    tol_deg : float
        Bisection tolerance, deg.

    Returns
    -------
    dict
        ``acceptance_deg``, ``phi_deg``, ``psi_deg`` (the direction that reaches it) and
        ``by_direction`` (``[phi, psi, theta]`` rows).
    """
    r = Renderer(camera, pattern, scene_options={"body": "none"}, spp=0)

    def flux(theta, phi, psi):
        return return_flux(r, theta, phi, psi, range_m)

    rows = []
    for psi in psis:
        f0 = flux(0.0, 0.0, psi)
        for phi in phis:
            lo, hi = 0.0, 89.0
            while hi - lo > tol_deg:
                m = 0.5 * (lo + hi)
                lo, hi = (m, hi) if flux(m, phi, psi) >= fraction * f0 else (lo, m)
            rows.append([float(phi), float(psi), round(lo, 2)])
    best = max(rows, key=lambda x: x[2])
    return {"acceptance_deg": best[2], "phi_deg": best[0], "psi_deg": best[1], "range_m": range_m,
            "fraction": fraction, "by_direction": rows}
