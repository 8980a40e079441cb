"""Rendered trials at scale (issue 12, item 6): the same numbers in this process, on a local
process pool and on a Dask LocalCluster (``--workers``); a rendered study on Dask killed with
SIGKILL half-way resumes, on a Dask scheduler (``--scheduler``), to the uninterrupted result,
every trial exactly once.

The study: two poses of the Galaxy Nexus (full frame, the renderer's default sampling) at 10
and 20 m with small target angles, each rendered once and exposed twice (two noise draws at
the phone's auto-exposure): four trials, two renders. The uninterrupted
in-process run is computed once for the module (:func:`reference`). Without the ``dask``
extra the Dask parts run on the process pool (or are skipped).
"""

import math
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from svgs_sim.studies.execution import ExecutorSpec, Trial, run_stored_study
from svgs_sim.studies.seeding import design_rng, trial_seed
from svgs_sim.studies.store import RESULTS, read_rows
from study_helpers import sigkill_after_rows

#: Columns that are timings (wall clock, CPU, the exposure's and the solve's wall time): the
#: only ones allowed to differ between runs (svgs_sim.sim.render_trial.RENDER_TIMING_OUTPUTS + the loop's).
TIMINGS = ("wall_s", "cpu_s", "expose_s", "solve_s")
#: (range_m, roll_deg, pitch_deg, yaw_deg) of the rendered poses.
POSES = ((10.0, 2.0, -1.5, 3.0), (20.0, -2.0, 1.0, -4.0))
#: Exposures (noise draws) of each render.
EXPOSURES_PER_RENDER = 2
STUDY_SEED = 21
N_TRIALS = len(POSES) * EXPOSURES_PER_RENDER
MANIFEST = {"study": "test-render-scale", "camera": "galaxy-nexus", "poses": [list(p) for p in POSES],
            "exposures_per_render": EXPOSURES_PER_RENDER, "seed": STUDY_SEED}


def study_trials(seed: int = STUDY_SEED) -> list:
    """The four trials: trial ``i = pose_index * 2 + exposure_index``; one render seed per pose
    (drawn from the design stream of the pose's first trial), the noise seed per trial.

    Returns
    -------
    list of :class:`svgs_sim.studies.execution.Trial`
    """
    from svgs_sim.sim.render_trial import render_trial_scenario

    trials = []
    for pk, (range_m, roll_deg, pitch_deg, yaw_deg) in enumerate(POSES):
        first = pk * EXPOSURES_PER_RENDER
        render_seed = int(design_rng(seed, first).integers(2**31))
        for ek in range(EXPOSURES_PER_RENDER):
            i = first + ek
            scen = render_trial_scenario(camera="galaxy-nexus", range_m=range_m, roll_deg=roll_deg,
                                         pitch_deg=pitch_deg, yaw_deg=yaw_deg, render_seed=render_seed,
                                         labels={"pose_index": pk, "exposure_index": ek})
            trials.append(Trial(i, scen, trial_seed(seed, i)))
    return trials


def run_render_study(out_dir, spec: ExecutorSpec, chunk_size: int = 1):
    """Run (or resume) the study into ``out_dir`` on ``spec``; returns the run's RunStats (None: nothing to do)."""
    from svgs_sim.sim.render_trial import RENDER

    _, stats = run_stored_study(RENDER, study_trials(), out_dir, MANIFEST, spec,
                                chunk_size=chunk_size, progress=False)
    return stats


def _numbers(rows):
    """Rows without the timing columns."""
    return [{k: v for k, v in r.items() if k not in TIMINGS} for r in rows]


