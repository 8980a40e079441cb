"""What the sensor saw: a zoomed crop around the target with the detected blobs, their labels,
the reprojected solution and each point's 1-sigma ellipse, and a full-frame thumbnail marking
the crop (``overlay.png`` of ``svgs solve`` and ``svgs render-and-solve``).

numpy + OpenCV only (runs on real photos). Coordinates follow OpenCV: pixel centres at integers.
"""

from __future__ import annotations

import math

import numpy as np

from svgs_sim.base.image_files import write_image

#: Colours (BGR).
BLOB_BGR = (255, 200, 0)
LABEL_BGR = (0, 255, 255)
REPROJ_BGR = (60, 60, 255)
ELLIPSE_BGR = (80, 255, 80)
BOX_BGR = (0, 200, 255)
#: Sub-pixel drawing: OpenCV's ``shift`` bits.
_SHIFT = 4


def _display_u8(gray: np.ndarray, box, black_level: float | None = None) -> np.ndarray:
    """A square-root stretch from ``black_level`` (default the frame's median) to the crop's
    brightest pixel (white); pixels at or below ``black_level`` are black.

    An integer image goes through a table of its values (the same formula on each level: the
    same bytes as the formula on every pixel, without a float copy of the frame)."""
    x0, y0, x1, y1 = box
    if black_level is None:
        lo = float(np.median(np.asarray(gray[:: max(1, gray.shape[0] // 200), :: max(1, gray.shape[1] // 200)],
                                        np.float64)))
    else:
        lo = float(black_level)
    hi = float(np.max(gray[y0:y1, x0:x1])) if (x1 > x0 and y1 > y0) else float(np.max(gray))
    hi = max(hi, lo + 1e-9)

    def stretch(g):
        return (255.0 * np.sqrt(np.clip((g - lo) / (hi - lo), 0.0, 1.0)) + 0.5).astype(np.uint8)

    if gray.dtype in (np.uint8, np.uint16):
        import cv2

        table = stretch(np.arange(np.iinfo(gray.dtype).max + 1, dtype=np.float64))
        return cv2.LUT(gray, table) if gray.dtype == np.uint8 else table[gray]
    return stretch(np.asarray(gray, np.float64))


def _pt(u, v, x0, y0, s):
    """Image point -> fixed-point zoomed pixel coordinates (OpenCV ``shift`` units)."""
    f = 1 << _SHIFT
    return (int(round(((u - x0) + 0.5) * s * f)), int(round(((v - y0) + 0.5) * s * f)))


def crop_box(points_px, shape, margin_px: float = 40.0) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` around the points with a margin of max(``margin_px``, 60 % of their span)."""
    P = np.asarray(points_px, float).reshape(-1, 2)
    H, W = shape[:2]
    if P.size == 0:
        return 0, 0, W, H
    lo, hi = P.min(0), P.max(0)
    m = max(margin_px, 0.6 * float(np.max(hi - lo)))
    c = 0.5 * (lo + hi)
    half = 0.5 * float(np.max(hi - lo)) + m
    x0, y0 = int(max(0, math.floor(c[0] - half))), int(max(0, math.floor(c[1] - half)))
    x1, y1 = int(min(W, math.ceil(c[0] + half) + 1)), int(min(H, math.ceil(c[1] + half) + 1))
    return x0, y0, max(x1, x0 + 1), max(y1, y0 + 1)


def render_overlay(image, *, blobs_px=(), targets_px=None, reprojected_px=None, sigma_px=None,
                   sigma_label: str = "1-sigma", title: str = "", size_px: int = 900, notes=(),
                   black_level: float | None = None, black_label: str | None = None) -> np.ndarray:
    """The overlay picture.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        The delivered image (any dtype).
    blobs_px : array_like, shape (N, 2)
        Every detected blob's centroid.
    targets_px : dict, optional
        Target id -> ``[u, v]``: the identified blobs (labelled with the id).
    reprojected_px : dict, optional
        Target id -> ``[u, v]``: the solution's reprojection of each target.
    sigma_px : dict, optional
        Target id -> ``[sigma_u, sigma_v]`` (px): drawn as ellipses about the detected points,
        magnified by a power of ten that the legend states.
    sigma_label : str
        What the ellipses are (e.g. "CRLB 1-sigma").
    title : str
    size_px : int
        Longer side of the zoomed crop.
    notes : sequence of str
        Lines of a text panel below the picture (e.g. the error against the truth and
        error/CRLB per component); none: no panel.
    black_level : float, optional
        The level shown black: pixels at or below it are black, the brighter ones stretched up
        to the crop's brightest (default the frame's median). ``svgs approach`` gives the
        detector's threshold, so the picture shows exactly the pixels the detector keeps.
    black_label : str, optional
        What ``black_level`` is, for the caption (e.g. "the threshold").

    Returns
    -------
    ndarray of uint8, shape (h, w, 3)
        BGR picture.
    """
    import cv2

    img = np.asarray(image)
    gray = img.mean(axis=2) if img.ndim == 3 else img
    H, W = gray.shape
    targets_px = dict(targets_px or {})
    reprojected_px = dict(reprojected_px or {})
    blobs = np.asarray(blobs_px, float).reshape(-1, 2)
    anchor = np.array(list(targets_px.values()) or list(reprojected_px.values()) or blobs[:8].tolist() or [[W / 2, H / 2]],
                      float)
    x0, y0, x1, y1 = crop_box(anchor, gray.shape)
    disp = _display_u8(gray, (x0, y0, x1, y1), black_level)
    crop = disp[y0:y1, x0:x1]
    s = size_px / max(crop.shape)
    zoom = cv2.resize(crop, (max(1, int(round(crop.shape[1] * s))), max(1, int(round(crop.shape[0] * s)))),
                      interpolation=cv2.INTER_NEAREST if s >= 1 else cv2.INTER_AREA)
    out = cv2.cvtColor(zoom, cv2.COLOR_GRAY2BGR)
    for u, v in blobs:
        if x0 <= u < x1 and y0 <= v < y1:
            cv2.circle(out, _pt(u, v, x0, y0, s), 14 << _SHIFT, BLOB_BGR, 1, cv2.LINE_AA, _SHIFT)
    mag = _draw_sigma_ellipses(out, sigma_px, targets_px, x0, y0, s)
    for k, (u, v) in reprojected_px.items():
        c = _pt(u, v, x0, y0, s)
        d = 9 << _SHIFT
        cv2.line(out, (c[0] - d, c[1]), (c[0] + d, c[1]), REPROJ_BGR, 1, cv2.LINE_AA, _SHIFT)
        cv2.line(out, (c[0], c[1] - d), (c[0], c[1] + d), REPROJ_BGR, 1, cv2.LINE_AA, _SHIFT)
    for k, (u, v) in targets_px.items():
        c = _pt(u, v, x0, y0, s)
        org = (c[0] // (1 << _SHIFT) + 16, c[1] // (1 << _SHIFT) - 12)
        cv2.putText(out, str(k), org, cv2.FONT_HERSHEY_SIMPLEX, 0.7, LABEL_BGR, 2, cv2.LINE_AA)
    _inset_thumbnail(out, disp, (x0, y0, x1, y1))
    bar = _legend_bar(out.shape[1], title, sigma_label if sigma_px else None, mag)
    crop_txt = f"crop x {x0}-{x1} y {y0}-{y1} of {W}x{H} px, zoom {s:.2g}x"
    if black_level is not None:
        crop_txt += f", black up to {black_level:g}" + (f" ({black_label})" if black_label else "")
    cv2.putText(out, crop_txt, (8, out.shape[0] - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (200, 200, 200), 1, cv2.LINE_AA)
    parts = [bar, out]
    if notes:
        parts.append(_notes_panel(out.shape[1], notes))
    return np.vstack(parts)


#: Text panel: line height (px), font, font scale.
_NOTE_LINE_PX = 18
_NOTE_FONT = 1  # cv2.FONT_HERSHEY_PLAIN
_NOTE_SCALE = 1.0


def _notes_panel(width_px: int, notes) -> np.ndarray:
    """A black panel with the notes: the tab-separated cells of a line set in aligned columns (a
    table), a line without tabs wrapped at spaces to the picture's width.

    Parameters
    ----------
    width_px : int
        The picture's width.
    notes : sequence of str

    Returns
    -------
    ndarray of uint8, shape (18 n_lines + 10, width_px, 3)
    """
    import cv2

    rows = []
    for n in notes:
        cells = str(n).split("\t")
        rows += [cells] if len(cells) > 1 else [[w] for w in _wrap(cells[0], width_px - 16)]
    widths: dict = {}
    for r in rows:
        if len(r) > 1:
            for j, cell in enumerate(r):
                w = cv2.getTextSize(cell, _NOTE_FONT, _NOTE_SCALE, 1)[0][0]
                widths[j] = max(widths.get(j, 0), w)
    panel = np.zeros((_NOTE_LINE_PX * len(rows) + 10, width_px, 3), np.uint8)
    for i, r in enumerate(rows):
        x = 8
        for j, cell in enumerate(r):
            w = cv2.getTextSize(cell, _NOTE_FONT, _NOTE_SCALE, 1)[0][0]
            # numbers right-aligned in their column, the first column left-aligned
            dx = widths.get(j, w) - w if (len(r) > 1 and j > 0) else 0
            cv2.putText(panel, cell, (x + dx, _NOTE_LINE_PX * (i + 1)), _NOTE_FONT, _NOTE_SCALE, (255, 255, 255), 1,
                        cv2.LINE_AA)
            x += widths.get(j, w) + 16
    return panel


def _wrap(text: str, width_px: int) -> list[str]:
    """``text`` broken at spaces into lines no wider than ``width_px`` in the panel's font (a
    single word wider than that stays whole)."""
    import cv2

    lines, cur = [], ""
    for word in text.split(" "):
        trial = word if not cur else cur + " " + word
        if cur and cv2.getTextSize(trial, _NOTE_FONT, _NOTE_SCALE, 1)[0][0] > width_px:
            lines.append(cur)
            cur = word
        else:
            cur = trial
    return lines + [cur]


def _draw_sigma_ellipses(out, sigma_px, targets_px: dict, x0: int, y0: int, s: float) -> float:
    """Draw the uncertainty ellipses about the identified targets into ``out``.

    Parameters
    ----------
    out : ndarray of uint8, shape (h, w, 3)
        The zoomed BGR crop; drawn into in place.
    sigma_px : dict or None
        Target id -> ``[sigma_u, sigma_v]`` (px).
    targets_px : dict
        Target id -> ``[u, v]`` (frame px): the ellipses' centres.
    x0, y0 : int
        Frame pixel of the crop's top-left corner.
    s : float
        Zoom (picture px per frame px).

    Returns
    -------
    float
        The magnification of the ellipses (a power of ten, 1 without ``sigma_px``).
    """
    import cv2

    mag = 1.0
    if sigma_px:
        sig = np.array([np.asarray(v, float) for v in sigma_px.values()])
        big = float(np.nanmax(sig)) * s if sig.size and np.isfinite(sig).any() else 0.0
        if big > 0:
            mag = 10.0 ** max(0, math.ceil(math.log10(12.0 / big)))
        for k, sv in sigma_px.items():
            if k not in targets_px or not np.all(np.isfinite(sv)):
                continue
            u, v = targets_px[k]
            axes = (max(1, int(round(sv[0] * s * mag * (1 << _SHIFT)))), max(1, int(round(sv[1] * s * mag * (1 << _SHIFT)))))
            cv2.ellipse(out, _pt(u, v, x0, y0, s), axes, 0.0, 0.0, 360.0, ELLIPSE_BGR, 1, cv2.LINE_AA, _SHIFT)
    return mag


def _inset_thumbnail(out, disp, box) -> None:
    """Paste a thumbnail of the full frame, with the crop ``box`` marked, into ``out``'s top-right corner.

    Parameters
    ----------
    out : ndarray of uint8, shape (h, w, 3)
        The zoomed BGR crop; drawn into in place (not when the thumbnail would not fit).
    disp : ndarray of uint8, shape (H, W)
        The full frame for display.
    box : tuple of int
        ``(x0, y0, x1, y1)``: the crop in frame px.
    """
    import cv2

    x0, y0, x1, y1 = box
    H, W = disp.shape
    tw = max(80, out.shape[1] // 4)
    th = max(1, int(round(H * tw / W)))
    thumb = cv2.cvtColor(_area_reduce(disp, tw, th), cv2.COLOR_GRAY2BGR)
    f = tw / W
    cv2.rectangle(thumb, (int(x0 * f), int(y0 * f)), (max(int(x0 * f) + 2, int(x1 * f)), max(int(y0 * f) + 2, int(y1 * f))),
                  BOX_BGR, 1)
    cv2.rectangle(thumb, (0, 0), (tw - 1, th - 1), (200, 200, 200), 1)
    if th < out.shape[0] and tw < out.shape[1]:
        out[0:th, out.shape[1] - tw:] = thumb


def _area_reduce(img: np.ndarray, width_px: int, height_px: int) -> np.ndarray:
    """``img`` averaged down to ``(height_px, width_px)`` (OpenCV's ``INTER_AREA``), first by the
    largest whole factor that divides both sides and stays within the reduction: OpenCV's
    whole-factor path is several times faster on a full frame than its general one (1.5 against
    11 ms for 2592 x 1944 -> 170 x 128); both steps cover the whole frame. A frame less than
    twice the size asked for (or smaller) takes the one step."""
    import cv2

    H, W = img.shape[:2]
    f = max((k for k in range(2, min(W // width_px, H // height_px) + 1) if W % k == 0 and H % k == 0), default=1)
    if f > 1:
        img = cv2.resize(img, (W // f, H // f), interpolation=cv2.INTER_AREA)
    return cv2.resize(img, (width_px, height_px), interpolation=cv2.INTER_AREA)


def _legend_bar(width_px: int, title: str, sigma_label, mag: float) -> np.ndarray:
    """The title and legend bar above the overlay.

    Parameters
    ----------
    width_px : int
        The picture's width.
    title : str
    sigma_label : str or None
        What the ellipses are; None: no ellipses drawn (no legend entry).
    mag : float
        The ellipses' magnification.

    Returns
    -------
    ndarray of uint8, shape (58, width_px, 3)
    """
    import cv2

    bar = np.zeros((58, width_px, 3), np.uint8)
    cv2.putText(bar, title[:110], (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    legend = [("o detected blob", BLOB_BGR), ("1-4 target labels", LABEL_BGR), ("+ reprojected solution", REPROJ_BGR)]
    if sigma_label is not None:
        legend.append((f"ellipse: {sigma_label} x{mag:g}", ELLIPSE_BGR))
    x = 8
    for text, col in legend:
        cv2.putText(bar, text, (x, 46), cv2.FONT_HERSHEY_SIMPLEX, 0.45, col, 1, cv2.LINE_AA)
        x += 12 + 8 * len(text)
    return bar


def solution_marks(result, camera, pattern) -> tuple[dict, dict]:
    """What an overlay draws of a solve: the identified blobs and the solution's reprojection.

    Parameters
    ----------
    result : svgs_sim.svgs.solver.Solution or a failure (falsy)
    camera : svgs.Camera
        The solver's camera (at the image's size).
    pattern : svgs.Pattern

    Returns
    -------
    targets_px, reprojected_px : dict
        Target id (str) -> ``[u, v]`` px; both empty for a failure.
    """
    if not result:
        return {}, {}
    targets = {str(k): [float(x) for x in v] for k, v in result.targets_px.items()}
    uv = camera.project_target(pattern.points_m, result.R_cam_target, result.t_cam_target_m)
    reproj = {str(int(i)): [float(a), float(b)] for i, (a, b) in zip(pattern.ids, uv)}
    return targets, reproj


def write_overlay(path, image, **kw) -> str:
    """:func:`render_overlay` written as a PNG; returns the path."""
    write_image(path, render_overlay(image, **kw))
    return str(path)


def window_centroid(gray, u, v, half_px: int = 6) -> tuple[float, float, float]:
    """The linear intensity-weighted centroid of the ``(2 half + 1)^2`` window at ``(u, v)``, its
    background (median of the window's border) subtracted: ``(cu, cv, net flux)``."""
    g = np.asarray(gray, np.float64)
    H, W = g.shape
    iu, iv = int(round(u)), int(round(v))
    xa, xb = max(0, iu - half_px), min(W, iu + half_px + 1)
    ya, yb = max(0, iv - half_px), min(H, iv + half_px + 1)
    win = g[ya:yb, xa:xb]
    ring = np.concatenate([win[0], win[-1], win[:, 0], win[:, -1]])
    net = win - np.median(ring)
    F = float(net.sum())
    yy, xx = np.mgrid[ya:yb, xa:xb]
    if F <= 0:
        return float("nan"), float("nan"), F
    return float((net * xx).sum() / F), float((net * yy).sum() / F), F


def centroid_sigma_from_image(gray, points_px, noise_sigma: float, half_px: int = 6) -> np.ndarray:
    """1-sigma of :func:`window_centroid` at each point from the image's background noise
    alone, shape (N, 2) px: first-order propagation, ``sigma_u^2 = [sum (u_i - c_u)^2 s^2 +
    (n (mean u_i - c_u))^2 var_b] / F^2`` (``s`` the frame's noise per pixel, ``F`` the window's
    net flux, ``var_b = pi/2 s^2 / n_border`` that of the border median). A lower bound for a real
    photo: its shot noise needs the gain, which a photo does not carry."""
    g = np.asarray(gray, np.float64)
    H, W = g.shape
    out = []
    for u, v in np.asarray(points_px, float).reshape(-1, 2):
        cu, cv, F = window_centroid(g, u, v, half_px)
        if not F > 0:
            out.append([np.inf, np.inf])
            continue
        iu, iv = int(round(u)), int(round(v))
        xa, xb = max(0, iu - half_px), min(W, iu + half_px + 1)
        ya, yb = max(0, iv - half_px), min(H, iv + half_px + 1)
        yy, xx = np.mgrid[ya:yb, xa:xb]
        n = xx.size
        n_ring = 2 * (xb - xa) + 2 * (yb - ya)
        var_b = 0.5 * math.pi * noise_sigma**2 / n_ring  # the border median's variance
        row = []
        for q, c in ((xx, cu), (yy, cv)):
            lever = n * (float(q.mean()) - c)  # d(centroid)/d(background) x F
            row.append(math.sqrt(float(((q - c) ** 2).sum()) * noise_sigma**2 + lever**2 * var_b) / F)
        out.append(row)
    return np.array(out)


__all__ = ["render_overlay", "write_overlay", "crop_box", "window_centroid", "centroid_sigma_from_image"]
