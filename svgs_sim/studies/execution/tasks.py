"""Trials and tasks: a :class:`Trial` (id, scenario, seed), the packing of trials into tasks
(:func:`make_tasks`: trials sharing a render kept together) and what a worker runs
(:func:`run_task`)."""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass

from svgs_sim.sim.trials import TrialKind, get_trial_kind

#: Default number of trials per task.
DEFAULT_CHUNK_SIZE = 16


def run_task(kind_ref: tuple[str, str], items: list) -> list[dict]:
    """Run one task of a study (in a worker process): trials sharing a render key or a chunk.

    Parameters
    ----------
    kind_ref : (module, name)
        Where the trial kind is registered (:attr:`svgs_sim.sim.trials.TrialKind.ref`).
    items : list of (trial_id, scenario, seed)

    Returns
    -------
    list of dict
        One row per trial: ``trial_id``, ``seed``, the scenario, the outputs, ``wall_s`` and
        ``cpu_s`` (wall-clock and worker CPU seconds, averaged over a render group).
    """
    kind = _kind(kind_ref)
    _warm(kind)
    return [row for rows in _group_rows(kind, items) for row in rows]


def _group_rows(kind: TrialKind, items: list):
    """Run the trials of one task render group by render group, yielding each group's rows.

    Parameters
    ----------
    kind : TrialKind
    items : list of (trial_id, scenario, seed)

    Yields
    ------
    list of dict
        The rows of one group of consecutive items sharing a render key (one row per trial
        when the kind has no ``run_group``), as :func:`run_task` returns them.
    """
    groups: list[list] = []
    for it in items:
        key = kind.render_key(it[1]) if (kind.render_key and kind.run_group) else None
        if groups and key is not None and groups[-1][0] == key:
            groups[-1][1].append(it)
        else:
            groups.append([key, [it]])
    for key, grp in groups:
        t0, c0 = time.perf_counter(), time.process_time()
        if key is not None and len(grp) > 1:
            outs = kind.run_group([g[1] for g in grp], [g[2] for g in grp])
        else:
            outs = [kind.run_trial(g[1], g[2]) for g in grp]
        dt, dc = (time.perf_counter() - t0) / len(grp), (time.process_time() - c0) / len(grp)
        yield [{"trial_id": int(tid), "seed": int(seed), **scen, **out, "wall_s": dt, "cpu_s": dc}
               for (tid, scen, seed), out in zip(grp, outs)]


def _kind(kind_ref: tuple[str, str]) -> TrialKind:
    """Import the module that registers the kind (in a fresh worker), then look it up."""
    module, name = kind_ref
    importlib.import_module(module)
    return get_trial_kind(name)


#: Trial kinds already warmed up in this process.
_WARMED: set = set()


def _warm(kind: TrialKind) -> None:
    if kind.warm_up is not None and kind.name not in _WARMED:
        kind.warm_up()
        _WARMED.add(kind.name)


def warm_up_worker(kind_ref: tuple[str, str]) -> None:
    """Import the kind's module and warm it up (in each worker of a pool or a LocalCluster)."""
    _warm(_kind(kind_ref))


@dataclass(frozen=True)
class Trial:
    """One trial of a study: its id (unique in the study), scenario and seed."""

    trial_id: int
    scenario: dict
    seed: int


def make_tasks(kind: TrialKind, trials: list[Trial], chunk_size: int) -> list[list]:
    """Pack trials into tasks of at most ``chunk_size`` trials (larger only to keep a render
    group whole, up to ``4 * chunk_size``); trials with equal render keys go to the same task,
    consecutively.

    Returns
    -------
    list of list of (trial_id, scenario, seed)
    """
    groups: dict = {}
    for tr in trials:
        key = kind.render_key(tr.scenario) if kind.render_key is not None else ("__trial__", tr.trial_id)
        groups.setdefault(key, []).append((tr.trial_id, tr.scenario, tr.seed))
    tasks, cur = [], []
    for grp in groups.values():
        while len(grp) > 4 * chunk_size:  # a huge group: split it (each part renders once)
            if cur:
                tasks.append(cur)
                cur = []
            tasks.append(grp[: 4 * chunk_size])
            grp = grp[4 * chunk_size:]
        if cur and len(cur) + len(grp) > chunk_size:
            tasks.append(cur)
            cur = []
        cur = cur + grp
    if cur:
        tasks.append(cur)
    return tasks
