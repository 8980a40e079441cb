"""Image and video files written through Python's own file system calls, for any path a user can type.

OpenCV's ``cv2.imwrite`` and ``cv2.VideoWriter`` take the path as a C string: a path holding a byte
that is not valid UTF-8 (a ``str`` with surrogate escapes, as Python gives for such a name) ends the
process in native code (SIGSEGV, issue 41). Here the image is encoded in memory
(``cv2.imencode``) and its bytes written with :func:`open`, and a video is written under a plain
ASCII name in the same folder and then renamed, so no user path reaches OpenCV. Write failures
(a full disk, a name the file system refuses) are ``OSError`` naming the path.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np


def write_image(path, image, params=()) -> Path:
    """Write an image file; the format from the path's suffix (``.png``, ``.jpg``, ``.tif`` ...).

    Parameters
    ----------
    path : str or Path
        Any path the file system accepts (non-UTF-8 bytes included).
    image : ndarray, shape (H, W) or (H, W, 3)
        As ``cv2.imwrite`` takes it (BGR for colour).
    params : sequence of int
        ``cv2.imencode``'s parameters (e.g. ``[cv2.IMWRITE_JPEG_QUALITY, 90]``).

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        OpenCV cannot encode the image in that format.
    OSError
        The file cannot be written (``filename`` set to the path).
    """
    import cv2  # heavy: loaded when an image is written

    path = Path(path)
    ok, buf = cv2.imencode(path.suffix or ".png", np.asarray(image), list(params))
    if not ok:
        raise ValueError(f"{path.name!r}: OpenCV could not encode the image as {path.suffix or '.png'}")
    with open(path, "wb") as fh:
        fh.write(buf.tobytes())
    return path


def read_image(path, flags: int = -1):
    """Read an image file through Python's ``open`` (any path); None where OpenCV cannot decode it.

    Parameters
    ----------
    path : str or Path
    flags : int
        ``cv2.imdecode``'s flags (default -1, ``cv2.IMREAD_UNCHANGED``).

    Returns
    -------
    ndarray or None
    """
    import cv2  # heavy: loaded when an image is read

    data = np.fromfile(str(path), dtype=np.uint8) if os.path.exists(path) else None
    if data is None or data.size == 0:
        return None
    return cv2.imdecode(data, flags)


class VideoFile:
    """``cv2.VideoWriter`` for any path: frames go to an ASCII-named file in the target's folder,
    renamed to the target by :meth:`close` (removed when nothing was written or on an error).

    Parameters
    ----------
    path : str or Path
    fourcc : str
        Four characters (``"mp4v"``).
    fps : float
    size : (int, int)
        Width, height, px.
    """

    def __init__(self, path, fourcc: str, fps: float, size):
        import cv2  # heavy: loaded when a video is written

        self.path = Path(path)
        fd, tmp = tempfile.mkstemp(suffix=self.path.suffix, prefix="video-", dir=self._ascii_dir())
        os.close(fd)
        self._tmp = Path(tmp)
        self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*fourcc), float(fps), tuple(size))

    def _ascii_dir(self) -> str:
        folder = str(self.path.parent)
        try:
            folder.encode("ascii")
            return folder
        except UnicodeEncodeError:
            return tempfile.gettempdir()

    def isOpened(self) -> bool:  # noqa: N802 (OpenCV's name)
        return bool(self._writer.isOpened())

    def write(self, frame) -> None:
        self._writer.write(frame)

    def release(self, keep: bool = True) -> Path | None:
        """Close the video; with ``keep`` move it to :attr:`path` (returned), else remove it."""
        self._writer.release()
        if keep and self._tmp.exists() and self._tmp.stat().st_size > 0:
            shutil.move(str(self._tmp), str(self.path))  # a rename within one file system
            return self.path
        self._tmp.unlink(missing_ok=True)
        return None


__all__ = ["VideoFile", "read_image", "write_image"]
