"""Each error mechanism's share of a campaign's std cells (the paper's Tables 3 and 5), with its
90 % sampling interval, and the verdict on each cell outside 2x
(:mod:`svgs_sim.studies.mechanisms`).

Reads a campaign run with ``--budget`` (``DIR/results.csv``, ``DIR/manifest.json``) and prints
Markdown (``--json``: the rows). By default the cells are every std cell outside 2x; ``--cells``
names others (``RANGE:COMPONENT``, e.g. ``6.5:x_m``).

Usage::

    python tools/mechanism_shares.py docs/reports/campaign-galaxy-nexus [--cells 20:pitch_deg ...]
        [--resamples 200] [--seed 0] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from svgs_sim.base.profiles import load_camera  # noqa: E402
from svgs_sim.studies.mechanisms import RESAMPLES, SEED, cell_mechanisms, mechanisms_markdown  # noqa: E402
from svgs_sim.studies.store import read_table  # noqa: E402
from svgs_sim.svgs.frames import STATE_KEYS  # noqa: E402


def _cell(text: str):
    r, _, c = text.partition(":")
    if c not in STATE_KEYS:
        raise argparse.ArgumentTypeError(f"--cells: {text!r}: expected RANGE:COMPONENT, COMPONENT one of {', '.join(STATE_KEYS)}")
    try:
        return float(r), c
    except ValueError:
        raise argparse.ArgumentTypeError(f"--cells: {text!r}: the range {r!r} is not a number") from None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", help="a campaign run with --budget (its results.csv and manifest.json)")
    ap.add_argument("--cells", nargs="+", type=_cell, help="RANGE:COMPONENT (default: every std cell outside 2x)")
    ap.add_argument("--resamples", type=int, default=RESAMPLES)
    ap.add_argument("--seed", type=int, default=SEED)
    ap.add_argument("--json", action="store_true", help="print the rows as JSON")
    a = ap.parse_args(argv)
    d = Path(a.dir)
    if not (d / "results.csv").is_file() or not (d / "manifest.json").is_file():
        print(f"{d}: not a campaign folder (results.csv, manifest.json)", file=sys.stderr)
        return 2
    camera = load_camera(json.loads((d / "manifest.json").read_text())["parameters"]["camera"]).key
    rows = cell_mechanisms(read_table(d / "results.csv"), camera, cells=a.cells, resamples=a.resamples, seed=a.seed)
    print(json.dumps(rows, indent=1) if a.json else mechanisms_markdown(rows, camera), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
