"""Part 1 of the calibration study: convergence of a full calibration with the number of views.

A board set (rendered by :func:`svgs_sim.sim.boards.render_board_set`, or geometric views from
:func:`svgs_sim.calibration.synthesize_views`) is searched for the board once (:func:`detect_all`);
then OpenCV calibrates from N of its views, for each N of a list, over several subsets
(:func:`convergence_subsets`), and each calibration is judged against the true camera
(:func:`calibration_errors`). One calibration is one trial of the kind
``calibration-convergence`` (:mod:`svgs_sim.studies.calibration.trials`); the detections it reads
are kept in the study folder (:func:`save_detections`).
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import DISTORTION_KEYS, Camera
from svgs_sim.calibration import Board, calibrate, detect_views, mapping_error_px
from svgs_sim.svgs.result import Failure

from .common import (
    DEFAULT_SUBSETS,
    DEFAULT_VIEWS_LIST,
    camera_columns,
    camera_from_columns,
)

#: Columns of one calibration's errors (:func:`calibration_errors`), in order.
#: The measured calibration errors use the names of the injected ones (``pp_error_u_px``,
#: ``pp_error_v_px``: estimate minus truth, px; ``fx_error_pct``, ``fy_error_pct``: estimate /
#: truth - 1, in %; ``pp_error_norm_px``: the norm of the principal-point error, px).
ERROR_COLUMNS = ("fx_px", "fy_px", "cx_px", "cy_px", *DISTORTION_KEYS, "fx_error_pct", "fy_error_pct",
                 "pp_error_u_px", "pp_error_v_px", "pp_error_norm_px", "map_rms_px", "map_max_px", "map_rot_rms_px",
                 "map_rot_max_px", "rms_px", "std_fx_px", "std_cx_px")
#: The columns' names before issue 25 (old -> new), read from stored results by
#: :func:`upgrade_stored_columns`.
RENAMED_COLUMNS = {"fx_err_pct": "fx_error_pct", "fy_err_pct": "fy_error_pct", "cx_err_px": "pp_error_u_px",
                   "cy_err_px": "pp_error_v_px", "pp_err_px": "pp_error_norm_px"}


@dataclass
class Detections:
    """Board features found in a set of images.

    Attributes
    ----------
    object_points : list of ndarray (M_k, 3)
    image_points : list of ndarray (M_k, 2)
    names : list of str
        Views where the board was found.
    skipped : list of (str, Failure)
    image_size : (int, int)
    """

    object_points: list
    image_points: list
    names: list
    skipped: list
    image_size: tuple

    def __len__(self) -> int:
        return len(self.names)


def detect_all(images, board: Board, names=None) -> Detections:
    """Detect the board in every image (views without it are listed in ``skipped``).

    Parameters
    ----------
    images : sequence of ndarray, shape (H, W) or (H, W, 3)
    board : Board
    names : sequence of str, optional
        Default ``view 1``, ``view 2``...

    Raises
    ------
    InputError
        No images, or images of different sizes.
    """
    images = [np.asarray(im) for im in images]
    if not images:
        raise InputError("calibration study: no board images")
    names = [f"view {k + 1}" for k in range(len(images))] if names is None else [str(n) for n in names]
    bad = [im.shape for im in images if im.ndim not in (2, 3) or im.size == 0]
    if bad:
        raise InputError(f"image: expected a 2-D grey or (H, W, 3) colour image, got shape {bad[0]}")
    sizes = {(im.shape[1], im.shape[0]) for im in images}
    if len(sizes) > 1:
        raise InputError(f"calibration study: board images differ in size ({sorted(sizes)})")
    obj, img, used, skipped = detect_views(images, names, board)
    return Detections(obj, img, used, skipped, sizes.pop())


def save_detections(path, det: Detections, camera: Camera, info: dict) -> None:
    """Write detections, the camera that made the images and the set's description to ``.npz``.

    Written to a temporary name and renamed, so a killed run leaves no partial file.
    """

    path = Path(path)
    counts = np.array([len(p) for p in det.object_points], int)
    meta = {"names": det.names, "skipped": [[n, f.reason, f.message] for n, f in det.skipped],
            "image_size": list(det.image_size), "camera": camera_columns("", camera), "info": info}
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, counts=counts,
             object_points=np.concatenate(det.object_points) if det.object_points else np.zeros((0, 3)),
             image_points=np.concatenate(det.image_points) if det.image_points else np.zeros((0, 2)),
             meta=np.array(json.dumps(meta, default=float)))
    os.replace(tmp, path)


def load_detections(path) -> tuple[Detections, Camera, dict]:
    """Read what :func:`save_detections` wrote: (detections, image camera, set description)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            counts, obj, img, meta = z["counts"], z["object_points"], z["image_points"], json.loads(str(z["meta"]))
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(f"{str(path)!r}: not a board-detections file ({exc})") from None
    cut = np.cumsum(counts)[:-1]
    det = Detections(list(np.split(obj, cut)) if counts.size else [], list(np.split(img, cut)) if counts.size else [],
                     meta["names"], [(n, Failure(r, m)) for n, r, m in meta["skipped"]], tuple(meta["image_size"]))
    return det, camera_from_columns("", meta["camera"], name="images"), meta["info"]


