"""The calibration study's plan: what each part does and how long it should take, before any work.

``svgs calibrate study`` prints one plan line (and ``--plan-only`` stops there): the board views,
the calibrations, the focal frames and cases and the pose-error cells, with an estimate from
measured per-unit costs; the warnings above an hour and for more workers than cores are the
other studies' (:meth:`svgs_sim.studies.execution.StudyPlan.warnings`). Each part's own plan line, when
it starts, takes its cost from the same constants.

The costs are core-seconds measured by ``benchmarks/bench_calibration_study.py`` (the Galaxy
Nexus at its 2592 x 1944 px, 5.04 Mpx; in one process) on the 2-core development machine while
another job shared it, so they err long: the geometric board set 17 s for its shared rays and
3.4 s a view, the detection 0.016 s a view, a rendered view at 4 and 16 spp 3.4 and 8.0 s (0.37 s
per megapixel and 0.076 s per megapixel and sample per pixel), a calibration 0.01 s a view, a
focal-method case 1.1 ms a noise draw, a pose-error cell 0.34 ms a pose (a second run: 10-30 %
less). The default geometric study took 187 s (its plan says 158 s), of which the board set
179 s and all 294 trials 1.7 s. Images cost in proportion to their pixels, a rendered board view
also to its samples per pixel; a rendered focal frame is the render kind's chain (one render and
``--focal-exposures`` exposures, :data:`svgs_sim.studies.execution.COST_TABLE_S`; measured 1.2-3.4 s with 4
exposures, against the table's 2.2 s).
"""

from __future__ import annotations

from dataclasses import dataclass

from svgs_sim.studies.execution.plan import COST_TABLE_S, StudyPlan, _duration, cpu_cores

from .common import DEFAULT_FOCAL_TRIALS
from .convergence import convergence_subsets
from .focal import default_range_sets

#: A geometric board set (``--geometric``): the sample rays shared by its views, once, s per megapixel.
GEOMETRIC_BOARD_SETUP_S_PER_MPX = 3.3
#: A geometric board view, s per megapixel.
GEOMETRIC_BOARD_VIEW_S_PER_MPX = 0.68
#: A rendered board view (Mitsuba, the phone model): s per megapixel, and s per megapixel and
#: sample per pixel of the render.
RENDERED_BOARD_VIEW_S_PER_MPX = 0.37
RENDERED_BOARD_VIEW_S_PER_MPX_SAMPLE = 0.076
#: Finding the board in a view (OpenCV), s per megapixel.
DETECTION_S_PER_MPX = 0.0032
#: A calibration (OpenCV), s per view it uses.
CALIBRATION_S_PER_VIEW = 0.01
#: A focal-method case, s per noise draw.
FOCAL_S_PER_DRAW = 0.0011
#: A pose-error cell, s per pose.
POSE_S_PER_POSE = 0.00034
#: Where the costs come from, for the plan line.
COST_SOURCE = "measured costs, svgs_sim/studies/calibration/plan.py"


@dataclass(frozen=True)
class CalibrationStudyPlan(StudyPlan):
    """A :class:`svgs_sim.studies.execution.StudyPlan` of the calibration study (or of one of its parts):
    work done in this process (the board set, its detections, the focal frames) and trials run
    on the executor, each with its measured cost.

    Attributes
    ----------
    counts : str
        What the study does, in words (``"40 board view(s) rendered (16 spp) at 2592x1944 px ..."``).
    serial_s : float
        Core-seconds of the work done in this process, one core.
    trials_s : float
        Core-seconds of the trials (shared among the executor's workers).
    """

    counts: str = ""
    serial_s: float = 0.0
    trials_s: float = 0.0

    @property
    def core_s(self) -> float:
        """Estimated core-seconds (the measured costs of the module notes)."""
        return self.serial_s + self.trials_s

    @property
    def wall_s(self) -> float | None:
        """Estimated wall-clock seconds (None on a remote cluster)."""
        return self.serial_s + self.trials_s / self.parallel if self.parallel else None

    def describe(self) -> str:
        """One line: the counts and the estimate."""
        note = f" ({self.note})" if self.note else ""
        est = f"~{_duration(self.core_s)} of one core ({COST_SOURCE})"
        return f"plan: {self.counts}{note}; {est}{self.spread_text()}"


def _plan(counts: str, serial_s: float, trials_s: float, spec, note: str = "") -> CalibrationStudyPlan:
    return CalibrationStudyPlan("calibration", 0, 0, spec, cpu_cores(), note, counts, float(serial_s), float(trials_s))


def trial_cost_s(part: str, scenario) -> float:
    """Estimated core-seconds of one trial of the study's ``part`` (``"convergence"``,
    ``"focal"``, ``"pose"``) from its scenario (:mod:`svgs_sim.studies.calibration.trials`)."""
    if part == "convergence":
        return CALIBRATION_S_PER_VIEW * int(scenario["n_views"])
    if part == "focal":
        return FOCAL_S_PER_DRAW * int(scenario["n_trials"])
    return POSE_S_PER_POSE * int(scenario["poses_per_range"])


