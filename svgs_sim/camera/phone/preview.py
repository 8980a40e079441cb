"""The phone's preview stream as a camera of its own: the sensor read out binned.

A phone's preview (the stream a camera app such as SVGS processes frame by frame) is far smaller
than its still picture: the Galaxy Nexus streams 640 x 480 against 2592 x 1944 stills
(``shared/notes/physics.md`` section 4). This module models the preview as the same lens on the
same sensor read out with ``s x s`` charge binning, ``s = picture width / preview width`` (an
effective factor: 4.05 for the Galaxy Nexus, 5.1 for the HTC Amaze 4G, not whole pixels):

- the intrinsics scale (:meth:`svgs_sim.base.profiles.Camera.scaled`) and the pixel pitch grows by ``s``
  (the focal length in metres, the aperture and the radiometry stay);
- a binned pixel collects the charge of ``s^2`` pixels: full well and dark current times ``s^2``;
  the read noise of the summed reads and the DSNU times ``s`` (independent per pixel; PRNU, a
  fraction, is averaged down by ``s``);
- lens blur given in pixels (aberration, glare core and support, ghost blur) is divided by ``s``.

A preview frame is the ISP's YCbCr 4:2:0 image handed to the app as it is (Android's
``onPreviewFrame``; ``yuv420sp`` by default on OMAP4, ``OMXDefaults.cpp``): no JPEG, the app reads
its Y plane (``[isp] jpeg_quality`` set to 0 here).

ASSUMPTION: charge (or digital) binning on the sensor. Phones of 2011 reached their preview size
by a mix of sensor binning and ISP scaling; both deliver the photons of ``s^2`` pixels per preview
pixel, and they differ in the read noise of a pixel (summed reads here), which matters only in the
darkest parts of the frame, not in the spots.
"""

from __future__ import annotations

import math

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import Camera, load_camera
from svgs_sim.camera.phone.params import SensorParams

#: The Galaxy Nexus' preview size (``shared/notes/physics.md`` section 4); the HTC Amaze 4G's was
#: not found and is taken to be the same (ASSUMPTION).
DEFAULT_PREVIEW_SIZE = (640, 480)


def binned_camera(camera, width: int = DEFAULT_PREVIEW_SIZE[0], height: int = DEFAULT_PREVIEW_SIZE[1]) -> Camera:
    """The camera profile's preview stream at ``width x height`` (see the module docstring).

    Parameters
    ----------
    camera : svgs.Camera or str
    width, height : int
        Preview size, px; the same aspect ratio as the picture (within 1 %).

    Returns
    -------
    svgs.Camera
        Named ``<name>-preview-<width>x<height>``.
    """
    cam = load_camera(camera)
    width, height = int(width), int(height)
    if width < 16 or height < 16 or width > cam.width or height > cam.height:
        raise InputError(f"preview size: expected 16 px up to the picture's {cam.width} x {cam.height}, "
                         f"got {width} x {height}")
    s = cam.width / width
    if abs(cam.height / height - s) > 0.01 * s:
        raise InputError(f"preview size: {width} x {height} does not keep the picture's aspect ratio "
                         f"({cam.width} x {cam.height})")
    sensor = cam.sensor.to_dict()
    d = SensorParams()
    get = lambda k: float(sensor.get(k, getattr(d, k)))  # noqa: E731
    sensor["pixel_pitch_m"] = get("pixel_pitch_m") * s
    sensor["full_well_e"] = get("full_well_e") * s * s
    sensor["dark_current_e_s"] = get("dark_current_e_s") * s * s
    sensor["read_noise_e"] = get("read_noise_e") * s
    sensor["dsnu_e"] = get("dsnu_e") * s
    sensor["prnu"] = get("prnu") / s
    changed = {"sensor": sensor}
    if cam.has("glare"):
        glare = changed["glare"] = cam.glare.to_dict()
        for k in ("aberration_sigma_px", "wing_core_px", "wing_radius_px"):
            if k in glare:
                glare[k] = float(glare[k]) / s
        if "ghosts" in glare:
            glare["ghosts"] = [[g[0], g[1], float(g[2]) / s] for g in glare["ghosts"]]
    if cam.has("isp"):
        isp = changed["isp"] = cam.isp.to_dict()
        if isp.get("output_width"):
            isp["output_width"], isp["output_height"] = 0, 0  # the preview is delivered at its own size
        # a preview frame is the ISP's YCbCr 4:2:0 (yuv420sp on OMAP4 and MSM8660), not a JPEG: the
        # app reads its Y plane (the luma of the toned colour image), so no JPEG round trip
        isp["jpeg_quality"] = 0
    # the phone whose stream this is: the app's settings for that phone apply to it
    changed["preview"] = {"of": cam.name, "binning": int(s)}
    out = cam.scaled(width, height).replace(name=f"{cam.name}-preview-{width}x{height}").with_tables(**changed)
    if not math.isfinite(out.fx) or out.fx <= 0:
        raise InputError(f"preview size: {width} x {height} gives no usable focal length")
    return out
