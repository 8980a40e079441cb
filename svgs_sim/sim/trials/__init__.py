"""Trial kinds: what one trial of a study computes, registered by name.

A trial kind is a top-level (picklable) function ``run_trial(scenario: dict, seed: int) ->
dict`` plus a description of its inputs and outputs. Studies (campaign, sensitivity, range
sweeps) only build scenarios and hand them, with per-trial seeds (:mod:`svgs_sim.studies.seeding`),
to an executor (:mod:`svgs_sim.studies.execution`); they never call a renderer or solver themselves.
So the render-and-solve trial plugs in with :func:`register_trial_kind` and every study runs
on it unchanged.

Render once, expose many
    A kind may declare ``render_key(scenario) -> hashable``: trials with equal keys need the
    same expensive render (same geometry, camera, pattern, flash...), differing only in what
    happens after it (noise draw, exposure, centroiding, calibration used by the solver).
    The runner packs such trials into one task and calls ``run_group(scenarios, seeds)``,
    which renders once and exposes/solves each trial. ``run_group`` must return exactly the
    rows ``run_trial`` would (a trial's numbers never depend on its companions).

The built-in kind ``geometric`` projects the pattern through the camera at the scenario's
pose, adds seeded Gaussian centroid noise, optionally gives the solver a wrong calibration
(focal length, principal point, radial distortion), solves with
:func:`svgs_sim.svgs.solve_centroids` and records truth, estimate, errors and the Cramer-Rao bound.
Its "render" (the projection) is grouped the same way, so the mechanism is exercised today.

The module is a package of one job per module: :mod:`.registry` (kinds, their parameters, the
registry), :mod:`.scenario` (the typed scenarios) and :mod:`.geometric` (the built-in kind); the
package exports their public names.
"""

from .registry import (
    ID_COLUMNS, KIND_MODULES, Code, Parameter, TIMING_COLUMNS, TrialKind, get_trial_kind, known_trial_kinds,
    register_trial_kind,
)
from .scenario import (
    POSE_KEYS, PoseKey, PoseScenario, RowView, TRUTH_KEYS, TrialScenario, as_scenario, build_scenario,
    camera_with_calibration_errors,
)
from .geometric import (
    GEOMETRIC, GEOMETRIC_OUTPUTS, GEOMETRIC_PARAMETERS, GeometricScenario, estimate_outputs, geometric_group,
    geometric_render_key, geometric_scenario, geometric_trial, geometric_warm_up,
)

__all__ = [
    "KIND_MODULES", "ID_COLUMNS", "TIMING_COLUMNS", "Code", "Parameter", "TrialKind", "register_trial_kind",
    "known_trial_kinds", "get_trial_kind", "POSE_KEYS", "TRUTH_KEYS", "TrialScenario", "PoseScenario", "RowView",
    "as_scenario", "camera_with_calibration_errors", "build_scenario", "PoseKey", "GEOMETRIC_PARAMETERS",
    "GeometricScenario", "geometric_scenario", "GEOMETRIC_OUTPUTS", "estimate_outputs", "geometric_trial",
    "geometric_group", "geometric_render_key", "geometric_warm_up", "GEOMETRIC",
]
