"""``svgs tof solve``: the ToF pose pipeline on gray + depth files.

Registered in the ``tof`` group of :data:`svgs_sim.cli.main.COMMANDS` (``render-and-solve`` comes from
:mod:`svgs_sim.cli.tof_render`).

Input files
    ``.npy``: any numeric array; a 3-D array ``(N, H, W)`` is a sequence of N frames.
    ``.png`` / ``.tif(f)``: decoded by OpenCV as stored (8/16-bit or float).
    Gray: any scale (colour images are averaged). Depth: **float arrays are metres; integer
    arrays (16-bit PNG/TIFF, integer .npy) are millimetres** (scale from the camera profile's
    ``tof.depth_png_scale_m``, default 0.001; ``--depth-unit`` overrides); 0 or NaN marks
    invalid pixels. Several ``--gray``/``--depth`` files (or 3-D arrays) run as one sequence
    through the stateful pipeline (temporal median, persistence); the last frame's result is
    printed and sets the exit code.

Exit codes: 0 solved, 1 no solution (the reason is printed), 2 bad input.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError

from svgs_sim.cli.exit_codes import EXIT_NO_SOLUTION, EXIT_OK


def register(group) -> None:
    """Add ``solve`` to the ``svgs tof`` group's sub-parsers."""
    p = group.add_parser(
        "solve",
        help="solve the pose from ToF gray + depth frames",
        description="Detect the eight circular markers in the gray image, read their depths, match them "
        "to the target by deterministic annealing and solve the pose (weighted SVD + line-of-sight "
        "refinement). Exit 0 when solved, 1 when no solution (with the reason), 2 for bad input.",
    )
    p.add_argument("--gray", nargs="+", required=True, metavar="G",
                   help="gray (amplitude) image(s): .npy, .png or .tiff; several files or an (N, H, W) .npy = a sequence")
    p.add_argument("--depth", nargs="+", required=True, metavar="D",
                   help="depth image(s): float = metres, integer (16-bit PNG/TIFF) = millimetres; 0/NaN invalid")
    p.add_argument("--camera", default="tof-epc660", help="ToF camera profile name or .toml path (default: tof-epc660)")
    p.add_argument("--pattern", default="tof-8", help="marker target name or .toml path (default: tof-8)")
    p.add_argument("--depth-unit", choices=("auto", "m", "mm"), default="auto",
                   help="unit of the depth values (default auto: float = m, integer = mm)")
    p.add_argument("--persistence", type=int, default=1, metavar="N",
                   help="persistence window in frames for sequences (default: 1 = single-frame)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=cmd_solve)


def load_frames(path, kind: str, depth_unit: str = "auto", scale_mm_m: float = 0.001) -> list[np.ndarray]:
    """Read a gray or depth file as a list of 2-D float32 frames.

    Parameters
    ----------
    path : str or Path
    kind : {"gray", "depth"}
    depth_unit : {"auto", "m", "mm"}
    scale_mm_m : float
        Metres per count of integer depth images.

    Raises
    ------
    InputError
        Missing, empty or undecodable file; not a 2-D image or a stack of them.
    """
    from svgs_sim.svgs.pipeline import load_image

    p = Path(path)
    if p.suffix.lower() == ".npy":
        if not p.is_file():
            raise InputError(f"{kind} {str(p)!r} does not exist")
        try:
            arr = np.load(p, allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - any decode failure is bad input
            raise InputError(f"{kind} {str(p)!r} is not a readable .npy array: {exc}") from None
    else:
        arr = load_image(p)
    if not np.issubdtype(arr.dtype, np.number) or np.issubdtype(arr.dtype, np.complexfloating):
        raise InputError(f"{kind} {str(p)!r}: expected a real numeric image, got dtype {arr.dtype}")
    if arr.ndim == 3 and arr.shape[-1] in (3, 4) and p.suffix.lower() != ".npy":
        if kind == "depth":
            raise InputError(f"depth {str(p)!r}: expected a single-channel image, got {arr.shape[-1]} channels")
        arr = arr[..., :3].astype(np.float32).mean(-1)
    if arr.ndim == 2:
        frames = [arr]
    elif arr.ndim == 3:
        frames = list(arr)
    else:
        raise InputError(f"{kind} {str(p)!r}: expected a 2-D image or an (N, H, W) stack, got shape {arr.shape}")
    if not frames or frames[0].size == 0:
        raise InputError(f"{kind} {str(p)!r}: empty image")
    out = []
    for f in frames:
        if kind == "depth":
            integer = np.issubdtype(f.dtype, np.integer) or f.dtype == bool
            unit = depth_unit if depth_unit != "auto" else ("mm" if integer else "m")
            f = f.astype(np.float64) * (scale_mm_m if unit == "mm" else 1.0)
        out.append(np.asarray(f, np.float32))
    return out


def _gather(paths, kind, depth_unit="auto", scale=0.001):
    frames = []
    for p in paths:
        frames.extend(load_frames(p, kind, depth_unit, scale))
    return frames


def solution_json(result, n_frames: int = 1) -> dict:
    """JSON object of ``svgs tof solve --json``: the keys of ``svgs solve --json``."""
    if result:
        d = result.to_json()
    else:
        from svgs_sim.cli.solve import solution_json as svgs_json

        details = {k: v for k, v in result.details.items() if k != "timings_s"}
        d = svgs_json(type(result)(result.reason, result.message, details))
    d["n_frames"] = int(n_frames)
    return d


def print_solution(result, out=None) -> None:
    """A readable summary of a ToF solution or failure (on ``out``, default stdout)."""
    from svgs_sim.cli.solve import print_pose_summary

    out = sys.stdout if out is None else out
    if not print_pose_summary(result, out, "candidate markers found"):
        return
    t = result.t_cam_target_m
    print(f"  target origin in the camera frame (m): {t[0]:+.4f} {t[1]:+.4f} {t[2]:+.4f}", file=out)
    print(f"  markers matched: {len(result.targets_px)} of {result.n_blobs} candidates; "
          f"reprojection residual {result.residual_rms_px:.3f} px RMS, 3-D residual {1e3 * result.residual_rms_m:.2f} mm RMS", file=out)
    for tid, uv in result.targets_px.items():
        print(f"  marker {tid}: u {uv[0]:.3f}  v {uv[1]:.3f} px  range {result.targets_slant_range_m[tid]:.4f} m", file=out)


def cmd_solve(args) -> int:
    from svgs_sim.tof.camera import load_camera, load_target
    from svgs_sim.tof.pipeline import TofPipeline

    camera = load_camera(args.camera)
    target = load_target(args.pattern)
    scale = float(camera.tof.given("depth_png_scale_m", 0.001))
    grays = _gather(args.gray, "gray")
    depths = _gather(args.depth, "depth", args.depth_unit, scale)
    if len(grays) != len(depths):
        raise InputError(f"--gray gives {len(grays)} frame(s) but --depth gives {len(depths)}")
    if args.persistence < 1:
        raise InputError(f"--persistence: expected a positive number of frames, got {args.persistence}")
    pipe = TofPipeline(camera, target, persistence_window=args.persistence,
                       persistence_min_count=max(1, (args.persistence + 1) // 2))
    result = None
    for k, (g, d) in enumerate(zip(grays, depths)):
        try:
            result = pipe.process(g, d)
        except InputError as exc:
            raise InputError(f"frame {k + 1}: {exc}" if len(grays) > 1 else str(exc)) from None
    if args.json:
        print(json.dumps(solution_json(result, len(grays))))
    else:
        print_solution(result)
    return EXIT_OK if result else EXIT_NO_SOLUTION
