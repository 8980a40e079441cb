"""The ``tof`` trial kind: one frame of a ToF stability run, for the study engine.

A trial is frame ``frame`` of a run: the :class:`svgs_sim.sim.tof_closed_loop.TofScenario` rendered
once, its noise stream's frames ``0 .. frame`` solved in sequence through one pipeline (the
pipeline carries state from frame to frame: its recursive median of depth, its persistence
window), reported at ``frame``. The frames of one run share a render key, so the study engine
(:mod:`svgs_sim.studies.execution`) hands them to :func:`tof_group` together and the run is solved once,
in order; a trial run alone (:func:`tof_trial`) replays the frames before it and gives the same
row - a trial's numbers depend only on its scenario and seed.

Seeds
    The trial's seed is the run's: the render's Monte Carlo seed and the noise stream
    ``[seed, NOISE_STREAM]`` (:mod:`svgs_sim.sim.tof_closed_loop`), frame ``k`` its ``k``-th draw. The
    ToF study gives every trial the study's seed (not :func:`svgs_sim.studies.seeding.trial_seed`), so
    its frames are the ones ``svgs tof stability --seed`` and ``svgs tof render-and-solve
    --seed`` draw, and the committed report's numbers did not move when the study moved onto
    the engine.

Rows (:data:`TOF_OUTPUTS`)
    The frame's :func:`svgs_sim.sim.tof_stability.frame_row` (``ok``, ``reason``, ``n_blobs``,
    ``iterations``, :data:`svgs_sim.sim.tof_stability.COLUMNS` as ``col_*``, ``rot_err_deg``, ``saturated_pixels``),
    the solved paper state ``est_*`` and its errors ``err_*``, ``pos_err_norm_m`` (all through
    :mod:`svgs_sim.sim.metrics`; None when unsolved), and the run's values
    (:data:`svgs_sim.sim.tof_stability.RUN_INFO_KEYS`, the same on every frame of a run).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields, replace

from svgs_sim.base.errors import InputError
from svgs_sim.render.variant import select_variant
from svgs_sim.sim.metrics import ERR_KEYS, POS_ERR_NORM_M, error_columns, state_m_deg
from svgs_sim.sim.tof_closed_loop import TofScenario, TofScene, render, solve_frames
from svgs_sim.sim.tof_stability import COLUMNS, REFERENCES, RUN_INFO_KEYS, frame_row, reference_point_m, run_info
from svgs_sim.sim.trials import Parameter, RowView, TrialKind, register_trial_kind
from svgs_sim.svgs.frames import STATE_KEYS
from svgs_sim.tof.camera import DESIGN_RANGE_M

#: The scenario's row keys that are text.
TEXT_KEYS = ("camera", "pattern", "run", "scene", "pipeline", "reference")
#: Numeric parameters of a ToF trial (validation; ``needs_render`` as in :class:`svgs_sim.sim.trials.Parameter`). The
#: ranges lie in the paper's design range (``svgs_sim.tof.camera.DESIGN_RANGE_M``), the envelope the ToF commands take.
TOF_PARAMETERS = {
    "range_m": Parameter("range_m", "m", "along the boresight to the target origin", 1.0, True, *DESIGN_RANGE_M),
    "nominal_range_m": Parameter("nominal_range_m", "m", "the stability run's range (selects the paper's tables)",
                                 1.0, False, *DESIGN_RANGE_M),
    # the ambient light on the target (the profile's 1000 lux, the paper's "normal light"; its high light
    # 10000 lux): acts on the sensor's frames, not the render
    "ambient_lux": Parameter("ambient_lux", "lux", "ambient illuminance on the target", 1000.0, False, 0.0, 200000.0),
    "frames": Parameter("frames", "", "frames of the run", 1, False, 1, 20000),
    "frame": Parameter("frame", "", "index of the frame in the run's noise stream", 0, False, 0, 19999),
}
#: Output columns of a ToF trial.
TOF_OUTPUTS = ("ok", "reason", "n_blobs", "iterations", *(f"col_{c}" for c in COLUMNS), "rot_err_deg", "saturated_pixels",
               *(f"est_{k}" for k in STATE_KEYS), *ERR_KEYS, POS_ERR_NORM_M, *RUN_INFO_KEYS)
#: Least frames per task of the study engine (:func:`chunk_frames`).
CHUNK_FRAMES = 250


def chunk_frames(longest_run: int, chunk_size: int | None = None) -> int:
    """Frames per task that keep every run whole: the engine splits a run only when it is longer
    than 4 tasks (:func:`svgs_sim.studies.execution.make_tasks`), and a split part replays the frames
    before it. At least ``chunk_size`` (default :data:`CHUNK_FRAMES`)."""
    return max(int(chunk_size or CHUNK_FRAMES), -(-int(longest_run) // 4))


@dataclass(frozen=True)
class TofTrialScenario(RowView):
    """Frame ``frame`` of a stability run: the ``tof`` kind's typed scenario (registered as its
    :attr:`svgs_sim.sim.trials.TrialKind.scenario_type`). As a mapping it is its results-store row
    (:meth:`to_row`, the codec; :meth:`from_row` reads one back), so the study engine and the store
    take it as they take the other kinds' scenarios.

    Attributes
    ----------
    scenario : svgs_sim.sim.tof_closed_loop.TofScenario
    nominal_range_m : float
        The run's range as asked for (0.697 and 5.712 m carry the paper's tables).
    frames : int
        Frames of the run.
    frame : int
        This trial's frame, ``0 .. frames - 1``.
    pipeline : tuple of (str, value)
        :class:`svgs_sim.tof.PipelineParams` overrides, sorted pairs.
    reference : {"markers", "plate"}
    run : str
        The study's label of the run (not part of the computation).
    """

    scenario: TofScenario
    nominal_range_m: float
    frames: int
    frame: int = 0
    pipeline: tuple = ()
    reference: str = "markers"
    run: str = ""

    def __post_init__(self):
        pl = self.pipeline
        object.__setattr__(self, "pipeline", tuple(sorted((pl.items() if isinstance(pl, dict) else pl))))
        if self.reference not in REFERENCES:
            raise InputError(f"reference: expected one of {REFERENCES}, got {self.reference!r}")
        for k in ("nominal_range_m", "frames", "frame"):
            TOF_PARAMETERS[k].check(getattr(self, k), k)
        if not 0 <= int(self.frame) < int(self.frames):
            raise InputError(f"frame: expected 0..{int(self.frames) - 1}, got {self.frame!r}")
        object.__setattr__(self, "_row", self.to_row())

    @classmethod
    def from_values(cls, values, labels=None) -> "TofTrialScenario":
        """The scenario of parameter values (:data:`TOF_PARAMETERS`; ``labels``: more of its columns,
        e.g. ``run``): what a study that sets only some of them gives (a sensitivity analysis's
        ``range_m`` and ``ambient_lux``) is one frame of its own run, rendered with seed 0, its
        ``nominal_range_m`` its ``range_m``."""
        row = {**values, **(labels or {})}
        row.setdefault("render_seed", 0)
        row.setdefault("frames", 1)
        row.setdefault("frame", 0)
        row.setdefault("nominal_range_m", row.get("range_m", TOF_PARAMETERS["range_m"].default))
        return cls.from_row(row)

    def run_key(self) -> tuple:
        """What decides the run's frames (everything but the frame and the label)."""
        return (self.scenario.render_key(), self.scenario.ambient_lux, self.scenario.integration_time_s,
                json.dumps(dict(self.pipeline), sort_keys=True), self.reference, float(self.nominal_range_m),
                int(self.frames))

    def to_row(self) -> dict:
        """The flat scenario columns of the results store (None: the default)."""
        sc = asdict(self.scenario)
        del sc["scene"]  # the column keeps its place after render_seed
        sc["render_seed"] = sc.pop("seed")
        sc["scene"] = json.dumps(self.scenario.scene_dict(), sort_keys=True)
        return {**sc, "nominal_range_m": float(self.nominal_range_m), "frames": int(self.frames),
                "frame": int(self.frame), "pipeline": json.dumps(dict(self.pipeline), sort_keys=True),
                "reference": self.reference, "run": self.run}

    @classmethod
    def from_row(cls, row) -> "TofTrialScenario":
        """The typed scenario of a row of :meth:`to_row` (extra keys are ignored; a
        :class:`TofTrialScenario` is returned as it is)."""
        if isinstance(row, cls):
            return row
        names = {f.name for f in fields(TofScenario)} - {"seed", "scene"}
        kw = {k: row[k] for k in names if k in row}
        for k in ("spp", "rim_spp_factor", "max_bounces"):
            if kw.get(k) is not None:
                kw[k] = int(kw[k])
        kw["pinhole"] = bool(kw.get("pinhole") or False)
        sc = TofScenario(seed=int(row["render_seed"]), scene=TofScene.from_dict(json.loads(row.get("scene") or "{}")),
                         **kw)
        return cls(sc, float(row["nominal_range_m"]), int(row["frames"]), int(row["frame"]),
                   tuple(json.loads(row.get("pipeline") or "{}").items()), str(row.get("reference") or "markers"),
                   str(row.get("run") or ""))


