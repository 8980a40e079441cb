"""ToF sensor pipeline of the second seed (Zhu et al. 2022): gray + depth frames -> pose.

numpy / OpenCV / scipy / scikit-image only - never Mitsuba, so it runs on real ToF frames.

>>> from svgs_sim import tof
>>> pipe = tof.TofPipeline("tof-epc660", "tof-8")
>>> result = pipe.process(gray, depth_m)  # doctest: +SKIP
>>> result.state_dict if result else result.reason  # doctest: +SKIP
"""

from .camera import (DEFAULT_CAMERA, DEFAULT_PATTERN, MarkerTarget, line_of_sight, load_camera, load_target,
                     points_from_depth)
from .match import match_points
from .pipeline import PipelineParams, TofPipeline, TofSolution, solve_frame, validate_frames
from .pose import refine_line_of_sight, weighted_svd_pose

__all__ = [
    "DEFAULT_CAMERA",
    "DEFAULT_PATTERN",
    "MarkerTarget",
    "load_camera",
    "load_target",
    "line_of_sight",
    "points_from_depth",
    "match_points",
    "weighted_svd_pose",
    "refine_line_of_sight",
    "PipelineParams",
    "TofPipeline",
    "TofSolution",
    "solve_frame",
    "validate_frames",
]
