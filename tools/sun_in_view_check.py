"""Issue 38's acceptance with the sun in the field of view: ``svgs render-and-solve --environment orbit
--sun-deg 0,-87`` (the sun 3 deg behind the target, seen past it) for both phones at 2, 5 and 10 m over
5 seeds; each run solves correctly or says why not, and none is a wrong lock (an identified blob
farther than max(3 px, the spot's image radius) from its target's spot: the sun study's rule,
:func:`svgs_sim.studies.sun_study.wrong_lock_px`).

Usage::

    python tools/sun_in_view_check.py [--cameras galaxy-nexus,htc-amaze-4g] [--ranges 2,5,10] [--seeds 5]

prints a line a run and one JSON object (the counts); exit 1 if any run is a wrong lock.
(About 30 renders: 5 minutes on 2 cores.)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def one(camera: str, range_m: float, seed: int, sun_deg: str, work: Path) -> dict:
    """One run of the command; its outcome (``solved``, ``wrong_lock`` or the failure reason)."""
    from PIL import Image

    from svgs_sim.base.profiles import load_camera, load_pattern
    from svgs_sim.studies.sun_study import wrong_lock_px

    out = work / f"{camera}-{range_m:g}-{seed}"
    cmd = [sys.executable, "-m", "svgs_sim.cli.main", "render-and-solve", "--camera", camera, "--range", f"{range_m:g}",
           "--environment", "orbit", "--sun-deg", sun_deg, "--seed", str(seed), "--json", "--out", str(out)]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(cmd[2:])}: exit {p.returncode}\n{p.stderr[-2000:]}")
    row = json.loads(p.stdout)
    truth = json.loads((out / "truth.json").read_text())
    scale = Image.open(out / "image.png").size[0] / truth["intrinsics"]["width"]
    err = None
    if row.get("identified_px"):
        spots = truth["spots_px_predicted"]
        err = max(float(np.hypot(*(np.array(uv) - np.array(spots[k]) * scale))) for k, uv in row["identified_px"].items())
    lim = wrong_lock_px(load_camera(camera), load_pattern("svgs-3u"), range_m)
    reported = row["ok"] or row["reason"] == "inconsistent"
    outcome = ("wrong_lock" if reported and err is not None and err > lim else "solved" if row["ok"] else row["reason"])
    return {"camera": camera, "range_m": range_m, "seed": seed, "outcome": outcome, "match_err_max_px": err,
            "rot_err_deg": row.get("rot_err_deg"), "message": row.get("message"), "n_blobs": row.get("n_blobs")}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cameras", default="galaxy-nexus,htc-amaze-4g")
    ap.add_argument("--ranges", default="2,5,10")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--sun-deg", default="0,-87")
    a = ap.parse_args(argv)
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for cam in a.cameras.split(","):
            for r in (float(x) for x in a.ranges.split(",")):
                for seed in range(a.seeds):
                    res = one(cam, r, seed, a.sun_deg, Path(tmp))
                    runs.append(res)
                    print(f"{cam} {r:g} m seed {seed}: {res['outcome']}"
                          + (f" ({res['message'][:120]})" if res["outcome"] not in ("solved", "wrong_lock") else "")
                          + (f", blobs off their spots by {res['match_err_max_px']:.2f} px at most"
                             if res["match_err_max_px"] is not None else ""), file=sys.stderr, flush=True)
    counts = {}
    for r in runs:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    print(json.dumps({"sun_deg": a.sun_deg, "runs": len(runs), "outcomes": counts, "wrong_locks": counts.get("wrong_lock", 0),
                      "by_run": runs}, indent=1))
    return 1 if counts.get("wrong_lock") else 0


if __name__ == "__main__":
    raise SystemExit(main())
