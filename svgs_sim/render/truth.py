"""Ground-truth records of rendered frames (JSON-serialisable)."""

from __future__ import annotations

import numpy as np

from svgs_sim.assets import package_relative
from svgs_sim.svgs.frames import pose_to_state, state_dict

from .predict import retro_factor, retro_irradiance_w_m2


def svgs_frame_truth(r, R, t, targets_px, visible, spots, **render_info) -> dict:
    """The truth record of one frame of a :class:`svgs_sim.render.api.Renderer`.

    Parameters
    ----------
    r : svgs_sim.render.api.Renderer
    R : ndarray, shape (3, 3)
    t : ndarray, shape (3,)
        ``R_cam_target``, ``t_cam_target_m``.
    targets_px : ndarray, shape (N, 2)
        Projected target reference points.
    visible : ndarray of bool, shape (N,)
    spots : ndarray, shape (N, 2)
        Predicted spot centres, px.
    **render_info
        ``seed``, ``spp``, ``roi_spp``, ``full_frame``, ``rois``, ``timings``, ``strategies``.

    Returns
    -------
    dict
    """
    cam, pat, fl, op = r.camera, r.pattern, r.flash, r.optics
    V_ref = pat.points_m @ R.T + t
    intens, irr = _flash_at_targets(r, V_ref)
    ph = fl.photometry["mean_photon_energy_j"]
    return {
        "camera": cam.name,
        "camera_source": package_relative(cam.source),
        "pattern": pat.name,
        "R_cam_target": np.asarray(R).tolist(),
        "t_cam_target_m": np.asarray(t).tolist(),
        "state": state_dict(pose_to_state(R, t)),
        "range_m": float(t[2]),
        "targets_px": {str(i): [float(u), float(v)] for i, (u, v) in zip(pat.ids, targets_px)},
        "targets_in_image": {str(i): bool(b) for i, b in zip(pat.ids, visible)},
        "spots_px_predicted": {str(i): [float(u), float(v)] for i, (u, v) in zip(pat.ids, spots)},
        "intrinsics": {"width": cam.width, "height": cam.height, "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy},
        "distortion": {k: float(v) for k, v in zip(("k1", "k2", "p1", "p2", "k3"), cam.dist)},
        "optics": op.to_json(),
        "flash": fl.to_json(),
        "reflector": r.reflector.to_json(op.band_nm),
        "scene": r.options.to_json(),
        "geometry": r.target.info,
        "radiometry": {
            "flux_unit": "photons per second per pixel, in optics.band_nm",
            "radiance_unit": "W m^-2 sr^-1 in band (rendered)",
            "chain": "flux = L * aperture_area_m2 * cos(theta)^4 / (fx * fy * |det J_distortion|) / mean_photon_energy_j",
            "aperture_area_m2": op.aperture_area_m2,
            "mean_photon_energy_j": ph,
            "led_radiance_w_m2_sr": fl.radiance_w_m2_sr,
            "flash_intensity_towards_target_w_sr": intens,
            "retro_factor": retro_factor(r.reflector, op.band_nm),
            "retro_irradiance_at_lens_predicted_w_m2": irr,
            "retro_photons_per_s_predicted": {k: v * op.aperture_area_m2 / ph for k, v in irr.items()},
        },
        "render": _render_record(r, render_info),
    }


def _flash_at_targets(r, V_ref) -> tuple[dict, dict]:
    """The flash's intensity towards each target and the retro-reflected irradiance at the lens.

    Parameters
    ----------
    r : svgs_sim.render.api.Renderer
    V_ref : ndarray, shape (N, 3)
        The targets' reference points in the camera frame, m.

    Returns
    -------
    intensity_w_sr : dict
        Target id (str) -> the LEDs' summed intensity towards it, W/sr.
    irradiance_w_m2 : dict
        Target id (str) -> predicted retro-reflected irradiance at the lens, W/m^2 in band.
    """
    pat, fl, op = r.pattern, r.flash, r.optics
    intens, irr = {}, {}
    for i, tid in enumerate(pat.ids):
        I_tot, E_tot = 0.0, 0.0
        for S in fl.led_offsets_m:
            d = V_ref[i] - S
            I = float(fl.intensity_w_sr(d[2] / np.linalg.norm(d)))
            I_tot += I
            E_tot += retro_irradiance_w_m2(I, S, V_ref[i], r.reflector, op.band_nm)
        intens[str(tid)] = I_tot
        irr[str(tid)] = E_tot
    return intens, irr


def _render_record(r, render_info: dict) -> dict:
    """The ``render`` section of the truth record: how the frame was rendered.

    Parameters
    ----------
    r : svgs_sim.render.api.Renderer
    render_info : dict
        ``seed``, ``spp``, ``roi_spp``, ``full_frame``, ``rois``, ``timings``, ``strategies``.

    Returns
    -------
    dict
    """
    import drjit as dr
    import mitsuba as mi

    return {
        "variant": r.variant.name,
        "variant_notice": r.variant.notice,
        "variant_requested": r.variant.requested,  # the argument or SVGS_MI_VARIANT; None: automatic
        "method": r.method,
        "integrator": "path" + (" (diffuse, LED as point light) + guided spot estimator" if r.method == "guided" else " (LED as disk area emitter)"),
        "spot_samples_per_strategy": r.spot_samples if r.method == "guided" else None,
        "spot_sampler": r.spot_sampler if r.method == "guided" else None,
        "spot_strategies": render_info.get("strategies", []),
        "max_depth": int(r.options.max_depth),
        "sampler": "ldsampler",
        "seed": render_info["seed"],
        "spp": render_info["spp"],
        "roi_spp": None if render_info["full_frame"] else render_info["roi_spp"],
        "roi_size_px": None if render_info["full_frame"] else r.roi_size_px,
        "full_frame": render_info["full_frame"],
        "rois": render_info["rois"],
        "timings_s": render_info["timings"],
        "versions": {"mitsuba": mi.__version__, "drjit": dr.__version__, "numpy": np.__version__},
    }
