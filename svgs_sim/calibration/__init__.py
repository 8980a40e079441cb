"""Camera calibration for the SVGS simulator (issue 5).

* :mod:`svgs_sim.calibration.focal` - the paper's method: focal length (and its uncertainty) from
  the spacings of the target's spots in images at known ranges.
* Full intrinsic calibration with OpenCV from chessboard, ChArUco and circle-grid images:
  :mod:`svgs_sim.calibration.boards` (board geometry and drawing), :mod:`svgs_sim.calibration.detection`
  (finding a board's features), :mod:`svgs_sim.calibration.intrinsics` (``calibrateCamera``, the
  result, mapping error), :mod:`svgs_sim.calibration.synthetic` (random board poses, geometric views).

Uses :mod:`svgs` only (profiles, detection, identification), so it runs on real photos.
Rendered board sets are made in :mod:`svgs_sim.sim.boards`; the calibration study (how intrinsics
converge, what their errors cost) is :mod:`svgs_sim.studies.calibration`.
"""

from .boards import BOARD_KINDS, Board, BoardImage
from .detection import BoardDetection, detect_board, detect_views
from .focal import FocalEstimate, ImageFocal, estimate_focal, estimate_focal_from_images
from .intrinsics import Calibration, calibrate, calibrate_images, mapping_error_px
from .synthetic import sample_board_poses, synthesize_views

__all__ = [
    "BOARD_KINDS",
    "Board",
    "BoardDetection",
    "BoardImage",
    "Calibration",
    "calibrate",
    "calibrate_images",
    "detect_board",
    "detect_views",
    "mapping_error_px",
    "sample_board_poses",
    "synthesize_views",
    "FocalEstimate",
    "ImageFocal",
    "estimate_focal",
    "estimate_focal_from_images",
]
