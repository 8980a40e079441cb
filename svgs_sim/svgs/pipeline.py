"""Image -> Solution: the SVGS processing chain (paper Figure 3).

threshold -> blob extraction -> target identification -> collinearity solve.
"""

from __future__ import annotations

import os
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..base.profiles import Camera, load_camera, load_pattern
from .app import consistency, settings
from .identify import identify, outside_test_envelope
from .result import Failure
from .solver import solve_centroids

#: EXIF ``Orientation`` tag (0x0112) values: what the viewer does to the stored pixels to show
#: the picture upright (EXIF 2.32, section 4.6.4 A).
EXIF_ORIENTATIONS = {
    1: "upright",
    2: "mirrored left-right",
    3: "rotated 180 deg",
    4: "mirrored top-bottom",
    5: "transposed: mirrored left-right, then rotated 90 deg anticlockwise",
    6: "rotated 90 deg clockwise",
    7: "transversed: mirrored left-right, then rotated 90 deg clockwise",
    8: "rotated 90 deg anticlockwise",
}
_EXIF_ORIENTATION_TAG = 0x0112


def _may_hold_exif(data: bytes) -> bool:
    """Whether a file's bytes can hold EXIF (so Pillow is asked only then: a PNG's EXIF makes it
    decode the whole image)."""
    if data[:4] in (b"II*\x00", b"MM\x00*"):  # TIFF: the tag, if any, is in the first directory
        return True
    if data[:2] == b"\xff\xd8":  # JPEG: an APP1 "Exif" segment, near the start
        return b"Exif\x00\x00" in data[:262144]
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return b"eXIf" in data
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return b"EXIF" in data
    return False


def exif_orientation(path, data: bytes | None = None) -> int:
    """The EXIF ``Orientation`` of an image file: 1 (as stored) to 8, 1 when it has none.

    Parameters
    ----------
    path : str or Path
    data : bytes, optional
        The file's content, if already read.

    Returns
    -------
    int
        A key of :data:`EXIF_ORIENTATIONS`; 1 for a file without EXIF, an unknown value, or a
        file Pillow cannot parse (OpenCV decodes the pixels; this reads only the header).
    """

    try:
        if not _may_hold_exif(Path(path).read_bytes() if data is None else data):
            return 1
        from PIL import Image  # a dependency of matplotlib and scikit-image

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Pillow's decompression-bomb warning: only the header is read
            with Image.open(path) as im:
                value = im.getexif().get(_EXIF_ORIENTATION_TAG, 1)
    except Exception:  # noqa: BLE001 - no EXIF to read is "as stored"; the decoder reports bad files
        return 1
    try:
        value = int(value)
    except (TypeError, ValueError):
        return 1
    return value if value in EXIF_ORIENTATIONS else 1


def apply_exif_orientation(image: np.ndarray, orientation: int) -> np.ndarray:
    """The stored pixels as a viewer shows them under an EXIF ``Orientation``.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, C)
        As stored in the file.
    orientation : int
        1-8 (:data:`EXIF_ORIENTATIONS`).

    Returns
    -------
    ndarray, shape (H, W[, C]) for 1-4, (W, H[, C]) for 5-8
        Same dtype, pixel values unchanged (only moved).
    """
    ops = {
        1: lambda a: a,
        2: lambda a: a[:, ::-1],
        3: lambda a: a[::-1, ::-1],
        4: lambda a: a[::-1, :],
        5: lambda a: np.swapaxes(a, 0, 1),
        6: lambda a: np.rot90(a, -1),
        7: lambda a: np.swapaxes(a, 0, 1)[::-1, ::-1],
        8: lambda a: np.rot90(a, 1),
    }
    if orientation not in ops:
        raise InputError(f"EXIF orientation: expected 1-8, got {orientation!r}")
    return np.ascontiguousarray(ops[orientation](image))


#: The most pixels an image may have: above the largest phone sensors (200 MP). A larger file is
#: refused from its header, before it is decoded (a 40000 x 40000 PNG of 1.6 MB made OpenCV assert;
#: a 20000 x 20000 one took 2.4 GB and 6 s before its size was refused).
MAX_IMAGE_PIXELS = 250_000_000


def image_header_size(path):
    """``(width, height)`` in pixels from an image file's header, without decoding it (Pillow);
    None where Pillow cannot read the header (OpenCV may still decode the file).

    Parameters
    ----------
    path : str or Path
    """
    from PIL import Image  # heavy: loaded when a photo is read

    old = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None  # the size is judged here, not by Pillow's bomb warning
    try:
        with Image.open(path) as im:
            return tuple(int(x) for x in im.size)
    except Exception:  # noqa: BLE001 - any header Pillow cannot read: leave the decision to the decoder
        return None
    finally:
        Image.MAX_IMAGE_PIXELS = old


