"""``svgs approach``: a docking approach simulated frame by frame, as a resumable study.

Writes into ``out``:

- ``manifest.json`` and ``results.csv``: the crash-safe store (:mod:`svgs_sim.studies.store`): one row per
  finished frame, appended and fsynced as it finishes; a rerun with the same parameters continues
  where a killed run stopped (the auto-exposure state is read back from the last stored frame),
  and a rerun with other parameters is refused before any work;
- ``frames/NNNNN.jpg``: each frame's overlay (what the video is made of; by default the pixels the
  detector keeps, :data:`VIDEO_IMAGES`) and ``frames/video_image.txt`` (which image they show);
- ``measurements.csv``: one row per frame, in time order (:data:`svgs_sim.sim.approach.MEASUREMENT_COLUMNS`);
- ``approach.mp4`` (OpenCV ``VideoWriter``, codec ``mp4v``, MPEG-4 Part 2; where the OpenCV build
  cannot write it, ``approach.avi`` with Motion-JPEG, and the summary says which);
- ``approach.png``: the errors against time and range, with the CRLB bands and the dropouts;
- ``summary.json``: frames, solved, failures by reason, RMS error per component over range bins,
  where the time went.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import time
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.base.image_files import VideoFile, read_image, write_image
from svgs_sim.sim import hard_stop
from svgs_sim.sim.approach import MEASUREMENT_COLUMNS, TIMING_KEYS, ApproachSensor, Trajectory, check_visible
from svgs_sim.sim.closed_loop import RenderOptions, Scenario
from svgs_sim.sim.scene import Scene
from svgs_sim.studies.diagnosis import (FAR_ABOVE_BOUND, bound_ratios, cause_text, far_above, glint_geometry,
                                        glint_targets_of_state)
from svgs_sim.studies.execution import StoredProgress
from svgs_sim.studies.progress import progress_bar
from svgs_sim.studies.store import ResultStore
from svgs_sim.svgs.frames import STATE_KEYS
from svgs_sim.svgs.overlay import render_overlay, solution_marks

#: Range bins of the summary's RMS errors, m (edges; each bin is [lo, hi), labelled so, the last one
#: open above: a frame at 5.0 m is in [5, 10), not in [2, 5)).
RANGE_BIN_EDGES_M = (0.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 40.0)
#: Size of a video frame, px (width, height): each frame's overlay, letterboxed.
VIDEO_SIZE_PX = (960, 720)
#: Slowest playback of the video, frames/s (slower approaches play faster than real time).
MIN_VIDEO_FPS = 2.0
FRAMES_DIR = "frames"
#: What a video frame shows. ``detector``: the pixels the detector keeps (above its threshold,
#: stretched from it; the rest black), which the deferred camera path has without making the full
#: image. ``delivered``: the whole delivered image, stretched from the frame's median (the full
#: image made for every frame: about twice the frame's time at full resolution).
VIDEO_IMAGES = ("detector", "delivered")
#: The file in ``frames/`` that records which of :data:`VIDEO_IMAGES` its pictures show.
VIDEO_IMAGE_FILE = "video_image.txt"
TEXT_COLUMNS = ("reason",)


def make_config(camera: str, trajectory: Trajectory, fps: float, *, seed: int = 0, preview: bool = False,
                motion: bool = True, crlb: bool = True, pattern: str = "svgs-3u", threshold=None,
                scene: Scene | None = None, body: dict | None = None, dark_pixels: str = "deferred") -> dict:
    """The approach's parameters (the store's manifest): what decides the numbers. ``threshold``:
    the detector's (None or ``"app"``: the app's for the camera, :mod:`svgs_sim.svgs.app`; ``"auto"``,
    ``"otsu"`` or a level in 8-bit counts). ``scene``: around the target (default the paper's lab;
    recorded as ``scene`` only when it is another, so a study folder made before the option resumes).
    ``dark_pixels``: how the camera model makes the dark pixels (:class:`svgs_sim.sim.approach.ApproachSensor`;
    recorded only when ``"fast"``, which changes the numbers: ``deferred`` and ``exact`` give the same)."""
    from svgs_sim.svgs.detect import parse_threshold

    t = parse_threshold(None if threshold is None else str(threshold))
    cfg = {"study": "approach", "camera": str(camera), "pattern": str(pattern), "fps": float(fps), "seed": int(seed),
           "preview": bool(preview), "motion": bool(motion), "crlb": bool(crlb), "trajectory": trajectory.to_json(),
           "threshold": "app" if t is None else t if isinstance(t, str) else float(t)}
    if scene is not None and scene != Scene():
        cfg["scene"] = scene.to_json()
    if dark_pixels == "fast":
        cfg["dark_pixels"] = str(dark_pixels)
    if body and any(v not in (None, {}, ()) for v in body.values()):  # recorded only when given: older folders resume
        opts = RenderOptions(**body)  # checked before any work
        cfg["body"] = {"body": opts.body, "body_material": opts.body_material,
                       "body_materials": dict(opts.body_materials)}
    return cfg


def scene_of(cfg: dict) -> Scene:
    """The scene around the target of a config (:func:`make_config`)."""
    return Scene(**cfg["scene"]) if "scene" in cfg else Scene()


def _threshold(cfg: dict):
    """The detector's ``threshold`` argument of a config (None: the app's)."""
    t = cfg.get("threshold", "app")
    return None if t == "app" else t


def sensor_camera(cfg: dict):
    """The camera the sensor images through: the profile, or its binned preview stream."""

    if cfg["preview"]:
        from svgs_sim.camera.phone.preview import binned_camera

        return binned_camera(cfg["camera"])
    return load_camera(cfg["camera"])


def trajectory_of(cfg: dict) -> Trajectory:
    return Trajectory.from_json(cfg["trajectory"])


def check_config(cfg: dict):
    """Everything checked before any rendering: the camera (a phone that renders, frames at this
    rate), the frames, the poses.

    Returns
    -------
    camera : svgs.Camera
        The camera the sensor images through (:func:`sensor_camera`).
    trajectory : Trajectory
    times_s : ndarray, shape (n,)
        The frame times, s.
    """
    cam = sensor_camera(cfg)
    for t in ("optics", "flash"):
        cam.table(t)  # before the trajectory's checks: a camera that cannot render is the first problem
    traj = trajectory_of(cfg)
    times = traj.frame_times(cfg["fps"])
    check_visible(traj, times, cam, cfg["pattern"])
    ApproachSensor(cam, cfg["pattern"], frame_rate_hz=cfg["fps"])  # the phone can take frames at this rate
    return cam, traj, times


def _overlay(m, cam, pattern, title: str, view: str = "detector") -> np.ndarray:
    """A video frame: the frame's overlay (:data:`VIDEO_IMAGES`), letterboxed to :data:`VIDEO_SIZE_PX`."""
    import cv2

    targets, reproj = solution_marks(m.solution, cam, pattern)
    if view == "detector":
        # the pixels above the threshold are the same in the detector's image and the delivered one
        # (an integer image's pixel passes a level when it passes the level's floor, as in the detector;
        # the detector's level is always finite)
        img, label = m.detect_image, "the threshold"
        black = float(math.floor(m.threshold_u8)) if np.issubdtype(img.dtype, np.integer) else float(m.threshold_u8)
    else:  # the delivered image
        img, black, label = m.image, None, None
    pic = render_overlay(img, blobs_px=m.blobs_px if m.blobs_px is not None else (), targets_px=targets,
                         reprojected_px=reproj, title=title, size_px=min(VIDEO_SIZE_PX) - 40, black_level=black,
                         black_label=label)
    W, H = VIDEO_SIZE_PX
    s = min(W / pic.shape[1], H / pic.shape[0])
    pic = cv2.resize(pic, (max(1, int(pic.shape[1] * s)), max(1, int(pic.shape[0] * s))), interpolation=cv2.INTER_AREA)
    canvas = np.zeros((H, W, 3), np.uint8)
    y0, x0 = (H - pic.shape[0]) // 2, (W - pic.shape[1]) // 2
    canvas[y0:y0 + pic.shape[0], x0:x0 + pic.shape[1]] = pic
    return canvas


