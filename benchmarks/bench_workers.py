"""Benchmark (issue 6): study throughput with 1 versus 2 workers.

Runs the same campaign (geometric trials, Galaxy Nexus, the paper's calibration practice so
the solver undistorts: ~1-3 ms per trial) through the study layer - tasks, executor, results
store with fsync - on a local process pool of 1 and of 2 processes (optionally also a Dask
LocalCluster), after warming the workers up (spawn, imports, compiled solver), and prints
trials/s and the ratio. Target: 2 workers >= 1.7x the throughput of 1. The machine's load
average is printed before and after, and, from the workers' own CPU clocks, how many cores'
worth of CPU time they got: other processes on the same cores lower the ratio, while an
unchanged CPU cost per trial shows the layer itself adds no serial bottleneck.

Run: ``.venv/bin/python benchmarks/bench_workers.py [--trials 600] [--repeats 3] [--dask]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.studies.campaign import campaign_trials, make_config  # noqa: E402
from svgs_sim.studies.execution import ExecutorSpec, open_executor, run_study  # noqa: E402
from svgs_sim.studies.store import ResultStore  # noqa: E402
from svgs_sim.sim.trials import GEOMETRIC  # noqa: E402


def _study(trials_per_range: int, seed: int):
    cfg = make_config("galaxy-nexus", trials_per_range=trials_per_range, seed=seed, calibration="paper",
                      trial_kind="geometric")
    return cfg, campaign_trials(cfg)


def throughput(spec: ExecutorSpec, trials_per_range: int, repeats: int, chunk: int) -> list[tuple[float, float, float]]:
    """``repeats`` timed runs on one warm executor.

    Returns
    -------
    list of (trials/s, worker CPU ms per trial, cores' worth of CPU the workers got)
    """
    from svgs_sim.studies.store import read_table

    rates = []
    with tempfile.TemporaryDirectory() as tmp, open_executor(spec, GEOMETRIC) as ex:
        cfg, warm = _study(max(4, chunk // 2), seed=999)  # spawns and warms every worker
        with ResultStore(Path(tmp) / "warm", cfg.manifest(), GEOMETRIC.columns(list(warm[0].scenario))) as st:
            run_study(GEOMETRIC, warm, st, ex, chunk_size=max(1, chunk // 4), n_workers=spec.n_workers, progress=False)
        for r in range(repeats):
            cfg, trials = _study(trials_per_range, seed=r)
            with ResultStore(Path(tmp) / f"run{r}", cfg.manifest(), GEOMETRIC.columns(list(trials[0].scenario))) as st:
                stats = run_study(GEOMETRIC, trials, st, ex, chunk_size=chunk, n_workers=spec.n_workers, progress=False)
            cpu = read_table(Path(tmp) / f"run{r}" / "results.csv")["cpu_s"]
            rates.append((stats.trials_per_s, 1e3 * cpu.mean(), cpu.sum() / stats.elapsed_s))
    return rates


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=600, help="trials per range, 5 ranges (default 600)")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs per configuration (default 3)")
    ap.add_argument("--chunk", type=int, default=32, help="trials per task (default 32)")
    ap.add_argument("--dask", action="store_true", help="also time a Dask LocalCluster of 1 and 2 workers")
    args = ap.parse_args(argv)
    print(f"cores: {os.cpu_count()}; load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    kinds = [("process pool", "process")] + ([("Dask LocalCluster", "dask-local")] if args.dask else [])
    for label, mode in kinds:
        res = {}
        for n in (1, 2):
            runs = throughput(ExecutorSpec(mode, n), args.trials, args.repeats, args.chunk)
            res[n] = statistics.median(r[0] for r in runs)
            print(f"{label}, {n} worker(s): {res[n]:8.1f} trials/s (median of {len(runs)}: "
                  f"{', '.join(f'{r[0]:.1f}' for r in runs)}); worker CPU per trial "
                  f"{statistics.median(r[1] for r in runs):.2f} ms; the workers got "
                  f"{statistics.median(r[2] for r in runs):.2f} core(s) of CPU time")
        ratio = res[2] / res[1]
        print(f"{label}: 2 workers / 1 worker throughput = {ratio:.2f}x (target >= 1.7x) "
              f"{'PASS' if ratio >= 1.7 else 'BELOW TARGET'}")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
