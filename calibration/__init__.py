"""Camera calibration for the SVGS simulator (issue 5).

* :mod:`calibration.focal` - the paper's method: focal length (and its uncertainty) from
  the spacings of the target's spots in images at known ranges.
* :mod:`calibration.boards` - full intrinsic calibration with OpenCV from chessboard,
  ChArUco and circle-grid images; board geometry, drawing and synthetic views.
* :mod:`calibration.study` - how intrinsics converge with the number of rendered views,
  and how each calibration error propagates into pose error versus range.
* :mod:`calibration.cli`, :mod:`calibration.study_cli` - ``svgs calibrate focal``,
  ``board``, ``render-board`` and ``study``.

Uses :mod:`svgs` (profiles, detection, identification); rendering of board images lives
in :mod:`render.boards` and is imported only by the study when it renders.
"""

from .boards import (
    BOARD_KINDS,
    Board,
    BoardDetection,
    BoardImage,
    Calibration,
    calibrate,
    calibrate_images,
    detect_board,
    mapping_error_px,
    sample_board_poses,
    synthesize_views,
)
from .focal import FocalEstimate, ImageFocal, estimate_focal, estimate_focal_from_images

__all__ = [
    "BOARD_KINDS",
    "Board",
    "BoardDetection",
    "BoardImage",
    "Calibration",
    "calibrate",
    "calibrate_images",
    "detect_board",
    "mapping_error_px",
    "sample_board_poses",
    "synthesize_views",
    "FocalEstimate",
    "ImageFocal",
    "estimate_focal",
    "estimate_focal_from_images",
]
