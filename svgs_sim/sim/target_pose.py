"""The target's pose besides its range, declared once.

Every scenario that places the target in front of a camera - the SVGS closed loop's
:class:`svgs_sim.sim.closed_loop.Scenario`, the trial kinds' :class:`svgs_sim.sim.trials.PoseScenario`
(and so the render kind), the range sweep's configuration and the ToF closed loop's
:class:`svgs_sim.sim.tof_closed_loop.TofScenario` - inherits these five fields from
:class:`TargetPose` rather than declaring them again. The range is not among them: each
scenario says what its distance is (the boresight distance ``range_m``, a stand's rail position
``rail_m``, a sweep's ``ranges_m``).

>>> from svgs_sim.sim.target_pose import TargetPose, POSE_FIELDS
>>> POSE_FIELDS
('target_x_m', 'target_y_m', 'roll_deg', 'pitch_deg', 'yaw_deg')
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True, kw_only=True)
class TargetPose:
    """The target's lateral offsets and the paper's attitude (keyword-only fields of a scenario).

    Attributes
    ----------
    target_x_m, target_y_m : float
        Lateral offsets of the target origin from the boresight (right, up in the paper's
        camera frame), m. Not the camera position ``x_m``, ``y_m`` of the paper state
        (:data:`svgs_sim.svgs.frames.STATE_KEYS`), which is in the target frame.
    roll_deg, pitch_deg, yaw_deg : float
        The paper's attitude (x-y-z sequence), degrees: of the target in front of the camera, or
        of the phone on the test stand's gimbal (``mount="stand"``), as the scenario says.
    """

    target_x_m: float = 0.0
    target_y_m: float = 0.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0


#: The names of the pose fields, in declaration order.
POSE_FIELDS = tuple(f.name for f in dataclasses.fields(TargetPose))
