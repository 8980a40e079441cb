"""Build the Mitsuba scene: target meshes at the world origin, the flash LED(s) as disk
area emitters at their real offset from the lens, and the OpenCV thin-lens sensor(s).

The world frame is the target frame. Between frames of a sweep only the camera pose
(opaque sensor arrays) and the LED disks' ``to_world`` change, updated in place through
``mi.traverse``; the target geometry is built once. Only importable after
:func:`svgs_sim.render.variant.select_variant`.
"""

from __future__ import annotations

import numpy as np

from .geometry import Reflector, SceneOptions, TargetGeometry, build_target
from .body_mesh import body_meshes
from .materials import PREFIX, bsdf_dict
from .optics import Flash, Optics
from .sensor import PLUGIN_NAME, sensor_class
from .sun import sun_disk_to_world

#: The background pass renders only square tiles covering the projected scene (outside
#: it the radiance is exactly 0): sensors with these tile counts exist, each a fixed
#: film (so each kernel compiles once); unused tile slots repeat the last tile.
TILE_SIZE_PX = 64
TILE_COUNTS = (1, 4, 16, 64, 256)


def _mesh(spec, bsdf):
    """A Mitsuba mesh from a :class:`MeshSpec`.

    Vertices are not shared between triangles, and each vertex carries its triangle's
    normal computed in float64: the shading normal (what mirrors and glass reflect
    about) is then exact to float32 rounding of a unit vector (~6e-8 rad), whereas the
    geometric normal of a thin float32 triangle 0.14 m from the origin can be off by
    ~1e-4 rad - enough to move a retro image by a pixel. Flat per-face normals, never
    interpolated across faces (physics.md section 2, pitfall 1).
    """
    import mitsuba as mi

    v = np.ascontiguousarray(spec.vertices_m, dtype=np.float64)
    f = np.ascontiguousarray(spec.faces, dtype=np.uint32)
    if len(np.unique(f)) != f.size:
        raise ValueError(f"mesh {spec.name}: vertices must not be shared between triangles")
    n_face = spec.face_normals()
    n_vert = np.zeros_like(v)
    n_vert[f.reshape(-1)] = np.repeat(n_face, 3, axis=0)
    m = mi.Mesh(spec.name, v.shape[0], f.shape[0], has_vertex_normals=True)
    params = mi.traverse(m)
    # float64 -> float32 happens once, here (the world-frame values are < 1 m)
    params["vertex_positions"] = type(params["vertex_positions"])(v.reshape(-1).astype(np.float32))
    params["vertex_normals"] = type(params["vertex_normals"])(n_vert.reshape(-1).astype(np.float32))
    params["faces"] = type(params["faces"])(f.reshape(-1))
    params.update()
    m.set_bsdf(bsdf)
    return m