def check_image_header(path, camera: Camera | None = None, name: str = "image") -> None:
    """Refuse an image file from its header, before decoding: more than :data:`MAX_IMAGE_PIXELS`
    pixels, or (with ``camera``) a size that is not the camera's in either orientation.

    Raises
    ------
    InputError
        Naming ``name`` and the sizes.
    """
    size = image_header_size(path)
    if size is None:
        return
    w, h = size
    if w * h > MAX_IMAGE_PIXELS:
        raise InputError(f"{name} {str(path)!r} is {w} x {h} px ({w * h / 1e6:.0f} MP): larger than any phone camera "
                         f"(at most {MAX_IMAGE_PIXELS / 1e6:.0f} MP); not decoded")
    if camera is not None and (w, h) not in ((camera.width, camera.height), (camera.height, camera.width)):
        raise InputError(f"{name} {str(path)!r}: size {w} x {h} px does not match camera {camera.name!r} "
                         f"({camera.width} x {camera.height} px); use the profile of the resolution the image was "
                         "taken at")


def load_image(path, *, say=None, camera: Camera | None = None) -> np.ndarray:
    """Read an image file (8- or 16-bit, grey or colour) upright: an EXIF orientation other
    than 1 (a phone held on its side) is applied, as a viewer shows the picture, and said.

    Parameters
    ----------
    path : str or Path
    say : callable, optional
        Called with the one line that names an applied EXIF orientation; default: printed
        on stderr.
    camera : Camera, optional
        Refuse a file whose header gives another size than the camera's before decoding it
        (:func:`check_image_header`; every file is refused above :data:`MAX_IMAGE_PIXELS`).

    Returns
    -------
    image : ndarray, shape (H, W) or (H, W, 3)

    Raises
    ------
    InputError
        The file is missing, empty, not a regular file, or not an image OpenCV can decode.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"image {str(p)!r} does not exist")
    if p.is_dir():
        raise InputError(f"image {str(p)!r} is a directory, not an image file")
    if not p.is_file():  # /dev/null, a FIFO, a socket: not read (a FIFO would block)
        raise InputError(f"image {str(p)!r} is not a regular file (a device, FIFO or socket); give an image file")
    if p.stat().st_size == 0:
        raise InputError(f"image {str(p)!r} is empty (0 bytes)")
    if p.suffix.lower() != ".npy":
        check_image_header(p, camera)  # the size from the header, before any decoding
    if p.suffix.lower() == ".npy":
        try:
            img = np.load(p, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - any decode failure is bad input
            raise InputError(f"image {str(p)!r} is not a readable .npy array: {exc}") from None
    else:
        data = np.fromfile(p, dtype=np.uint8)
        img, said = _decode_quietly(data)
        if img is None:
            why = f" ({said})" if said else ""
            raise InputError(f"image {str(p)!r} is corrupt or not an image format OpenCV can read{why}")
    if img.ndim == 3 and img.shape[2] not in (3, 4):
        raise InputError(f"image {str(p)!r}: expected a 2-D grey image (H, W) or a colour one (H, W, 3), got an "
                         f"array of shape {tuple(img.shape)}")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    if img.ndim == 3 and img.shape[2] == 3 and p.suffix.lower() != ".npy":
        img = img[..., ::-1]  # OpenCV decodes BGR; the rest of the code expects RGB
    if img.size == 0 or img.ndim not in (2, 3):
        raise InputError(f"image {str(p)!r}: expected a 2-D grey or 3-channel colour image, got shape {img.shape}")
    if p.suffix.lower() != ".npy":
        # OpenCV's IMREAD_UNCHANGED keeps the stored layout (it ignores EXIF orientation)
        o = exif_orientation(p, data.tobytes())
        if o != 1:
            h0, w0 = img.shape[:2]
            img = apply_exif_orientation(img, o)
            h, w = img.shape[:2]
            line = (f"note: image {str(p)!r}: EXIF orientation {o} ({EXIF_ORIENTATIONS[o]}) applied; used as "
                    f"displayed, {w} x {h} px (stored {w0} x {h0} px)")
            if say is None:
                print(f"svgs: {line}", file=sys.stderr, flush=True)
            else:
                say(line)
    return img


def _decode_quietly(data: np.ndarray):
    """``cv2.imdecode`` with what the codec libraries print on the process's stderr (libpng's
    "libpng error: IDAT: CRC error") captured instead of printed.

    Returns
    -------
    image : ndarray or None
        As ``cv2.imdecode(data, cv2.IMREAD_UNCHANGED)``.
    said : str
        The captured lines, joined by "; " (empty when none).
    """

    import cv2

    fd = 2  # the process's stderr, where the C libraries write (whatever sys.stderr is)
    try:
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):
        pass
    saved = os.dup(fd)
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), fd)
        try:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        finally:
            os.dup2(saved, fd)
            os.close(saved)
        tmp.seek(0)
        said = "; ".join(ln.strip() for ln in tmp.read().decode("utf-8", "replace").splitlines() if ln.strip())
    return img, said


def check_image_matches_camera(image: np.ndarray, camera: Camera, name: str = "image") -> None:
    """Raise :class:`InputError` unless the image has the camera profile's size."""
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] not in (3, 4)):
        raise InputError(f"{name}: expected a grey (H, W) or colour (H, W, 3) image of {camera.width} x "
                         f"{camera.height} px, got an array of shape {tuple(image.shape)}")
    h, w = image.shape[:2]
    if (w, h) != (camera.width, camera.height):
        raise InputError(
            f"{name}: size {w} x {h} px does not match camera {camera.name!r} ({camera.width} x {camera.height} px); "
            "use the profile of the resolution the image was taken at"
        )