def trial_rows(first: TofTrialScenario) -> list:
    """The scenario rows (:meth:`TofTrialScenario.to_row`) of every frame ``0 .. frames - 1`` of
    the run of ``first``."""

    return [replace(first, frame=k).to_row() for k in range(int(first.frames))]


# --------------------------------------------------------------------------- the runs
_RENDERS: dict = {}
#: Renders a worker keeps (a run's variants reuse their baseline's render).
MAX_CACHED_RENDERS = 24


def cached_render(scenario: TofScenario):
    """This worker's render of ``scenario`` (rendered once per render key; the sensor's
    overrides applied to the cached render)."""

    key = scenario.render_key()
    if key not in _RENDERS:
        if len(_RENDERS) >= MAX_CACHED_RENDERS:
            _RENDERS.pop(next(iter(_RENDERS)))
        base = TofScenario(**{**asdict(scenario), "ambient_lux": None, "integration_time_s": None})
        _RENDERS[key] = render(base)
    tr = _RENDERS[key]
    over = {k: getattr(scenario, k) for k in ("ambient_lux", "integration_time_s") if getattr(scenario, k) is not None}
    return tr.with_sensor(**over) if over else tr


def _run_rows(ts: TofTrialScenario, wanted: set) -> dict:
    """Frames ``0 .. max(wanted)`` of the run of ``ts``, solved in sequence; the rows of ``wanted``."""

    tr = cached_render(ts.scenario)
    overrides = dict(ts.pipeline)
    pt = reference_point_m(tr.target, ts.reference)
    info = run_info(tr, overrides, pt)
    results, _ = solve_frames(tr, max(wanted) + 1, overrides)
    out = {}
    for res in results:
        if res.frame not in wanted:
            continue
        row = frame_row(res, tr, pt)
        del row["frame"]
        row.update({f"col_{c}": row.pop(c) for c in COLUMNS})
        sol = res.solution
        if sol:
            row.update({f"est_{k}": float(v) for k, v in zip(STATE_KEYS, state_m_deg(sol.state))})
            ec = error_columns(sol.state, tr.truth_state, R_cam_target_est=sol.R_cam_target)
            row.update({k: ec[k] for k in (*ERR_KEYS, POS_ERR_NORM_M)})
        else:
            row.update({f"est_{k}": None for k in STATE_KEYS})
            row.update({k: None for k in (*ERR_KEYS, POS_ERR_NORM_M)})
        out[res.frame] = {**row, **info}
    return out


