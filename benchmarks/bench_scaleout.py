"""Benchmark (issue 23, scale-out): the rendered campaign on a process pool and on Dask, 1 and 2 workers.

What it measures
    - **Throughput**: one rendered campaign (``svgs_sim.studies.campaign``, the ``render`` trial kind:
      the Galaxy Nexus on the test stand, the paper's calibration practice, ``--exposures``
      noise draws of every rendered stand setting) through the study layer - tasks, executor,
      results store with fsync - on a local process pool of 1 and of 2 spawned processes and on
      a Dask LocalCluster of 1 and of 2 single-threaded worker processes (``svgs campaign
      --processes N`` / ``--workers N``). Each executor is fresh and warmed up first (spawn,
      imports, one render per worker on poses never timed), so no worker reuses a render. The
      peer is the 1-process pool; every configuration prints its trials/s, the peer's and the
      ratio, and the rows of the four runs are compared (timings aside: they must agree).
    - **Where a trial's time goes**: the same campaign's first stand setting of each range run
      in this process through the workers' own code (:func:`svgs_sim.studies.execution.run_task`), with
      the stages of :mod:`svgs_sim.sim.render_trial` timed: render (Mitsuba and the lab's light,
      ``_frame``), optics (the lens PSF, glare and CFA, once per render: ``_exposer``), expose
      (sensor, ISP, JPEG: ``_exposure``), detect + identify + solve (``solve_exposure``), the
      sensor's centroid CRLB (once per render and exposure setting: ``_sensor_centroid_sigma``)
      and the rest (merge margin, projections, the pose bound, the row).
    - **Scheduler overhead**: no-op tasks (``os.getpid``) on the warm executors, one at a time
      (round trip) and 400 at once (per task); and the workers' memory (VmRSS now and VmHWM,
      the peak, from ``/proc``) after the timed campaign.
    - With ``--merge-range``: the cost of a trial of the merge-range study (``svgs
      merge-range --camera htc-amaze-4g``, :mod:`svgs_sim.studies.merge_range`: the Amaze facing the
      target at 6 and 7 m, the f-number at the profile's value, low and high, 2 exposures per
      render), timed by stage the same way.

    It ends with the projection of docs/performance.md: a study of ``--project-trials`` trials
    on ``--project-workers`` Dask workers takes ``trials * c / (workers * efficiency)``.

Run it on an otherwise idle machine (a render keeps one core busy)::

    .venv/bin/python benchmarks/bench_scaleout.py [--trials-per-range 8] [--exposures 4] [--ranges 5,15]
                                                  [--no-dask] [--merge-range]

About 3 minutes on this two-core machine with the defaults (170 s measured; the machine shared with
another process, so the figures vary by 10-25 % from run to run); ``--merge-range``: about 30 s more.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.studies.campaign import campaign_trials, make_config, rendered_paper_calibration  # noqa: E402
from svgs_sim.studies.execution import (DEFAULT_CHUNK_SIZE, TASKS_PER_WORKER, ExecutorSpec, open_executor,  # noqa: E402
                               run_study, run_task)
from svgs_sim.studies.store import ResultStore, read_rows  # noqa: E402
from svgs_sim.sim.render_trial import RENDER, RENDER_TIMING_OUTPUTS, render_key  # noqa: E402

CAMERA = "galaxy-nexus"
#: Seed of the timed campaign and of the warm-up study (other poses, so no worker reuses a render).
SEED, WARM_SEED = 23, 9_999
#: Range of the warm-up renders, m.
WARM_RANGE_M = 10.0
#: No-op tasks per executor: one at a time, then all at once.
NOOP_SERIAL, NOOP_BATCH = 50, 400
#: The timings of a row (everything else must be the same on every executor).
TIMINGS = ("wall_s", "cpu_s", *RENDER_TIMING_OUTPUTS)
#: The stages timed in :func:`breakdown`: (label, module, function).
STAGES = (("render", "svgs_sim.sim.render_trial", "_frame"), ("optics", "svgs_sim.sim.render_trial", "_exposer"),
          ("expose", "svgs_sim.sim.render_trial", "_exposure"), ("detect+solve", "svgs_sim.sim.closed_loop", "solve_exposure"),
          ("CRLB", "svgs_sim.sim.render_trial", "_sensor_centroid_sigma"))


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def campaign(ranges, trials_per_range: int, exposures: int, calib_dir):
    """The timed campaign (its rendered focal-length calibration made here, once) and its trials."""
    config = make_config(CAMERA, ranges_m=ranges, trials_per_range=trials_per_range, exposures_per_render=exposures,
                         seed=SEED, trial_kind="render", calibration="paper")
    config = rendered_paper_calibration(config, calib_dir)
    return config, campaign_trials(config)


def warm_trials(n_workers: int):
    """One render per worker at ``WARM_RANGE_M``: another seed (poses and true lens never timed), the
    same kind of render (a distorted true lens: the renderer's custom sensor)."""
    config = make_config(CAMERA, ranges_m=(WARM_RANGE_M,), trials_per_range=max(1, n_workers), exposures_per_render=1,
                         seed=WARM_SEED, trial_kind="render", calibration="paper")
    return config, campaign_trials(config)


# --------------------------------------------------------------------------- memory, overhead
def _worker_pids(ex, spec: ExecutorSpec) -> list[int]:
    if spec.mode == "process":
        return sorted(getattr(ex, "_processes", {}) or {})
    client = getattr(ex, "_client", None)
    return sorted(client.run(os.getpid).values()) if client is not None else []


def _proc_mem_mb(pid: int) -> tuple[float, float]:
    """(VmRSS, VmHWM) of a process, MB (NaN where /proc does not say)."""
    out = {"VmRSS": math.nan, "VmHWM": math.nan}
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            k, _, v = line.partition(":")
            if k in out:
                out[k] = float(v.split()[0]) / 1024.0
    except OSError:
        pass
    return out["VmRSS"], out["VmHWM"]


def noop_overhead(ex) -> tuple[float, float]:
    """(round trip of one no-op task, per-task time of a batch of no-op tasks), ms."""
    ex.submit(os.getpid).result()
    t0 = time.perf_counter()
    for _ in range(NOOP_SERIAL):
        ex.submit(os.getpid).result()
    t1 = time.perf_counter()
    futs = [ex.submit(os.getpid) for _ in range(NOOP_BATCH)]
    for f in futs:
        f.result()
    t2 = time.perf_counter()
    return 1e3 * (t1 - t0) / NOOP_SERIAL, 1e3 * (t2 - t1) / NOOP_BATCH


# --------------------------------------------------------------------------- throughput
def throughput(spec: ExecutorSpec, config, trials, tmp: Path) -> dict:
    """The campaign on a fresh, warmed-up executor of ``spec``.

    Returns
    -------
    dict
        ``trials_per_s``, ``elapsed_s``, ``cpu_per_trial_s`` and ``wall_per_trial_s`` (the
        workers' clocks, a render shared by its group), ``cores`` (worker CPU s per s of the
        run), ``rows``, ``start_s`` (executor start and warm-up), ``mem`` ([(pid, VmRSS MB,
        VmHWM MB)]), ``noop_ms`` (round trip, per task in a batch).
    """
    tag = f"{spec.mode}-{spec.n_workers}"
    t0 = time.perf_counter()
    with open_executor(spec, RENDER) as ex:
        wcfg, wtr = warm_trials(spec.n_workers)
        with ResultStore(tmp / f"warm-{tag}", wcfg.manifest(), RENDER.columns(list(wtr[0].scenario))) as st:
            run_study(RENDER, wtr, st, ex, chunk_size=1, n_workers=spec.n_workers, progress=False)
        start_s = time.perf_counter() - t0
        out = tmp / f"run-{tag}"
        with ResultStore(out, config.manifest(), RENDER.columns(list(trials[0].scenario))) as st:
            stats = run_study(RENDER, trials, st, ex, chunk_size=config.exposures_per_render, n_workers=spec.n_workers,
                              progress=False)
        mem = [(pid, *_proc_mem_mb(pid)) for pid in _worker_pids(ex, spec)]
        noop = noop_overhead(ex)
    rows = read_rows(out / "results.csv")
    cpu = [r["cpu_s"] for r in rows]
    n_ok = sum(1 for r in rows if r["ok"] == 1)
    if n_ok < len(rows):
        print(f"  note: {len(rows) - n_ok} of {len(rows)} trials did not solve", flush=True)
    return {"trials_per_s": stats.trials_per_s, "elapsed_s": stats.elapsed_s, "cpu_per_trial_s": statistics.mean(cpu),
            "wall_per_trial_s": statistics.mean(r["wall_s"] for r in rows), "cores": sum(cpu) / stats.elapsed_s,
            "rows": rows, "start_s": start_s, "mem": mem, "noop_ms": noop}


def _differences(rows, ref) -> list:
    """(trial_id, column) of every non-timing cell that differs (exact comparison; NaN equals NaN)."""
    def same(a, b):
        return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))

    by = {r["trial_id"]: r for r in ref}
    out = [(r["trial_id"], "<trial>") for r in rows if r["trial_id"] not in by]
    out += [(t, "<missing>") for t in set(by) - {r["trial_id"] for r in rows}]
    for r in rows:
        q = by.get(r["trial_id"])
        if q is not None:
            out += [(r["trial_id"], k) for k in r if k not in TIMINGS and not same(r[k], q.get(k))]
    return out


