"""The ``render`` trial kind: Mitsuba render -> phone exposure -> SVGS solve.

Registers with :mod:`svgs_sim.sim.trials`, so ``svgs campaign --trial-kind render`` and
``svgs sensitivity --trial-kind render`` run the full physical chain, and
``svgs_sim.studies.range_sweep`` and ``svgs_sim.studies.exposure_study`` build its scenarios (with
:func:`render_trial_scenario`). A trial is :func:`svgs_sim.sim.closed_loop.render_scenario` (Mitsuba, the
lab light) followed by :func:`svgs_sim.sim.closed_loop.expose_and_solve` (phone model, detector,
solver), exactly the chain of ``svgs render-and-solve``.

Render once, expose many
    The render key is everything that decides the rendered flux: camera, pattern and its
    scale, pose, lab, samples per pixel and the render's own Monte Carlo seed
    (``render_seed``, a scenario parameter, so trials sharing a render agree on it). What acts
    after the render - the noise draw (the trial's seed), a forced exposure or ISO, a
    neutral-density filter over the reflectors (``target_scale``), the detector threshold,
    the calibration the solver uses - varies within a render group. A trial's numbers depend
    only on its scenario and seed, whether it runs alone or in a group.

Scenario keys
    Text: ``camera``, ``pattern`` (name or path). Numbers: :data:`RENDER_PARAMETERS` (the
    defaults are a render with seed 0 of the pattern as it is, no ND filter, the renderer's
    samples per pixel, the phone's auto-exposure, the app's brightness threshold (svgs_sim.svgs.app) and the exact
    calibration). With ``stand = 1`` the angles turn the phone on the test stand
    (:mod:`svgs_sim.sim.stand`); ``lens_*`` make the true lens differ from the profile (the solver's
    ``*_error`` are relative to it); ``sensor_noise``, ``glare``, ``quantise``, ``cfa``, ``nr``,
    ``sharpen``, ``chroma``, ``jpeg`` switch error sources off and ``truth_actual``,
    ``truth_stand``, ``truth_rail`` take the errors against the pose with the phone's
    misalignment, the stand's errors (``stand_err_*``) or the rail's (``rail_err_m``) included (the
    campaign's error budget); ``turbulence_cn2`` moves each exposure's spots through the lab's air
    (:func:`turbulent_points`); ``demosaic``,
    ``jpeg_quality`` and ``jpeg_grid_offset_*_px`` choose the ISP's demosaic and JPEG;
    ``f_number``, ``led_offset_scale``, ``glare_*``, ``exposure_compensation_ev`` are the physics
    a sensitivity study varies. Studies add labels (``nominal_range_m``, ``pose_index``,
    ``trial``, ``remedy``...) carried into the rows unchanged.

The module is a package of one job per module: :mod:`.scenario` (the parameters, the typed scenario
and the render key) and :mod:`.run` (the frame, its exposures and the solve; the kind's
registration); the package exports their public names.
"""

from .scenario import (
    DEMOSAIC_CODES, RENDER_OUTPUTS, RENDER_PARAMETERS, RENDER_TIMING_OUTPUTS, RenderKey, RenderScenario,
    SOURCE_SWITCHES, THRESHOLD_APP, THRESHOLD_AUTO, THRESHOLD_OTSU, camera_overrides, check_threshold,
    render_key, render_trial_scenario, threshold_parameter,
)
from .run import (
    RENDER, exposure_isp, exposure_stages, merge_margin_dn, render_group, render_trial, rendered_frame,
    trial_picture, turbulent_points,
)

__all__ = [
    "DEMOSAIC_CODES", "RENDER_OUTPUTS", "RENDER_PARAMETERS", "RENDER_TIMING_OUTPUTS", "RenderKey",
    "RenderScenario", "SOURCE_SWITCHES", "THRESHOLD_APP", "THRESHOLD_AUTO", "THRESHOLD_OTSU",
    "camera_overrides", "check_threshold", "render_key", "render_trial_scenario", "threshold_parameter",
    "RENDER", "exposure_isp", "exposure_stages", "merge_margin_dn", "render_group", "render_trial",
    "rendered_frame", "trial_picture", "turbulent_points",
]
