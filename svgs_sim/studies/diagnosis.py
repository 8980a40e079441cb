"""Why an error is far above its Cramer-Rao bound: one line for a report.

The CRLB holds noise only (shot, read, quantisation). An error many times wider is a bias, and
the simulator can tell one bias apart: the **head-on glint**. Within a small angle of exact facing
the uncoated front face of a solid corner cube reflects the flash straight back into the lens, on
top of the cube's retro spot, and moves that spot's centroid against the other three
(``examples/head_on_glint.py``, ``docs/approach.md``, ``docs/renderer.md``). Whether it does at a
pose is the renderer's own geometric test (:func:`svgs_sim.render.predict.virtual_sources`: the line from
the flash's mirror image in the front face to the lens crosses the face). Any other error far
above the bound is a bias the bound does not hold (the spots' centroid bias, or a calibration
error); which one, the code cannot tell, and the line says so.

numpy only (no Mitsuba): the renderer's geometry is evaluated without building a scene.
"""

from __future__ import annotations

import math

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_pattern
from svgs_sim.render.geometry import Reflector, SceneOptions, build_target
from svgs_sim.render.optics import Flash, Optics
from svgs_sim.render.predict import virtual_sources
from svgs_sim.svgs.frames import STATE_KEYS, state_to_pose

#: An error this many times its 1-sigma CRLB or more is "far above its bound" (noise reaches
#: 10 sigma with probability ~1e-23: it is a bias).
FAR_ABOVE_BOUND = 10.0
#: Where the head-on glint is shown and explained.
GLINT_REFERENCE = "examples/head_on_glint.py, docs/approach.md"


def glint_geometry(camera, pattern) -> tuple:
    """What :func:`front_glint_targets` builds for a camera and pattern before it looks at a pose.

    Built once, it serves every pose of a run (building the target's meshes takes about 0.1-0.4 s).

    Parameters
    ----------
    camera : svgs.Camera
        A profile with ``[optics]`` and ``[flash]``.
    pattern : svgs.Pattern or str

    Returns
    -------
    tuple
        ``(pattern, optics, flash, reflector, target)``: the loaded pattern, its
        :class:`~svgs_sim.render.optics.Optics` and :class:`~svgs_sim.render.optics.Flash` under the
        camera, the pattern's reflector and the built target geometry.
    """
    pat = load_pattern(pattern)
    optics = Optics.from_camera(camera)
    flash = Flash.from_camera(camera, optics.band_nm)
    refl = Reflector.resolve(None, pat)
    return pat, optics, flash, refl, build_target(pat, refl, SceneOptions.resolve(None), optics.band_nm)


def front_glint_targets(camera, pattern, R_cam_target, t_cam_target_m, *, geometry=None) -> tuple[str, ...]:
    """The targets whose cube's front-face glint reaches the lens at this pose.

    The renderer's own test (:func:`svgs_sim.render.predict.virtual_sources`, strategy ``front``) for the
    pattern's default reflector and target geometry (as :func:`svgs_sim.sim.closed_loop.render_scenario`
    renders them), under the camera's flash.

    Parameters
    ----------
    camera : svgs.Camera
        A profile with ``[optics]`` and ``[flash]``.
    pattern : svgs.Pattern or str
    R_cam_target : array_like, shape (3, 3)
    t_cam_target_m : array_like, shape (3,)
    geometry : tuple, optional
        :func:`glint_geometry` of the same camera and pattern (built here when not given).

    Returns
    -------
    tuple of str
        Target ids (as the pattern numbers them), empty when no glint reaches the lens.
    """

    R = np.asarray(R_cam_target, float)
    t = np.asarray(t_cam_target_m, float)
    if R.shape != (3, 3) or t.shape != (3,):
        raise InputError(f"front_glint_targets: expected R (3, 3) and t (3,), got {R.shape} and {t.shape}")
    pat, optics, flash, refl, target = glint_geometry(camera, pattern) if geometry is None else geometry
    V = target.cube_vertex_m @ R.T + t
    A = target.cube_axis @ R.T
    _, _, active, labels = virtual_sources(camera, flash, refl, optics.band_nm, V, A)
    hit = set()
    for on, lab in zip(active, labels):
        cube, _, kind = lab.split(":")
        if on and kind == "front":
            hit.add(int(cube[len("cube"):]))
    return tuple(str(int(pat.ids[i])) for i in sorted(hit))


