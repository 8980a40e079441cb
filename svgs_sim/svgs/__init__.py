"""SVGS: the Smartphone Video Guidance Sensor's algorithms (Becker, Howard & Rakoczy 2014).

Runs on any image - a real photo or a rendered one - with numpy, OpenCV and scipy only.

>>> from svgs_sim import svgs
>>> cam = svgs.Camera.load("galaxy-nexus")
>>> pat = svgs.Pattern.load("svgs-3u")
"""

from ..base.errors import InputError, ProfileError
from ..base.profiles import Camera, Pattern
from .frames import pose_from_scenario, pose_to_state, state_dict, state_to_pose
from .pipeline import load_image, solve_image
from .result import REASONS, Failure
from .solver import BatchSolution, Solution, solve_centroids

__all__ = [
    "Camera",
    "Pattern",
    "solve_centroids",
    "solve_image",
    "load_image",
    "Solution",
    "BatchSolution",
    "Failure",
    "REASONS",
    "InputError",
    "ProfileError",
    "pose_from_scenario",
    "pose_to_state",
    "state_to_pose",
    "state_dict",
]
