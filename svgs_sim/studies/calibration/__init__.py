"""Calibration studies (issue 5, item 4): what a calibration recovers, and what its errors cost.

Three parts, run by :func:`run_calibration_study` (``svgs calibrate study``), each as trials
of its own kind (:mod:`.trials`) through :func:`svgs_sim.studies.execution.run_study`, stored and
resumable in the study folder:

1. **Convergence of a full calibration** (:mod:`.convergence`): a rendered board set
   (:func:`svgs_sim.sim.boards.render_board_set`: Mitsuba, the profile's exact camera, the phone's
   noise and ISP) is calibrated with OpenCV from N of its views, for N in a list, over
   several subsets; errors of fx, fy, principal point and the mapping error over the image
   (:func:`svgs_sim.calibration.mapping_error_px`) against the truth.
2. **The paper's focal-length method** (:mod:`.focal`) on rendered images of the SVGS
   target facing the camera at known ranges (:func:`svgs_sim.sim.closed_loop.render_scenario`, the
   phone's exposure, detection and identification): its error against the true focal
   length for fewer ranges and added centroid noise.
3. **Propagation into pose** (:mod:`.pose`): centroids projected with the true camera,
   solved (:func:`svgs_sim.svgs.solver.solve_centroids`) with a camera that is wrong in one way -
   focal length, principal point, distortion - or with the cameras the two calibrations
   produced (focal-only, as the paper did, versus a full board calibration); pose error
   versus range, 1-40 m; and the same with centroid noise and exact intrinsics (the noise
   floor), set beside the paper's Table 4 (:mod:`.table4`).

The true camera is the profile plus a principal-point offset and distortion
(:func:`true_camera`, ASSUMPTIONS; see :mod:`.common`). The report: :mod:`.report`,
:mod:`.figures`; the orchestration: :mod:`.run`.
"""

from .common import (
    DEFAULT_BOARD,
    DEFAULT_FOCAL_EXPOSURES,
    DEFAULT_POSES_PER_RANGE,
    DEFAULT_SUBSETS,
    DEFAULT_TRUE_DIST,
    DEFAULT_TRUE_PP_OFFSET_PX,
    DEFAULT_VIEWS_LIST,
    parse_number_list,
    true_camera,
)
from .convergence import (
    Detections,
    calibration_convergence,
    calibration_errors,
    convergence_summary,
    detect_all,
)
from .focal import (
    FocalFrames,
    centroid_noise,
    default_range_sets,
    focal_frames_geometric,
    focal_frames_rendered,
    focal_study,
)
from .pose import error_cases, pose_error_study, pose_errors_batch, study_poses
from .report import summary_text, write_report
from .run import StudyResult, plan_calibration_study, run_calibration_study
from .table4 import (
    paper_phone,
    power_law_exponent,
    table4_comparison,
    table4_conclusion,
)

__all__ = [
    "DEFAULT_BOARD",
    "DEFAULT_FOCAL_EXPOSURES",
    "DEFAULT_POSES_PER_RANGE",
    "DEFAULT_SUBSETS",
    "DEFAULT_TRUE_DIST",
    "DEFAULT_TRUE_PP_OFFSET_PX",
    "DEFAULT_VIEWS_LIST",
    "Detections",
    "FocalFrames",
    "StudyResult",
    "calibration_convergence",
    "calibration_errors",
    "centroid_noise",
    "convergence_summary",
    "default_range_sets",
    "detect_all",
    "error_cases",
    "focal_frames_geometric",
    "focal_frames_rendered",
    "focal_study",
    "paper_phone",
    "parse_number_list",
    "plan_calibration_study",
    "pose_error_study",
    "pose_errors_batch",
    "power_law_exponent",
    "run_calibration_study",
    "study_poses",
    "summary_text",
    "table4_comparison",
    "table4_conclusion",
    "true_camera",
    "write_report",
]
