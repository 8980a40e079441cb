"""An approach simulated frame by frame: trajectories and a sensor that measures along them.

The SVGS sensor in a GNC loop sees one frame after another. :class:`ApproachSensor` is that
sensor for a simulation loop: give it the pose at each frame time and it renders the target
(Mitsuba), exposes it through the phone (its auto-exposure carried over from the previous frame,
as a phone's camera runs on a stream), detects, identifies and solves, and returns a
:class:`Measurement` (the estimate, the truth, the 1-sigma Cramer-Rao bound, ``ok`` and the
reason, and where the time went). :class:`Trajectory` gives the poses: a straight approach, or a
CSV file.

Motion during a frame. A phone's CMOS sensor exposes its rows one after another (a rolling
shutter, ``[sensor] readout_time_s``: 30 ms top to bottom, ASSUMPTION) and each row for the
exposure time. Both are modelled on the spots, which carry the measurement: every point sample
of the render (:class:`svgs_sim.camera.rendered.PointFlux`) is moved by its spot's image velocity times
its arrival time (:meth:`~svgs_sim.camera.rendered.PointFlux.moved`), the time measured from the frame's
timestamp, the exposure midpoint of the centre row. The image velocity comes from the
trajectory (the projected targets at ``t +- 1 ms``). The target body and the lab (a uniform
backdrop, ambient light) are not moved: the body's light is ~1e-7 of the spots' and a uniform
field does not change when it moves.

The sensor keeps what a real one keeps from frame to frame: one renderer (the scene built once,
the lens refocused on the target each frame, as the phones' autofocus), one sensor (its fixed
pattern noise), the auto-exposure state. The numbers of a frame are those of
:func:`svgs_sim.sim.closed_loop.render_scenario` and :func:`svgs_sim.sim.closed_loop.expose_and_solve` for the same
scenario, seeds and exposure (``tests/test_sim_approach.py``).

Modules
    :mod:`.trajectory` (poses against time, :class:`Trajectory`, :func:`check_visible`),
    :mod:`.stream` (what the phone carries between frames: the auto-exposure, the one renderer),
    :mod:`.sensor` (:class:`ApproachSensor`, :class:`Measurement`). Every public name is
    re-exported here.
"""

from __future__ import annotations

from .sensor import (
    CRLB_DRAWS,
    MEASUREMENT_COLUMNS,
    OUT_OF_VIEW,
    TIMING_KEYS,
    ApproachSensor,
    Measurement,
    scenario_from_pose,
)
from .stream import MAX_AE_STEPS, STREAM_FPS, ExposureStream, RenderStream, ae_steps, frame_seeds
from .trajectory import (
    MAX_FRAMES,
    STAND_COLUMNS,
    STAND_FIELDS,
    STATE_COLUMNS,
    TARGET_FIELDS,
    VELOCITY_STEP_S,
    VISIBILITY_MARGIN_PX,
    Trajectory,
    check_visible,
)

__all__ = [
    "ApproachSensor", "CRLB_DRAWS", "ExposureStream", "MAX_AE_STEPS", "MAX_FRAMES", "MEASUREMENT_COLUMNS",
    "Measurement", "OUT_OF_VIEW", "RenderStream", "STAND_COLUMNS", "STAND_FIELDS", "STATE_COLUMNS", "STREAM_FPS",
    "TARGET_FIELDS", "TIMING_KEYS", "Trajectory", "VELOCITY_STEP_S", "VISIBILITY_MARGIN_PX", "ae_steps",
    "check_visible", "frame_seeds", "scenario_from_pose",
]