# --------------------------------------------------------------------------- where a trial's time goes
def breakdown(trials) -> dict:
    """Run ``trials`` (whole render groups) in this process through :func:`run_task`, each stage timed.

    Returns
    -------
    dict
        ``n_trials``, ``n_renders``, ``total_s`` (wall), ``stages`` ({label: (seconds, calls)},
        ``other`` included), ``per_render_s`` (render + optics + CRLB per render),
        ``per_exposure_s`` (the rest per trial), ``c1_s`` (a trial alone on its render).
    """
    import importlib

    acc: dict = {}
    saved = []
    for label, mod, name in STAGES:
        m = importlib.import_module(mod)
        fn = getattr(m, name, None)
        if fn is None:  # the code moved on: that stage is counted in "other"
            print(f"  note: {mod}.{name} not found; its time is in 'other'")
            continue

        def timed(*a, _fn=fn, _label=label, **k):
            t = time.perf_counter()
            try:
                return _fn(*a, **k)
            finally:
                s, n = acc.get(_label, (0.0, 0))
                acc[_label] = (s + time.perf_counter() - t, n + 1)

        saved.append((m, name, fn))
        setattr(m, name, timed)
    groups: dict = {}
    for t in trials:
        groups.setdefault(render_key(t.scenario), []).append((t.trial_id, t.scenario, t.seed))
    try:
        t0 = time.perf_counter()
        for items in groups.values():
            run_task(RENDER.ref, items)
        total = time.perf_counter() - t0
    finally:
        for m, name, fn in saved:
            setattr(m, name, fn)
    stages = {label: acc.get(label, (0.0, 0)) for label, _, _ in STAGES}
    stages["other"] = (total - sum(s for s, _ in stages.values()), len(trials))
    n, g = len(trials), len(groups)
    once = sum(stages[k][0] for k in ("render", "optics", "CRLB"))
    per_exp = (total - once) / n
    return {"n_trials": n, "n_renders": g, "total_s": total, "stages": stages, "per_render_s": once / g,
            "per_exposure_s": per_exp, "c1_s": once / g + per_exp}


