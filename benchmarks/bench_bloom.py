"""Benchmark: the blooming spill (``svgs_sim.camera.phone.sensor.bloom``) on frames the sun fills.

The sun in an HTC Amaze 4G's field at its 66.7 ms auto-exposure puts ~6.6e13 e- above full well
on the frame, 18 times what the frame holds, plus a few hundred small saturated glints. The
spill's rings used to come from one dilation each, over the whole frame, for each saturated
region: one trial of the committed 3U sun study spent 4390 s there. They now come from a distance
transform and a stable sort (and a frame already full is recognised), with the same bits.

Peer, measured in the same run: the ring-by-ring definition (``bloom(..., rings="dilation")``,
the code before the change), on the same frames; the outputs are checked equal to the bit. Frames (synthetic, seeded; sizes scaled down so the peer finishes):

- ``sun``: a disk holding 18 frames' worth of excess charge plus ``--glints`` saturated glints;
- ``spots``: four flash spots and a few glints, no sun (an ordinary frame: what must not slow).

Run: ``.venv/bin/python benchmarks/bench_bloom.py [--height 1224 --width 1632 --glints 10]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FULL_WELL_E = 4500.0  # the Amaze profile's
DRAIN = 0.99


def make_frame(kind: str, height: int, width: int, glints: int, seed: int = 0) -> np.ndarray:
    """A synthetic electron frame, float32, shape (height, width)."""
    rng = np.random.default_rng(seed)
    e = rng.uniform(0, 0.5 * FULL_WELL_E, (height, width)).astype(np.float32)
    yy, xx = np.mgrid[:height, :width]
    if kind == "sun":
        r2 = (yy - height * 0.4) ** 2 + (xx - width * 0.3) ** 2
        disk = r2 < (0.06 * min(height, width)) ** 2
        e[disk] = 18 * height * width * FULL_WELL_E / (1 - DRAIN) / disk.sum()  # spill: 18 frames
    else:
        for cy, cx in ((0.3, 0.3), (0.3, 0.7), (0.7, 0.3), (0.7, 0.7)):
            r2 = (yy - cy * height) ** 2 + (xx - cx * width) ** 2
            e += (40 * FULL_WELL_E * np.exp(-r2 / 8.0)).astype(np.float32)
    for _ in range(glints):
        y, x = int(rng.integers(0, height)), int(rng.integers(0, width))
        e[y, x] += FULL_WELL_E * float(10 ** rng.uniform(0.1, 3))
    return e


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--height", type=int, default=1224, help="frame rows (default 1224: half the Amaze's 2448)")
    ap.add_argument("--width", type=int, default=1632, help="frame columns (default 1632: half its 3264)")
    ap.add_argument("--glints", type=int, default=10, help="saturated single-pixel glints (default 10)")
    args = ap.parse_args(argv)
    from svgs_sim.camera.phone.sensor import bloom

    print(f"bloom, {args.height} x {args.width} px, full well {FULL_WELL_E:g} e-, drain {DRAIN}")
    for kind in ("sun", "spots"):
        frame = make_frame(kind, args.height, args.width, args.glints)
        ours, peer = frame.copy(), frame.copy()
        bloom(frame.copy(), FULL_WELL_E, DRAIN)  # warm
        t0 = time.perf_counter()
        st = bloom(ours, FULL_WELL_E, DRAIN)
        t_ours = time.perf_counter() - t0
        t0 = time.perf_counter()
        st_peer = bloom(peer, FULL_WELL_E, DRAIN, rings="dilation")
        t_peer = time.perf_counter() - t0
        same = bool(np.array_equal(ours, peer)) and st == st_peer
        print(f"  {kind:5s}: {st['regions']} regions; ours {t_ours * 1e3:.1f} ms, ring-by-ring peer "
              f"{t_peer * 1e3:.1f} ms, ratio {t_peer / t_ours:.1f}x; same bits: {same}")
        if not same:
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
