"""``svgs render`` and ``svgs doctor``.

Registered by :mod:`svgs_sim.cli.main` through :func:`register`. Nothing here imports mitsuba or
drjit at import time: the handlers do, after :func:`svgs_sim.render.variant.select_variant` has
chosen the LLVM library.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from svgs_sim.base.errors import InputError


def register(sub) -> None:
    """Add the ``render`` and ``doctor`` sub-commands to an argparse subparsers object."""
    from svgs_sim.cli.sim import POSE_ARGS, add_focus_arg
    from svgs_sim.sim.scene import add_scene_options

    p = sub.add_parser(
        "render",
        help="ray-trace the target under the phone's flash: photon flux, preview and truth",
        description="Render the noise-free photon flux (photons/s/pixel in the camera band) of the target "
        "pattern lit by the phone's flash, seen by the phone's camera, with Mitsuba 3. Writes DIR/flux.npy "
        "(float32, full frame), DIR/preview.png (tone-mapped) and DIR/truth.json (pose, state, targets_px, "
        "every physical parameter used). Range is along the boresight to the target origin (m); attitude "
        "(deg) and lateral offsets as in 'svgs solve'. Exit 0 done, 2 bad input.",
    )
    p.add_argument("--camera", required=True, help="camera profile name or .toml path (needs [optics] and [flash])")
    p.add_argument("--pattern", default="svgs-3u", help="target pattern name or .toml path (default: svgs-3u)")
    p.add_argument("--range", dest="range_m", type=float, required=True, help="range along the boresight, m")
    for flag, dest, text in POSE_ARGS:  # the pose options of every rendering command, declared once
        p.add_argument(flag, dest=dest, type=float, default=0.0, help=text)
    p.add_argument("--spp", type=int, default=None, help="samples per pixel of the background (default 4)")
    p.add_argument("--roi-spp", type=int, default=None, help="samples per pixel in the windows around the spots (default 64 with --method guided, 4096 with path)")
    p.add_argument("--spot-samples", type=int, default=None, help="guided samples per spot strategy (default 16384, placed by the 4-D R4 sequence)")
    p.add_argument("--reflector", default=None, help="'solid', 'hollow' or a model name (default: the pattern's)")
    p.add_argument("--body", default=None, choices=("plate", "3u", "none"), help="target body (default plate)")
    p.add_argument("--method", default="guided", choices=("guided", "path"),
                   help="'guided' (default) or 'path' (brute force, the reference; slow beyond a few metres)")
    add_focus_arg(p)
    p.add_argument("--full-frame", action="store_true", help="render the whole frame at --spp, no windows")
    p.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    add_scene_options(p)  # --backdrop-m, --ambient: the scene around the target (added to flux.npy)
    p.add_argument("--exposure-s", type=float, default=None, help="exposure time of image.png (default: the phone's)")
    p.add_argument("--iso", type=float, default=None, help="ISO of image.png (default: the phone's)")
    p.add_argument("--no-expose", action="store_true", help="write only the flux (no raw.npy / image.png)")
    p.add_argument("--out", required=True, help="output folder (created if missing)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=cmd_render)

    d = sub.add_parser(
        "doctor",
        help="print the Mitsuba variant, the LLVM library found and library versions",
        description="Check the rendering set-up: which Mitsuba variant would be used, which LLVM library "
        "Dr.Jit loads (LLVM 15 aborts Dr.Jit 1.5: it must not be used), library versions and whether each "
        "is usable. Exit 0 when a renderer is usable (scalar counts, with a warning).",
    )
    d.add_argument("--variant", default=None, help="try this Mitsuba variant or backend, as SVGS_MI_VARIANT does (default: SVGS_MI_VARIANT, else the best available)")
    d.add_argument("--json", action="store_true", help="print one JSON object")
    d.set_defaults(func=cmd_doctor)


def cmd_render(args) -> int:
    from svgs_sim.svgs.frames import pose_from_scenario
    from svgs_sim.base.profiles import Camera, Pattern

    camera = Camera.load(args.camera)
    for table in ("optics", "flash"):
        camera.table(table)  # ProfileError naming the missing table, before any heavy import
    pattern = Pattern.load(args.pattern)
    if not (args.range_m == args.range_m) or args.range_m <= 0:
        raise InputError(f"--range: expected a positive range in metres, got {args.range_m}")
    R, t = pose_from_scenario(args.range_m, args.target_x_m, args.target_y_m, args.roll_deg, args.pitch_deg,
                              args.yaw_deg)
    if args.focus_m is not None and not (np.isfinite(args.focus_m) and args.focus_m > 0):
        raise InputError(f"--focus-m: expected a positive distance in metres, got {args.focus_m}")
    from svgs_sim.cli.outdir import output_folder

    with output_folder(args.out):  # made and probed before the render; removed again if refused
        return _render(args, camera, pattern, R, t)


#: Samples per second the renderer draws on this kind of machine (LLVM, two cores): the demo
#: (``make demo``) renders its 2592 x 1944 frame at 4 spp plus four 32 x 32 px windows at 64 spp,
#: about 2e7 samples, in 1.8 s.
RENDER_SAMPLES_PER_S = 1.1e7
#: A render estimated to take longer than this many seconds is announced before it starts.
LONG_RENDER_S = 120.0


def render_cost_warning(width_px: int, height_px: int, spp: int, roi_spp: int, n_spots: int, full_frame: bool = False,
                        roi_size_px: int | None = None) -> str | None:
    """One warning line when a render's samples (``spp`` over the frame, ``roi_spp`` over the spot
    windows, or ``spp`` everywhere with ``full_frame``) would take longer than
    :data:`LONG_RENDER_S` at :data:`RENDER_SAMPLES_PER_S`; None otherwise."""
    from svgs_sim.render.constants import DEFAULT_ROI_SIZE_PX

    side = DEFAULT_ROI_SIZE_PX if roi_size_px is None else int(roi_size_px)
    samples = float(spp) * width_px * height_px + (0.0 if full_frame else float(roi_spp) * n_spots * side * side)
    est_s = samples / RENDER_SAMPLES_PER_S
    if est_s <= LONG_RENDER_S:
        return None
    minutes = est_s / 60.0
    when = f"{minutes:.0f} min" if minutes < 120 else f"{minutes / 60:.1f} h"
    return (f"warning: this render draws {samples:.2g} samples ({spp} spp over {width_px} x {height_px} px"
            + ("" if full_frame else f", {roi_spp} spp in {n_spots} windows of {side} x {side} px")
            + f"): about {when} at ~{RENDER_SAMPLES_PER_S:.2g} samples/s (the demo's rate on two cores); "
            "Ctrl-C stops it")


def _render(args, camera, pattern, R, t) -> int:
    """``svgs render`` once its inputs are checked and ``--out`` is ready."""
    from svgs_sim.render.api import Renderer
    from svgs_sim.render.constants import DEFAULT_ROI_SPP, DEFAULT_ROI_SPP_PATH, DEFAULT_SPOT_SAMPLES, DEFAULT_SPP

    focus = float(np.linalg.norm(t)) if args.focus_m is None else float(args.focus_m)  # autofocus, as render-and-solve
    opts = {"focus_distance_m": focus} if args.body is None else {"body": args.body, "focus_distance_m": focus}
    spp = DEFAULT_SPP if args.spp is None else args.spp
    roi_spp = args.roi_spp if args.roi_spp is not None else (DEFAULT_ROI_SPP if args.method == "guided" else DEFAULT_ROI_SPP_PATH)
    r = Renderer(camera, pattern, reflector=args.reflector, scene_options=opts, spp=spp, roi_spp=roi_spp,
                 spot_samples=args.spot_samples or DEFAULT_SPOT_SAMPLES, method=args.method)
    warn = render_cost_warning(camera.width, camera.height, spp, roi_spp, int(pattern.n), args.full_frame)
    if warn:
        print(f"svgs render: {warn}", file=sys.stderr, flush=True)
    from svgs_sim.render.variant import is_fallback

    if r.variant.notice and not is_fallback(r.variant.requested, r.variant.name):  # a fallback: said by select_variant
        print(f"svgs render: note: {r.variant.notice}", file=sys.stderr)
    from svgs_sim.sim import hard_stop

    with hard_stop.scope():  # Ctrl-C stops the render within a second (nothing is written yet)
        res = r.render(R, t, seed=args.seed, full_frame=args.full_frame)
    res.truth["command"] = {k: v for k, v in vars(args).items() if k != "func"}
    from svgs_sim.sim.closed_loop import Scenario, lab_flux
    from svgs_sim.sim.scene import scene_from_args

    scen = Scenario(camera=args.camera, pattern=args.pattern, range_m=args.range_m,
                    target_x_m=args.target_x_m, target_y_m=args.target_y_m, roll_deg=args.roll_deg,
                    pitch_deg=args.pitch_deg, yaw_deg=args.yaw_deg, scene=scene_from_args(args))
    lab, lab_info = lab_flux(camera, scen)
    res.flux = res.flux + lab
    if res.flux_diffuse is not None:
        res.flux_diffuse = res.flux_diffuse + lab
    res.truth["lab"] = lab_info
    res.truth["focus_distance_m"] = focus
    if not args.no_expose:
        import cv2

        from svgs_sim.camera.phone import PhoneCamera

        flux, points = res.film()
        ex = PhoneCamera(camera).expose(flux, points=points, seed=args.seed, exposure_s=args.exposure_s, iso=args.iso)
        res.truth["exposure"] = {"exposure_s": ex.exposure_s, "iso": ex.iso, "gain_dn_per_e": ex.gain_dn_per_e,
                                 **{k: v for k, v in ex.info.items()}}
    paths = res.save(args.out)
    if not args.no_expose:
        from pathlib import Path

        np.save(Path(args.out) / "raw.npy", ex.raw_dn.astype(np.float32))
        cv2.imwrite(str(Path(args.out) / "image.png"), ex.image)
        paths.update({"raw": str(Path(args.out) / "raw.npy"), "image": str(Path(args.out) / "image.png")})
    summary = {
        "out": paths,
        "variant": r.variant.name,
        "total_flux_photons_per_s": float(res.flux.sum(dtype="float64")),
        "targets_px": res.truth["targets_px"],
        "timings_s": res.timings_s,
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"rendered {camera.name} at range {args.range_m:g} m with {r.variant.name} in "
              f"{sum(v for v in res.timings_s.values() if isinstance(v, float)):.2f} s")
        for k, v in paths.items():
            print(f"  {k:8s} {v}")
    return 0


def doctor_report(variant=None) -> dict:
    """What ``svgs doctor`` prints, as a dict."""
    import importlib.metadata as md
    import platform

    from svgs_sim.render.variant import MIN_LLVM_MAJOR, backend_report, llvm_candidates, pick_llvm, select_variant

    rep = {"python": platform.python_version(), "platform": platform.platform()}
    versions = {}
    for pkg in ("mitsuba", "drjit", "karellen-llvm-core", "numpy", "scipy", "opencv-python-headless", "scikit-image"):
        try:
            versions[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            versions[pkg] = None
    rep["versions"] = versions
    cands = llvm_candidates()
    chosen, note = pick_llvm(cands)
    rep["llvm_candidates"] = [
        {"path": p, "major": v, "origin": o, "usable": v is not None and v >= MIN_LLVM_MAJOR} for p, v, o in cands
    ]
    rep["llvm_chosen"] = chosen
    rep["llvm_min_major"] = MIN_LLVM_MAJOR
    ok = True
    try:
        info = select_variant(variant)
        rep["variant"] = info.to_json()
        rep.update(backend_report(info))
        rep["usable"] = True
        rep["warning"] = info.notice or ("scalar variant: rendering works but is slow" if info.backend == "scalar" else "")
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - report, do not crash the doctor
        ok = False
        rep["usable"] = False
        rep["error"] = f"{type(exc).__name__}: {exc}"
    rep["ok"] = ok
    return rep


def cmd_doctor(args) -> int:
    rep = doctor_report(args.variant)
    if args.json:
        print(json.dumps(rep, default=str))
        return 0 if rep["ok"] else 1
    print(f"python      {rep['python']} on {rep['platform']}")
    for k, v in rep["versions"].items():
        print(f"{k:22s} {v or 'not installed'}")
    print(f"LLVM libraries (Dr.Jit needs LLVM >= {rep['llvm_min_major']}; 15 aborts Dr.Jit 1.5):")
    for c in rep["llvm_candidates"]:
        print(f"  {'usable    ' if c['usable'] else 'NOT usable'} LLVM {c['major']}  {c['path']}  ({c['origin']})")
    if not rep["llvm_candidates"]:
        print("  none found")
    if rep["ok"]:
        v = rep["variant"]
        ver = ".".join(map(str, v["llvm_version"])) if v["llvm_version"] else "not loaded"
        print(f"variant     {v['name']} (backend {v['backend']}); LLVM loaded: {ver} from {v['llvm_path'] or '-'}")
        print(f"usable      yes{' - ' + rep['warning'] if rep['warning'] else ''}")
    else:
        print(f"usable      NO - {rep['error']}")
    return 0 if rep["ok"] else 1

