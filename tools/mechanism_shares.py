"""Each error mechanism's share of each cell of the paper's Tables 2-5, with its sampling interval.

Reads a campaign run with ``--budget`` (``DIR/results.csv``) and prints Markdown tables: per
range and component the simulated statistic over the paper's, and for each mechanism its
contribution ``sqrt(s_base^2 - s_without^2)`` (the part of the baseline that goes when it goes,
in quadrature: ``svgs_sim.studies.error_budget``) over the paper's value, with a 90 % interval from a
paired bootstrap over the stand settings (a setting's exposures stay together; the baseline and
the variant are resampled alike: common random numbers).

Usage::

    python tools/mechanism_shares.py docs/reports/campaign-galaxy-nexus [--statistic std mean_abs]
        [--mechanisms no_turbulence no_jpeg ...] [--resamples 200] [--seed 0]
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.assets.papers import svgs_2014_results  # noqa: E402
from svgs_sim.studies.error_budget import SOURCE_LABELS  # noqa: E402
from svgs_sim.svgs.frames import STATE_KEYS  # noqa: E402

#: The mechanisms of issue 24 (the image path and the lab), the default selection.
ISSUE_24 = ("no_jpeg", "no_chroma_subsampling", "no_cfa", "no_stand_error", "no_rail_error", "no_turbulence")
PAPER_STATISTIC = {"std": "std", "mean_abs": "mean_error", "abs_mean": "mean_error", "rms": "mean_error"}


def _stat(e: np.ndarray, which: str) -> np.ndarray:
    if which == "std":
        return e.std(axis=0, ddof=1)
    if which == "mean_abs":
        return np.abs(e).mean(axis=0)
    if which == "abs_mean":
        return np.abs(e.mean(axis=0))
    return np.sqrt((e ** 2).mean(axis=0))


def shares(results_csv, camera: str, statistics=("std", "mean_abs"), mechanisms=ISSUE_24, resamples: int = 200,
           seed: int = 0) -> str:
    """The Markdown tables (see the module docstring)."""
    with open(results_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    paper = svgs_2014_results()
    present = {r["variant"] for r in rows}
    mech = [m for m in mechanisms if m in present]
    ranges = sorted({float(r["nominal_range_m"]) for r in rows})

    def table(variant, R):
        out = {}
        for r in rows:
            if r["variant"] == variant and float(r["nominal_range_m"]) == R and r["ok"] in ("1", "True"):
                out[(int(r["pose_index"]), int(r["exposure_index"]))] = [float(r[f"err_{c}"]) for c in STATE_KEYS]
        return out

    rng = np.random.default_rng(seed)
    lines = []
    for which in statistics:
        pst = PAPER_STATISTIC[which]
        lines += ["", f"**{which}**: simulated / paper, and each mechanism's share sqrt(s^2 - s_without^2) / paper "
                      f"(90 % paired bootstrap over the stand settings, {resamples} resamples)", "",
                  "| range m | component | simulated / paper | " + " | ".join(SOURCE_LABELS.get(m, m) for m in mech) + " |",
                  "|---|---|---|" + "---|" * len(mech)]
        for R in ranges:
            if (camera, pst, R) not in paper:
                continue
            base = table("baseline", R)
            poses = sorted({k[0] for k in base})
            cells = {}
            for m in mech:
                var = table(m, R)
                keys = [k for k in base if k in var]
                if len(keys) < 2:
                    cells[m] = None
                    continue
                B, V = np.array([base[k] for k in keys]), np.array([var[k] for k in keys])
                P = np.array([k[0] for k in keys])

                def contrib(idx):
                    b, w = _stat(B[idx], which), _stat(V[idx], which)
                    return np.sqrt(np.clip(b ** 2 - w ** 2, 0.0, None))

                boots = []
                for _ in range(resamples):
                    idx = np.concatenate([np.flatnonzero(P == p) for p in rng.choice(poses, len(poses))])
                    boots.append(contrib(idx))
                boots = np.array(boots)
                cells[m] = (contrib(np.arange(len(keys))), np.percentile(boots, 5, axis=0),
                            np.percentile(boots, 95, axis=0))
            sb = _stat(np.array(list(base.values())), which)
            for ci, c in enumerate(STATE_KEYS):
                p = paper[(camera, pst, R)][c]
                txt = ["-" if cells[m] is None else
                       f"{cells[m][0][ci] / p:.2f} ({cells[m][1][ci] / p:.2f}-{cells[m][2][ci] / p:.2f})" for m in mech]
                lines.append(f"| {R:g} | {c} | {sb[ci] / p:.2f} | " + " | ".join(txt) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", help="a campaign run with --budget (its results.csv and manifest.json)")
    ap.add_argument("--statistic", nargs="+", default=["std", "mean_abs"], choices=sorted(PAPER_STATISTIC))
    ap.add_argument("--mechanisms", nargs="+", default=list(ISSUE_24),
                    help="budget variants (default: issue 24's image path and lab)")
    ap.add_argument("--resamples", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    import json

    d = Path(a.dir)
    if not (d / "results.csv").is_file() or not (d / "manifest.json").is_file():
        print(f"{d}: not a campaign folder (results.csv, manifest.json)", file=sys.stderr)
        return 2
    camera = json.loads((d / "manifest.json").read_text())["parameters"]["camera"]
    print(shares(d / "results.csv", camera, a.statistic, a.mechanisms, a.resamples, a.seed))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
