"""The paper's calibration practice, simulated: the focal length from images at known ranges (the
hand-held rangefinder's readings), the principal point and distortion as the paper assumed them
(image centre, none) against the true lens drawn from ASSUMED spreads."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.calibration.focal import estimate_focal
from svgs_sim.sim.lab import lab_errors
from svgs_sim.studies.calibration.focal import focal_frames_rendered
from svgs_sim.svgs.frames import pose_from_scenario

from ..seeding import study_rng

if TYPE_CHECKING:
    from .design import CampaignConfig


#: ASSUMED 1-sigma differences between the paper's assumed camera (principal point at the image
#: centre, no distortion) and the real lens. Not sourced: typical of phone cameras of 2011
#: (principal points within ~1 % of the width of the centre, mild barrel distortion).
PAPER_CALIBRATION_SPREAD = {"pp_error_u_px": 15.0, "pp_error_v_px": 15.0, "k1_error": 0.03}


CALIBRATION_KEYS = ("focal_error_frac", "pp_error_u_px", "pp_error_v_px", "k1_error")


def paper_calibration_error(camera, pattern, ranges_m, sigma_px: float, seed: int,
                            range_sigma_m: float | None = None) -> dict:
    """One calibration as the paper made it, simulated (seeded, once per campaign).

    Focal length: the paper's procedure - one image of the target facing the camera at each
    test range, the range measured with a hand-held laser range finder (1-sigma
    ``range_sigma_m``, default :func:`svgs_sim.sim.lab.lab_errors`' ``rangefinder_sigma_m``; the paper leaves it blank), the focal
    length fitted to the spot spacings (:func:`svgs_sim.calibration.focal.estimate_focal`) from
    centroids with ``sigma_px`` noise. Principal point and k1: the paper assumed the image
    centre and no distortion; the real lens differs by draws from
    :data:`PAPER_CALIBRATION_SPREAD` (ASSUMED spreads).

    Returns
    -------
    dict
        ``focal_error_frac``, ``pp_error_u_px``, ``pp_error_v_px``, ``k1_error``.
    """


    if range_sigma_m is None:

        range_sigma_m = lab_errors()["rangefinder_sigma_m"]
    pat = load_pattern(pattern)
    rng = study_rng(seed, 0)
    images, measured = [], []
    for r in ranges_m:
        R, t = pose_from_scenario(r)
        uv = camera.project_target(pat.points_m, R, t)
        images.append(uv + sigma_px * rng.standard_normal(uv.shape))
        measured.append(r + range_sigma_m * rng.standard_normal())
    est = estimate_focal(images, measured, camera, pat, centroid_sigma_px=max(sigma_px, 1e-3),
                         range_sigma_m=max(range_sigma_m, 1e-4))
    err = {"focal_error_frac": float(est.f_px / camera.fx - 1.0)}
    for k in ("pp_error_u_px", "pp_error_v_px", "k1_error"):
        err[k] = float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD[k]))
    return err


def paper_lens(seed: int) -> dict:
    """The true lens of a campaign with the paper's calibration practice: how its principal point
    and radial distortion differ from what the paper assumed (image centre, no distortion),
    drawn once per campaign from :data:`PAPER_CALIBRATION_SPREAD` (ASSUMED spreads).

    Returns
    -------
    dict
        ``lens_pp_u_px``, ``lens_pp_v_px`` (px), ``lens_k1``.
    """
    rng = study_rng(seed, 1)
    return {"lens_pp_u_px": float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD["pp_error_u_px"])),
            "lens_pp_v_px": float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD["pp_error_v_px"])),
            "lens_k1": float(rng.normal(0.0, PAPER_CALIBRATION_SPREAD["k1_error"]))}


def rangefinder_readings(config: CampaignConfig) -> list[float]:
    """The ranges the lab recorded with its hand-held rangefinder, one per test range (the rail
    positions' truth and the paper's focal calibration; 1-sigma the lab's
    ``rangefinder_sigma_m``, seeded: ``study_rng(seed, 2)``)."""
    rng = study_rng(config.seed, 2)
    sig = config.lab_error("rangefinder_sigma_m")
    return [float(r + sig * rng.standard_normal()) for r in config.ranges_m]


#: The file of a campaign folder that keeps the rendered calibration (:func:`rendered_paper_calibration`).
CALIBRATION_FILE = "calibration.json"


def _calibration_key(config: CampaignConfig) -> dict:
    """What decides the rendered calibration (a kept one is reused only for the same)."""
    return {"camera": config.camera, "pattern": config.pattern, "ranges_m": list(config.ranges_m),
            "seed": config.seed, "lens": config.lens, "range_sigma_m": config.lab_error("rangefinder_sigma_m")}


def save_paper_calibration(config: CampaignConfig, out_dir) -> bool:
    """Keep ``config``'s rendered calibration in ``out_dir/calibration.json`` for a rerun (unless
    it holds this one already: the file is then left as it is).

    Returns
    -------
    bool
        Whether the file was written.
    """

    if not config.calibration_info:
        return False
    path = Path(out_dir) / CALIBRATION_FILE
    text = json.dumps({"key": _calibration_key(config), "result": config.calibration_info}, indent=1, default=float)
    try:
        if path.read_text() == text:
            return False
    except (OSError, UnicodeDecodeError):
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return True


def rendered_paper_calibration(config: CampaignConfig, out_dir=None, progress=None, *,
                               save: bool = True) -> CampaignConfig:
    """The paper's focal-length calibration simulated on rendered frames; returns the config
    with the solver's ``focal_error_frac`` set (and ``calibration_info``).

    One image of the target facing the phone at each of the campaign's ranges, through the
    true lens (:attr:`CampaignConfig.lens`), exposed as the phone does; the spots detected and
    identified with the assumed camera (image centre, no distortion); each range as a
    hand-held laser range finder gives it (:func:`rangefinder_readings`, the readings that are also the
    rail positions' truth);
    :func:`svgs_sim.calibration.focal.estimate_focal` on those. Kept in ``out_dir/calibration.json``
    (a rerun reuses it when the campaign's configuration is the same); with ``save=False`` it is
    only read from there, and :func:`save_paper_calibration` keeps a new one once the campaign's
    store has taken it (:func:`svgs_sim.studies.campaign.run_campaign`: a refused run writes nothing).
    """


    if config.trial_kind != "render" or config.calibration != "paper":
        return config
    sig = config.lab_error("rangefinder_sigma_m")
    key = _calibration_key(config)
    path = Path(out_dir) / CALIBRATION_FILE if out_dir is not None else None
    info = None
    if path is not None and path.is_file():
        try:
            saved = json.loads(path.read_text())
            info = saved["result"] if saved.get("key") == key else None
        except (ValueError, KeyError, TypeError):
            info = None
    if info is None:
        cam, pat = load_camera(config.camera), load_pattern(config.pattern)
        lens = config.lens
        true = cam.replace(name=f"{cam.name}-true-lens", cx=cam.cx + lens["lens_pp_u_px"], cy=cam.cy + lens["lens_pp_v_px"],
                           dist=cam.dist + np.array([lens["lens_k1"], 0.0, 0.0, 0.0, 0.0]))
        frames = focal_frames_rendered(true, cam, pat, config.ranges_m, exposures=1, seed=config.seed,
                                       progress=progress)
        measured = rangefinder_readings(config)
        imgs, rngs, used = [], [], []
        for k, r in enumerate(config.ranges_m):
            c = frames.centroids_px[k, 0]
            if np.all(np.isfinite(c)):
                imgs.append(c)
                rngs.append(measured[k])
                used.append(float(r))
        if not imgs:
            raise InputError("calibration: no rendered calibration frame had its four targets identified "
                             f"({frames.info}); the paper's focal-length method needs at least one")
        est = estimate_focal(imgs, rngs, cam, pat, range_sigma_m=max(sig, 1e-4))
        info = {"f_px": float(est.f_px), "f_sigma_px": float(est.sigma_f_px),
                "f_true_px": float(cam.fx), "focal_error_frac": float(est.f_px / cam.fx - 1.0),
                "ranges_used_m": used, "ranges_measured_m": rngs, "frames": frames.info}
    err = dict(config.calibration_error)
    err["focal_error_frac"] = info["focal_error_frac"]
    config = dataclasses.replace(config, calibration_error=err, calibration_info=info)
    if save and out_dir is not None:
        save_paper_calibration(config, out_dir)
    return config
