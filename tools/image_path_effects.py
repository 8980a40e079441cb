"""How much each stage of the phone's image path moves the spot centroids and the pose (issue
24, deliverable 1): a findings table for ``docs/camera-model.md``, not a fit.

One render per range of the nominal scene (``svgs_sim.sim.closed_loop.Scenario(camera, range_m)``: the
fitted profile, the lab's light), then ``--seeds`` exposures (noise seeds 0..n-1, the same
draws for every configuration: common random numbers) through each configuration of the ISP,
each solved by the app's chain. Per configuration and range it prints

- ``scatter``: the centroids' standard deviation over the exposures, px per axis (RMS over
  the four targets and both axes);
- ``dbias``: the centroids' mean offset from the targets' true projections less the offset
  common to the four targets (the flash-to-lens parallax moves every spot alike), px per axis
  (RMS over targets and axes): the bias that changes the pattern's shape;
- ``shift b`` and ``shift s``: the paired difference from the reference configuration (the
  one named in the list, the same noise draws), px per axis: its mean over the exposures (RMS
  over targets and axes: the bias the stage adds) and its standard deviation over them (the
  scatter it adds);
- ``std x/y/roll`` and ``|mean| x/y/roll``: the pose errors' scatter and bias (m, deg).

Run: ``.venv/bin/python tools/image_path_effects.py [--ranges 10 20 30] [--seeds 6]``
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def configurations(isp):
    """``(name, reference name, stages removed, isp, demosaic, cfa)`` of every configuration,
    from the profile's ``[isp]`` (its quality kept)."""
    q = isp.jpeg_quality or 90
    gray = dataclasses.replace(isp, jpeg_subsampling="gray", jpeg_quality=q)
    c444 = dataclasses.replace(isp, jpeg_subsampling="4:4:4", jpeg_quality=q)
    c420 = dataclasses.replace(isp, jpeg_subsampling="4:2:0", jpeg_quality=q)
    no_jpeg = ("jpeg",)
    out = [
        ("gray, no JPEG", None, no_jpeg, gray, None, True),
        (f"gray q{q} (before issue 24)", "gray, no JPEG", (), gray, None, True),
        ("colour, no JPEG", None, no_jpeg, c444, None, True),
        (f"colour 4:4:4 q{q}", f"colour 4:2:0 q{q}", (), c444, None, True),
        (f"colour 4:2:0 q{q}", "colour, no JPEG", (), c420, None, True),
        ("colour 4:2:0 q95", "colour, no JPEG", (), dataclasses.replace(c420, jpeg_quality=95), None, True),
    ]
    for off in ((4, 4), (8, 8)):
        out.append((f"colour 4:2:0 q{q} grid +{off[0]},+{off[1]}", f"colour 4:2:0 q{q}", (),
                    dataclasses.replace(c420, jpeg_grid_offset_px=off), None, True))
    for m in ("edge_aware", "vng"):
        out.append((f"colour 4:2:0 q{q} demosaic {m}", f"colour 4:2:0 q{q}", (), c420, m, True))
    for label, kw in (("NR Gaussian 0.7 px", {"nr_sigma_px": 0.7}),
                      ("NR bilateral 1 px, 0.1", {"nr_sigma_px": 1.0, "nr_range": 0.1}),
                      ("sharpen 0.5, 1 px", {"sharpen_amount": 0.5, "sharpen_sigma_px": 1.0}),
                      ("sharpen 1.0, 1 px", {"sharpen_amount": 1.0, "sharpen_sigma_px": 1.0})):
        out.append((f"colour 4:2:0 q{q} + {label}", f"colour 4:2:0 q{q}", (), dataclasses.replace(c420, **kw), None,
                    True))
    out.append(("mono, no JPEG", "gray, no JPEG", no_jpeg, gray, None, False))
    out.append((f"mono q{q}", "mono, no JPEG", (), gray, None, False))
    return out


def centroids(row, frame, pattern):
    """The identified targets' centroids minus their true projections, (N, 2) px (NaN: unsolved)."""
    from svgs_sim.sim.closed_loop import solver_camera

    sol = row["_solution"]
    if not sol:
        return np.full((len(pattern.ids), 2), np.nan)
    R, t = frame.scenario.pose()
    uv = solver_camera(frame.camera, row["_exposure"].image.shape).project_target(pattern.points_m, R, t)
    return np.array([sol.targets_px[i] for i in pattern.ids], float) - uv


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranges", type=float, nargs="+", default=[10.0, 20.0, 30.0], help="ranges, m (default 10 20 30)")
    ap.add_argument("--seeds", type=int, default=6, help="exposures (noise seeds) per configuration (default 6)")
    ap.add_argument("--camera", default="galaxy-nexus", help="phone profile (default galaxy-nexus)")
    args = ap.parse_args(argv)
    from svgs_sim.camera.phone import ALL_STAGES
    from svgs_sim.sim.closed_loop import Scenario, expose_and_solve, render_scenario
    from svgs_sim.base.profiles import Pattern

    print(f"{args.camera}: {args.seeds} exposures per configuration; centroids px per axis, pose m / deg")
    for r in args.ranges:
        t0 = time.perf_counter()
        frame = render_scenario(Scenario(camera=args.camera, range_m=float(r)))
        pattern = Pattern.load(frame.scenario.pattern)
        exposers = {True: frame.exposer(), False: frame.exposer(tuple(s for s in ALL_STAGES if s != "cfa"))}
        configs = configurations(exposers[True].phone.params.isp)
        cen, err = {}, {}
        for name, _, off, isp, dem, cfa in configs:
            st = tuple(s for s in ALL_STAGES if s not in off and (cfa or s != "cfa"))
            rows = [expose_and_solve(frame, exposers[cfa], seed=k, stages=st, isp=isp, demosaic=dem)
                    for k in range(args.seeds)]
            cen[name] = np.array([centroids(row, frame, pattern) for row in rows])  # (seeds, N, 2)
            err[name] = np.array([[np.nan] * 6 if row["state"] is None else
                                  [*row["pos_err_vec_m"], *row["att_err_vec_deg"]] for row in rows])
        print(f"\n{r:g} m (render and exposures {time.perf_counter() - t0:.0f} s)")
        print(f"{'configuration':40s} {'scatter':>7s} {'dbias':>6s} {'shift b':>7s} {'shift s':>7s}   {'std x':>6s} "
              f"{'std y':>6s} {'std roll':>8s}   {'|mean| x':>8s} {'|mean| y':>8s} {'|mean| roll':>11s}")
        for name, ref, *_ in configs:
            c = cen[name]
            scatter = np.sqrt(np.nanmean(np.nanvar(c, axis=0, ddof=1)))
            m = np.nanmean(c, axis=0)  # (N, 2)
            dbias = np.sqrt(np.nanmean((m - m.mean(axis=0)) ** 2))
            if ref:
                d = c - cen[ref]
                shift_b = np.sqrt(np.nanmean(np.nanmean(d, axis=0) ** 2))
                shift_s = np.sqrt(np.nanmean(np.nanvar(d, axis=0, ddof=1)))
            else:
                shift_b = shift_s = float("nan")
            e = err[name]
            sd = np.nanstd(e, axis=0, ddof=1)
            mn = np.abs(np.nanmean(e, axis=0))
            print(f"{name:40s} {scatter:7.4f} {dbias:6.3f} {shift_b:7.4f} {shift_s:7.4f}   {sd[0]:6.4f} {sd[1]:6.4f} "
                  f"{sd[3]:8.4f}   {mn[0]:8.4f} {mn[1]:8.4f} {mn[3]:11.4f}")


if __name__ == "__main__":
    main()