def _differences(rows, ref_rows) -> list:
    """(trial_id, column, value, reference value) of every non-timing cell that differs (the assertion message)."""
    ref = {r["trial_id"]: r for r in ref_rows}
    return [(r["trial_id"], k, v, ref.get(r["trial_id"], {}).get(k)) for r in _numbers(rows) for k, v in r.items()
            if v != ref.get(r["trial_id"], {}).get(k)]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The uninterrupted in-process run: its rows, checked to be real solutions of the intended study."""
    out = tmp_path_factory.mktemp("render-scale") / "inline"
    stats = run_render_study(out, ExecutorSpec("inline", 1), chunk_size=4)
    assert (stats.n_run, stats.n_render_groups) == (N_TRIALS, len(POSES))
    rows = read_rows(out / RESULTS)
    assert [r["trial_id"] for r in rows] == list(range(N_TRIALS))
    # every trial solved, with finite errors: an executor that lost the outputs cannot match by accident
    assert all(r["ok"] == 1 and r["n_blobs"] == 4 for r in rows), [(r["reason"], r["message"]) for r in rows]
    assert all(math.isfinite(r["est_z_m"]) and abs(r["err_z_m"]) < 0.5 for r in rows)
    # render once, expose many: one render (truth, render seed) per pose, two exposures of it
    for pk in range(len(POSES)):
        pair = [r for r in rows if r["pose_index"] == pk]
        assert len(pair) == 2 and len({(r["render_seed"], r["true_z_m"]) for r in pair}) == 1
        assert pair[0]["seed"] != pair[1]["seed"] and pair[0]["est_z_m"] != pair[1]["est_z_m"]  # another noise draw
    assert len({r["est_x_m"] for r in rows}) == N_TRIALS
    return rows


@pytest.mark.render
@pytest.mark.parametrize("spec, chunk_size", [(ExecutorSpec("process", 2), 1), (ExecutorSpec("dask-local", 2), 2)],
                         ids=["process-pool", "dask-local"])
def test_rendered_trials_identical_inline_process_pool_and_dask(reference, tmp_path, spec, chunk_size):
    """Every non-timing column equal to the in-process run, on 2 pool processes and on a 2-worker LocalCluster."""
    if spec.mode.startswith("dask"):
        pytest.importorskip("distributed", reason="the 'dask' extra is not installed")
    stats = run_render_study(tmp_path / spec.mode, spec, chunk_size=chunk_size)
    assert (stats.n_run, stats.n_already_done, stats.n_render_groups) == (N_TRIALS, 0, len(POSES))
    rows = read_rows(tmp_path / spec.mode / RESULTS)
    assert [r["trial_id"] for r in rows] == list(range(N_TRIALS))
    assert _numbers(rows) == _numbers(reference), _differences(rows, reference)


#: The child below runs the study on 2 workers and SIGKILLs itself right after the store has
#: fsynced a task's rows and holds KILL_AT or more: tasks are whole render groups (2 rows), so
#: the kill lands after the first group, with 2 of the 4 rows stored and the second group in
#: flight on the other worker (no polling, no timing window).
KILL_AT = 1
ROWS_AT_KILL = 2
_KILL_CHILD = sigkill_after_rows(KILL_AT, """
from svgs_sim.studies.execution import ExecutorSpec
from test_studies_render_scale import run_render_study
run_render_study(sys.argv[2], ExecutorSpec(sys.argv[3], 2), chunk_size=1)
""", path_arg=True)


def _have_dask() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True



@pytest.fixture
def resume_spec():
    """Where the resumed run goes: a Dask scheduler (a one-worker LocalCluster started here,
    reached through its address as ``--scheduler`` would), or in this process without Dask."""
    if not _have_dask():
        yield ExecutorSpec("inline", 1)
        return
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0",
                      silence_logs=logging.ERROR) as cluster:
        yield ExecutorSpec("dask-scheduler", 0, cluster.scheduler_address)


@pytest.mark.render
def test_sigkill_halfway_then_rerun_completes_every_rendered_trial_once(reference, tmp_path, resume_spec):
    """Killed on a 2-worker LocalCluster (the process pool without Dask) after half the trials;
    the rerun computes the other half only, and the store then holds each trial once."""
    out = tmp_path / "study"
    kill_mode = "dask-local" if _have_dask() else "process"
    proc = subprocess.run([sys.executable, "-c", _KILL_CHILD, str(Path(__file__).parent), str(out), kill_mode],
                          check=False, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    results = out / RESULTS
    assert proc.returncode == -signal.SIGKILL, f"the run was not killed mid-way: {proc.stderr[-2000:]!r}"
    killed = read_rows(results)
    assert len(killed) == ROWS_AT_KILL, [r["trial_id"] for r in killed]
    # the stored rows of the killed run are already the final numbers
    by_id = {r["trial_id"]: r for r in _numbers(reference)}
    assert _numbers(killed) == [by_id[r["trial_id"]] for r in killed], _differences(killed, reference)

    stats = run_render_study(out, resume_spec, chunk_size=1)  # the same study again: the missing trials only
    assert (stats.n_run, stats.n_already_done) == (N_TRIALS - ROWS_AT_KILL, ROWS_AT_KILL)
    assert stats.n_render_groups == 1  # the group in flight at the kill, rendered again
    assert stats.executor == resume_spec.describe()
    rows = read_rows(results)
    ids = [r["trial_id"] for r in rows]
    assert len(ids) == len(set(ids)) == N_TRIALS and sorted(ids) == list(range(N_TRIALS))
    lines = results.read_text().splitlines()
    assert len(lines) == 1 + N_TRIALS  # header + one line per trial: nothing twice in the file either
    assert sorted(int(ln.split(",", 1)[0]) for ln in lines[1:]) == list(range(N_TRIALS))
    assert _numbers(rows) == _numbers(reference), _differences(rows, reference)
    assert run_render_study(out, resume_spec) is None  # complete: a third run does nothing
    assert results.read_text().splitlines() == lines