def calibration_errors(cal, camera_true: Camera, step_px: float | None = None) -> dict:
    """Errors of a :class:`svgs_sim.calibration.Calibration` against the true camera.

    Returns
    -------
    dict
        :data:`ERROR_COLUMNS`: the estimates, ``fx_error_pct``, ``fy_error_pct``, ``pp_error_u_px``,
        ``pp_error_v_px``, ``pp_error_norm_px``, ``map_rms_px``/``map_max_px`` (mapping error over the
        image, no alignment), ``map_rot_rms_px``/``map_rot_max_px`` (after the best rotation,
        which absorbs most of a principal-point error), ``rms_px``, ``std_fx_px``, ``std_cx_px``.
    """
    est = cal.to_camera(name="estimate")
    step = step_px or max(camera_true.width, camera_true.height) / 40.0
    m0 = mapping_error_px(camera_true, est, step_px=step)
    m1 = mapping_error_px(camera_true, est, step_px=step, align="rotation")
    row = {
        "fx_px": cal.fx, "fy_px": cal.fy, "cx_px": cal.cx, "cy_px": cal.cy,
        **{k: float(v) for k, v in zip(DISTORTION_KEYS, cal.dist)},
        "fx_error_pct": 100.0 * (cal.fx / camera_true.fx - 1.0),
        "fy_error_pct": 100.0 * (cal.fy / camera_true.fy - 1.0),
        "pp_error_u_px": cal.cx - camera_true.cx,
        "pp_error_v_px": cal.cy - camera_true.cy,
        "map_rms_px": float(np.sqrt(np.mean(m0**2))),
        "map_max_px": float(m0.max()),
        "map_rot_rms_px": float(np.sqrt(np.mean(m1**2))),
        "map_rot_max_px": float(m1.max()),
        "rms_px": float(cal.rms_px),
        "std_fx_px": float(cal.std["fx"]), "std_cx_px": float(cal.std["cx"]),
    }
    row["pp_error_norm_px"] = float(np.hypot(row["pp_error_u_px"], row["pp_error_v_px"]))
    return {k: row[k] for k in ERROR_COLUMNS}


def upgrade_stored_columns(folder) -> bool:
    """Rename the columns of a convergence results store written before issue 25
    (:data:`RENAMED_COLUMNS`) in ``results.csv``'s header and ``manifest.json``, so that its
    results are read and resumed; the values are untouched.

    Parameters
    ----------
    folder : str or Path
        The store's folder (``OUT/trials/convergence``); a missing or current one is left alone.

    Returns
    -------
    bool
        Whether anything was renamed.
    """
    folder = Path(folder)
    manifest, results = folder / "manifest.json", folder / "results.csv"
    if not manifest.is_file():
        return False
    stored = json.loads(manifest.read_text())
    cols = stored.get("columns", [])
    if not set(RENAMED_COLUMNS) & set(cols):
        return False
    stored["columns"] = [RENAMED_COLUMNS.get(c, c) for c in cols]
    if results.is_file():
        data = results.read_bytes()
        head, sep, rest = data.partition(b"\n")
        names = head.decode("utf-8").split(",")
        tmp = results.with_suffix(".csv.tmp")
        tmp.write_bytes(",".join(RENAMED_COLUMNS.get(c, c) for c in names).encode("utf-8") + sep + rest)
        os.replace(tmp, results)
    tmp = manifest.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(stored, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, manifest)
    return True


def check_views_list(detections: Detections, camera_true: Camera, views_list) -> list[int]:
    """The sorted, distinct numbers of views, checked against the detections and the camera.

    Raises
    ------
    InputError
        An N below 3 or above the number of views with the board (the message lists the
        skipped views), or an image size that is not the camera's.
    """
    n_have = len(detections)
    if (camera_true.width, camera_true.height) != tuple(detections.image_size):
        raise InputError(f"calibration study: images are {detections.image_size[0]} x {detections.image_size[1]} px "
                         f"but camera {camera_true.name!r} is {camera_true.width} x {camera_true.height} px")
    vl = sorted({int(v) for v in views_list})
    if not vl:
        raise InputError("--views-list: no number of views given")
    if vl[0] < 3:
        raise InputError(f"--views-list: a calibration needs at least 3 views, got {vl[0]}")
    if vl[-1] > n_have:
        skipped = _skipped_text(detections.skipped)
        raise InputError(f"--views-list: {vl[-1]} views asked but the board was found in only {n_have}"
                         + (f" (skipped: {skipped})" if skipped else "")
                         + (f"; give numbers from 3 to {n_have}" if n_have >= 3 else
                            "; a calibration needs 3: a board with fewer, larger squares, or a larger image"))
    return vl


