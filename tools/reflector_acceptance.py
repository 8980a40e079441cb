"""Print the corner cubes' acceptance (deg) as the renderer computes it, for each shipped phone
(:mod:`svgs_sim.render.acceptance`); the pattern file's ``[reflector] acceptance_deg`` is the largest.

Usage::

    python tools/reflector_acceptance.py [--cameras galaxy-nexus,htc-amaze-4g] [--range 5]

prints one JSON object: per camera the acceptance and the direction (phi, psi, deg) that reaches it.
(About 2 minutes on 2 cores.)
"""

from __future__ import annotations

import argparse
import json


def main(argv=None) -> int:
    from svgs_sim.render.acceptance import acceptance

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cameras", default="galaxy-nexus,htc-amaze-4g")
    ap.add_argument("--pattern", default="svgs-3u")
    ap.add_argument("--range", type=float, default=5.0, dest="range_m", help="range along the boresight, m")
    ap.add_argument("--fraction", type=float, default=1e-3, help="'returns light': at least this fraction of head-on")
    a = ap.parse_args(argv)
    out = {}
    for cam in a.cameras.split(","):
        res = acceptance(cam, a.pattern, range_m=a.range_m, fraction=a.fraction)
        out[cam] = {k: v for k, v in res.items() if k != "by_direction"}
    out["pattern_acceptance_deg"] = max(v["acceptance_deg"] for v in out.values())
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
