"""The 2014 MSFC Flight Robotics Lab campaign of Becker, Howard & Rakoczy, simulated.

Test set-up (paper, "Test Setup")
    The phone sits on the Sensor Mount: a 3-axis gimbal (roll and pitch +/-25 deg, yaw
    +/-45 deg) on a 1-axis translation stage (+/-15 cm along the line between the mounts),
    carried on a cart along a rail to each test range. The Target Mount stays fixed.

Simulated campaign
    At each of the paper's ranges for the phone (Amaze 4G: 1, 2, 3, 4, 6.5 m; Galaxy Nexus:
    5, 10, 15, 20, 30 m) run ``trials`` trials; trial ``i`` draws its gimbal attitude
    uniformly in the envelope and its stage position uniformly in +/-15 cm (its own stream,
    :func:`svgs_sim.studies.seeding.design_rng`). The attitude is the paper's relative attitude
    (roll, pitch, yaw = phi, theta, psi) with the target origin on the boresight
    (:func:`svgs_sim.svgs.frames.pose_from_scenario`): the campaign measured the target in view.

Statistics (paper Tables 2-5)
    The paper does not define "mean error". It is computed three ways per component: |mean e|
    (the magnitude of the signed mean, the verdicts' headline reading), mean |e| and RMS
    (:data:`svgs_sim.studies.error_budget.HEADLINE_REASON` says why the headline is |mean e|); the
    standard deviation is that of the signed error (ddof = 1). Each is put beside the paper's
    numbers (``assets/data/svgs_2014_results.csv``) with the simulated/paper ratio. The
    Cramer-Rao bound per range is the median over trials of the solver's 1-sigma bound for the
    trial's centroid noise.

The honest count
    :func:`fitted_values_table` lists every fitted value (and chosen app setting) that applies
    to the campaign, what it was fitted to and the cells of Tables 2-5 it consumes
    (:data:`FIT_USES`); consumed cells get the verdict ``fitted`` and are not counted as
    reproduced. Counts are given under each reading (:func:`honest_counts`). A cell outside 2x
    is explained only by a source measured by switching it off (the error budget), otherwise it
    is ``unexplained`` with its size (:func:`svgs_sim.studies.error_budget.cell_verdicts`).
    :func:`rebuild_report` (``python -m svgs_sim.studies.campaign rebuild DIR``) rewrites a finished
    campaign's report and tables from its stored results without running a trial.

Calibration practice (``calibration="paper"``)
    The paper calibrated only "a rough approximation of each camera's focal length" from
    images at known ranges and assumed nothing about the principal point and distortion.
    With ``paper``, one calibration is made per campaign (seeded) and used by the solver in
    every trial: the focal length by simulating that procedure (:func:`paper_calibration_error`:
    images at the campaign's ranges, ranges from a hand-held range finder with an ASSUMED
    2 cm 1-sigma error, :func:`svgs_sim.calibration.focal.estimate_focal`), the principal point and k1
    off by draws from ASSUMED spreads (15 px per axis, 0.03).

Modules
    :mod:`.design` (configuration, stand settings, trials), :mod:`.paper_calibration` (the paper's
    calibration practice simulated), :mod:`.statistics` (per-range statistics), :mod:`.honest_count`
    (fitted values, verdicts, counts), :mod:`.figures`, :mod:`.html_report` (the report and its
    tables), :mod:`.folder` (a campaign folder's own files), :mod:`.run` (running, resuming,
    rebuilding). Every public name is re-exported here.
"""

from __future__ import annotations

from .design import (
    campaign_poses,
    campaign_trials,
    CampaignConfig,
    COMPONENT_LABELS,
    GIMBAL_PITCH_DEG,
    GIMBAL_ROLL_DEG,
    GIMBAL_YAW_DEG,
    make_config,
    PAPER_RANGES_M,
    POSE_STRIDE,
    SHORT,
    STAGE_HALF_TRAVEL_M,
    STAND_ERROR_STREAM,
    stand_errors,
)
from .paper_calibration import (
    CALIBRATION_KEYS,
    paper_calibration_error,
    PAPER_CALIBRATION_SPREAD,
    paper_lens,
    rangefinder_readings,
    rendered_paper_calibration,
)
from .statistics import (
    READING_OUTPUT_NAMES,
    RENAMED_STATISTICS,
    explain,
    summarize,
    SUMMARY_CELL_STATISTICS,
    SUMMARY_COLUMNS,
    summary_long_rows,
)
from .honest_count import (
    APP_SETTINGS_FILE,
    campaign_verdicts,
    consumes_text,
    FIT_USES,
    fitted_cells,
    fitted_values_table,
    FitUse,
    honest_count_object,
    honest_counts,
    misalignment_text,
    paper_table,
    UNKNOWN_FIT_USE,
)
from .figures import (
    crlb_figure,
    histogram_figures,
    sample_image_figure,
)
from .folder import (
    config_from_manifest,
    finite_json,
    log_run,
    read_honest_count,
    run_log,
)
from .html_report import (
    carried_figure,
    print_summary,
    write_campaign_report,
    write_campaign_tables,
)
from .run import (
    main,
    rebuild_report,
    run_budget_geometric,
    run_campaign,
)

__all__ = [
    "APP_SETTINGS_FILE",
    "CALIBRATION_KEYS",
    "campaign_poses",
    "campaign_trials",
    "campaign_verdicts",
    "CampaignConfig",
    "carried_figure",
    "COMPONENT_LABELS",
    "config_from_manifest",
    "consumes_text",
    "crlb_figure",
    "explain",
    "finite_json",
    "FIT_USES",
    "fitted_cells",
    "fitted_values_table",
    "FitUse",
    "GIMBAL_PITCH_DEG",
    "GIMBAL_ROLL_DEG",
    "GIMBAL_YAW_DEG",
    "histogram_figures",
    "honest_count_object",
    "honest_counts",
    "log_run",
    "main",
    "make_config",
    "misalignment_text",
    "paper_calibration_error",
    "PAPER_CALIBRATION_SPREAD",
    "paper_lens",
    "PAPER_RANGES_M",
    "paper_table",
    "POSE_STRIDE",
    "print_summary",
    "rangefinder_readings",
    "read_honest_count",
    "READING_OUTPUT_NAMES",
    "RENAMED_STATISTICS",
    "rebuild_report",
    "rendered_paper_calibration",
    "run_budget_geometric",
    "run_campaign",
    "run_log",
    "sample_image_figure",
    "SHORT",
    "STAGE_HALF_TRAVEL_M",
    "STAND_ERROR_STREAM",
    "stand_errors",
    "summarize",
    "SUMMARY_CELL_STATISTICS",
    "SUMMARY_COLUMNS",
    "summary_long_rows",
    "UNKNOWN_FIT_USE",
    "write_campaign_report",
    "write_campaign_tables",
]