def camera_threshold(image, camera, threshold=None):
    """The detector's threshold for an image of a camera: the app's brightness threshold for the
    camera's test set-up when ``threshold`` is None or ``"app"`` (:mod:`svgs_sim.svgs.app`, scaled to the
    image's type by :func:`svgs_sim.svgs.detect.app_level`), else ``threshold`` as given.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
    camera : Camera or str
        A binned preview profile (its ``[preview] of`` table) takes its phone's threshold.
    threshold : None, "app", "auto", "otsu" or float

    Returns
    -------
    float or str
        A level in the image's units, or ``threshold`` itself ("auto", "otsu", a level).
    """
    from .detect import app_level

    if threshold is None or (isinstance(threshold, str) and threshold == "app"):
        return app_level(np.asarray(image).dtype, settings().threshold_for(camera_key(camera)))
    return threshold


def detector_settings(camera, threshold=None) -> dict:
    """What the detector was given for a camera, for every output to say: the camera's key, the
    brightness threshold and where it came from, and the fitted overlay its profile applied.

    Parameters
    ----------
    camera : Camera or str
    threshold : None, "app", "auto", "otsu" or float
        As the command took it (None and "app": the app's threshold for the camera).

    Returns
    -------
    dict
        ``{"camera_key": str | None, "threshold": float | str, "threshold_source": str,
        "fitted_overlay": str | None}``: ``threshold`` in 8-bit DN for the app's (the image's
        own units for a level given by the user); ``threshold_source`` ``"app by_camera[KEY]"``,
        ``"app default"`` or ``"given"``; ``fitted_overlay`` the overlay file (``fitted/KEY.toml``).
    """

    key = camera_key(camera)
    overlays = sorted({f.overlay for f in load_camera(camera).fitted if f.overlay})
    if threshold is None or (isinstance(threshold, str) and threshold == "app"):
        level, source = settings().threshold_for(key), f"app {settings().threshold_source(key)}"
    else:
        level, source = threshold, "given"
    return {"camera_key": key, "threshold": level, "threshold_source": source,
            "fitted_overlay": ", ".join(overlays) or None}


def describe_detector(settings: dict) -> str:
    """One line of :func:`detector_settings` for the text output."""
    thr = settings["threshold"]
    thr = f"{thr:g} DN" if isinstance(thr, (int, float)) else str(thr)
    return (f"detector: threshold {thr} ({settings['threshold_source']}); camera key {settings['camera_key']}; "
            f"fitted overlay {settings['fitted_overlay'] or 'none'}")


def camera_key(camera) -> str | None:
    """The key that chooses the app's per-camera settings for ``camera``: its profile's ``key``
    (a binned preview stream keeps its phone's, :mod:`svgs_sim.camera.phone.preview`), never its
    display name; None for a camera without one.

    Parameters
    ----------
    camera : Camera or str

    Returns
    -------
    str or None
    """
    cam = load_camera(camera)
    if cam.key is not None:
        return cam.key
    return cam.preview_of


