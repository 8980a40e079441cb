"""The sun study's trials rerun with the phone's auto-exposure switched off: which exposure keeps
lock on orbit, and how much of a phone's lost availability its auto-exposure is.

On orbit the frame is black space: a metering auto-exposure (the HTC Amaze 4G's) runs to its longest
exposure, and then the sunlit body saturates and merges with the spots. The Galaxy Nexus' profile
has a fitted manual exposure (0.5 ms, ``assets/cameras/fitted``), which is why the two phones'
sun studies differ. This tool takes a committed sun study's trials (the same scenarios and seeds,
one render each) and exposes each render again at fixed exposures: the switch that measures the
mechanism.

Usage::

    python tools/exposure_switch.py docs/reports/sun-study-htc-amaze-4g --exposures-s 5e-4,2e-3 \\
        [--elevations-deg=-45,-15] [--azimuths-deg 0,90,180,270] [--trials-per-cell 1] [--json FILE]

prints a table (per range and sun elevation: solved / wrong locks / trials for the auto-exposure and
each fixed exposure) and writes the rows as JSON. About 30 s a trial on 2 cores (an 8 Mpx render).
"""

from __future__ import annotations

import argparse
import collections
import csv
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.base.profiles import load_camera, load_pattern  # noqa: E402
from svgs_sim.sim.render_trial.run import render_group  # noqa: E402
from svgs_sim.studies.sun_study import classify, make_config, sun_study_trials  # noqa: E402


def _floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",") if x.strip()]


def _typed(row: dict) -> dict:
    """A results.csv row with the numbers :func:`classify` reads as numbers."""
    out = dict(row)
    for k in ("ok", "paper_gates_reported"):
        out[k] = out.get(k) in ("1", "True", "true")
    for k in ("range_m", "match_err_max_px", "paper_gates_match_err_max_px", "stray_px", "stray_saturated_px", "n_blobs",
              "sun_azimuth_deg", "sun_elevation_deg", "earth_azimuth_deg", "earth_elevation_deg", "altitude_km",
              "roll_deg", "pitch_deg", "yaw_deg", "target_x_m", "target_y_m"):
        v = out.get(k)
        out[k] = float(v) if v not in (None, "") else None
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", help="a sun study's folder (its manifest.json gives the trials)")
    ap.add_argument("--exposures-s", default="5e-4,2e-3", help="fixed exposures to compare with the auto-exposure, s")
    ap.add_argument("--elevations-deg", default=None, help="only these sun elevations (default: all)")
    ap.add_argument("--azimuths-deg", default=None, help="only these sun azimuths (default: all)")
    ap.add_argument("--ranges", default=None, help="only these ranges, m (default: all)")
    ap.add_argument("--trials-per-cell", type=int, default=1)
    ap.add_argument("--json", default=None, help="write the rows here (default: print only)")
    a = ap.parse_args(argv)
    man = json.loads((Path(a.study) / "manifest.json").read_text())
    cfg = man["parameters"]
    config = make_config(cfg["camera"], cfg["ranges_m"], cfg["azimuths_deg"], cfg["elevations_deg"], cfg["trials"],
                         seed=cfg["seed"], pattern=cfg["pattern"], earth=cfg.get("earth"))
    exposures = _floats(a.exposures_s)
    keep = {k: set(_floats(v)) for k, v in (("elevation", a.elevations_deg), ("azimuth", a.azimuths_deg),
                                             ("range", a.ranges)) if v}
    trials = []
    for t in sun_study_trials(config):
        s = t.scenario
        if int(s["trial_in_cell"]) >= a.trials_per_cell:
            continue
        if ("elevation" in keep and float(s["sun_elevation_deg"]) not in keep["elevation"]) or (
                "azimuth" in keep and float(s["sun_azimuth_deg"]) not in keep["azimuth"]) or (
                "range" in keep and float(s["range_m"]) not in keep["range"]):
            continue
        trials.append(t)
    cam, pat = load_camera(config.camera), load_pattern(config.pattern)
    with open(Path(a.study) / "results.csv", newline="") as fh:  # the committed outcomes: the rerun must repeat them
        committed = {int(r["trial_id"]): r for r in csv.DictReader(fh)}
    print(f"{len(trials)} trials of {a.study}, each exposed with the auto-exposure and at "
          f"{', '.join(f'{e * 1e3:g} ms' for e in exposures)}", file=sys.stderr)
    out = []
    for n, t in enumerate(trials, 1):
        scen = [dict(t.scenario)] + [dict(t.scenario, exposure_s=e) for e in exposures]
        rows = render_group(scen, [t.seed] * len(scen))
        for label, sc, row in zip(["auto"] + [f"{e:g}" for e in exposures], scen, rows):
            row = {**sc, **row}
            c = classify([row], cam, pat)[0]
            if label == "auto":
                old = classify([_typed(committed[t.trial_id])], cam, pat)[0]["outcome"]
                if old != c["outcome"]:
                    raise SystemExit(f"trial {t.trial_id}: the rerun gives {c['outcome']}, the committed study {old}")
            out.append({"trial_id": t.trial_id, "exposure": label, "range_m": float(sc["range_m"]),
                        "sun_azimuth_deg": float(sc["sun_azimuth_deg"]), "sun_elevation_deg": float(sc["sun_elevation_deg"]),
                        "outcome": c["outcome"], "exposure_s_used": row.get("exposure_s_used"),
                        "stray_saturated_px": row.get("stray_saturated_px")})
        print(f"[{n}/{len(trials)}] {t.scenario['range_m']:g} m sun {t.scenario['sun_azimuth_deg']:g},"
              f"{t.scenario['sun_elevation_deg']:g}: " + ", ".join(f"{o['exposure']} {o['outcome']}" for o in out[-len(scen):]),
              file=sys.stderr, flush=True)
    tab = collections.defaultdict(collections.Counter)
    for o in out:
        tab[(o["range_m"], o["sun_elevation_deg"], o["exposure"])][o["outcome"]] += 1
        tab[(o["range_m"], o["sun_elevation_deg"], o["exposure"])]["trials"] += 1
    labels = ["auto"] + [f"{e:g}" for e in exposures]
    print("| range, m | sun el, deg | " + " | ".join(f"{x} (solved / wrong / trials)" for x in labels) + " |")
    print("|---|---|" + "---|" * len(labels))
    for r in sorted({k[0] for k in tab}):
        for el in sorted({k[1] for k in tab}):
            cells = [tab[(r, el, x)] for x in labels]
            print(f"| {r:g} | {el:g} | " + " | ".join(f"{c['solved']} / {c['wrong_lock']} / {c['trials']}" for c in cells) + " |")
    tot = {x: collections.Counter() for x in labels}
    for o in out:
        tot[o["exposure"]][o["outcome"]] += 1
    print("all: " + "; ".join(f"{x}: {dict(tot[x])}" for x in labels))
    if a.json:
        Path(a.json).write_text(json.dumps({"study": a.study, "exposures_s": exposures, "rows": out}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
