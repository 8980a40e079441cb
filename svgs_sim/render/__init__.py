"""The renderer: Mitsuba 3 scenes of corner-cube targets under a phone's flash.

Importing :mod:`render` does not import mitsuba or drjit (the CLI must stay light and
the LLVM library must be chosen first, see :mod:`svgs_sim.render.variant`); the public names
below are loaded on first use.

Public API
----------
select_variant(prefer=None) -> VariantInfo
render_flux(camera, pattern, R_cam_target, t_cam_target_m, ...) -> RenderResult
Renderer(camera, pattern, ...).render(R, t, seed=...) -> RenderResult
"""

from __future__ import annotations

from .variant import VariantInfo, select_variant

__all__ = ["select_variant", "VariantInfo", "render_flux", "Renderer", "RenderResult", "Reflector", "SceneOptions"]


def __getattr__(name):
    if name in ("render_flux", "Renderer", "RenderResult"):
        from . import api

        return getattr(api, name)
    if name in ("Reflector", "SceneOptions"):
        from . import geometry

        return getattr(geometry, name)
    raise AttributeError(f"module 'render' has no attribute {name!r}")
