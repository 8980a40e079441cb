"""Study plans (:func:`plan_study`, :func:`plan_trials`): counts and an estimate from the
measured per-unit costs (:data:`COST_TABLE_S`) before any work, with warnings for long studies
and for more workers than cores."""

from __future__ import annotations

import os
from dataclasses import dataclass

from svgs_sim.sim.trials import TrialKind

from .executors import ExecutorSpec
from .tasks import Trial

#: Core-seconds of one render and of one trial (an exposure, or a geometric trial) per trial
#: kind: the cost table a study's plan is estimated from (docs/performance.md, "Plans"). The
#: render kind's are the 400-trial campaigns' measured cost (97 s and 172 s on two processes,
#: 100 renders and 400 exposures: about 1 s a render and 0.3 s an exposure of one core).
#: The tof kind's: the committed ToF study (docs/reports/tof_stability.md, 15,800 frames, 20
#: renders): renders of 2.8-20 s (about 10 s), each frame's exposure and pipeline 0.067 s.
COST_TABLE_S = {"render": (1.0, 0.3), "geometric": (0.0, 0.001), "tof": (10.0, 0.067)}


#: A plan warns when its estimated wall-clock time exceeds this many seconds.
LONG_STUDY_S = 3600.0


def cpu_cores() -> int:
    """The CPU cores this process may run on (``os.sched_getaffinity`` where there is one,
    else ``os.cpu_count()``; at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.2g} s" if seconds < 10 else f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


@dataclass(frozen=True)
class StudyPlan:
    """What a study is about to do and how long it should take, before any work starts.

    Attributes
    ----------
    kind : str
        Trial kind (a key of :data:`COST_TABLE_S`).
    n_trials : int
        Trials of the study (those already stored are skipped when it runs).
    n_renders : int
        Renders (distinct render keys); 0 for a kind that does not render.
    spec : ExecutorSpec
        Where the trials run.
    cores : int
        CPU cores this process may use (:func:`cpu_cores`).
    note : str
        Said after the counts (e.g. what they leave out); may be empty.
    """

    kind: str
    n_trials: int
    n_renders: int
    spec: ExecutorSpec
    cores: int
    note: str = ""

    @property
    def core_s(self) -> float | None:
        """Estimated core-seconds, from :data:`COST_TABLE_S` (None for a kind not in it)."""
        if self.kind not in COST_TABLE_S:
            return None
        render_s, trial_s = COST_TABLE_S[self.kind]
        return self.n_renders * render_s + self.n_trials * trial_s

    @property
    def parallel(self) -> int:
        """Trials running at once on this machine (0: a remote cluster of unknown size)."""
        if self.spec.mode == "dask-scheduler":
            return 0
        return max(1, min(self.spec.n_workers, self.cores))

    @property
    def wall_s(self) -> float | None:
        """Estimated wall-clock seconds (None on a remote cluster or without a cost)."""
        return self.core_s / self.parallel if self.parallel and self.core_s is not None else None

    def warnings(self) -> list[str]:
        """Lines to print after the plan: above :data:`LONG_STUDY_S`, more workers than cores."""
        out = []
        local = self.spec.mode in ("process", "dask-local")
        if local and self.spec.n_workers > self.cores:
            flag = "--processes" if self.spec.mode == "process" else "--workers"
            out.append(f"warning: {flag} {self.spec.n_workers} exceeds the {self.cores} CPU core(s) this process may "
                       f"use: the workers share them and each trial is slower (use {flag} {self.cores} or fewer)")
        if self.wall_s is not None and self.wall_s > LONG_STUDY_S:
            out.append(f"warning: this study is estimated to take about {_duration(self.wall_s)}; interrupt it with "
                       "Ctrl-C (finished trials are kept and a rerun resumes), or ask for fewer trials; --plan-only "
                       "prints this plan without running")
        return out

    def describe(self) -> str:
        """One line: trials, renders, the estimate and where it comes from."""
        renders = f"{self.n_renders:,} render(s)" if self.n_renders else "no render"
        note = f" ({self.note})" if self.note else ""
        if self.core_s is None:
            return f"plan: {self.n_trials:,} {self.kind} trial(s), {renders}{note}; no cost table entry for the estimate"
        render_s, trial_s = COST_TABLE_S[self.kind]
        table = (f"{render_s:g} s a render, {trial_s:g} s a trial" if render_s else f"{trial_s:g} s a trial")
        est = f"~{_duration(self.core_s)} of one core ({self.kind} cost table, docs/performance.md: {table})"
        return f"plan: {self.n_trials:,} {self.kind} trial(s), {renders}{note}; {est}{self.spread_text()}"

    def spread_text(self) -> str:
        """How the estimate spreads over the executor: ``", ~T on N core(s) (pool)"``, or the
        Dask cluster's share (its size is not known here)."""
        if self.wall_s is not None:
            return f", ~{_duration(self.wall_s)} on {self.parallel} core(s) ({self.spec.describe()})"
        return f", divided among the workers of the Dask cluster at {self.spec.scheduler}"

    def lines(self) -> list[str]:
        """:meth:`describe` and :meth:`warnings`."""
        return [self.describe(), *self.warnings()]

    def to_json(self) -> dict:
        """The plan as ``--plan-only --json`` prints it: ``kind``, ``trials``, ``renders``,
        ``core_s`` and ``wall_s`` (estimates, None without one), ``parallel``, ``executor``,
        ``note``, ``warnings`` (lines)."""
        return {"kind": self.kind, "trials": int(self.n_trials), "renders": int(self.n_renders), "core_s": self.core_s,
                "wall_s": self.wall_s, "parallel": self.parallel, "executor": self.spec.describe(), "note": self.note,
                "warnings": self.warnings()}


def plan_study(kind: str, n_trials: int, n_renders: int, spec: ExecutorSpec, *, note: str = "") -> StudyPlan:
    """The :class:`StudyPlan` of a study, from its counts alone (nothing is built: a plan of
    ten million trials costs nothing).

    Parameters
    ----------
    kind : str
        Trial kind (``"render"``, ``"geometric"``, ``"tof"``).
    n_trials, n_renders : int
        Trials and renders (distinct render keys) of the study.
    spec : ExecutorSpec
    note : str
        Said after the counts.
    """
    return StudyPlan(str(kind), int(n_trials), int(n_renders), spec, cpu_cores(), note)


def plan_trials(kind: TrialKind, trials: list[Trial], spec: ExecutorSpec, *, done_ids=()) -> StudyPlan:
    """The :class:`StudyPlan` of built trials: those not in ``done_ids``, renders counted as
    their distinct render keys."""
    done = set(done_ids)
    pending = [t for t in trials if t.trial_id not in done]
    costly = COST_TABLE_S.get(kind.name, (1.0, 0.0))[0] > 0  # a geometric "render" (a projection) costs nothing
    renders = len({kind.render_key(t.scenario) for t in pending}) if kind.render_key and costly else 0
    note = f"{len(trials) - len(pending):,} already stored" if done else ""
    return plan_study(kind.name, len(pending), renders, spec, note=note)
