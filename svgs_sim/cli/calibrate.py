"""``svgs calibrate`` sub-commands: ``focal`` (the paper's method) and ``board`` (OpenCV).

Registered by :mod:`svgs_sim.cli.main` through :func:`register`. Nothing here imports Mitsuba.
Exit codes: 0 done, 2 bad input (:class:`svgs_sim.base.errors.InputError`, printed without a
traceback by ``svgs_sim.cli.main.main``).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from svgs_sim.svgs.detect import parse_threshold
from svgs_sim.base.errors import InputError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm", ".ppm", ".npy")


def register(sub) -> None:
    """Add ``focal`` and ``board`` to the ``svgs calibrate`` group's sub-parsers."""
    _add_focal(sub)
    _add_board(sub)


# --------------------------------------------------------------------------- focal
def _add_focal(sub) -> None:
    p = sub.add_parser(
        "focal",
        help="focal length from images of the target at known ranges (the paper's method)",
        description="Estimate the focal length (px) from the spacings of the target's spots in images taken "
        "at known ranges, the target facing the camera (Becker et al. 2014, 'Test Setup'). Give one "
        "--range per --image, in the same order. Prints the estimate with its 1-sigma uncertainty and "
        "writes the camera profile with the new focal length (--out).",
    )
    p.add_argument("--camera", required=True, help="camera profile name or .toml path (its fx is the starting value)")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default: svgs-3u)")
    p.add_argument("--image", action="append", required=True, metavar="PATH", help="image of the target (repeat)")
    p.add_argument("--range", action="append", required=True, type=float, metavar="R",
                   help="range of the matching --image along the boresight to the target plane, metres (repeat)")
    p.add_argument("--centroid-sigma-px", type=float, default=None,
                   help="known centroid noise per axis, px (default: estimated from the residuals)")
    p.add_argument("--range-sigma-m", type=float, default=0.0,
                   help="1-sigma uncertainty of each range, metres (default 0)")
    p.add_argument("--no-roll", action="store_true",
                   help="do not let the pattern rotate in the image plane (default: a free roll per image)")
    p.add_argument("--threshold", default=None, help="blob threshold: 'app' (the app's brightness threshold for the camera, assets/app/svgs-app.toml; the default), a level in image counts, 'auto' or 'otsu'")
    p.add_argument("--name", default=None, help="name written into the profile (default: the camera's)")
    p.add_argument("--out", default=None, metavar="PROFILE.toml", help="write the camera profile with the new focal length (default: none, only printed)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_focal)


_threshold = parse_threshold  # one parser for every command's --threshold


def cmd_focal(args) -> int:
    from svgs_sim.base.profiles import load_camera, load_pattern

    from svgs_sim.calibration.focal import estimate_focal_from_images

    if len(args.image) != len(args.range):
        raise InputError(f"give one --range per --image: got {len(args.image)} images and {len(args.range)} ranges")
    camera = load_camera(args.camera)
    pattern = load_pattern(args.pattern)
    threshold = _threshold(args.threshold)
    from svgs_sim.cli.outdir import output_file_if

    with output_file_if(args.out):  # its folder made and probed before the work; removed again if refused
        est = estimate_focal_from_images(
            args.image, args.range, camera, pattern, threshold=threshold,
            centroid_sigma_px=args.centroid_sigma_px, range_sigma_m=args.range_sigma_m, allow_roll=not args.no_roll,
        )
        out_path = None
        if args.out:
            cam = est.to_camera(camera)
            if args.name:
                cam = cam.replace(name=args.name)
            out_path = str(cam.save(args.out))
    if args.json:
        d = est.to_json()
        d.update(camera=camera.name, fx_px_before=camera.fx, out=out_path)
        for w in d["warnings"]:
            print(f"svgs calibrate focal: warning: {w}", file=sys.stderr)
        print(json.dumps(d))
    else:
        print(f"camera {camera.name!r}: fx was {camera.fx:.2f} px")
        print(est.summary())
        if out_path:
            print(f"wrote camera profile {out_path}")
    return 0


# --------------------------------------------------------------------------- board
def _add_board(sub) -> None:
    from svgs_sim.calibration.boards import BOARD_KINDS, DEFAULT_DICTIONARY
    from svgs_sim.calibration.intrinsics import MIN_VIEWS

    p = sub.add_parser(
        "board",
        help="full intrinsic calibration from board images (OpenCV)",
        description="Calibrate fx, fy, cx, cy and Brown-Conrady distortion (k1, k2, p1, p2, k3) from images "
        "of a planar board with OpenCV. Views where the board is not found are listed and skipped. "
        "--cols/--rows: chessboard inner corners; ChArUco squares; circle grids circles per row / rows "
        "(OpenCV's asymmetric grid: 4 x 11). --spacing-mm: square side, or circle spacing (asymmetric "
        "grid: OpenCV's square_size, half the distance between circles in a row).",
    )
    p.add_argument("images", nargs="+", metavar="IMAGE", help="board images, or folders of them")
    p.add_argument("--board", required=True, choices=BOARD_KINDS, help="board kind")
    p.add_argument("--cols", required=True, type=int, help="features per row (see above)")
    p.add_argument("--rows", required=True, type=int, help="features per column (see above)")
    p.add_argument("--spacing-mm", required=True, type=float, help="square side or circle spacing, mm")
    p.add_argument("--marker-mm", type=float, default=None, help="ChArUco marker side, mm (default 0.7 x spacing)")
    p.add_argument("--dictionary", default=DEFAULT_DICTIONARY, help=f"ChArUco ArUco dictionary (default {DEFAULT_DICTIONARY})")
    p.add_argument("--legacy", action="store_true", help="ChArUco board made by OpenCV < 4.6 (even row count)")
    p.add_argument("--fix-aspect", action="store_true", help="keep fx / fy fixed (at --aspect-ratio, default 1)")
    p.add_argument("--aspect-ratio", type=float, default=1.0, help="fx / fy, a dimensionless ratio, with --fix-aspect (default 1)")
    p.add_argument("--fix-principal-point", action="store_true",
                   help="keep the principal point at the image centre ((W-1)/2, (H-1)/2), or at --principal-point")
    p.add_argument("--principal-point", type=float, nargs=2, metavar=("CX", "CY"), default=None,
                   help="fix the principal point here, px (implies --fix-principal-point; default: the image centre)")
    p.add_argument("--zero-tangent", action="store_true", help="p1 = p2 = 0")
    p.add_argument("--fix-k3", action="store_true", help="k3 = 0 (few or near-frontal views)")
    p.add_argument("--min-views", type=int, default=MIN_VIEWS, help=f"fewest views with the board (default {MIN_VIEWS})")
    p.add_argument("--camera", default=None,
                   help="base camera profile: keep its other tables (sensor, optics...); its size must match (default: none, "
                        "a profile of the intrinsics alone)")
    p.add_argument("--name", default=None, help="profile name (default: the base camera's, or 'calibrated')")
    p.add_argument("--out", default=None, metavar="CAMERA.toml", help="write the calibrated camera profile (default: none, only printed)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_board)


def expand_images(paths) -> list[Path]:
    """Files as given; folders replaced by their image files (sorted)."""
    out = []
    for s in paths:
        p = Path(s)
        if p.is_dir():
            files = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES)
            if not files:
                raise InputError(f"folder {str(p)!r} holds no image files ({', '.join(IMAGE_SUFFIXES)})")
            out.extend(files)
        else:
            out.append(p)
    return out


def cmd_board(args) -> int:
    from svgs_sim.base.profiles import load_camera

    from svgs_sim.calibration.boards import Board
    from svgs_sim.calibration.intrinsics import calibrate_images

    if args.spacing_mm is None or not np.isfinite(args.spacing_mm) or args.spacing_mm <= 0:
        raise InputError(f"--spacing-mm: expected a positive size in mm, got {args.spacing_mm}")
    if args.min_views < 1:
        raise InputError(f"--min-views: expected a positive integer, got {args.min_views}")
    board = Board(
        args.board, args.cols, args.rows, args.spacing_mm * 1e-3,
        marker_m=None if args.marker_mm is None else args.marker_mm * 1e-3,
        dictionary=args.dictionary, legacy=args.legacy,
    )
    base = load_camera(args.camera) if args.camera else None
    files = expand_images(args.images)
    names = [f.name for f in files]
    if len(set(names)) != len(names):
        names = [str(f) for f in files]
    from svgs_sim.cli.outdir import output_file_if

    with output_file_if(args.out):  # its folder made and probed before the work; removed again if refused
        cal = calibrate_images(
            files, board, names=names, min_views=args.min_views,
            fix_aspect=args.fix_aspect, aspect_ratio=args.aspect_ratio,
            fix_principal_point=args.fix_principal_point,
            principal_point=None if args.principal_point is None else tuple(args.principal_point),
            zero_tangent=args.zero_tangent, fix_k3=args.fix_k3,
        )
        name = args.name or (base.name if base is not None else "calibrated")
        cam = cal.to_camera(name=name, base=base)
        out_path = str(cam.save(args.out)) if args.out else None
    if args.json:
        d = cal.to_json()
        d["out"] = out_path
        for w in d["warnings"]:  # the summary (with them) is not printed: say them on stderr
            print(f"svgs calibrate board: warning: {w}", file=sys.stderr)
        print(json.dumps(d))
    else:
        print(cal.summary())
        if out_path:
            print(f"wrote camera profile {out_path}")
    return 0


__all__ = ["register", "cmd_focal", "cmd_board", "expand_images"]