def glint_targets_of_truth(truth: dict, pattern) -> tuple[str, ...]:
    """The targets whose front-face glint the renderer sampled for a rendered frame.

    Parameters
    ----------
    truth : dict
        A frame's truth record (``truth.json``; its ``render.spot_strategies``).
    pattern : svgs.Pattern or str

    Returns
    -------
    tuple of str
        Target ids; empty when the record holds no front-face strategy.
    """

    ids = load_pattern(pattern).ids
    hit = set()
    for s in (truth.get("render") or {}).get("spot_strategies") or ():
        cube, _, kind = str(s.get("label", "::")).split(":")
        if kind == "front" and int(s.get("samples", 0)) > 0:
            hit.add(int(cube[len("cube"):]))
    return tuple(str(int(ids[i])) for i in sorted(hit))


def glint_targets_of_state(camera, pattern, state: dict, *, geometry=None) -> tuple[str, ...]:
    """:func:`front_glint_targets` at a paper state (``x_m`` ... ``yaw_deg``, :data:`STATE_KEYS`);
    ``geometry``: :func:`glint_geometry` of the camera and pattern, for many states."""
    v = [float(state[k]) for k in STATE_KEYS]
    R, t = state_to_pose(v[:3] + [math.radians(a) for a in v[3:]])
    return front_glint_targets(camera, pattern, R, t, geometry=geometry)


def bound_ratios(errors: dict, crlb: dict) -> dict:
    """``|error| / CRLB`` per state component where both are known and the bound is > 0.

    Parameters
    ----------
    errors, crlb : dict
        State key (:data:`STATE_KEYS`) -> error (estimate - truth) and 1-sigma CRLB, same units.

    Returns
    -------
    dict
        State key -> ratio (float).
    """
    out = {}
    for k in STATE_KEYS:
        e, b = (errors or {}).get(k), (crlb or {}).get(k)
        if e is None or b is None:
            continue
        e, b = float(e), float(b)
        if math.isfinite(e) and math.isfinite(b) and b > 0:
            out[k] = abs(e) / b
    return out


def far_above(ratios: dict, factor: float = FAR_ABOVE_BOUND) -> dict:
    """The components of ``ratios`` at or above ``factor``, largest first."""
    return dict(sorted(((k, r) for k, r in ratios.items() if r >= factor), key=lambda kv: -kv[1]))


def cause_text(glint_targets=(), *, glint: bool | None = None) -> str:
    """The likely why of an error far above its bound, from what the simulator knows.

    Parameters
    ----------
    glint_targets : sequence of str
        Targets whose front-face glint reaches the lens (named in the text).
    glint : bool, optional
        Whether a glint reaches the lens (default: ``glint_targets`` is not empty); True with no
        targets names none.
    """
    if glint is None:
        glint = bool(glint_targets)
    if glint:
        which = f"target {', '.join(glint_targets)}" if glint_targets else "a target"
        return (f"likely the head-on glint: the front face of {which} reflects the flash into the lens at this "
                f"attitude and moves its spot ({GLINT_REFERENCE})")
    return ("not the head-on glint (no front-face glint reaches the lens): a bias the CRLB does not hold "
            "(centroid or calibration)")


def bound_note(errors: dict, crlb: dict, glint_targets=(), factor: float = FAR_ABOVE_BOUND) -> str | None:
    """One line when an error is far above its bound, with its likely why; None when none is.

    Parameters
    ----------
    errors, crlb : dict
        State key -> error and 1-sigma CRLB (same units).
    glint_targets : sequence of str
        Targets whose front-face glint reaches the lens (:func:`front_glint_targets`).
    factor : float

    Returns
    -------
    str or None
    """
    big = far_above(bound_ratios(errors, crlb), factor)
    if not big:
        return None
    parts = ", ".join(f"{k} {r:.0f}x" for k, r in big.items())
    return f"error far above its bound (>= {factor:g}x the CRLB): {parts}; {cause_text(glint_targets)}"


__all__ = ["FAR_ABOVE_BOUND", "front_glint_targets", "glint_geometry", "glint_targets_of_truth", "glint_targets_of_state",
           "bound_ratios", "far_above", "cause_text", "bound_note"]
