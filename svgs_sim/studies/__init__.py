"""Studies: campaigns, sensitivity analyses and sweeps over many trials.

One function runs one trial (:mod:`svgs_sim.sim.trials`); an executor runs many
(:mod:`svgs_sim.studies.execution`: local process pool, Dask LocalCluster or an existing Dask
cluster); a results store appends rows as they finish and lets an interrupted study resume
(:mod:`svgs_sim.studies.store`); seeds are per trial (:mod:`svgs_sim.studies.seeding`), so results do not
depend on the executor. :mod:`svgs_sim.studies.campaign` reproduces the 2014 MSFC test campaign,
:mod:`svgs_sim.studies.sensitivity` computes Sobol'/Morris indices, :mod:`svgs_sim.studies.report` writes
self-contained HTML reports.

Trial kinds (what one trial computes) live in :mod:`svgs_sim.sim.trials`. Nothing here imports
Mitsuba; the ``render`` trial kind (:mod:`svgs_sim.sim.render_trial`) loads it when it runs.
"""

from .execution import ExecutorSpec, Trial, executor_spec, open_executor, run_study
from .seeding import design_rng, trial_seed
from .store import ResultStore, read_rows, read_table
from svgs_sim.sim.trials import (GEOMETRIC, Parameter, TrialKind, geometric_scenario, geometric_trial, get_trial_kind,
                     register_trial_kind)

__all__ = [
    "ExecutorSpec",
    "Trial",
    "executor_spec",
    "open_executor",
    "run_study",
    "trial_seed",
    "design_rng",
    "ResultStore",
    "read_rows",
    "read_table",
    "Parameter",
    "TrialKind",
    "GEOMETRIC",
    "geometric_scenario",
    "geometric_trial",
    "get_trial_kind",
    "register_trial_kind",
]
