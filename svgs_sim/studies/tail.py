"""The tail the rendered studies share: run (or resume) the trials in a results store, then
write the study's outputs from the stored rows.

Used by :mod:`svgs_sim.studies.range_sweep` and :mod:`svgs_sim.studies.exposure_study`; each gives its trials,
its manifest and a function that turns the store's rows into its files.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Callable

from svgs_sim.sim.trials import get_trial_kind

from .execution import run_stored_study


def run_rendered_study(trials: list, out_dir, manifest: dict, spec, write_outputs: Callable[[list], object], *,
                       description: str, chunk_size: int | None = None, progress: bool = True):
    """Run the trials of a rendered study that its store does not hold yet, then write its outputs.

    Parameters
    ----------
    trials : list of :class:`svgs_sim.studies.execution.Trial`
        Trials of the ``render`` trial kind (:mod:`svgs_sim.sim.render_trial`).
    out_dir : str or Path
        The study directory (the resumable store: a rerun skips the finished trials, a changed
        manifest is refused).
    manifest : dict
        What the study computes (:func:`svgs_sim.studies.execution.run_stored_study`).
    spec : svgs_sim.studies.execution.ExecutorSpec
    write_outputs : callable
        ``write_outputs(rows)`` with the store's rows (list of dict, in trial order); its
        return value is returned.
    description : str
        The progress bar's label.
    chunk_size : int, optional
        Trials per task (a render group is kept whole).

    Returns
    -------
    (outputs, stats)
        What ``write_outputs`` returned, and the :class:`~svgs_sim.studies.execution.RunStats` (None if
        every trial was already done).
    """


    store, stats = run_stored_study(get_trial_kind("render"), trials, out_dir, manifest, spec, chunk_size=chunk_size,
                                    progress=progress, description=description)
    return write_outputs(store.read_rows()), stats


def write_dict_csv(path, rows: list[dict]) -> None:
    """``rows`` (dicts with the same keys, in order) as a CSV file with a header, at ``path``."""
    with open(Path(path), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
