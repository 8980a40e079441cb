"""``svgs solve``: detect, identify and solve the pose from one image (a real photo or a render),
and the readable and JSON forms of a solution that the other sensor commands share.

Imports only :mod:`svgs`: solving a photo loads no renderer, study or calibration code.
"""

from __future__ import annotations

import json
from pathlib import Path
import sys

import numpy as np

from svgs_sim.cli.exit_codes import EXIT_NO_SOLUTION, EXIT_OK
from svgs_sim.svgs.detect import parse_threshold
from svgs_sim.base.errors import InputError, check_finite_positive
from svgs_sim.base.jsonable import json_default  # noqa: F401  (the writers of solution.json import it from here)


def register(sub) -> None:
    """Add ``svgs solve``."""
    p = sub.add_parser(
        "solve",
        help="solve the 6-DOF pose from one image of the target",
        description="Detect the retroreflector spots in IMAGE, identify the targets and solve the "
        "relative state with the collinearity equations (paper eqs. 12-13). Exit 0 when solved, "
        "1 when no solution (with the reason), 2 for bad input.",
    )
    p.add_argument("image", help="image file (PNG/JPEG/TIFF, 8 or 16 bit, grey or colour, or .npy)")
    p.add_argument("--camera", required=True, help="camera profile name (e.g. galaxy-nexus) or path to a .toml")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default: svgs-3u)")
    p.add_argument("--threshold", default=None,
                   help="binarisation threshold: 'app' (the app's brightness threshold for the camera, assets/app/svgs-app.toml; the default), a level in image counts, 'auto' or 'otsu'")
    p.add_argument("--sigma-px", type=float, default=0.1,
                   help="centroid noise in px for the reported Cramer-Rao bound (default: 0.1)")
    p.add_argument("--consistency-sigma-px", type=float, default=None,
                   help="the stated centroid accuracy in px that the solution's residual is tested against "
                        "(chi-square, svgs_sim.svgs.app; a solution with p < alpha is 'inconsistent'; default: the app's, "
                        "assets/app/svgs-app.toml)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="write overlay.png (what the detector found and where the solution puts the targets) and "
                        "solution.json here (default: none, nothing written)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_solve)


def write_solution_overlay(path, image, camera, pattern, result, threshold=None, sigma_px=None,
                           sigma_label: str | None = None, title: str | None = None, blobs=None, notes=()) -> str:
    """``overlay.png`` of one solved (or unsolved) image: every blob the detector found, the
    identified targets' labels, the solution's reprojection and each point's 1-sigma ellipse.

    ``sigma_px`` (target id -> [su, sv]) defaults to the centroid scatter the image's own
    background noise gives (:func:`svgs_sim.svgs.overlay.centroid_sigma_from_image`); ``blobs`` are the
    image's detections when the caller has them; ``notes``: lines of a text panel below it."""
    from svgs_sim.svgs.detect import detect_blobs, to_gray
    from svgs_sim.svgs.overlay import centroid_sigma_from_image, solution_marks, write_overlay

    from svgs_sim.svgs.pipeline import camera_threshold

    threshold = camera_threshold(image, camera, threshold)
    if blobs is None:
        blobs = detect_blobs(image, threshold=threshold)
    targets, reproj = solution_marks(result, camera, pattern)
    if sigma_px is None and targets:
        sig = centroid_sigma_from_image(to_gray(image), list(targets.values()), float(blobs.noise_sigma))
        sigma_px = dict(zip(targets, sig.tolist()))
        sigma_label = sigma_label or "centroid 1-sigma from the image's background noise"
    if title is None:
        title = (f"SOLVED: range {result.t_cam_target_m[2]:.3f} m, residual {result.residual_rms_px:.3f} px RMS, "
                 f"{len(blobs)} blobs" if result else f"NO SOLUTION ({result.reason}): {len(blobs)} blobs")
    return write_overlay(path, image, blobs_px=blobs.centroid_px, targets_px=targets, reprojected_px=reproj,
                         sigma_px=sigma_px, sigma_label=sigma_label or "1-sigma", title=title, notes=notes)


def solution_json(result) -> dict:
    """The JSON object of ``svgs solve --json`` for a Solution or a Failure."""
    if result:
        return result.to_json()
    d = {
        "ok": False,
        "reason": result.reason,
        "message": result.message,
        "state": None,
        "R_cam_target": None,
        "t_cam_target_m": None,
        "targets_px": {},
        "n_blobs": result.details.get("n_blobs"),
        "residual_rms_px": result.details.get("residual_rms_px"),
        **{k: result.details.get(k) for k in ("chi2", "dof", "p_value", "consistency_sigma_px", "alpha", "consistent")},
    }
    d["details"] = {k: v for k, v in result.details.items() if k not in ("n_blobs", "residual_rms_px")}
    return d


def print_pose_summary(result, out, blobs_label: str = "blobs found") -> bool:
    """First lines of a readable summary, shared by every sensor's CLI: the failure and
    its reason, or SOLVED with position and attitude. Returns whether it solved."""
    if not result:
        print(f"NO SOLUTION ({result.reason}): {result.message}", file=out)
        if result.details.get("n_blobs") is not None:
            print(f"  {blobs_label}: {result.details['n_blobs']}", file=out)
        return False
    s = result.state_dict
    print("SOLVED", file=out)
    print(f"  position of the camera in the target frame (m): x {s['x_m']:+.4f}  y {s['y_m']:+.4f}  z {s['z_m']:+.4f}", file=out)
    print(f"  attitude (deg, paper x-y-z sequence): roll {s['roll_deg']:+.3f}  pitch {s['pitch_deg']:+.3f}  yaw {s['yaw_deg']:+.3f}", file=out)
    return True


def print_solution(result, out=None) -> None:
    """A readable summary of a Solution or Failure."""
    out = sys.stdout if out is None else out
    if not print_pose_summary(result, out):
        return
    sd = result.std
    print(f"  range along the boresight to the target origin: {result.t_cam_target_m[2]:.4f} m", file=out)
    print(f"  reprojection residual: {result.residual_rms_px:.3f} px RMS; blobs found: {result.n_blobs}", file=out)
    if getattr(result, "consistency", None) is not None:
        c = result.consistency
        print(f"  consistency: chi2 {c.chi2:.3g} with {c.dof} degrees of freedom, p = {c.p_value:.2g} "
              f"(centroid noise {c.sigma_px:.3g} px; 'inconsistent' below p = {c.alpha:g})", file=out)
    print(
        f"  Cramer-Rao 1-sigma for {result.sigma_px:g} px centroid noise: "
        f"pos {sd[0]:.3g} {sd[1]:.3g} {sd[2]:.3g} m, att {np.degrees(sd[3]):.3g} {np.degrees(sd[4]):.3g} {np.degrees(sd[5]):.3g} deg",
        file=out,
    )
    for tid, uv in result.targets_px.items():
        print(f"  target {tid}: u {uv[0]:.3f}  v {uv[1]:.3f} px", file=out)
    if getattr(result, "outside_test_envelope", None):
        from svgs_sim.svgs.envelope import OUTSIDE_TEST_ENVELOPE_NOTE

        print(f"  note: {OUTSIDE_TEST_ENVELOPE_NOTE}", file=out)


def cmd_solve(args) -> int:
    from svgs_sim.base.profiles import load_camera, load_pattern

    camera = load_camera(args.camera)
    pattern = load_pattern(args.pattern)
    if not (np.isfinite(args.sigma_px) and args.sigma_px > 0):
        raise InputError(f"--sigma-px: expected a positive number of pixels, got {args.sigma_px}")
    if args.consistency_sigma_px is not None:
        check_finite_positive(args.consistency_sigma_px, "--consistency-sigma-px")
    from svgs_sim.svgs.pipeline import check_image_matches_camera, load_image

    image = load_image(args.image, camera=camera)  # its size read from the header first
    check_image_matches_camera(image, camera)
    from svgs_sim.svgs.pipeline import camera_threshold

    thr = camera_threshold(image, camera, parse_threshold(args.threshold))
    from svgs_sim.cli.outdir import output_folder_if

    with output_folder_if(args.out):  # made and probed before the solve; removed again if refused
        return _solve(args, image, camera, pattern, thr)


def _solve(args, image, camera, pattern, thr) -> int:
    """``svgs solve`` once its inputs are checked and ``--out`` is ready."""
    from svgs_sim.svgs.detect import detect_blobs
    from svgs_sim.svgs.pipeline import solve_image

    blobs = detect_blobs(image, threshold=thr)  # once: for the solve and for the overlay
    result = solve_image(image, camera, pattern, threshold=thr, sigma_px=args.sigma_px, blobs=blobs,
                         consistency_sigma_px=args.consistency_sigma_px)
    from svgs_sim.svgs.pipeline import describe_detector, detector_settings

    d = solution_json(result)
    d["detector"] = detector_settings(camera, parse_threshold(args.threshold))
    if args.out:
        out = Path(args.out)
        d["outputs"] = {"overlay": write_solution_overlay(out / "overlay.png", image, camera, pattern, result, thr,
                                                          blobs=blobs),
                        "solution": str(out / "solution.json")}
        (out / "solution.json").write_text(json.dumps(d, indent=1), encoding="utf-8")
    if args.json:
        print(json.dumps(d))
    else:
        print_solution(result)
        print(describe_detector(d["detector"]))
        for v in (d.get("outputs") or {}).values():
            print(f"wrote {v}")
    return EXIT_OK if result else EXIT_NO_SOLUTION
