"""Finding a calibration board's features in images, with OpenCV.

Chessboards with ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix`` (falling back to
``cv2.findChessboardCornersSB``), ChArUco boards with ``cv2.aruco.CharucoDetector`` (partial
views are used), circle grids with ``cv2.findCirclesGrid``. See :mod:`svgs_sim.calibration.boards` for
the boards' layouts and object points.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.svgs.result import Failure

from .boards import Board

#: Fewest ChArUco corners a view needs to be used.
MIN_CHARUCO_CORNERS = 6


@dataclass
class BoardDetection:
    """Board features found in one view (truthy).

    Attributes
    ----------
    image_points_px : ndarray, shape (M, 2)
    object_points_m : ndarray, shape (M, 3)
    ids : ndarray of int, shape (M,)
        Index of each feature in :meth:`Board.object_points`.
    """

    image_points_px: np.ndarray
    object_points_m: np.ndarray
    ids: np.ndarray

    def __bool__(self) -> bool:
        return True

    def __len__(self) -> int:
        return int(self.ids.shape[0])


def to_gray8(image) -> np.ndarray:
    """Any 2-D grey or (H, W, 3|4) RGB image (uint8, uint16 or float) -> uint8 grey (H, W)."""
    import cv2

    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = img[..., :3]
        if img.dtype not in (np.uint8, np.uint16, np.float32):
            img = img.astype(np.float32)
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY)
    if img.ndim != 2 or img.size == 0:
        raise InputError(f"image: expected a 2-D grey or (H, W, 3) colour image, got shape {img.shape}")
    if img.dtype == np.uint8:
        return img
    if img.dtype == bool:
        return img.astype(np.uint8) * 255
    f = img.astype(np.float64)
    if not np.all(np.isfinite(f)):
        raise InputError("image: contains NaN or infinite values")
    top = f.max()
    if np.issubdtype(img.dtype, np.integer):
        hi = top if top > 255 else 255.0  # 16-bit data: stretch what is there
    else:
        hi = 1.0 if top <= 1.0 else top  # float: 0..1, or stretch
    return np.clip(np.round(f / hi * 255.0), 0, 255).astype(np.uint8)


class DistinctViews:
    """Refuses a view seen before: the same picture given twice (under two names or one) would
    count as two independent measurements and shrink the uncertainty as if it were.

    Views are compared by a SHA-256 of their pixels (shape, type and values), so a copy of a
    file under another name is caught, and a re-encoded photo (other pixels) is not.

    Parameters
    ----------
    option : str
        The option or argument the views came from, for the message (``"--image"``).
    """

    def __init__(self, option: str):
        self.option = option
        self._seen = {}

    def add(self, image, name: str) -> None:
        """Record one view; :class:`InputError` naming both if its pixels were seen before.

        Parameters
        ----------
        image : ndarray, shape (H, W) or (H, W, C)
        name : str
        """

        a = np.ascontiguousarray(image)
        h = hashlib.sha256(f"{a.shape}{a.dtype.str}".encode() + a.tobytes()).hexdigest()
        if h in self._seen:
            raise InputError(f"{self.option}: {self._seen[h]} and {name} are the same picture (identical pixels, "
                             f"sha256 {h[:12]}); one view counted twice would pass for two measurements and shrink "
                             "the uncertainty: give each view once")
        self._seen[h] = str(name)


def detect_board(image, board: Board):
    """Find the board's features in one image.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        Grey or RGB, any depth (converted with :func:`to_gray8`).
    board : Board

    Returns
    -------
    BoardDetection or Failure
        Failure reasons: ``no_board`` (the pattern was not found), ``too_few_corners``
        (ChArUco: fewer than :data:`MIN_CHARUCO_CORNERS`), ``degenerate`` (the corners found
        are collinear).
    """
    import cv2

    gray = to_gray8(image)
    if board.kind == "charuco":
        det = cv2.aruco.CharucoDetector(board.cv_board())
        corners, ids, _, marker_ids = det.detectBoard(gray)
        n = 0 if ids is None else len(ids)
        if n == 0:
            nm = 0 if marker_ids is None else len(marker_ids)
            return Failure("no_board", f"no ChArUco corners found ({nm} markers of {board.dictionary} detected)", {"n_markers": nm})
        if n < MIN_CHARUCO_CORNERS:
            return Failure("too_few_corners", f"only {n} ChArUco corners found, need {MIN_CHARUCO_CORNERS}", {"n_corners": n})
        ids = np.asarray(ids).reshape(-1).astype(int)
        img_pts = np.asarray(corners, float).reshape(-1, 2)
        obj = board.object_points()[ids]
        c = obj[:, :2] - obj[:, :2].mean(0)
        sv = np.linalg.svd(c, compute_uv=False)
        if sv[1] < 1e-6 * sv[0]:
            return Failure("degenerate", f"the {n} ChArUco corners found lie on one line", {"n_corners": n})
        return BoardDetection(img_pts, obj, ids)

    if board.kind == "chessboard":
        pts = _find_chessboard(gray, board)
    else:
        pts = _find_circles(gray, board)
    if pts is None:
        return Failure("no_board", f"no {board.cols} x {board.rows} {board.kind} found", {})
    return BoardDetection(pts, board.object_points(), np.arange(board.n_points))


def _find_chessboard(gray: np.ndarray, board: Board):
    """Classic detector + ``cornerSubPix`` first (more accurate on sharp images: 0.03-0.05 px
    RMS against 0.06-0.09 px for the SB detector on synthetic views), SB as the fallback."""
    import cv2

    ok, corners = cv2.findChessboardCorners(
        gray, board.pattern_size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    )
    if ok:
        c = np.asarray(corners, np.float32).reshape(-1, 1, 2)
        grid = c.reshape(board.rows, board.cols, 2)
        step = min(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(), np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
        half = int(np.clip(0.4 * step, 2, 11))
        crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
        c = cv2.cornerSubPix(gray, c, (half, half), (-1, -1), crit)
        return np.asarray(c, float).reshape(-1, 2)
    flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_ACCURACY
    ok, corners = cv2.findChessboardCornersSB(gray, board.pattern_size, flags=flags)
    if ok:
        return np.asarray(corners, float).reshape(-1, 2)
    return None


def _find_circles(gray: np.ndarray, board: Board):
    import cv2

    flags = cv2.CALIB_CB_ASYMMETRIC_GRID if board.kind == "acircles" else cv2.CALIB_CB_SYMMETRIC_GRID
    ok, centres = cv2.findCirclesGrid(gray, board.pattern_size, flags=flags)
    if not ok:
        # OpenCV's default blob detector keeps blobs of 25..5000 px: widen it for large
        # images / small circles, and try light circles on a dark ground.
        p = cv2.SimpleBlobDetector_Params()
        p.minArea = 4.0
        p.maxArea = 0.5 * gray.size / board.n_points
        p.minDistBetweenBlobs = 2.0
        det = cv2.SimpleBlobDetector_create(p)
        for g in (gray, 255 - gray):
            ok, centres = cv2.findCirclesGrid(g, board.pattern_size, flags=flags, blobDetector=det)
            if ok:
                break
    if not ok:
        return None
    return np.asarray(centres, float).reshape(-1, 2)


def detect_views(grays, names, board):
    """Detect the board in each grey image.

    Returns
    -------
    object_points : list of ndarray (n_i, 3)
    image_points : list of ndarray (n_i, 2)
    used : list of str
        Names of the views where the board was found.
    skipped : list of (str, Failure)
        The others, with the reason.
    """
    obj, img, used, skipped = [], [], [], []
    for g, n in zip(grays, names):
        det = detect_board(g, board)
        if det:
            obj.append(det.object_points_m)
            img.append(det.image_points_px)
            used.append(n)
        else:
            skipped.append((n, det))
    return obj, img, used, skipped


__all__ = ["MIN_CHARUCO_CORNERS", "BoardDetection", "DistinctViews", "to_gray8", "detect_board", "detect_views"]