def print_breakdown(title: str, b: dict) -> None:
    print(f"{title}: {b['n_trials']} trials, {b['n_renders']} renders, {b['total_s']:.1f} s in this process "
          f"({b['total_s'] / b['n_trials']:.3f} s per trial)")
    print(f"  {'stage':<14}{'s per trial':>12}{'share':>8}{'calls':>7}  (calls: cache hits included)")
    for k, (s, calls) in b["stages"].items():
        print(f"  {k:<14}{s / b['n_trials']:>12.3f}{100 * s / b['total_s']:>7.1f}%{calls:>7d}")
    print(f"  once per render (render + optics + CRLB): {b['per_render_s']:.3f} s; per exposure (expose + "
          f"detect/solve + other): {b['per_exposure_s']:.3f} s; a trial alone on its render: {b['c1_s']:.3f} s")


#: The Sobol' study of the rendered merge range (docs/performance.md): d = 9 parameters (range_m and the 8 of
#: svgs_sim.studies.merge_range.PHYSICS), k = 5 of them change the render (range_m, f_number, led_offset_scale,
#: pattern_scale, ambient_radiance_w_m2_sr); 2 change the optics after the render (the glare's veiling fraction
#: and wing exponent), 1 the exposure (exposure_compensation_ev), 1 only the detector (threshold).
SOBOL_D, SOBOL_K, SOBOL_OPTICS, SOBOL_EXPOSURE, SOBOL_DETECTOR = 9, 5, 2, 1, 1


def sobol_cost(b: dict) -> float:
    """Mean cost of a trial of that Sobol' design (Saltelli: n (d + 2) trials, n (k + 2) renders; an
    AB^(i) row of a post-render parameter shares the render of row A) from the stage times of
    :func:`breakdown`: per design row, k + 2 trials alone on their renders, the optics' and the exposure's
    variants redo the optics + CRLB + exposure or the CRLB + exposure, the detector's only detect + solve."""
    g, n, st = b["n_renders"], b["n_trials"], b["stages"]
    optics, crlb = st["optics"][0] / g, st["CRLB"][0] / g
    detect = (st["detect+solve"][0] + st["other"][0]) / n
    e = b["per_exposure_s"]
    row = ((SOBOL_K + 2) * b["c1_s"] + SOBOL_OPTICS * (optics + crlb + e) + SOBOL_EXPOSURE * (crlb + e)
           + SOBOL_DETECTOR * detect)
    return row / (SOBOL_D + 2)


