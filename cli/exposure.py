"""``svgs exposure-study``: what would have extended a phone's range (the paper's remedies).

The paper: "Possible remedies for this issue could include replacing the corner cubes with
reflectors with a lower return brightness or increasing the spacing between the
reflectors." This study renders the scenario over a set of ranges and, for each remedy,
exposes and solves ``--trials`` noise draws per range:

- ``baseline``: the profile as it is;
- ``exposure=T``: a fixed exposure of T seconds at base ISO (if the phone had allowed it);
- ``nd=OD``: a neutral-density filter of optical density OD over every reflector (the
  return passes it twice: the spots' flux scales by 10^(-2 OD)); render once, expose many;
- ``spacing=K``: the pattern scaled by K about its origin (a wider target; re-rendered).

It reports the success rate per range and remedy, the largest range at which >= 95 % of
trials solve, a CSV, a plot and a Markdown table.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from svgs.errors import InputError


def parse_remedy(text: str) -> tuple[str, float | None]:
    """'baseline', 'exposure=0.001', 'nd=1', 'spacing=1.5' -> (kind, value)."""
    if text == "baseline":
        return ("baseline", None)
    kind, _, val = text.partition("=")
    if kind not in ("exposure", "nd", "spacing") or not val:
        raise InputError(f"--remedy: expected baseline, exposure=SECONDS, nd=OD or spacing=FACTOR, got {text!r}")
    try:
        v = float(val)
    except ValueError:
        raise InputError(f"--remedy {text!r}: {val!r} is not a number") from None
    if not np.isfinite(v) or v <= 0 or (kind == "exposure" and v > 60) or (kind == "spacing" and v > 10):
        raise InputError(f"--remedy {text!r}: value out of range")
    return (kind, v)


def scaled_pattern_file(pattern, factor: float, folder: Path) -> str:
    """Write the pattern scaled by ``factor`` about its origin as a TOML file; returns its path."""
    import tomli_w

    from svgs.profiles import Pattern

    pat = Pattern.load(pattern)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{pat.name}-x{factor:g}.toml"
    data = {"name": f"{pat.name}-x{factor:g}", **{k: v for k, v in pat.tables.items()},
            "target": [{"id": int(i), "x_m": float(p[0] * factor), "y_m": float(p[1] * factor), "z_m": float(p[2] * factor)}
                       for i, p in zip(pat.ids, pat.points_m)]}
    with open(path, "wb") as fh:
        tomli_w.dump(data, fh)
    return str(path)


def run_study(camera, ranges, remedies, *, trials=5, seed=0, out: Path, pattern="svgs-3u", progress=True):
    """Rows of (remedy, range_m, trial, ok, reason, n_blobs, exposure_s, iso, errors)."""
    from tqdm import tqdm

    from svgs.profiles import Camera

    from sim.closed_loop import Scenario, expose_and_solve, render_scenario

    cam = Camera.load(camera)
    base_iso = float((cam.tables.get("sensor") or {}).get("base_iso", 100.0))
    parsed = [(r, *parse_remedy(r)) for r in remedies]
    rows = []
    bar = tqdm(total=len(ranges) * len(parsed) * trials, desc="exposure study", unit="trial", disable=not progress,
               file=sys.stderr)
    for ri, rng_m in enumerate(ranges):
        frames = {}
        for name, kind, val in parsed:
            pat = scaled_pattern_file(pattern, val, out / "patterns") if kind == "spacing" else pattern
            if pat not in frames:
                frames[pat] = render_scenario(Scenario(camera=camera, pattern=pat, range_m=rng_m), seed=ri)
            frame = frames[pat]
            exposer = frame.exposer(target_scale=10.0 ** (-2.0 * val) if kind == "nd" else 1.0)
            for k in range(trials):
                row = expose_and_solve(frame, exposer, seed=seed * 1000003 + ri * 1009 + k,
                                       exposure_s=val if kind == "exposure" else None,
                                       iso=base_iso if kind == "exposure" else None)
                rows.append({"remedy": name, "range_m": rng_m, "trial": k, "ok": row["ok"], "reason": row["reason"],
                             "n_blobs": row["n_blobs"], "exposure_s": row["exposure_s"], "iso": row["iso"],
                             "pos_err_m": None if row["pos_err_m"] is None else float(np.linalg.norm(row["pos_err_m"])),
                             "rot_err_deg": row["rot_err_deg"]})
                bar.update(1)
    bar.close()
    return rows


def summarise(rows, remedies, ranges):
    table = []
    for name in remedies:
        d = {"remedy": name}
        best = None
        for r in ranges:
            rr = [x for x in rows if x["remedy"] == name and x["range_m"] == r]
            rate = float(np.mean([x["ok"] for x in rr])) if rr else float("nan")
            d[f"{r:g} m"] = rate
            if rate >= 0.95 and (best is None or r > best):
                best = r
        d["max_range_95_m"] = best
        table.append(d)
    return table


def cmd_exposure_study(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cli.sim import _check_camera_renderable, _parse_ranges

    _check_camera_renderable(args.camera)
    ranges = _parse_ranges(args.ranges)
    remedies = args.remedy or ["baseline", "exposure=0.001", "exposure=0.0002", "nd=1", "nd=2", "spacing=1.5", "spacing=2"]
    for r in remedies:
        parse_remedy(r)
    if args.trials < 1:
        raise InputError(f"--trials must be >= 1, got {args.trials}")
    out = Path(args.out or f"exposure-study-{Path(str(args.camera)).stem}")
    rows = run_study(args.camera, ranges, remedies, trials=args.trials, seed=args.seed, out=out)
    table = summarise(rows, remedies, ranges)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "trials.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(out / "summary.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(table[0]))
        w.writeheader()
        w.writerows(table)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for d in table:
        ax.plot(ranges, [d[f"{r:g} m"] for r in ranges], "o-", label=d["remedy"])
    ax.axhline(0.95, color="grey", lw=0.5)
    ax.set(xlabel="range (m)", ylabel="fraction of trials solved", title=f"{args.camera}: remedies", ylim=(-0.05, 1.05))
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "remedies.png", dpi=110)
    plt.close(fig)
    lines = ["| remedy | " + " | ".join(f"{r:g} m" for r in ranges) + " | max range (>= 95 %) |",
             "|---|" + "---|" * len(ranges) + "---|"]
    for d in table:
        lines.append(f"| {d['remedy']} | " + " | ".join(f"{d[f'{r:g} m']:.2f}" for r in ranges)
                     + f" | {d['max_range_95_m'] if d['max_range_95_m'] is not None else '-'} |")
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {out / 'summary.csv'}, {out / 'summary.md'}, {out / 'trials.csv'}, {out / 'remedies.png'}")
    return 0


def register(sub) -> None:
    p = sub.add_parser("exposure-study", help="which remedy (exposure, ND filter, spacing) extends the range",
                       description=__doc__.split("\n\n")[1].replace("\n", " ") + " Writes summary.csv, summary.md, "
                       "trials.csv and remedies.png.")
    p.add_argument("--camera", required=True, help="camera profile (needs [optics] and [flash])")
    p.add_argument("--ranges", default="2,4,6.5,8,10,15,20,30", help="comma-separated ranges, m")
    p.add_argument("--remedy", action="append", default=None,
                   help="baseline | exposure=SECONDS | nd=OD | spacing=FACTOR (repeat; default: a standard set)")
    p.add_argument("--trials", type=int, default=5, help="noise draws per range and remedy (default 5)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=None, help="output folder (default exposure-study-CAMERA)")
    p.set_defaults(func=cmd_exposure_study)