def materials(refl: Reflector, opts: SceneOptions, band_nm) -> dict:
    """Scene dict entries of the BSDFs, keyed by :class:`svgs_sim.render.geometry.MeshSpec` material."""
    import mitsuba as mi

    return {
        "glass": mi.load_dict({"type": "dielectric", "int_ior": refl.index(band_nm), "ext_ior": 1.0}),
        "mirror": mi.load_dict({"type": "conductor", "material": "none",
                                "specular_reflectance": {"type": "uniform", "value": refl.mirror_reflectance}}),
        "black": mi.load_dict({"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}}),
        "mount": mi.load_dict({"type": "diffuse", "reflectance": {"type": "uniform", "value": refl.mount_reflectance}}),
        "body": mi.load_dict({"type": "diffuse", "reflectance": {"type": "uniform", "value": opts.body_reflectance}}),
    }


def film_dict(width: int, height: int) -> dict:
    import mitsuba as mi

    return {
        "type": "hdrfilm", "width": int(width), "height": int(height),
        "rfilter": {"type": "box"},  # a sample counts in its own pixel only
        "pixel_format": "luminance" if mi.is_monochromatic else "rgb",
        "component_format": "float32",
        "sample_border": False,
    }


def build_scene(camera, pattern, optics: Optics, flash: Flash, refl: Reflector, opts: SceneOptions,
                roi_size_px: int, n_windows: int, extra_meshes=(), method: str = "guided", sun=None, earth=None):
    """Load the scene.

    Parameters
    ----------
    camera : svgs.Camera
    pattern : svgs.Pattern
    optics, flash, refl, opts
        See :mod:`svgs_sim.render.optics` and :mod:`svgs_sim.render.geometry`.
    roi_size_px : int
        Side of the (square) windows; the ROI sensor's film is ``roi x (n_windows*roi)``.
    n_windows : int
        Number of windows rendered in one ROI pass.
    extra_meshes : sequence of MeshSpec
        Added to the target (tests use it).
    method : {"guided", "path"}
        ``"guided"``: LEDs as point lights for the diffuse part, spots by
        :mod:`svgs_sim.render.spots`; ``"path"``: LEDs as disk area emitters, everything by the
        ``path`` integrator (brute force, the reference).
    sun : (direction, radiance_w_m2_sr) or None
        The sun's scene instead of the flash's: no LED, the sun as a disk area emitter
        (:func:`svgs_sim.render.sun.sun_disk_to_world`) of this band radiance, everything by the
        ``path`` integrator (the sun's disk is far wider than a pixel's footprint, so camera
        paths find it through mirrors and glass). ``direction`` None: the sun hidden (eclipse),
        the pass lit by the Earth alone.
    earth : (radiance, to_world) or None
        With ``sun``: the Earth as an ``envmap`` emitter (:func:`svgs_sim.render.earth.earth_map`:
        a float32 (rows, 2 rows) band radiance map and its 4x4 ``to_world``).

    Returns
    -------
    scene : mi.Scene
    handles : dict
        ``sensor_full``, ``sensor_roi`` (sensor objects), ``target`` (TargetGeometry),
        ``flash_keys`` (per LED, traversal keys of its transform or position/intensity), ``params``.
    """
    import mitsuba as mi

    cls = sensor_class()
    target: TargetGeometry = build_target(pattern, refl, opts, optics.band_nm)
    mats = materials(refl, opts, optics.band_nm)
    d = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(opts.max_depth), "rr_depth": int(opts.max_depth) + 1,
                       "hide_emitters": False},
        "sensor_full": {"type": PLUGIN_NAME, "svgs_role": "full", "film": film_dict(camera.width, camera.height),
                        "sampler": {"type": "ldsampler", "sample_count": 4}},
        "sensor_roi": {"type": PLUGIN_NAME, "svgs_role": "roi", "film": film_dict(roi_size_px, roi_size_px * n_windows),
                       "sampler": {"type": "ldsampler", "sample_count": 64}},
    }
    for n in TILE_COUNTS:
        d[f"sensor_tiles{n}"] = {"type": PLUGIN_NAME, "svgs_role": f"tiles{n}", "film": film_dict(TILE_SIZE_PX, TILE_SIZE_PX * n),
                                 "sampler": {"type": "ldsampler", "sample_count": 4}}
    body = body_meshes(opts.body, opts.body_material, dict(opts.body_materials)) if opts.mesh_body else []
    if body:
        target.info.update(body_file_sha1=opts.body_file_sha1, body_parts=[m.material for m in body])
    for spec in list(target.meshes) + body + list(extra_meshes):
        if spec.material not in mats:  # a library surface (svgs_sim.render.materials): a mesh body's part
            mats[spec.material] = mi.load_dict(bsdf_dict(spec.material.removeprefix(PREFIX)))
        d[spec.name] = _mesh(spec, mats[spec.material])
    flash_keys = []
    r_led = 0.5 * flash.emitter_diameter_m
    if earth is not None:
        emap, to_world = earth
        d["earth"] = {"type": "envmap", "bitmap": mi.Bitmap(np.repeat(np.asarray(emap, np.float32)[..., None], 3, -1)),
                      "to_world": mi.ScalarTransform4f(np.asarray(to_world, float).tolist())}
    if sun is not None and sun[0] is not None:
        direction, radiance = sun
        d["sun"] = {"type": "disk", "to_world": mi.ScalarTransform4f(sun_disk_to_world(direction).tolist()),
                    "emitter": {"type": "area", "radiance": {"type": "uniform", "value": float(radiance)}},
                    "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}}}
    for i in range(0 if sun is not None else flash.led_offsets_m.shape[0]):
        key = f"flash{i}"
        if method == "path":
            # brute force: the LED as a Lambertian disk area emitter of its real size
            d[key] = {
                "type": "disk",
                "to_world": mi.ScalarTransform4f().scale([r_led, r_led, 1.0]),
                "emitter": {"type": "area", "radiance": {"type": "uniform", "value": flash.radiance_w_m2_sr}},
                "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}},
            }
            flash_keys.append({"to_world": f"{key}.to_world", "radiance": f"{key}.emitter.radiance.value"})
        else:
            # guided: diffuse lighting from a point light (NEE only, never hit by rays); the
            # LED seen through glass/mirrors is the job of svgs_sim.render.spots
            d[key] = {"type": "point", "position": [0.0, 0.0, 0.0],
                      "intensity": {"type": "uniform", "value": flash.radiant_intensity_w_sr}}
            flash_keys.append({"position": f"{key}.position", "intensity": f"{key}.intensity.value"})
    for i, dd in enumerate(opts.distractors):
        to_world = mi.ScalarTransform4f().translate(dd["position_m"]).scale(dd["radius_m"])
        if dd["type"] == "glint":
            d[f"distractor{i}"] = {"type": "sphere", "to_world": to_world,
                                   "bsdf": {"type": "conductor", "material": "none",
                                            "specular_reflectance": {"type": "uniform", "value": dd["reflectance"]}}}
        elif sun is not None:  # a lamp glows in the flash's pass only (its radiance is counted there); here it is black
            d[f"distractor{i}"] = {"type": "sphere", "to_world": to_world,
                                   "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}}}
        else:
            d[f"distractor{i}"] = {"type": "sphere", "to_world": to_world,
                                   "emitter": {"type": "area", "radiance": {"type": "uniform", "value": dd["radiance_w_m2_sr"]}},
                                   "bsdf": {"type": "diffuse", "reflectance": {"type": "uniform", "value": 0.0}}}
    scene = mi.load_dict(d)
    roles = {getattr(s, "role", ""): s for s in scene.sensors()}
    s_full, s_roi = roles.get("full"), roles.get("roi")
    tiles = {n: roles[f"tiles{n}"] for n in TILE_COUNTS}
    for s in (s_full, s_roi):
        if not isinstance(s, cls):
            raise RuntimeError("the custom sensor plugin was not instantiated as a Python object")
    return scene, {"sensor_full": s_full, "sensor_roi": s_roi, "sensor_tiles": tiles, "target": target, "flash_keys": flash_keys,
                   "params": mi.traverse(scene)}
