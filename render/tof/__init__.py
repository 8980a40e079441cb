"""The ToF camera of the second seed (Zhu et al. 2022) rendered with Mitsuba.

- :mod:`render.tof.scene`: the marker target (black plate, eight white disks on posts) as
  Mitsuba geometry.
- :mod:`render.tof.camera`: :class:`TofRenderer`, a custom wavefront integrator that turns
  per-sample optical path lengths into per-pixel AMCW phasors (flying pixels, multipath).
- :mod:`render.tof.taps`: :class:`TofSensor`, the 4-tap pixel with shot/read/ambient noise,
  amplitude (gray), depth and passive gray images; numpy only.
- :mod:`render.tof.cli`: ``svgs tof render-and-solve``.
- :mod:`render.tof.stability`: the paper's stability runs re-enacted (``docs/reports/``).

Importing this package does not import Mitsuba; the renderer's names load on first use.

>>> from render.tof import TofRenderer, TofSensor           # doctest: +SKIP
>>> r = TofRenderer("tof-epc660", "tof-8", spp=64)          # doctest: +SKIP
>>> rendered = r.render(R_cam_target, t_cam_target_m)        # doctest: +SKIP
>>> frame = TofSensor.from_camera(r.camera).frame(rendered, rng=1)   # doctest: +SKIP
>>> frame.gray, frame.depth_m                                # doctest: +SKIP
"""

from __future__ import annotations

from .taps import RenderedTof, TofFrame, TofSensor, phase_noise_rad, phasor_depth_m, unambiguous_range_m

__all__ = ["TofRenderer", "Illumination", "TofOptics", "TofSceneOptions", "render_tof", "RenderedTof", "TofFrame",
           "TofSensor", "phase_noise_rad", "phasor_depth_m", "unambiguous_range_m"]


def __getattr__(name):
    if name in ("TofRenderer", "Illumination", "TofOptics", "render_tof"):
        from . import camera

        return getattr(camera, name)
    if name == "TofSceneOptions":
        from .scene import TofSceneOptions

        return TofSceneOptions
    raise AttributeError(f"module 'render.tof' has no attribute {name!r}")
