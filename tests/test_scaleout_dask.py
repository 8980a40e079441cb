"""Scale-out (issue 23): a rendered campaign gives the same rows on a local process pool and on
a Dask LocalCluster.

The campaign is the one ``svgs campaign --camera galaxy-nexus`` runs (``svgs_sim.studies.campaign``:
the phone on the test stand, the paper's calibration practice, the ``render`` trial kind of
:mod:`svgs_sim.sim.render_trial` - a full-frame Mitsuba render at the renderer's default sampling, the
phone model, the detector, the solver and the sensor's CRLB), made tiny: two ranges, two
trials per range, two exposures of each rendered stand setting (4 trials, 2 renders). The
campaign's focal-length calibration (rendered frames, in this process) is made once and is
part of the configuration both runs get. It then runs twice, independently: on a pool of 2
spawned processes (``--processes 2``) and on a Dask LocalCluster of 2 single-threaded worker
processes (``--workers 2``); every row must agree, column by column, except the timings.

About 50 s on this two-core machine (60 s with another process busy on it): two executors
started and warmed up, the calibration's and the campaign's renders; a long form
(``SVGS_LONG_TESTS=1``), since the default run's ``tests/test_studies_render_scale.py`` checks the
same executors on rendered trials.

``test_scheduler_window_keeps_every_worker_busy`` (sleeping trials, a few seconds): a study on
an existing cluster (``--scheduler``) keeps every worker thread of the cluster busy (the window
of tasks in flight is sized from the cluster, not from the command line).
"""

import logging
import math
import os
import threading
import time

import pytest

#: Columns that are timings: the only ones allowed to differ between runs.
LOOP_TIMINGS = ("wall_s", "cpu_s")
#: Relative tolerance of float cells (round-off only; the runs are expected to be bit-identical).
REL_TOL = 1e-9


def _campaign(tmp_path):
    from svgs_sim.studies.campaign import campaign_trials, make_config, rendered_paper_calibration

    config = make_config("galaxy-nexus", ranges_m=(5.0, 15.0), trials_per_range=2, exposures_per_render=2, seed=23,
                         trial_kind="render", calibration="paper")
    config = rendered_paper_calibration(config, tmp_path / "calibration")
    return config, campaign_trials(config)


def _run(config, trials, out_dir, spec, chunk_size):
    from svgs_sim.sim.render_trial import RENDER
    from svgs_sim.studies.execution import run_stored_study

    store, stats = run_stored_study(RENDER, trials, out_dir, config.manifest(), spec, chunk_size=chunk_size,
                                    progress=False)
    assert stats is not None and stats.n_run == len(trials)
    return store.read_rows(), stats


def _same(a, b) -> bool:
    if isinstance(a, float) or isinstance(b, float):
        if a is None or b is None or isinstance(a, str) or isinstance(b, str):
            return a == b
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=0.0)
    return a == b


def differences(rows, ref_rows, timings) -> list:
    """(trial_id, column, value, reference value) of every non-timing cell that differs, and
    of every trial or column present in one run only."""
    ref = {r["trial_id"]: r for r in ref_rows}
    got = {r["trial_id"]: r for r in rows}
    out = [(t, "<missing trial>", t in got, t in ref) for t in sorted(set(ref) ^ set(got))]
    for t in sorted(set(ref) & set(got)):
        r, q = got[t], ref[t]
        for k in sorted(set(r) | set(q)):
            if k in timings:
                continue
            if k not in r or k not in q or not _same(r[k], q[k]):
                out.append((t, k, r.get(k, "<absent>"), q.get(k, "<absent>")))
    return out


@pytest.mark.render
@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SVGS_LONG_TESTS"), reason="long form (~50 s): the default run's "
                    "tests/test_studies_render_scale.py checks rendered rows on a process pool and on Dask against "
                    "the in-process run; set SVGS_LONG_TESTS=1")