def part_plan(part: str, trials, spec, done_ids=()) -> CalibrationStudyPlan:
    """The plan of one part's trials not in ``done_ids`` (said when the part starts)."""
    done = set(done_ids)
    pending = [t for t in trials if t.trial_id not in done]
    note = f"{len(trials) - len(pending):,} already stored" if done else ""
    return _plan(f"{len(pending):,} trial(s)", 0.0, sum(trial_cost_s(part, t.scenario) for t in pending), spec, note)


def board_set_cost_s(n_views: int, width: int, height: int, *, geometric: bool, spp: int, make: bool = True) -> float:
    """Estimated core-seconds of making ``n_views`` board views (unless ``make`` is False: views
    kept from a previous run) and finding the board in them."""
    mpx = width * height / 1e6
    if not make:
        made = 0.0
    elif geometric:
        made = GEOMETRIC_BOARD_SETUP_S_PER_MPX * mpx + n_views * GEOMETRIC_BOARD_VIEW_S_PER_MPX * mpx
    else:
        made = n_views * mpx * (RENDERED_BOARD_VIEW_S_PER_MPX + RENDERED_BOARD_VIEW_S_PER_MPX_SAMPLE * spp)
    return made + n_views * DETECTION_S_PER_MPX * mpx


def _kept_text(kept: dict) -> str:
    if kept.get("detections"):
        board = "the views' detections kept"
    elif kept.get("views"):
        board = "the views kept, searched again"
    else:
        board = "made and searched"
    return board + ("; the focal frames kept" if kept.get("focal_frames") else "")


def study_plan(config: dict, width: int, height: int, n_error_cases: int, spec, *, convergence_seed: int = 0,
               kept=None, note: str = "") -> CalibrationStudyPlan:
    """The plan of a whole study from its configuration (nothing is made or run).

    Parameters
    ----------
    config : dict
        The study's checked parameters (``views_list``, ``subsets``, ``geometric``, ``spp``,
        ``focal_ranges_m``, ``focal_exposures``, ``noise_levels_px``, ``pose_ranges_m``,
        ``poses_per_range``, ``floor_noise_px``), as :func:`svgs_sim.studies.calibration.run_calibration_study`
        checks them.
    width, height : int
        The true camera's image size, px.
    n_error_cases : int
        Believed cameras wrong in one way (:func:`svgs_sim.studies.calibration.pose.error_cases`).
    spec : svgs_sim.studies.execution.ExecutorSpec
    convergence_seed : int
        The convergence part's seed (the subsets drawn, duplicates dropped, as the study will).
    kept : dict, optional
        What a rerun reuses, at no cost: ``"detections"`` (the board set and its detections),
        ``"views"`` (the board views; they are still searched), ``"focal_frames"`` (bools).
    note : str
        Said after the counts.
    """

    c = config
    vl, n_views = list(c["views_list"]), int(c["views_list"][-1])
    subsets = convergence_subsets(n_views, vl, c["subsets"], convergence_seed)
    n_sets = len(default_range_sets(c["focal_ranges_m"]))
    draws = n_sets * sum(1 if s == 0 else DEFAULT_FOCAL_TRIALS for s in c["noise_levels_px"])
    n_cases = n_sets * len(c["noise_levels_px"])
    believed = 1 + len(vl)  # the focal-only calibration and a full one per N
    n_cells = len(c["pose_ranges_m"]) * (n_error_cases + believed + 3 * len(c["floor_noise_px"]))
    n_ranges, exposures = len(c["focal_ranges_m"]), int(c["focal_exposures"])
    kept = dict(kept or {})
    render_s, exposure_s = COST_TABLE_S["render"]
    serial_s = 0.0 if kept.get("detections") else board_set_cost_s(
        n_views, width, height, geometric=c["geometric"], spp=c["spp"], make=not kept.get("views"))
    if not c["geometric"] and not kept.get("focal_frames"):
        serial_s += n_ranges * (render_s + exposures * exposure_s)
    trials_s = (CALIBRATION_S_PER_VIEW * sum(n for n, _, _ in subsets) + FOCAL_S_PER_DRAW * draws
                + POSE_S_PER_POSE * n_cells * int(c["poses_per_range"]))
    how = "geometric" if c["geometric"] else f"rendered ({c['spp']} spp)"
    views = (f"{n_views} board view(s) {how} at {width}x{height} px and their detection" if not any(kept.values()) else
             f"{n_views} board view(s) at {width}x{height} px ({_kept_text(kept)})")
    frames = f"{n_ranges} focal frame(s) of {exposures} exposure(s)" + ("" if c["geometric"] else " rendered")
    counts = (f"{views}, {len(subsets)} calibration(s), {frames}, {n_cases} focal-method case(s), {n_cells} "
              f"pose-error cell(s) of {int(c['poses_per_range'])} pose(s)")
    return _plan(counts, serial_s, trials_s, spec, note)


__all__ = ["CalibrationStudyPlan", "board_set_cost_s", "part_plan", "study_plan", "trial_cost_s"]
