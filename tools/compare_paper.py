"""Side-by-side table of a range sweep and the paper's Tables 2-5.

Usage: python tools/compare_paper.py SWEEP_DIR PHONE > SWEEP_DIR/comparison.md
(SWEEP_DIR from `svgs range-sweep --out`; PHONE: galaxy-nexus or htc-amaze-4g)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from svgs_sim.assets.papers import svgs_2014_results
from svgs_sim.svgs.frames import STATE_KEYS

KEYS = STATE_KEYS


def paper(phone):
    return {(st, rng): [v[k] for k in KEYS] for (ph, st, rng), v in svgs_2014_results().items() if ph == phone}


def main(sweep_dir, phone):
    p = paper(phone)
    rows = [json.loads(line) for line in open(Path(sweep_dir) / "trials.jsonl")]
    ranges = sorted({r["range_m"] for r in rows})
    print(f"| range m | statistic | source | {' | '.join(KEYS)} |")
    print("|---|---|---|" + "---|" * len(KEYS))
    for rng in ranges:
        ok = [r for r in rows if r["range_m"] == rng and r["ok"]]
        if not ok:
            print(f"| {rng:g} | - | simulated | " + " | ".join("no solution" for _ in KEYS) + " |")
            continue
        err = np.array([r["pos_err_vec_m"] + r["att_err_vec_deg"] for r in ok])
        sim_mean, sim_std = np.mean(np.abs(err), 0), np.std(err, 0)
        for stat, sim in (("mean_error", sim_mean), ("std", sim_std)):
            print(f"| {rng:g} | {stat} | simulated | " + " | ".join(f"{v:.3g}" for v in sim) + " |")
            if (stat, rng) in p:
                pv = np.array(p[(stat, rng)])
                print(f"| {rng:g} | {stat} | paper | " + " | ".join(f"{v:.3g}" for v in pv) + " |")
                print(f"| {rng:g} | {stat} | sim/paper | " + " | ".join(f"{a / b:.2g}" for a, b in zip(sim, pv)) + " |")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