def solve_image(
    image,
    camera,
    pattern="svgs-3u",
    *,
    threshold=None,
    sigma_px: float = 0.1,
    detect_options: dict | None = None,
    identify_options: dict | None = None,
    blobs=None,
    consistency_sigma_px: float | None = None,
    sensor_sigma_px: float | None = None,
    alpha: float | None = None,
):
    """Detect, identify and solve the pose from one image.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3), or str/Path
        8- or 16-bit (or float) image, or the path to one. Must match the camera's size.
    camera : Camera or str
    pattern : Pattern or str
    threshold : None, number or str
        Binarisation threshold (see :func:`svgs_sim.svgs.detect.detect_blobs`); ``None``: the app's
        brightness threshold for this camera's test set-up (:meth:`svgs_sim.svgs.app.AppSettings.threshold_for`);
        ``"auto"``: the automatic rule.
    sigma_px : float
        Centroid noise (px) for which the Cramer-Rao covariance is reported (default 0.1).
    detect_options, identify_options : dict, optional
        Passed to :func:`svgs_sim.svgs.detect.detect_blobs` and :func:`svgs_sim.svgs.identify.identify`.
    blobs : svgs_sim.svgs.detect.Blobs, optional
        This image's detections, when the caller already has them (detection is skipped).
    consistency_sigma_px : float, optional
        The stated centroid accuracy (px) the consistency test is made against (default: the
        app's, :func:`svgs_sim.svgs.app.settings`).
    sensor_sigma_px : float, optional
        The sensor's own centroid bound (a simulated frame's CRLB), px: added in quadrature to
        ``consistency_sigma_px`` in the consistency test.
    alpha : float, optional
        Level of the consistency test (default the app's, 1e-3).

    Returns
    -------
    Solution or Failure
        A solution carries :attr:`~svgs_sim.svgs.solver.Solution.consistency` (:func:`svgs_sim.svgs.app.consistency`);
        one whose residual is improbable for its centroid noise (``p < alpha``) is returned as the
        failure ``inconsistent``, whose ``details`` keep the rejected ``state``, ``chi2``, ``dof``,
        ``p_value`` and ``residual_rms_px``. Every failure's ``details`` hold ``n_blobs`` and
        ``threshold_used`` (the detector's level); a solution's ``n_blobs`` and ``threshold_used``
        likewise.
    """
    from .detect import detect_blobs

    camera = load_camera(camera)
    pattern = load_pattern(pattern)
    if isinstance(image, (str, Path)):
        image = load_image(image, camera=camera)
    image = np.asarray(image)
    check_image_matches_camera(image, camera)
    threshold = camera_threshold(image, camera, threshold)
    if blobs is None:
        blobs = detect_blobs(image, threshold=threshold, **(detect_options or {}))
    ident = identify(blobs, camera, pattern, **{"sigma_px": sigma_px, **(identify_options or {})})
    if not ident:
        ident.details.setdefault("n_blobs", len(blobs))
        ident.details.setdefault("threshold_used", float(blobs.threshold_used))
        return ident
    sol = ident.solution  # identification verified the set with the solver already
    if sol is None or not sol or getattr(sol, "sigma_px", None) != sigma_px:
        sol = solve_centroids(ident.points_px, camera, pattern, sigma_px=sigma_px)
        if sol:
            sol.outside_test_envelope = outside_test_envelope(sol.R_cam_target, sol.t_cam_target_m)
    if not sol:
        sol.details["n_blobs"] = len(blobs)
        sol.details["threshold_used"] = float(blobs.threshold_used)
        return sol
    sol.n_blobs = len(blobs)
    sol.threshold_used = float(blobs.threshold_used)
    sol.consistency = consistency(sol.residual_rms_px, len(ident.points_px), sigma_px=consistency_sigma_px,
                                  sensor_sigma_px=sensor_sigma_px, alpha=alpha)
    if not sol.consistency.consistent:
        return inconsistent_failure(sol)
    return sol


def inconsistent_failure(sol) -> Failure:
    """The ``inconsistent`` failure of a solution whose consistency test failed.

    Parameters
    ----------
    sol : svgs_sim.svgs.solver.Solution
        With :attr:`~svgs_sim.svgs.solver.Solution.consistency` set.

    Returns
    -------
    Failure
        Reason ``inconsistent``; ``details`` keep the state, targets, residual and the statistic.
    """
    c = sol.consistency
    return Failure("inconsistent",
                   f"the solution's residual ({sol.residual_rms_px:.3g} px RMS) is improbable for centroid noise of "
                   f"{c.sigma_px:.3g} px: chi2 = {c.chi2:.3g} with {c.dof} degrees of freedom, p = {c.p_value:.2g} "
                   f"< {c.alpha:g}",
                   {"n_blobs": sol.n_blobs, "threshold_used": sol.threshold_used,
                    "residual_rms_px": float(sol.residual_rms_px), "state": sol.state_dict,
                    "targets_px": {str(k): [float(x) for x in v] for k, v in sol.targets_px.items()},
                    **c.to_json()})


__all__ = ["MAX_IMAGE_PIXELS", "check_image_header", "image_header_size", "load_image", "exif_orientation", "apply_exif_orientation", "EXIF_ORIENTATIONS", "solve_image", "camera_threshold", "camera_key", "detector_settings", "describe_detector", "check_image_matches_camera", "inconsistent_failure", "Failure"]