def test_rendered_campaign_same_rows_on_process_pool_and_dask(tmp_path):
    """Long form (``SVGS_LONG_TESTS=1``): the default run's ``tests/test_studies_render_scale.py``
    checks the same executors on rendered trials; this one adds the campaign's configuration with
    its rendered calibration."""
    pytest.importorskip("distributed", reason="the 'dask' extra is not installed")
    from svgs_sim.sim.render_trial import RENDER_TIMING_OUTPUTS
    from svgs_sim.studies.execution import ExecutorSpec

    timings = (*LOOP_TIMINGS, *RENDER_TIMING_OUTPUTS)
    config, trials = _campaign(tmp_path)
    assert len(trials) == 4 and len({t.trial_id for t in trials}) == 4
    assert config.calibration_info, "the rendered focal-length calibration did not run"

    pool, pool_stats = _run(config, trials, tmp_path / "pool", ExecutorSpec("process", 2), chunk_size=2)
    dask, dask_stats = _run(config, trials, tmp_path / "dask", ExecutorSpec("dask-local", 2), chunk_size=1)
    assert "process pool" in pool_stats.executor and "Dask LocalCluster" in dask_stats.executor

    # a real rendered campaign: every trial solved, its estimate near the truth, the sensor's bound computed
    assert [r["trial_id"] for r in pool] == [t.trial_id for t in trials]
    for r in pool:
        assert r["ok"] == 1, (r["trial_id"], r["reason"], r["message"])
        assert r["nominal_range_m"] in (5.0, 15.0) and r["variant"] == "baseline"
        assert 0.0 < r["pos_err_norm_m"] < 0.5, r["pos_err_norm_m"]
        assert r["crlb_centroid_px"] > 0 and r["exposure_s_used"] > 0

    # the comparison can fail: a one-part-in-a-million change of one estimate is caught
    nudged = [dict(r) for r in dask]
    nudged[1]["est_x_m"] = nudged[1]["est_x_m"] * (1 + 1e-6)
    assert differences(nudged, pool, timings) == [(trials[1].trial_id, "est_x_m", nudged[1]["est_x_m"],
                                                  pool[1]["est_x_m"])]
    assert differences(dask[:-1], pool, timings)  # a missing trial too

    diff = differences(dask, pool, timings)
    assert not diff, f"{len(diff)} cell(s) differ between the process pool and Dask: {diff[:10]}"


_ACTIVE = {"now": 0, "most": 0}
_ACTIVE_LOCK = threading.Lock()
SLEEP_S = 0.2


def _sleep_trial(scenario, seed):
    with _ACTIVE_LOCK:
        _ACTIVE["now"] += 1
        _ACTIVE["most"] = max(_ACTIVE["most"], _ACTIVE["now"])
    time.sleep(SLEEP_S)
    with _ACTIVE_LOCK:
        _ACTIVE["now"] -= 1
    return {"y": 1.0}


def test_scheduler_window_keeps_every_worker_busy(tmp_path):
    """An existing cluster (``--scheduler``) of 8 worker threads: 32 sleeping trials, one per
    task, must run 8 at a time (in-process threads: sleeps, no CPU)."""
    pytest.importorskip("distributed", reason="the 'dask' extra is not installed")
    from distributed import LocalCluster

    from svgs_sim.sim.trials import TrialKind, register_trial_kind
    from svgs_sim.studies.execution import ExecutorSpec, Trial, run_stored_study

    kind = register_trial_kind(TrialKind("test-scaleout-sleep", _sleep_trial, ("y",), {}, text_keys=(),
                                         module=__name__))
    trials = [Trial(i, {"range_m": float(i)}, 0) for i in range(32)]
    _ACTIVE.update(now=0, most=0)
    with LocalCluster(n_workers=1, threads_per_worker=8, processes=False, protocol="tcp", host="127.0.0.1",
                      dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR) as cluster:
        spec = ExecutorSpec("dask-scheduler", 0, cluster.scheduler_address)
        store, stats = run_stored_study(kind, trials, tmp_path / "study", {"study": "sleep"}, spec, chunk_size=1,
                                        progress=False)
    assert len(store.read_rows()) == 32
    assert _ACTIVE["most"] == 8, f"at most {_ACTIVE['most']} of 8 workers were busy at once"
