"""Multi-frame stages: recursive temporal median of depth, persistence counter (paper 3.1.2, 3.4).

Recursive temporal median (paper section 3.1.2)
    ``D^_k = median(D^_{k-1}, D_{k-1}, D_k)`` per pixel: the previous *output*, the previous
    and the current input. ASSUMPTION: the paper's window is not legible; this causal
    three-sample form removes single-frame outliers (flying pixels, noise spikes) and follows
    a moving target with a one-frame lag, where ``median(D^_{k-2}, D^_{k-1}, D_k)`` would
    lock on a ramp. Invalid (NaN) samples are ignored; the first frame passes through.

Persistence counter (paper section 3.4)
    The counter image counts, over the last ``window`` frames, how often each pixel belonged
    to a candidate blob; pixels counted at least ``min_count`` times are kept, and their gray
    and depth are the sums over those frames divided by the counter (the mean intensity and
    depth images). ``window = 1`` is the single-frame pipeline.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from svgs_sim.base.errors import InputError


def median3(a, b, c) -> np.ndarray:
    """Element-wise median of three arrays; NaNs are ignored (median of the others)."""
    lo = np.fmin(a, b)
    hi = np.fmax(a, b)
    return np.fmax(lo, np.fmin(hi, c))


class RecursiveMedianDepth:
    """Recursive temporal median filter of depth images.

    Examples
    --------
    >>> f = RecursiveMedianDepth()
    >>> out = [f.update(d) for d in depth_frames]  # doctest: +SKIP
    """

    def __init__(self):
        self.prev_out = None
        self.prev_in = None

    def reset(self) -> None:
        self.prev_out = None
        self.prev_in = None

    def update(self, depth_m) -> np.ndarray:
        """Filter one depth frame, shape (H, W) -> (H, W) float32."""
        d = np.asarray(depth_m, np.float32)
        if self.prev_out is None or self.prev_out.shape != d.shape:
            out = d.copy()
        else:
            out = median3(self.prev_out, self.prev_in, d)
        self.prev_out, self.prev_in = out, d
        return out


class PersistenceCounter:
    """Counter image over the last ``window`` frames and the mean gray / depth images.

    Parameters
    ----------
    window : int
        Frames remembered (1 = single-frame pipeline).
    min_count : int
        Pixels counted fewer times are dropped; capped at the number of frames seen, so the
        first frames of a sequence are not lost.
    """

    def __init__(self, window: int = 1, min_count: int = 1):
        if int(window) < 1 or int(min_count) < 1 or int(min_count) > int(window):
            raise InputError(f"persistence: need 1 <= min_count <= window, got window={window!r}, min_count={min_count!r}")
        self.window = int(window)
        self.min_count = int(min_count)
        self.reset()

    def reset(self) -> None:
        self.frames = deque()
        self.count = None
        self.sum_gray = None
        self.sum_depth = None
        self.count_depth = None

    def update(self, mask, gray, depth_m) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Add one frame's blob mask; return the persistent pixels and mean images.

        Parameters
        ----------
        mask : ndarray of bool, shape (H, W)
            Pixels of this frame's candidate blobs.
        gray : ndarray, shape (H, W)
        depth_m : ndarray, shape (H, W)
            NaN where invalid.

        Returns
        -------
        keep : ndarray of bool, shape (H, W)
            Counter >= min(min_count, frames seen).
        mean_gray : ndarray of float32, shape (H, W)
            Sum of gray over the frames a pixel was in a blob / counter (0 elsewhere).
        mean_depth : ndarray of float32, shape (H, W)
            Same for valid depth samples (NaN where none).
        counter : ndarray of int16, shape (H, W)
        """
        m = np.asarray(mask, bool)
        g = np.where(m, np.asarray(gray, np.float32), 0).astype(np.float32)
        d = np.asarray(depth_m, np.float32)
        dv = m & np.isfinite(d)
        dd = np.where(dv, d, 0).astype(np.float32)
        if self.window == 1:
            with np.errstate(invalid="ignore"):
                return m, g, np.where(dv, d, np.nan).astype(np.float32), m.astype(np.int16)
        if self.count is None or self.count.shape != m.shape:
            self.reset()
            self.count = np.zeros(m.shape, np.int16)
            self.sum_gray = np.zeros(m.shape, np.float32)
            self.sum_depth = np.zeros(m.shape, np.float64)
            self.count_depth = np.zeros(m.shape, np.int16)
        self.frames.append((m, g, dd, dv))
        self.count += m
        self.sum_gray += g
        self.sum_depth += dd
        self.count_depth += dv
        if len(self.frames) > self.window:
            om, og, od, ov = self.frames.popleft()
            self.count -= om
            self.sum_gray -= og
            self.sum_depth -= od
            self.count_depth -= ov
        need = min(self.min_count, len(self.frames))
        keep = self.count >= need
        with np.errstate(invalid="ignore", divide="ignore"):
            mg = np.where(keep, self.sum_gray / np.maximum(self.count, 1), 0).astype(np.float32)
            md = np.where(keep & (self.count_depth > 0), self.sum_depth / np.maximum(self.count_depth, 1), np.nan)
        return keep, mg, md.astype(np.float32), self.count.copy()