def _check_video_image(frames_dir: Path, video_image: str, *, record: bool = True) -> None:
    """Refuse a ``video_image`` other than the one of the pictures already in ``frames_dir``
    (pictures without a record are from before the choice: ``delivered``; a record without
    pictures, of a run stopped before its first picture, is not binding); with ``record``,
    record it there."""
    marker = frames_dir / VIDEO_IMAGE_FILE
    had = None
    if any(frames_dir.glob("*.jpg")):
        had = marker.read_text(encoding="utf-8").strip() if marker.is_file() else "delivered"
    if had is not None and had != video_image:
        raise InputError(f"--video-image {video_image}: the stored frames' pictures in {str(frames_dir)!r} show the "
                         f"{had} image; continue with --video-image {had} (or remove the folder to start again)")
    if record and had is None:
        marker.write_text(video_image + "\n", encoding="utf-8")


def _title(m) -> str:
    """A video frame's title line."""
    return (f"t = {m.t_s:7.2f} s  range {m.range_m:6.2f} m  " + ("SOLVED" if m.ok else f"NO SOLUTION ({m.reason})")
            + f"  exposure {m.exposure_s * 1e3:.2f} ms ISO {m.iso:.0f}")


def run_approach(cfg: dict, out_dir, *, progress: bool = True, on_frame=None, command: str | None = None,
                 overlap_render: bool = True, video: bool = True, video_image: str = "detector") -> dict:
    """Run (or continue) an approach into ``out_dir`` and write its outputs.

    Parameters
    ----------
    cfg : dict
        From :func:`make_config`.
    out_dir : str or Path
    progress : bool
        A progress bar on stderr.
    on_frame : callable, optional
        Called with each new :class:`svgs_sim.sim.approach.Measurement` (tests).
    command : str, optional
        The command line that made the run, for ``report.md``.
    overlap_render : bool
        Render the next frame in a background thread (:class:`svgs_sim.sim.approach.ApproachSensor`).
    video : bool
        Write each frame's overlay picture and the video. Off: no pictures and no video (the same
        numbers).
    video_image : {"detector", "delivered"}
        What the pictures show (:data:`VIDEO_IMAGES`). A run continued with the other one is
        refused before any work (its video would mix the two).

    Returns
    -------
    dict
        The summary (:func:`summarise`) with ``outputs`` and ``run`` (frames run now, reused).
    """
    import cv2


    if video_image not in VIDEO_IMAGES:
        raise InputError(f"video_image: expected one of {', '.join(VIDEO_IMAGES)}, got {video_image!r}")
    cam, traj, times = check_config(cfg)
    out = Path(out_dir)
    ids = range(len(times))
    store = ResultStore(out, cfg, ("trial_id",) + MEASUREMENT_COLUMNS, trial_ids=ids, text_columns=TEXT_COLUMNS)
    pattern = load_pattern(cfg["pattern"])
    t_start = t_first = time.perf_counter()
    n_new = 0
    with store.open():
        done = store.done_ids
        todo = [k for k in ids if k not in done]
        if todo and todo != list(range(todo[0], len(times))):
            raise InputError(f"--out {str(out)!r}: the stored frames have a gap before frame {todo[0]}; a stream can "
                             "only continue from its last frame (remove the folder to start again)")
        frames_dir = out / FRAMES_DIR
        frames_dir.mkdir(exist_ok=True)
        if video:  # the pictures stored must show the same image (and the command in report.md say so)
            _check_video_image(frames_dir, video_image, record=bool(todo))
        if todo:
            sensor = ApproachSensor(cam, cfg["pattern"], seed=cfg["seed"], motion=cfg["motion"], crlb=cfg["crlb"],
                                    keep_images=(True if video_image == "delivered" else "detector") if video else False,
                                    frame_rate_hz=cfg["fps"], threshold=_threshold(cfg),
                                    overlap_render=overlap_render, base=Scenario(scene=scene_of(cfg)),
                                    body=cfg.get("body"), dark_pixels=cfg.get("dark_pixels", "deferred"))
            if todo[0] > 0:
                last = {r["trial_id"]: r for r in store.read_rows()}[todo[0] - 1]
                sensor.restore(todo[0], last["next_exposure_s"], last["next_iso"])
            def kept() -> StoredProgress:
                return StoredProgress(len(store.done_ids), len(times), str(out))

            # the scope outermost: a Ctrl-C that waits for the background render (closing) is stopped too
            with hard_stop.scope(kept), progress_bar(len(todo), f"approach {cfg['camera']}", progress,
                                                     unit="frame") as bar, contextlib.closing(sensor):
                for k in todo:
                    # the next frame renders while this one is exposed, solved and written
                    m = sensor.measure_on(traj, float(times[k]),
                                          next_t_s=float(times[k + 1]) if k + 1 < len(times) else None)
                    picture = _overlay(m, cam, pattern, _title(m), video_image) if video else None
                    with hard_stop.protected():  # Ctrl-C inside a render stops the process, never mid-write
                        if picture is not None:
                            write_image(frames_dir / f"{k:05d}.jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, 90])
                        store.append([{"trial_id": k, **m.row()}])
                    n_new += 1
                    if n_new == 1:  # the first frame builds the scene and compiles the kernels
                        t_first = time.perf_counter()
                    if on_frame is not None:
                        on_frame(m)
                    bar.update(1)
        rows = store.read_rows()
    t_end = time.perf_counter()
    wall = t_end - t_start
    summary = summarise(rows, cfg)
    # the wall time a frame takes once running, pictures and all (the timing block is the sensor's stages)
    per_frame = (t_end - t_first) / (n_new - 1) if n_new > 1 else None
    summary["run"] = {"frames_run": n_new, "frames_reused": len(rows) - n_new, "wall_s": wall,
                      "wall_per_frame_s": per_frame}
    summary["outputs"] = write_outputs(rows, cfg, out, glint_frames=summary["far_above_bound"]["glint_frames"])
    summary["outputs"]["report"] = str(write_report(summary, out / "report.md", command))
    (out / "summary.json").write_text(json.dumps(summary, indent=1, allow_nan=False) + "\n", encoding="utf-8")
    return summary


def _num(v):
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else v


def summarise(rows: list[dict], cfg: dict) -> dict:
    """frames, solved, failures by reason, RMS error per component over range bins, timings."""
    n = len(rows)
    ok = [r for r in rows if int(r["ok"]) == 1]
    reasons: dict = {}
    for r in rows:
        if int(r["ok"]) != 1:
            reasons[r["reason"] or "unknown"] = reasons.get(r["reason"] or "unknown", 0) + 1
    bins = []
    edges = list(RANGE_BIN_EDGES_M) + [math.inf]
    for lo, hi in zip(edges[:-1], edges[1:]):
        inbin = [r for r in rows if lo <= float(r["range_m"]) < hi]  # [lo, hi): a 30 m start is in [30, 40)
        if not inbin:
            continue
        sol = [r for r in inbin if int(r["ok"]) == 1]
        b = {"range_m": [lo, None if math.isinf(hi) else hi], "frames": len(inbin), "solved": len(sol)}
        for k in STATE_KEYS:
            e = np.array([float(r[f"err_{k}"]) for r in sol], float)
            c = np.array([float(r[f"crlb_{k}"]) for r in sol if _num(r[f"crlb_{k}"]) is not None], float)
            b[f"rms_err_{k}"] = float(np.sqrt(np.mean(e**2))) if e.size else None
            b[f"mean_err_{k}"] = float(np.mean(e)) if e.size else None
            b[f"rms_crlb_{k}"] = float(np.sqrt(np.mean(c**2))) if c.size else None
        bins.append(b)
    # time per frame: over the frames after the first (which builds the scene and compiles kernels);
    # the bound's over the solved frames (the only ones that compute it)
    timed = [r for r in rows if int(r["frame"]) > 0] or rows
    timing = {}
    for k in TIMING_KEYS:
        v = [float(r[f"{k}_s"]) for r in timed if _num(r.get(f"{k}_s")) is not None
             and (k != "crlb" or int(r["ok"]) == 1)]
        timing[f"mean_{k}_s"] = float(np.mean(v)) if v else None
    n_solved_timed = sum(int(r["ok"]) == 1 for r in timed)
    share = n_solved_timed / len(timed) if timed else 0.0  # the bound's time spread over all frames
    per_frame = sum(v * (share if k == "mean_crlb_s" else 1.0) for k, v in timing.items() if v is not None)
    timing["mean_frame_s"] = per_frame
    timing["frames_per_s"] = 1.0 / per_frame if per_frame > 0 else None
    solved_ranges = [float(r["range_m"]) for r in ok]
    return {
        "camera": cfg["camera"], "preview": cfg["preview"], "fps": cfg["fps"], "seed": cfg["seed"],
        "trajectory": cfg["trajectory"]["source"], "frames": n, "solved": len(ok),
        "solved_fraction": len(ok) / n if n else 0.0, "failures": reasons,
        # poses the app would report with a blob off its target's spot (svgs_sim.sim.approach.Measurement.wrong_lock)
        "wrong_locks": sum(int(r.get("wrong_lock") or 0) for r in rows),
        "solved_range_m": [min(solved_ranges), max(solved_ranges)] if solved_ranges else None,
        "rms_by_range": bins, "far_above_bound": far_above_bound(rows, cfg), "timing": timing,
    }


def bin_label(lo: float, hi) -> str:
    """A range bin of :data:`RANGE_BIN_EDGES_M` as written in the report: ``[2, 5)``, ``[40, inf)``."""
    return f"[{lo:g}, {'inf' if hi is None else f'{hi:g}'})"


def far_above_bound(rows: list[dict], cfg: dict, factor: float | None = None) -> dict:
    """The solved frames with an error far above its CRLB, and whether the head-on glint explains them.

    Parameters
    ----------
    rows : list of dict
        The stored frames (:data:`svgs_sim.sim.approach.MEASUREMENT_COLUMNS`).
    cfg : dict
        The approach's config (its camera and pattern: the glint's geometry).
    factor : float, optional
        "Far above": ``|error| >= factor x CRLB`` (default :data:`svgs_sim.studies.diagnosis.FAR_ABOVE_BOUND`).

    Returns
    -------
    dict
        ``factor``; ``frames``: the frame numbers; ``glint_frames``: those of them at which a cube's
        front-face glint reaches the lens (:func:`svgs_sim.studies.diagnosis.front_glint_targets`);
        ``worst``: ``{"frame", "range_m", "component", "ratio"}`` of the largest ratio, or None.
    """

    factor = FAR_ABOVE_BOUND if factor is None else float(factor)
    frames, glint, worst = [], [], None
    cam = geometry = None
    for r in sorted(rows, key=lambda r: int(r["frame"])):
        if int(r["ok"]) != 1:
            continue
        big = far_above(bound_ratios({k: _num(_float(r.get(f"err_{k}"))) for k in STATE_KEYS},
                                     {k: _num(_float(r.get(f"crlb_{k}"))) for k in STATE_KEYS}), factor)
        if not big:
            continue
        f = int(r["frame"])
        frames.append(f)
        k, ratio = next(iter(big.items()))
        if worst is None or ratio > worst["ratio"]:
            worst = {"frame": f, "range_m": float(r["range_m"]), "component": k, "ratio": float(ratio)}
        if cam is None:  # the glint's geometry (the target's meshes) once for every frame
            cam = sensor_camera(cfg)
            geometry = glint_geometry(cam, cfg["pattern"])
        if glint_targets_of_state(cam, cfg["pattern"], {k: float(r[f"true_{k}"]) for k in STATE_KEYS},
                                  geometry=geometry):
            glint.append(f)
    return {"factor": factor, "frames": frames, "glint_frames": glint, "worst": worst}


def _float(v):
    """A stored cell as a float (None for an empty one)."""
    return None if v is None or v == "" else float(v)


def bound_line(s: dict) -> str | None:
    """The report's one line on errors far above their bound (None when there are none)."""

    fb = s.get("far_above_bound") or {}
    n = len(fb.get("frames") or ())
    if not n:
        return None
    w, g = fb["worst"], len(fb["glint_frames"])
    line = (f"**{n} of {s['solved']} solved frames have an error >= {fb['factor']:g}x its CRLB** (worst: "
            f"{w['component']} {w['ratio']:.0f}x at {w['range_m']:.2f} m, frame {w['frame']}): ")
    if g == n:
        return line + cause_text(glint=True) + "."
    if g == 0:
        return line + cause_text(glint=False) + "."
    return (line + f"{g} of them (frames {', '.join(map(str, fb['glint_frames']))}) "
            + cause_text(glint=True).replace("likely ", "likely at ", 1) + "; the other " + str(n - g) + ": "
            + cause_text(glint=False) + ".")


def write_outputs(rows: list[dict], cfg: dict, out: Path, *, glint_frames=None) -> dict:
    """measurements.csv, the video and approach.png from the stored rows; returns their paths.
    ``glint_frames``: :func:`far_above_bound`'s, when the caller has them (else computed)."""

    paths = {}
    p = out / "measurements.csv"
    with open(p, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(MEASUREMENT_COLUMNS)
        for r in sorted(rows, key=lambda r: r["frame"]):
            w.writerow(["" if _num(r.get(c)) is None else r[c] for c in MEASUREMENT_COLUMNS])
    paths["measurements"] = str(p)
    paths.update(write_video(out, cfg["fps"], len(rows)))
    paths["plot"] = str(plot_approach(rows, cfg, out / "approach.png", glint_frames=glint_frames))
    return paths


def write_video(out: Path, fps: float, n: int) -> dict:
    """The frames' overlays as a video: ``approach.mp4`` (mp4v), else ``approach.avi`` (MJPG)."""
    import cv2

    frames = [out / FRAMES_DIR / f"{k:05d}.jpg" for k in range(n)]
    rate = max(float(fps), MIN_VIDEO_FPS)
    missing = sum(not f.is_file() for f in frames)
    if missing:  # run (or partly run) with --no-video: an earlier video would show other frames
        for name in ("approach.mp4", "approach.avi"):
            (out / name).unlink(missing_ok=True)
        return {"video": None, "video_codec": f"none: {missing} of {n} frames run without pictures (--no-video)",
                "video_fps": rate}
    for name, fourcc, codec in (("approach.mp4", "mp4v", "mp4v (MPEG-4 Part 2)"),
                                ("approach.avi", "MJPG", "MJPG (Motion-JPEG)")):
        path = out / name
        vw = VideoFile(path, fourcc, rate, VIDEO_SIZE_PX)  # any path: OpenCV never sees it
        if not vw.isOpened():
            vw.release(keep=False)
            continue
        done = False
        try:
            for f in frames:
                img = read_image(f, cv2.IMREAD_COLOR)
                if img is None:
                    raise InputError(f"video: frame picture {str(f)!r} is missing or unreadable; rerun the approach")
                vw.write(img)
            done = True
        finally:
            vw.release(keep=done)
        if path.exists() and path.stat().st_size > 0:
            return {"video": str(path), "video_codec": codec, "video_fps": rate}
    return {"video": None, "video_codec": "none: this OpenCV build writes neither mp4v nor MJPG", "video_fps": rate}


def write_report(s: dict, path: Path, command: str | None) -> Path:
    """``report.md``: the command, what was solved, the RMS errors per range bin beside the CRLB,
    the plot and the video."""
    lines = [f"# Approach: {s['camera']}{' (preview stream)' if s['preview'] else ''}", ""]
    if command:
        lines += ["Regenerate with:", "", "```", command, "```", ""]
    lines += [f"Trajectory: {s['trajectory']}; {s['frames']} frames at {s['fps']:g} frames/s, seed {s['seed']}.", "",
              f"**Solved {s['solved']} of {s['frames']} frames** ({100 * s['solved_fraction']:.0f} %)"
              + (f", from {s['solved_range_m'][1]:.2f} m down to {s['solved_range_m'][0]:.2f} m" if s["solved_range_m"] else "")
              + "." + (" Failures: " + ", ".join(f"`{k}` {v}" for k, v in sorted(s["failures"].items())) + "."
                       if s["failures"] else ""), "",
              "RMS error (estimate - truth) per range bin, and in brackets the RMS of the frames' 1-sigma CRLB:", "",
              "| range, m | frames | solved | " + " | ".join(STATE_KEYS) + " |",
              "|---|---|---|" + "---|" * len(STATE_KEYS)]
    for b in s["rms_by_range"]:
        lo, hi = b["range_m"]
        cells = []
        for k in STATE_KEYS:
            e, c = b[f"rms_err_{k}"], b[f"rms_crlb_{k}"]
            cells.append("-" if e is None else f"{e:.4g}" + ("" if c is None else f" ({c:.2g})"))
        lines.append(f"| {bin_label(lo, hi)} | {b['frames']} | {b['solved']} | " + " | ".join(cells) + " |")
    note = bound_line(s)
    if note:
        lines += ["", note]
    t = s["timing"]
    lines += ["", "Mean time per frame on the machine that ran it: " + ", ".join(
        f"{k[5:-2]} {t[k]:.2f} s" for k in t if k.startswith("mean_") and k != "mean_frame_s" and t[k] is not None)
        + f" ({t['frames_per_s']:.2f} frames/s).", "",
        "![errors against time and range](approach.png)", ""]
    o = s["outputs"]
    if o.get("video"):
        lines += [f"Video of the delivered frames with overlays: [{Path(o['video']).name}]({Path(o['video']).name}) "
                  f"({o['video_codec']}, {o['video_fps']:g} frames/s).", ""]
    lines += ["Each frame's row (truth, estimate, error, CRLB, settings, timings): [measurements.csv](measurements.csv).", ""]
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def plot_approach(rows: list[dict], cfg: dict, path: Path, *, glint_frames=None) -> Path:
    """Errors against time (left) and range (middle), +-1-sigma CRLB bands, dropouts marked; and
    |error| / CRLB against range on a log scale (right), with 1 and the "far above"
    line (:data:`svgs_sim.studies.diagnosis.FAR_ABOVE_BOUND`): the bound stays visible beside errors a
    hundred times larger, and the frames at the head-on glint are marked."""

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rows = sorted(rows, key=lambda r: r["frame"])
    t = np.array([float(r["t_s"]) for r in rows])
    rng = np.array([float(r["range_m"]) for r in rows])
    ok = np.array([int(r["ok"]) == 1 for r in rows])
    glint = set(far_above_bound(rows, cfg)["glint_frames"] if glint_frames is None else glint_frames)
    at_glint = np.array([int(r["frame"]) in glint for r in rows])
    fig = Figure(figsize=(17, 14), constrained_layout=True)
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(STATE_KEYS), 3, sharex="col")
    for i, k in enumerate(STATE_KEYS):
        e = np.array([float(r[f"err_{k}"]) if ok[j] else np.nan for j, r in enumerate(rows)])
        c = np.array([float(r[f"crlb_{k}"]) if ok[j] and _num(r[f"crlb_{k}"]) is not None else np.nan
                      for j, r in enumerate(rows)])
        unit = "deg" if k.endswith("_deg") else "m"
        scale = 1.0 if unit == "deg" else 1000.0
        lab = k.replace("_deg", "").replace("_m", "") + (" error, deg" if unit == "deg" else " error, mm")
        for col, x in enumerate((t, rng)):
            ax = axes[i, col]
            order = np.argsort(x)
            ax.fill_between(x[order], -c[order] * scale, c[order] * scale, color="tab:green", alpha=0.3, lw=0,
                            label="+-1-sigma CRLB")
            ax.plot(x[order], e[order] * scale, ".-", ms=3, lw=0.8, color="tab:blue", label="estimate - truth")
            ax.axhline(0, color="k", lw=0.5)
            if (~ok).any():
                ax.vlines(x[~ok], 0, 1, transform=ax.get_xaxis_transform(), color="tab:red", alpha=0.25, lw=1)
            ax.set_ylabel(lab)
            if i == 0:
                ax.set_title(("against time" if col == 0 else "against range")
                             + f" ({int((~ok).sum())} dropouts in red)")
                ax.legend(loc="best", fontsize=8)
        ax = axes[i, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.abs(e) / c
        good = np.isfinite(ratio) & (ratio > 0)
        ax.set_yscale("log")
        ax.axhspan(1e-12, 1.0, color="tab:green", alpha=0.3, lw=0, label="within 1-sigma CRLB")
        ax.axhline(FAR_ABOVE_BOUND, color="tab:red", lw=0.8, ls="--", label=f"{FAR_ABOVE_BOUND:g}x: a bias, not noise")
        ax.semilogy(rng[good & ~at_glint], ratio[good & ~at_glint], ".", ms=4, color="tab:blue", label="|error| / CRLB")
        if (good & at_glint).any():
            ax.semilogy(rng[good & at_glint], ratio[good & at_glint], "x", ms=5, color="tab:orange",
                        label="at the head-on glint")
        top = float(np.nanmax(ratio[good])) if good.any() else FAR_ABOVE_BOUND
        bottom = float(np.nanmin(ratio[good])) if good.any() else 0.1
        ax.set_ylim(min(0.1, bottom / 2), max(2 * FAR_ABOVE_BOUND, 2 * top))
        ax.set_ylabel(k.replace("_deg", "").replace("_m", "") + " |error| / CRLB")
        if i == 0:
            ax.set_title("error in units of its bound (log)")
            ax.legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("t, s")
    axes[-1, 1].set_xlabel("range, m")
    axes[-1, 2].set_xlabel("range, m")
    if rng.size and rng[0] > rng[-1]:
        axes[-1, 1].invert_xaxis()
        axes[-1, 2].invert_xaxis()
    fig.suptitle(f"svgs approach: {cfg['camera']}{' (preview)' if cfg['preview'] else ''}, {len(rows)} frames at "
                 f"{cfg['fps']:g} fps, {int(ok.sum())} solved\n{cfg['trajectory']['source']}", fontsize=10)
    fig.savefig(path, dpi=80)
    return path
