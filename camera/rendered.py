"""What every renderer hands to a camera model: one result type for the SVGS and ToF renders.

A renderer (:mod:`render`, the only Mitsuba code) turns a pose into noise-free per-pixel
means - numpy arrays - plus a JSON-serialisable truth record; a camera model
(:mod:`camera.phone`, :mod:`camera.amcw`) then draws noisy frames from them (render once,
expose many). :class:`RenderedFrame` is the part both results share; the SVGS renderer's
:class:`render.api.RenderResult` and the ToF renderer's :class:`camera.amcw.RenderedTof` add
their own arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(kw_only=True)
class RenderedFrame:
    """Base of a rendered frame (keyword-only fields, after the subclass's own).

    Attributes
    ----------
    truth : dict
        Pose (``R_cam_target``, ``t_cam_target_m``, ``state``), projections and every
        physical and render parameter used (JSON-serialisable).
    timings_s : dict
        Wall-clock seconds of the render's stages.

    Subclasses provide ``flux`` (ndarray, shape (H, W)): photons per second reaching each
    pixel (noise-free expectation) of the light the renderer modelled.
    """

    truth: dict = field(default_factory=dict)
    timings_s: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple:
        """Frame shape (H, W)."""
        return tuple(np.shape(self.flux))

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """``(R_cam_target (3, 3), t_cam_target_m (3,))`` from the truth record."""
        return np.asarray(self.truth["R_cam_target"], float), np.asarray(self.truth["t_cam_target_m"], float)
