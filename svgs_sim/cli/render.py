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
from svgs_sim.base.image_files import write_image


def register(sub) -> None:
    """Add the ``render`` and ``doctor`` sub-commands to an argparse subparsers object."""
    from svgs_sim.cli.sim import scenario_args

    p = sub.add_parser(
        "render",
        help="ray-trace the target under the phone's flash: photon flux, preview and truth",
        description="Render the noise-free photon flux (photons/s/pixel in the camera band) of the target "
        "pattern lit by the phone's flash, seen by the phone's camera, with Mitsuba 3. Writes DIR/flux.npy "
        "(float32, full frame), DIR/preview.png (tone-mapped) and DIR/truth.json (pose, state, targets_px, "
        "every physical parameter used) and, unless --no-expose, the phone's exposure of it: DIR/raw.npy and "
        "DIR/image.png, the image 'svgs render-and-solve' solves for the same options and seed (one route: "
        "svgs_sim.sim.closed_loop.render_scenario). Range is along the boresight to the target origin (m); "
        "attitude (deg) and lateral offsets as in 'svgs solve'. Exit 0 done, 2 bad input.",
    )
    scenario_args(p, with_threshold=False)  # the options of render-and-solve, declared once
    p.add_argument("--spot-samples", type=int, default=None, help="guided samples per spot strategy (default 16384, placed by the 4-D R4 sequence)")
    p.add_argument("--reflector", default=None, help="'solid', 'hollow' or a model name (default: the pattern's)")
    body_args(p)
    p.add_argument("--method", default="guided", choices=("guided", "path"),
                   help="'guided' (default) or 'path' (brute force, the reference; slow beyond a few metres)")
    p.add_argument("--full-frame", action="store_true", help="render the whole frame at --spp, no windows")
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
    from svgs_sim.cli.outdir import output_folder
    from svgs_sim.cli.sim import check_camera_renderable, scenario_from_args
    from svgs_sim.sim.closed_loop import RenderOptions

    check_camera_renderable(args.camera)  # ProfileError naming a missing [optics] or [flash], before any heavy import
    scen = scenario_from_args(args)  # the scenario of render-and-solve: pose, scene, samples, focus (InputError naming the input)
    options = RenderOptions(method=args.method, reflector=args.reflector, spot_samples=args.spot_samples,
                            full_frame=args.full_frame, **body_options(args))
    with output_folder(args.out):  # made and probed before the render; removed again if refused
        return _render(args, scen, options)


def body_args(p) -> None:
    """The target body's options (``--body``, ``--body-material``, ``--body-materials``), declared once
    for ``svgs render``, ``svgs render-and-solve`` and ``svgs approach``."""
    p.add_argument("--body", default=None,
                   help="target body: 'plate' (the default: the lab's breadboard), '3u' (a 3U CubeSat: rails, MLI, "
                   "body-mounted cells; svgs_sim.render.cubesat), 'none', or a mesh file ending in .ply or .obj "
                   "(metres, target frame) with --body-material or --body-materials")
    p.add_argument("--body-material", default=None, metavar="NAME",
                   help="a mesh body's surface, from the library svgs_sim/assets/materials/surfaces.toml: "
                   "lambertian-white, white-paint, solar-cell, mli, anodised-aluminium (default: none; required with a "
                   "mesh body unless --body-materials names every part)")
    p.add_argument("--body-materials", default=None, metavar="FILE.toml",
                   help="a mesh body's parts and their surfaces, one line each: part = \"surface\" (default: none)")


def body_options(args) -> dict:
    """The :class:`svgs_sim.sim.closed_loop.RenderOptions` fields of the body options."""
    return {"body": args.body, "body_material": args.body_material,
            "body_materials": body_materials_of(args.body_materials)}


def body_materials_of(path) -> dict:
    """Part -> surface of a ``--body-materials`` TOML file (``part = "surface"`` lines); {} for None."""
    if path is None:
        return {}
    from svgs_sim.base.profiles import read_toml

    data = read_toml(path, "--body-materials")
    bad = {k: v for k, v in data.items() if not isinstance(v, str)}
    if bad:
        raise InputError(f"--body-materials {path}: each line is part = \"surface\"; not a surface name: "
                         f"{', '.join(f'{k} = {v!r}' for k, v in bad.items())}")
    return dict(data)


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


