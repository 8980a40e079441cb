"""The ToF camera of the second seed (Zhu et al. 2022) rendered with Mitsuba.

- :mod:`svgs_sim.render.tof.scene`: the marker target (black plate, eight white disks on posts) as
  Mitsuba geometry.
- :mod:`svgs_sim.render.tof.camera`: :class:`TofRenderer`, a custom wavefront integrator that turns
  per-sample optical path lengths into per-pixel AMCW phasors (flying pixels, multipath).

The pixel model that turns the rendered phasors into noisy frames (:class:`svgs_sim.camera.amcw.TofSensor`)
is numpy only and lives in :mod:`svgs_sim.camera.amcw`; the stability runs in :mod:`svgs_sim.sim.tof_stability`.

Importing this package does not import Mitsuba; the renderer's names load on first use.

>>> from svgs_sim.render.tof import TofRenderer                      # doctest: +SKIP
>>> from svgs_sim.camera.amcw import TofSensor                       # doctest: +SKIP
>>> r = TofRenderer("tof-epc660", "tof-8")                  # doctest: +SKIP
>>> rendered = r.render(R_cam_target, t_cam_target_m)        # doctest: +SKIP
>>> frame = TofSensor.from_camera(r.camera).frame(rendered, rng=1)   # doctest: +SKIP
>>> frame.gray, frame.depth_m                                # doctest: +SKIP
"""

from __future__ import annotations

__all__ = ["TofRenderer", "Illumination", "TofOptics", "TofSceneOptions", "render_tof"]


def __getattr__(name):
    if name in ("TofRenderer", "Illumination", "TofOptics", "render_tof"):
        from . import camera

        return getattr(camera, name)
    if name == "TofSceneOptions":
        from .scene import TofSceneOptions

        return TofSceneOptions
    raise AttributeError(f"module 'svgs_sim.render.tof' has no attribute {name!r}")
