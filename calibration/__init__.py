"""Camera calibration for the SVGS simulator (issue 5).

* :mod:`calibration.focal` - the paper's method: focal length (and its uncertainty) from
  the spacings of the target's spots in images at known ranges.
* :mod:`calibration.boards` - full intrinsic calibration with OpenCV from chessboard,
  ChArUco and circle-grid images; board geometry, drawing and synthetic views.

Uses :mod:`svgs` only (profiles, detection, identification), so it runs on real photos.
Rendered board sets are made in :mod:`sim.boards`; the calibration study (how intrinsics
converge, what their errors cost) is :mod:`studies.calibration`.
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