def _render(args, scen, options) -> int:
    """``svgs render`` once its inputs are checked and ``--out`` is ready: the closed loop's
    render (:func:`svgs_sim.sim.closed_loop.render_scenario`, as ``render-and-solve``) and, unless
    ``--no-expose``, the phone's exposure of it (:meth:`svgs_sim.sim.closed_loop.Frame.exposer`)."""
    from pathlib import Path

    from svgs_sim.render.api import write_preview
    from svgs_sim.render.constants import DEFAULT_ROI_SPP, DEFAULT_ROI_SPP_PATH, DEFAULT_SPP
    from svgs_sim.sim import hard_stop
    from svgs_sim.sim.closed_loop import render_scenario

    camera, pattern = scen.camera, scen.pattern
    spp = DEFAULT_SPP if scen.spp is None else scen.spp
    roi_spp = scen.roi_spp if scen.roi_spp is not None else (DEFAULT_ROI_SPP if options.method == "guided"
                                                            else DEFAULT_ROI_SPP_PATH)
    warn = render_cost_warning(camera.width, camera.height, spp, roi_spp, int(pattern.n), options.full_frame)
    if warn:
        print(f"svgs render: {warn}", file=sys.stderr, flush=True)
    with hard_stop.scope():  # Ctrl-C stops the render within a second (nothing is written yet)
        frame = render_scenario(scen, seed=args.seed, options=options)
    from svgs_sim.render.variant import is_fallback

    info = frame.truth["render"]
    if info.get("variant_notice") and not is_fallback(info.get("variant_requested"), info["variant"]):
        print(f"svgs render: note: {info['variant_notice']}", file=sys.stderr)  # a fallback: said by select_variant
    truth = dict(frame.truth)
    truth["command"] = {k: v for k, v in vars(args).items() if k != "func"}
    out = Path(args.out)
    np.save(out / "flux.npy", frame.flux.astype(np.float32))
    paths = {"flux": str(out / "flux.npy"), "truth": str(out / "truth.json"), "preview": str(out / "preview.png")}
    if frame.points is not None and frame.target_diffuse is not None:  # the film before the lens PSF
        lab = frame.lab if frame.lab is not None else np.float32(0.0)
        np.save(out / "flux_diffuse.npy", (frame.target_diffuse + lab).astype(np.float32))
        frame.points.save(out / "points.npz")
        paths.update({"flux_diffuse": str(out / "flux_diffuse.npy"), "points": str(out / "points.npz")})
    if not args.no_expose:

        ex = frame.exposer().expose(seed=args.seed, exposure_s=args.exposure_s, iso=args.iso)
        truth["exposure"] = {"exposure_s": ex.exposure_s, "iso": ex.iso, "gain_dn_per_e": ex.gain_dn_per_e,
                             **{k: v for k, v in ex.info.items()}}
        np.save(out / "raw.npy", ex.raw_dn.astype(np.float32))
        write_image(out / "image.png", ex.image)
        paths.update({"raw": str(out / "raw.npy"), "image": str(out / "image.png")})
    from svgs_sim.cli.solve import json_default

    (out / "truth.json").write_text(json.dumps(truth, indent=2, default=json_default), encoding="utf-8")
    write_preview(out / "preview.png", frame.flux)
    summary = {
        "out": paths,
        "variant": info["variant"],
        "total_flux_photons_per_s": float(frame.flux.sum(dtype="float64")),
        "targets_px": truth["targets_px"],
        "timings_s": info.get("timings_s", {}),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"rendered {camera.name} at range {scen.distance_m:g} m with {info['variant']} in {frame.render_s:.2f} s")
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

    def dist_version(pkg):
        try:
            return md.version(pkg)
        except md.PackageNotFoundError:
            return None

    for pkg in ("svgs-sim", "mitsuba", "drjit", "karellen-llvm-core", "numpy", "numba", "scipy"):
        versions[pkg] = dist_version(pkg)
    # OpenCV ships as one of four distributions (the project installs the contrib headless one)
    opencv = ("opencv-contrib-python-headless", "opencv-python-headless", "opencv-contrib-python", "opencv-python")
    found = {p: v for p in opencv if (v := dist_version(p)) is not None}
    versions.update(found or {opencv[0]: None})
    versions["scikit-image"] = dist_version("scikit-image")
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
    print(f"{'python':31s} {rep['python']} on {rep['platform']}")
    for k, v in rep["versions"].items():
        print(f"{k:31s} {v or 'not installed'}")
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

