"""Crop the delivered images of several render-and-solve runs around the target and put
them side by side with labels (for reports).

Usage: python tools/montage.py OUT.png DIR1 [DIR2 ...]   (each DIR from `svgs render-and-solve --out`)
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np


def crop(d: Path, half: int = 120) -> np.ndarray:
    img = cv2.imread(str(d / "image.png"), cv2.IMREAD_GRAYSCALE)
    truth = json.loads((d / "truth.json").read_text())
    uv = np.array(list(truth["targets_px"].values()), float)
    sx = img.shape[1] / truth.get("camera", {}).get("width", img.shape[1]) if isinstance(truth.get("camera"), dict) else 1.0
    c = np.round(uv.mean(0) * sx).astype(int)
    pad = cv2.copyMakeBorder(img, half, half, half, half, cv2.BORDER_CONSTANT, value=0)
    out = pad[c[1]: c[1] + 2 * half, c[0]: c[0] + 2 * half]
    sol = json.loads((d / "solution.json").read_text())
    label = f"{truth['scenario']['range_m']:g} m: " + (f"solved, {sol['n_blobs']} blobs" if sol["ok"] else f"{sol['reason']}, {sol['n_blobs']} blobs")
    out = cv2.cvtColor(out, cv2.COLOR_GRAY2BGR)
    cv2.putText(out, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 200, 255), 1, cv2.LINE_AA)
    return out


if __name__ == "__main__":
    tiles = [crop(Path(p)) for p in sys.argv[2:]]
    cv2.imwrite(sys.argv[1], cv2.hconcat(tiles))
    print(f"wrote {sys.argv[1]}")
