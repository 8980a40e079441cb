"""Rerun trials of a committed sun study and compare them with its rows.

Each trial is rebuilt from the study's ``manifest.json`` (the same scenario and seed), rendered,
exposed and solved again, and printed beside the committed row: the outcome, blobs, saturated
pixels away from the spots, the match error and the time spent exposing. Used to check that a
change to the camera model left a study's numbers alone (and what it did to their cost).

Usage::

    python tools/rerun_sun_trial.py docs/reports/sun-study-3u-htc-amaze-4g 17 9 56

Exit 1 when a rerun differs from its committed row in any compared column.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.sim.render_trial.run import render_group  # noqa: E402
from svgs_sim.studies.sun_study import make_config, sun_study_trials  # noqa: E402

COMPARED = ("ok", "reason", "n_blobs", "match_err_max_px", "stray_saturated_px", "exposure_s_used")


def _same(new, old: str) -> bool:
    if new is None or new == "":
        return old in ("", "None")
    if isinstance(new, bool):
        return old in (("1", "True", "true") if new else ("0", "False", "false"))
    try:
        return float(new) == float(old)
    except (TypeError, ValueError):
        return str(new) == old


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", help="a sun study's folder (manifest.json, results.csv)")
    ap.add_argument("trial_ids", nargs="+", type=int, help="trial ids (results.csv's trial_id)")
    a = ap.parse_args(argv)
    folder = Path(a.study)
    for name in ("manifest.json", "results.csv"):
        if not (folder / name).is_file():
            print(f"error: study: {folder / name} not found", file=sys.stderr)
            return 2
    p = json.loads((folder / "manifest.json").read_text())["parameters"]
    cfg = make_config(p["camera"], p["ranges_m"], p["azimuths_deg"], p["elevations_deg"], p["trials"], seed=p["seed"],
                      pattern=p["pattern"], earth=p.get("earth"), earth_albedos=p.get("earth_albedos"),
                      body=p.get("body", "plate"))
    trials = {t.trial_id: t for t in sun_study_trials(cfg)}
    with open(folder / "results.csv", newline="") as fh:
        committed = {int(r["trial_id"]): r for r in csv.DictReader(fh)}
    missing = [i for i in a.trial_ids if i not in trials or i not in committed]
    if missing:
        print(f"error: trial_ids: {missing} not in {folder}", file=sys.stderr)
        return 2
    differ = 0
    for tid in a.trial_ids:
        t = trials[tid]
        t0 = time.perf_counter()
        row = render_group([dict(t.scenario)], [t.seed])[0]
        wall = time.perf_counter() - t0
        old = committed[tid]
        bad = [k for k in COMPARED if not _same(row.get(k), old.get(k, ""))]
        differ += bool(bad)
        print(f"trial {tid} ({t.scenario['range_m']:g} m, sun {t.scenario['sun_azimuth_deg']:g},"
              f"{t.scenario['sun_elevation_deg']:g}): {'differs in ' + ', '.join(bad) if bad else 'same'}; "
              f"reason {row.get('reason') or 'solved'}; expose {row['expose_s']:.2f} s (committed "
              f"{float(old['expose_s']):.2f} s); wall {wall:.1f} s", flush=True)
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
