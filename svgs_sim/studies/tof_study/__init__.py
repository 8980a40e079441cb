"""The committed ToF report (``svgs tof study``): the paper's stability runs, what moves them, the
accuracy-versus-distance sweep of its Fig. 14 and the failure modes.

Writes into ``out``: ``tof_stability.md`` (the report), ``tof_stability.csv`` (every
statistic of every run, the paper's rows beside them), ``tof_stability_series.png``,
``tof_mechanisms.png``, ``tof_fig14.png`` and ``tof_failure_modes.png``.

The study is a package of one job per module: :mod:`.design` (the configuration, the paper's
ranges, the mechanisms and the runs), :mod:`.run` (the runs on the study engine and their
sections), :mod:`.failures` (the failure-mode demonstrations), :mod:`.figures` and
:mod:`.report` (the CSV and the Markdown report).
"""

from .design import PAPER_RANGES_M, SWEEP_RANGES_M, TofStudyConfig, runs_from_rows, study_runs, study_trials
from .run import run_study

__all__ = ["run_study", "TofStudyConfig", "study_runs", "study_trials", "runs_from_rows", "PAPER_RANGES_M",
           "SWEEP_RANGES_M"]
