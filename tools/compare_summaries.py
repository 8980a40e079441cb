"""Before/after table of two runs of a study: the simulated value of every (range, component,
statistic) cell of their ``summary.csv``, the ratio new/old, and how far the change is in units
of the cell's own sampling noise (the standard error of a mean, or of a standard deviation,
from the trials per range).

Run: ``.venv/bin/python tools/compare_summaries.py OLD/summary.csv NEW/summary.csv [--trials 80]
[--statistic std] [--markdown]``

Either file may be a campaign's ``summary.csv`` made before the statistics were renamed
(``abs_mean_error`` is now ``abs_bias``, ``rms_error`` is now ``rms``): the old names are read
as the new ones, so an old and a new summary compare cell by cell.
"""

from __future__ import annotations

import argparse
import csv
import math


#: Statistic names of summaries made before the renaming -> their names now (the same as
#: ``svgs_sim.studies.campaign.RENAMED_STATISTICS``; kept here so that the tool needs nothing of the project).
RENAMED_STATISTICS = {"abs_mean_error": "abs_bias", "rms_error": "rms"}


def read(path):
    """``(range_m, component, statistic) -> row`` of a ``summary.csv``, old statistic names renamed."""
    with open(path, newline="") as fh:
        return {(float(r["range_m"]), r["component"], RENAMED_STATISTICS.get(r["statistic"], r["statistic"])): r
                for r in csv.DictReader(fh)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--trials", type=int, default=80, help="trials per range (default 80)")
    ap.add_argument("--statistic", default="std", help="statistic to compare (default std; 'all' for every one)")
    ap.add_argument("--markdown", action="store_true", help="print a Markdown table")
    args = ap.parse_args(argv)
    old, new = read(args.old), read(args.new)
    n = args.trials
    rows = []
    for key in sorted(set(old) & set(new)):
        rng, comp, stat = key
        if args.statistic != "all" and stat != args.statistic:
            continue
        try:
            a, b = float(old[key]["simulated"]), float(new[key]["simulated"])
        except (TypeError, ValueError):
            continue
        if not (math.isfinite(a) and math.isfinite(b)):
            continue
        # sampling noise of the cell: a standard deviation's relative standard error is
        # 1/sqrt(2(n-1)); for means the std of the same component is needed
        if stat == "std":
            se = abs(a) / math.sqrt(2 * (n - 1))
        elif (rng, comp, "std") in old:
            se = float(old[(rng, comp, "std")]["simulated"]) / math.sqrt(n)
        else:
            se = float("nan")
        z = (b - a) / se if se and math.isfinite(se) and se > 0 else float("nan")
        rows.append((rng, comp, stat, a, b, b / a if a else float("nan"), z))
    if args.markdown:
        print("| range m | component | statistic | before | after | after/before | change / own noise |")
        print("|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r[0]:g} | {r[1]} | {r[2]} | {r[3]:.4g} | {r[4]:.4g} | {r[5]:.3f} | {r[6]:+.2f} |")
    else:
        for r in rows:
            print(f"{r[0]:>6g} {r[1]:>10} {r[2]:>16} {r[3]:>12.4g} {r[4]:>12.4g} {r[5]:>8.3f} {r[6]:>+7.2f}")
    zs = [abs(r[6]) for r in rows if math.isfinite(r[6])]
    if zs:
        print(f"\n{len(zs)} cells; |change| / own noise: median {sorted(zs)[len(zs) // 2]:.2f}, max {max(zs):.2f}, "
              f"beyond 2: {sum(z > 2 for z in zs)}, beyond 3: {sum(z > 3 for z in zs)}")


if __name__ == "__main__":
    main()