def tof_group(scenarios, seeds) -> list[dict]:
    """Trials of one run (or several): each run's frames solved once, in order; the rows in the given order."""
    typed = [TofTrialScenario.from_row(s) for s in scenarios]
    for ts, seed in zip(typed, seeds):
        if int(seed) != int(ts.scenario.seed):
            raise InputError(f"seed: a ToF trial's seed is its run's render seed ({ts.scenario.seed}), got {seed}")
    runs: dict = {}
    for i, ts in enumerate(typed):
        runs.setdefault(ts.run_key(), []).append(i)
    out = [None] * len(typed)
    for idx in runs.values():
        rows = _run_rows(typed[idx[0]], {typed[i].frame for i in idx})
        for i in idx:
            out[i] = rows[typed[i].frame]
    return out


def tof_trial(scenario: dict, seed: int) -> dict:
    """One frame of a run (replays the frames before it); the row :func:`tof_group` gives it."""
    return tof_group([scenario], [seed])[0]


def tof_render_key(scenario: dict):
    """The run's key: its frames go to one task and are solved in one sequence."""
    return TofTrialScenario.from_row(scenario).run_key()


def _warm_up():

    select_variant()


TOF = register_trial_kind(TrialKind(
    name="tof",
    run_trial=tof_trial,
    outputs=TOF_OUTPUTS,
    parameters=TOF_PARAMETERS,
    text_keys=TEXT_KEYS,
    run_group=tof_group,
    render_key=tof_render_key,
    warm_up=_warm_up,
    description="one frame of a ToF stability run: Mitsuba render of the marker target (AMCW phasors), the sensor's "
                "noisy frames, the ToF pipeline in sequence (svgs_sim.sim.tof_closed_loop)",
    module=__name__,
    scenario_type=TofTrialScenario,
))

__all__ = ["TOF", "TOF_OUTPUTS", "TofTrialScenario", "trial_rows", "tof_trial", "tof_group", "cached_render", "CHUNK_FRAMES", "chunk_frames"]
