"""``make demo``: one render-and-solve of the Galaxy Nexus at 10 m.

Renders the SVGS 3U target under the phone's flash (Mitsuba), exposes it with the phone
camera model, solves the pose with the SVGS detector and collinearity solver, and prints
truth, solution, errors and the paths of what it wrote (``out/demo/``).
"""

from __future__ import annotations

import sys

from svgs_sim.cli.main import main as svgs_main

DEMO_ARGS = ["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--x", "0.3", "--y", "-0.2",
             "--roll", "5", "--pitch", "-3", "--yaw", "10", "--seed", "1", "--out", "out/demo"]


def main() -> int:
    print("svgs demo: " + "svgs " + " ".join(DEMO_ARGS), file=sys.stderr)
    return svgs_main(DEMO_ARGS)


if __name__ == "__main__":
    sys.exit(main())