def _skipped_text(skipped) -> str:
    """The views the detection skipped, each with its reason; a reason shared by more than three
    views once, with their count (the message stays one line a reader takes in)."""
    by_reason: dict[str, list[str]] = {}
    for name, failure in skipped:
        by_reason.setdefault(failure.message, []).append(name)
    parts = []
    for reason, names in by_reason.items():
        if len(names) > 3:
            parts.append(f"{len(names)} views, {names[0]} to {names[-1]} ({reason})")
        else:
            parts.extend(f"{n} ({reason})" for n in names)
    return "; ".join(parts[:8])


def convergence_subsets(n_have: int, views_list, subsets: int = DEFAULT_SUBSETS, seed: int = 0) -> list[tuple]:
    """The calibrations of the convergence study: which views each one uses.

    Per N: the first N views, then ``subsets - 1`` random draws of N of the ``n_have`` views
    (one generator seeded with ``seed`` over all N, in order; a draw equal to an earlier
    one of the same N is dropped).

    Returns
    -------
    list of (n_views, subset, view_indices)
        ``view_indices`` a sorted tuple of int.
    """
    rng = np.random.default_rng(seed)
    out = []
    for n in views_list:
        seen = set()
        for s in range(max(1, int(subsets))):
            idx = tuple(range(n)) if s == 0 else tuple(sorted(rng.choice(n_have, n, replace=False).tolist()))
            if idx in seen:
                continue
            seen.add(idx)
            out.append((n, s, idx))
    return out


@contextlib.contextmanager
def _one_opencv_thread():
    import cv2

    n = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        yield
    finally:
        cv2.setNumThreads(n)


def calibrate_subset(detections: Detections, idx, camera_true: Camera, board: Board | None = None, **constraints):
    """Calibrate from the views ``idx`` of ``detections``; (row, calibration).

    The row holds :func:`calibration_errors` and ``views`` (the views' names, space-separated).
    OpenCV runs on one thread here: its multi-threaded solver adds up in an order that
    depends on the threads, which moves the result in the 12th digit from run to run.
    """
    with _one_opencv_thread():
        cal = calibrate([detections.object_points[i] for i in idx], [detections.image_points[i] for i in idx],
                        detections.image_size, views=[detections.names[i] for i in idx], board=board, **constraints)
    return {**calibration_errors(cal, camera_true), "views": " ".join(detections.names[i] for i in idx)}, cal


def calibration_convergence(detections: Detections, camera_true: Camera, views_list=DEFAULT_VIEWS_LIST, *,
                            subsets: int = DEFAULT_SUBSETS, seed: int = 0, board: Board | None = None, **constraints):
    """Calibrate from N views for each N, over several subsets, against the truth (in this process).

    Parameters
    ----------
    detections : Detections
        From :func:`detect_all`.
    camera_true : Camera
        The true geometry of the images.
    views_list : sequence of int
        Numbers of views; each at least 3 and at most the views with the board.
    subsets : int
        Subsets per N (:func:`convergence_subsets`).
    seed : int
    board : Board, optional
        Recorded in the calibrations.
    **constraints
        Passed to :func:`svgs_sim.calibration.calibrate`.

    Returns
    -------
    rows : list of dict
        One per calibration: ``n_views``, ``subset``, :func:`calibration_errors` and ``views``.
    calibrations : dict
        ``n_views -> Calibration`` of the first subset.
    """
    vl = check_views_list(detections, camera_true, views_list)
    rows, cals = [], {}
    for n, s, idx in convergence_subsets(len(detections), vl, subsets, seed):
        row, cal = calibrate_subset(detections, idx, camera_true, board, **constraints)
        if s == 0:
            cals[n] = cal
        rows.append({"n_views": n, "subset": s, **row})
    return rows, cals


def convergence_summary(rows) -> list[dict]:
    """Per N: mean and worst absolute errors over the subsets."""
    out = []
    for n in sorted({r["n_views"] for r in rows}):
        rs = [r for r in rows if r["n_views"] == n]

        def agg(k, f, rs=rs):
            return float(f([abs(r[k]) for r in rs]))

        out.append({
            "n_views": n, "subsets": len(rs),
            "fx_error_pct_mean_abs": agg("fx_error_pct", np.mean), "fx_error_pct_max_abs": agg("fx_error_pct", np.max),
            "fy_error_pct_mean_abs": agg("fy_error_pct", np.mean), "fy_error_pct_max_abs": agg("fy_error_pct", np.max),
            "pp_error_norm_px_mean": agg("pp_error_norm_px", np.mean),
            "pp_error_norm_px_max": agg("pp_error_norm_px", np.max),
            "map_rms_px_mean": agg("map_rms_px", np.mean),
            "map_rot_rms_px_mean": agg("map_rot_rms_px", np.mean), "map_rot_rms_px_max": agg("map_rot_rms_px", np.max),
            "rms_px_mean": agg("rms_px", np.mean),
        })
    return out
