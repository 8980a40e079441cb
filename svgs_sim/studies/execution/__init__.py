"""Where trials run: a ``concurrent.futures.Executor`` chosen by the user, and the loop that
feeds it and stores rows as they finish.

Executors (:func:`executor_spec`)
    - default: a local process pool with one process per CPU core;
    - ``--processes N``: a local process pool of N processes (``0``: run in this process,
      no pool - for debugging);
    - ``--workers N``: a Dask ``LocalCluster`` of N single-threaded worker processes,
      through ``distributed.Client(cluster).get_executor()``;
    - ``--scheduler tcp://HOST:PORT``: an existing Dask cluster.

Dask is an optional extra (``pip install 'svgs-sim[dask]'``). Missing Dask and an
unreachable scheduler are :class:`~svgs_sim.base.errors.InputError`\\ s raised by
:func:`check_executor`, before any work starts.

Workers die with their parent: a local pool's or LocalCluster's worker processes end when the
process that started them dies, even by SIGKILL (:func:`die_with_parent`).

Interrupts: Ctrl-C (``KeyboardInterrupt``, or a subclass such as the CLI's SIGTERM exception)
stops a study at once. In this process (``--processes 0``) the trials run render group by render
group and each group's rows are stored as it finishes; an interrupt lets the group under way
finish (a few trials, or one render and its exposures: a second Ctrl-C abandons it), stores it
and stops, so no group starts after the interrupt; run from the command line, a group still
under way half a second after the signal (a render cannot be entered by Python's handler) is
abandoned and the process stops with the rows stored so far (:mod:`svgs_sim.sim.hard_stop`). On a pool
the rows of every finished task are stored, then the workers are terminated (they ignore SIGINT themselves: Ctrl-C in a
terminal reaches the whole process group). The interrupt is re-raised with :class:`StoredProgress` attached as its
``svgs_stored`` attribute (:func:`stored_progress`): how many trials the store holds.

Results do not depend on the executor: each trial carries its own seed
(:mod:`svgs_sim.studies.seeding`) and trials never share random state. Trials are packed into tasks
(chunks of ``chunk_size`` trials, trials sharing a render key kept together) to amortise the
per-task overhead; the packing does not change any trial's numbers either.
"""

from __future__ import annotations

from .executors import (
    SCHEDULER_TIMEOUT_S,
    STOP_JOIN_S,
    ExecutorSpec,
    InlineExecutor,
    check_executor,
    executor_spec,
    open_executor,
    parse_scheduler_address,
)
from .loop import (
    TASKS_PER_WORKER,
    RunStats,
    StoredProgress,
    library_versions,
    run_stored_study,
    run_study,
    stored_progress,
)
from .parent_watch import PARENT_POLL_S, die_with_parent
from .plan import (
    COST_TABLE_S,
    LONG_STUDY_S,
    StudyPlan,
    cpu_cores,
    plan_study,
    plan_trials,
)
from .tasks import DEFAULT_CHUNK_SIZE, Trial, make_tasks, run_task, warm_up_worker

__all__ = [
    "COST_TABLE_S",
    "DEFAULT_CHUNK_SIZE",
    "ExecutorSpec",
    "InlineExecutor",
    "LONG_STUDY_S",
    "PARENT_POLL_S",
    "RunStats",
    "SCHEDULER_TIMEOUT_S",
    "STOP_JOIN_S",
    "StoredProgress",
    "StudyPlan",
    "TASKS_PER_WORKER",
    "Trial",
    "check_executor",
    "cpu_cores",
    "die_with_parent",
    "executor_spec",
    "library_versions",
    "make_tasks",
    "open_executor",
    "parse_scheduler_address",
    "plan_study",
    "plan_trials",
    "run_stored_study",
    "run_study",
    "run_task",
    "stored_progress",
    "warm_up_worker",
]