def merge_range_trials():
    from svgs_sim.studies.merge_range import make_config as mr_config, merge_range_trials as mr_trials

    cfg = mr_config("htc-amaze-4g", ranges_m=(6.0, 7.0), vary=["f_number"], exposures=2)
    return mr_trials(cfg)


def _parse_args(argv):
    """The command line: ``(args, ranges)``, the campaign ranges (m) as a tuple of float."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranges", default="5,15", help="campaign ranges, m (default 5,15)")
    ap.add_argument("--trials-per-range", type=int, default=8, help="rendered trials per range (default 8)")
    ap.add_argument("--exposures", type=int, default=4, help="exposures per rendered stand setting (default 4, the "
                    "campaign's)")
    ap.add_argument("--no-dask", action="store_true", help="the process pool only")
    ap.add_argument("--merge-range", action="store_true", help="also time merge-range trials (htc-amaze-4g)")
    ap.add_argument("--project-trials", type=float, default=1e5, help="trials of the projected study (default 1e5)")
    ap.add_argument("--project-workers", type=int, default=100, help="Dask workers of the projection (default 100)")
    ap.add_argument("--project-efficiency", type=float, default=0.9,
                    help="parallel efficiency assumed for the projection (default 0.9)")
    args = ap.parse_args(argv)
    ranges = tuple(float(x) for x in args.ranges.split(","))
    if args.trials_per_range < 1 or args.exposures < 1 or args.trials_per_range % args.exposures:
        ap.error("--trials-per-range must be a positive multiple of --exposures")
    if args.project_trials <= 0 or args.project_workers < 1 or not 0 < args.project_efficiency <= 1:
        ap.error("--project-trials > 0, --project-workers >= 1 and 0 < --project-efficiency <= 1")
    return args, ranges


def _executor_kinds(no_dask: bool) -> list:
    """The executors to time: ``(label, mode)`` pairs, the process pool and, if importable, Dask."""
    kinds = [("process pool", "process")]
    if not no_dask:
        try:
            import distributed  # noqa: F401

            kinds.append(("Dask LocalCluster", "dask-local"))
        except ModuleNotFoundError:
            print("note: dask.distributed is not installed; the process pool only")
    return kinds


def _print_throughput_table(kinds, res: dict) -> float:
    """Print the throughput of each executor against the peer (the 1-worker process pool).

    Parameters
    ----------
    kinds : list of (str, str)
        The timed executors' labels and modes.
    res : dict
        ``(mode, n_workers)`` -> :func:`throughput`'s result.

    Returns
    -------
    float
        The peer's throughput, trials/s.
    """
    peer = res[("process", 1)]["trials_per_s"]
    print(f"\npeer: process pool, 1 worker, {peer:.3f} trials/s")
    print(f"{'configuration':<28}{'trials/s':>10}{'peer':>9}{'ours/peer':>11}{'efficiency':>12}")
    for label, mode in kinds:
        for n in (1, 2):
            tps = res[(mode, n)]["trials_per_s"]
            print(f"{label + f', {n} worker(s)':<28}{tps:>10.3f}{peer:>9.3f}{tps / peer:>11.2f}"
                  f"{tps / (n * peer):>12.2f}")
    return peer


def _print_projection(args, res: dict, peer: float, b: dict, mr) -> None:
    """Print the projected wall time of a large study on a Dask cluster.

    Parameters
    ----------
    args : argparse.Namespace
        The command line (``project_trials``, ``project_workers``, ``project_efficiency``).
    res : dict
        ``(mode, n_workers)`` -> :func:`throughput`'s result.
    peer : float
        The 1-worker process pool's throughput, trials/s.
    b, mr : dict
        :func:`breakdown` of the campaign trials and of the merge-range trials (None when not timed).
    """
    best = res[("dask-local", 2)] if ("dask-local", 2) in res else res[("process", 2)]
    eff2 = best["trials_per_s"] / (2 * peer)
    o_ms = res[("dask-local", 1)]["noop_ms"][1] if ("dask-local", 1) in res else res[("process", 1)]["noop_ms"][1]
    N, P, eta = args.project_trials, args.project_workers, args.project_efficiency
    tasks = N / DEFAULT_CHUNK_SIZE
    print(f"\nprojection: {N:.0f} trials on {P} Dask workers, wall = trials * c / (workers * efficiency) "
          f"(+ tasks * o = {tasks:.0f} * {o_ms:.2f} ms = {tasks * o_ms / 1e3:.0f} s of scheduling, spread over "
          f"the run)")
    print(f"  efficiency measured on 2 workers ({'Dask' if ('dask-local', 2) in res else 'pool'}): {eff2:.2f}; "
          f"assumed for {P} workers: {eta:.2f}")
    cs = [("campaign trial, measured (1-process pool)", 1 / peer),
          ("campaign trial alone on its render", b["c1_s"])]
    if mr is not None:
        cs += [("merge-range trial alone on its render", mr["c1_s"]),
               (f"merge-range Sobol' trial (d {SOBOL_D}, k {SOBOL_K})", sobol_cost(mr))]
    for label, c in cs:
        print(f"  {label:<42} c = {c:.3f} s: {N * c / (P * eta) / 3600:.2f} h at efficiency {eta:.2f}, "
              f"{N * c / (P * eff2) / 3600:.2f} h at {eff2:.2f}")
    cap = TASKS_PER_WORKER  # run_stored_study sizes the window with n_workers = max(0, 1) for --scheduler
    print(f"  note: on an existing cluster (--scheduler) run_study keeps {cap} tasks in flight (the window of one "
          f"worker), so at most {cap} of the {P} workers are busy: the times above are {P / cap:.0f}x longer until "
          f"the window is sized from the cluster")


# --------------------------------------------------------------------------- main
def main(argv=None) -> int:
    args, ranges = _parse_args(argv)
    kinds = _executor_kinds(args.no_dask)
    t_start = time.perf_counter()
    print(f"cores: {os.cpu_count()}; load average before: {_load()}")
    with tempfile.TemporaryDirectory(prefix="bench-scaleout-") as tmpdir:
        tmp = Path(tmpdir)
        t0 = time.perf_counter()
        config, trials = campaign(ranges, args.trials_per_range, args.exposures, tmp / "calibration")
        n_renders = len({render_key(t.scenario) for t in trials})
        print(f"rendered campaign {CAMERA}: ranges {', '.join(f'{r:g}' for r in ranges)} m, {len(trials)} trials, "
              f"{n_renders} renders ({args.exposures} exposures each), calibration paper (rendered focal length "
              f"{time.perf_counter() - t0:.1f} s, once); chunk = one render group", flush=True)

        res = {}
        for label, mode in kinds:
            for n in (1, 2):
                r = throughput(ExecutorSpec(mode, n), config, trials, tmp)
                res[(mode, n)] = r
                mem = "; ".join(f"pid {p}: RSS {a:.0f} MB, peak {b:.0f} MB" for p, a, b in r["mem"]) or "n/a"
                print(f"{label}, {n} worker(s): {r['trials_per_s']:.3f} trials/s ({len(trials)} trials in "
                      f"{r['elapsed_s']:.1f} s; executor start + warm-up {r['start_s']:.1f} s); worker CPU "
                      f"{r['cpu_per_trial_s']:.2f} s/trial, wall {r['wall_per_trial_s']:.2f} s/trial; the workers "
                      f"got {r['cores']:.2f} core(s); no-op task: {r['noop_ms'][0]:.2f} ms round trip, "
                      f"{r['noop_ms'][1]:.2f} ms each in a batch of {NOOP_BATCH}; memory: {mem}", flush=True)
        peer = _print_throughput_table(kinds, res)
        ref = res[("process", 1)]["rows"]
        diffs = {k: _differences(v["rows"], ref) for k, v in res.items() if k != ("process", 1)}
        bad = {k: d for k, d in diffs.items() if d}
        print("rows (timings aside) identical on every executor: "
              + ("yes" if not bad else f"NO: {', '.join(f'{m}-{n}: {d[:5]}' for (m, n), d in bad.items())}"))

        print(f"\nwhere a trial's time goes (load average now {_load()}):")
        sub = [t for t in trials if t.scenario["pose_index"] == 0]
        b = breakdown(sub)
        print_breakdown(f"rendered campaign, {CAMERA}, first stand setting of each range", b)
        mr = None
        if args.merge_range:
            mr = breakdown(merge_range_trials())
            print_breakdown("merge range, htc-amaze-4g, 6 and 7 m, f-number nominal/low/high, 2 exposures/render", mr)

    _print_projection(args, res, peer, b, mr)
    print(f"load average after: {_load()}; the benchmark took {time.perf_counter() - t_start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
