"""``svgs sun-study``: where SVGS holds lock on orbit, loses it, or locks onto a glint.

A grid of ranges and sun directions (azimuth, elevation in the target frame:
:func:`svgs_sim.render.sun.sun_direction_target`), ``trials`` rendered trials per cell on the study
engine (plan, progress, resume, a process pool or Dask): the render trial kind with the scene's
``environment = "orbit"`` and the sun. Each trial's pose is drawn over the paper's test envelope
at the cell's range: roll and pitch uniform in +/-25 deg, yaw uniform in +/-45 deg, the target on
the boresight (``design_rng`` of the trial: the same draw on a rerun, a resume or a cluster).

Each trial is one of (``solved + wrong_lock + sum(reasons) == trials``):

- **solved**: the sensor reported a pose and every identified blob is its target's spot;
- **wrong_lock**: a pose the paper's app would report (it reports every solution: solved, or refused
  only by this simulator's consistency test) with an identified blob that is not its target's spot:
  farther than ``max(3 px, the spot's image radius)`` from the spot's predicted centroid
  (:data:`WRONG_LOCK_PX`; the spot's own centroid lies up to a few pixels from the target's
  projection at close range, by the flash's offset from the lens). ``wrong_lock_flagged`` of them
  the consistency test refused; ``wrong_lock_paper_gates``: the wrong locks of the same images
  identified with the gates of earlier versions (the paper's test envelope instead of the sensor's
  physical one, :func:`svgs_sim.svgs.envelope.physical_envelope`): the wider gates' cost;
- a failure, counted by its reason in ``reasons`` (``inconsistent``: refused by the consistency
  test with the right blobs).

Mechanisms, counted per cell (a trial may show several): ``sun_in_fov`` (the sun's disk projects
into the image), ``lit_body`` (pixels at or above the detector's threshold away from every spot:
the sunlit body or a glint), ``glint`` (more blobs passed the detector's gates than there are
targets), ``saturation`` (pixels at full scale away from the spots), ``earth_background`` (the
Earth in the image, with ``--earth-deg``).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.render.sun import sun_direction_target, sun_in_image
from svgs_sim.render.earth import earth_in_image, in_eclipse
from svgs_sim.sim.scene import BODIES, Scene
from svgs_sim.sim.render_trial import RENDER, render_trial_scenario
from svgs_sim.sim.metrics import WRONG_LOCK_PX, wrong_lock_px
from svgs_sim.studies.execution import Trial, library_versions, run_stored_study
from svgs_sim.studies.seeding import check_seed, design_rng, trial_seed
from svgs_sim.svgs.envelope import PAPER_ENVELOPE, check_range_m
from svgs_sim.svgs.frames import pose_from_scenario

#: The mechanisms counted per cell.
MECHANISMS = ("sun_in_fov", "lit_body", "glint", "saturation", "earth_background")


@dataclass(frozen=True)
class SunStudyConfig:
    """What a sun study computes (its manifest).

    Attributes
    ----------
    camera, pattern : str
    ranges_m : tuple of float
        Boresight distances of the grid, m.
    azimuths_deg, elevations_deg : tuple of float
        Sun directions of the grid in the target frame, deg.
    trials : int
        Trials per cell.
    seed : int
    earth : tuple or None
        ``(azimuth_deg, elevation_deg, altitude_km)`` of the Earth in every trial (the target frame;
        :mod:`svgs_sim.render.earth`), or None: no Earth.
    earth_albedos : tuple of float
        The Earth's albedos, an axis of the grid (with the Earth; ``(0.3,)`` without).
    body : {"plate", "3u", "none"}
        The target's body in every trial (:attr:`svgs_sim.sim.scene.Scene.body`).
    """

    camera: str
    pattern: str
    ranges_m: tuple
    azimuths_deg: tuple
    elevations_deg: tuple
    trials: int
    seed: int = 0
    earth: tuple | None = None
    earth_albedos: tuple = (0.3,)
    body: str = "plate"

    def cells(self) -> list[tuple[float, float, float, float]]:
        """``(range_m, earth_albedo, azimuth_deg, elevation_deg)`` of every cell, in the trials' order."""
        return [(r, b, a, e) for r in self.ranges_m for b in self.earth_albedos for a in self.azimuths_deg
                for e in self.elevations_deg]

    @property
    def n_trials(self) -> int:
        return len(self.cells()) * self.trials

    def manifest(self) -> dict:
        d = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
        if d["earth"] is None:  # no Earth: the manifest of a study made before the Earth
            del d["earth"], d["earth_albedos"]
        return {"study": "sun-study", "trial_kind": "render", **d}

    def earth_parameters(self, albedo: float) -> dict:
        """The Earth's scene parameters of a trial (empty: no Earth)."""
        if self.earth is None:
            return {}
        az, el, alt = self.earth
        return {"earth_azimuth_deg": az, "earth_elevation_deg": el, "altitude_km": alt, "earth_albedo": albedo}


def _angles(values, what: str, lim: float) -> tuple:
    out = []
    for v in values:
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise InputError(f"{what}: expected numbers in deg, got {v!r}") from None
        if not (np.isfinite(x) and -lim <= x <= lim):
            raise InputError(f"{what}: expected -{lim:g} to {lim:g} deg, got {v!r}")
        out.append(x)
    if not out or len(set(out)) != len(out):
        raise InputError(f"{what}: expected distinct values, got {list(values)!r}")
    return tuple(out)


def make_config(camera: str, ranges_m, azimuths_deg, elevations_deg, trials: int, *, seed: int = 0,
                pattern: str = "svgs-3u", earth=None, earth_albedos=None, body: str = "plate") -> SunStudyConfig:
    """A checked configuration (InputError naming the input, before any work). ``earth``:
    ``(azimuth_deg, elevation_deg, altitude_km)`` or None; ``earth_albedos``: the albedos swept
    (default 0.3; only with the Earth); ``body``: ``plate``, ``3u`` or ``none``."""
    cam, pat = load_camera(camera), load_pattern(pattern)
    for t in ("optics", "flash"):
        cam.table(t)
    rs = tuple(check_range_m(ranges_m, cam, pat, "--ranges"))
    if len(set(rs)) != len(rs):
        raise InputError(f"--ranges: repeated range in {list(rs)}")
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
        raise InputError(f"--trials: expected a whole number >= 1, got {trials!r}")
    albedos = (0.3,)
    if earth_albedos is not None:
        if earth is None:
            raise InputError("--earth-albedos: the Earth's; give them with --earth-deg AZ,EL")
        albedos = tuple(_albedo(x) for x in earth_albedos)
        if not albedos or len(set(albedos)) != len(albedos):
            raise InputError(f"--earth-albedos: expected distinct values, got {list(earth_albedos)!r}")
    if body not in BODIES:
        raise InputError(f"--body: a study takes one of {', '.join(BODIES)} (a mesh file renders with svgs render, "
                         f"render-and-solve and approach), got {body!r}")
    if earth is not None:
        az, el, alt = (float(x) for x in earth)
        for albedo in albedos:
            Scene(environment="orbit", earth_azimuth_deg=az, earth_elevation_deg=el, altitude_km=alt,
                  earth_albedo=albedo)
        earth = (az, el, alt)
    return SunStudyConfig(str(camera), str(pattern), rs, _angles(azimuths_deg, "--sun-azimuths-deg", 360.0),
                          _angles(elevations_deg, "--sun-elevations-deg", 90.0), int(trials), check_seed(seed), earth,
                          albedos, str(body))


def _albedo(v) -> float:
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(f"--earth-albedos: expected numbers 0 to 1, got {v!r}") from None
    if not (np.isfinite(x) and 0.0 <= x <= 1.0):
        raise InputError(f"--earth-albedos: expected numbers 0 to 1, got {v!r}")
    return x


def _pose(rng) -> dict:
    """A pose over the paper's test envelope: roll, pitch, yaw uniform within its limits."""
    env = PAPER_ENVELOPE
    return {"roll_deg": float(rng.uniform(-env.roll_deg, env.roll_deg)),
            "pitch_deg": float(rng.uniform(-env.pitch_deg, env.pitch_deg)),
            "yaw_deg": float(rng.uniform(-env.yaw_deg, env.yaw_deg))}


def sun_study_trials(config: SunStudyConfig) -> list:
    """Every trial: cell by cell (range, then azimuth, then elevation), ``trials`` per cell."""
    out = []
    for c, (r, albedo, az, el) in enumerate(config.cells()):
        for k in range(config.trials):
            i = c * config.trials + k
            scen = render_trial_scenario(
                camera=config.camera, pattern=config.pattern, range_m=r, **_pose(design_rng(config.seed, i)),
                environment="orbit", sun_azimuth_deg=az, sun_elevation_deg=el, **config.earth_parameters(albedo),
                body=BODIES.index(config.body), labels={"cell": c, "trial_in_cell": k})
            out.append(Trial(i, scen, trial_seed(config.seed, i)))
    return out


def phase_angle_deg(azimuth_deg: float, elevation_deg: float) -> float:
    """Target -> sun against target -> camera (the camera on the target's +z, head-on), deg."""
    return float(np.degrees(np.arccos(np.clip(sun_direction_target(azimuth_deg, elevation_deg)[2], -1.0, 1.0))))


def sun_in_fov(camera, row: dict) -> bool:
    """Whether the sun's disk projects into the image for a trial's pose and sun."""
    R, _ = pose_from_scenario(row["range_m"], 0.0, 0.0, row["roll_deg"], row["pitch_deg"], row["yaw_deg"])
    return sun_in_image(camera, R, sun_direction_target(row["sun_azimuth_deg"], row["sun_elevation_deg"]))


def earth_in_view(camera, row: dict) -> bool:
    """Whether the Earth lies in the image for a trial's pose (False without the Earth)."""
    az, el = row.get("earth_azimuth_deg"), row.get("earth_elevation_deg")
    if az is None or el is None or az != az:
        return False
    R, _ = pose_from_scenario(row["range_m"], 0.0, 0.0, row["roll_deg"], row["pitch_deg"], row["yaw_deg"])
    return earth_in_image(camera, R, sun_direction_target(az, el), 1e3 * float(row.get("altitude_km") or 400.0))


def classify(rows, camera, pattern) -> list[dict]:
    """Each trial's outcome (``solved``, ``wrong_lock`` or its failure reason), whether the consistency
    test flagged it, and its mechanisms."""
    out = []
    n_t = len(pattern.ids)
    for row in rows:
        err = row.get("match_err_max_px")
        reported = bool(row["ok"]) or row.get("reason") == "inconsistent"
        lim = wrong_lock_px(camera, pattern, row["range_m"])
        wrong = reported and err is not None and err == err and err > lim
        outcome = "wrong_lock" if wrong else "solved" if row["ok"] else str(row.get("reason") or "unknown")
        err_p = row.get("paper_gates_match_err_max_px")
        wrong_p = bool(row.get("paper_gates_reported")) and err_p is not None and err_p == err_p and err_p > lim
        stray = row.get("stray_px") or 0
        out.append({"outcome": outcome, "flagged": wrong and not row["ok"], "wrong_lock_paper_gates": wrong_p,
                    "sun_in_fov": sun_in_fov(camera, row), "lit_body": stray > 0,
                    "glint": (row.get("n_blobs") or 0) > n_t, "saturation": (row.get("stray_saturated_px") or 0) > 0,
                    "earth_background": earth_in_view(camera, row)})
    return out


def cells(config: SunStudyConfig, rows) -> list[dict]:
    """The cells of the study (see the module docstring), in the grid's order."""
    cam, pat = load_camera(config.camera), load_pattern(config.pattern)
    by = {}
    for row, c in zip(rows, classify(rows, cam, pat)):
        by.setdefault(int(row["cell"]), []).append(c)
    out = []
    for i, (r, albedo, az, el) in enumerate(config.cells()):
        cs = by.get(i, [])
        reasons = {}
        for c in cs:
            if c["outcome"] not in ("solved", "wrong_lock"):
                reasons[c["outcome"]] = reasons.get(c["outcome"], 0) + 1
        out.append({"range_m": r, **({"earth_albedo": albedo} if config.earth else {}),
                    "sun_azimuth_deg": az, "sun_elevation_deg": el,
                    "phase_angle_deg": phase_angle_deg(az, el), "trials": len(cs),
                    "solved": sum(c["outcome"] == "solved" for c in cs),
                    "wrong_lock": sum(c["outcome"] == "wrong_lock" for c in cs),
                    "wrong_lock_flagged": sum(c["flagged"] for c in cs),
                    "wrong_lock_paper_gates": sum(c["wrong_lock_paper_gates"] for c in cs),
                    "reasons": dict(sorted(reasons.items())),
                    "mechanisms": {m: sum(bool(c[m]) for c in cs) for m in MECHANISMS}})
    return out


#: The target's body in every trial (:attr:`SunStudyConfig.body`), as the reports say it.
BODY = {"plate": "the lab's breadboard (`plate`: the pattern's mounts on a dark Lambertian plate 12 mm beyond them, "
                 "reflectance 0.05)",
        "3u": "the shipped 3U cubesat (`3u`, svgs_sim/render/cubesat.py: 100 x 340.5 x 100 mm, anodised rails and "
              "ends, an MLI face under the pattern, body-mounted cells under cover glass on the other three long "
              "sides, target 3's boom)",
        "none": "none (`none`: the cubes and their mounts alone)"}

#: The beta angles (deg) of the sun paths drawn on the study's figure.
PATH_BETAS_DEG = (0.0, 30.0, 60.0)


def sun_path_vbar(beta_deg: float, altitude_km: float = 400.0, n: int = 721):
    """The sun's direction in the target frame over one orbit, for a target that holds the local
    orbital frame with its pattern facing a chaser on the V-bar behind it.

    Basilisk's Hill frame: x radial (out), y along track, z orbit normal. The target's face normal
    (+z) points along -y (toward a chaser on -y looking +y); its +x is radial out, its +y the orbit
    normal: ``(x, y, z)_target = (x, z, -y)_Hill``. Over the orbit the sun turns once in the Hill
    frame: ``s = (cos b cos u, -cos b sin u, sin b)``, ``u`` the orbit angle from the point nearest
    the sun and ``b`` the beta angle (the sun's elevation above the orbit plane). The target is in
    eclipse where the sun lies inside the Earth's disk (:func:`svgs_sim.render.earth.in_eclipse`;
    the Earth's centre along -x_Hill).

    Returns
    -------
    azimuth_deg, elevation_deg : ndarray, shape (n,)
        The sun's direction in the target frame (:func:`svgs_sim.render.sun.sun_direction_target`).
    eclipsed : ndarray of bool, shape (n,)
    """
    b = np.radians(float(beta_deg))
    u = np.linspace(0.0, 2 * np.pi, n)
    s_hill = np.stack([np.cos(b) * np.cos(u), -np.cos(b) * np.sin(u), np.full_like(u, np.sin(b))], 1)
    s = np.stack([s_hill[:, 0], s_hill[:, 2], -s_hill[:, 1]], 1)
    earth = np.array([-1.0, 0.0, 0.0])  # -x_Hill in the target frame
    ecl = np.array([in_eclipse(v, earth, 1e3 * altitude_km) for v in s])
    return (np.degrees(np.arctan2(s[:, 1], s[:, 0])), np.degrees(np.arcsin(np.clip(s[:, 2], -1, 1))), ecl)


def figure(config: SunStudyConfig, table: list, path) -> Path:
    """Availability (solved fraction) against the sun's direction, one row of panels per range (and
    Earth albedo, when several): the sun above the pattern plane (elevation >= 0) and below it;
    wrong locks marked with a red ring;
    the sun's path over an orbit for the beta angles :data:`PATH_BETAS_DEG` (:func:`sun_path_vbar`:
    sunlit solid, in eclipse dotted)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = _row_groups(config)
    n = len(rows)
    fig, axes = plt.subplots(n, 2, figsize=(9, 3.6 * n), subplot_kw={"projection": "polar"}, squeeze=False)
    for row_ax, (r, albedo, label) in zip(axes, rows):
        for ax, above in zip(row_ax, (True, False)):
            cs = [c for c in _in_row(table, r, albedo) if (c["sun_elevation_deg"] >= 0) == above]
            if cs:
                th = np.deg2rad([c["sun_azimuth_deg"] for c in cs])
                rad = [90.0 - abs(c["sun_elevation_deg"]) for c in cs]  # the centre: the sun on the face normal
                avail = [c["solved"] / c["trials"] if c["trials"] else np.nan for c in cs]
                sc = ax.scatter(th, rad, c=avail, cmap="RdYlGn", vmin=0, vmax=1, s=160, edgecolors="k", linewidths=0.5)
                wl = [c for c in cs if c["wrong_lock"]]
                if wl:
                    ax.scatter(np.deg2rad([c["sun_azimuth_deg"] for c in wl]), [90 - abs(c["sun_elevation_deg"]) for c in wl],
                               s=320, facecolors="none", edgecolors="red", linewidths=2)
                fig.colorbar(sc, ax=ax, shrink=0.7, label="solved fraction")
            for beta, colour in zip(PATH_BETAS_DEG, ("tab:blue", "tab:purple", "tab:gray")):
                az, el, ecl = sun_path_vbar(beta)
                side = (el >= 0) == above
                for lit, style in ((True, "-"), (False, ":")):
                    m = side & (ecl != lit)
                    y = np.where(m, 90.0 - np.abs(el), np.nan)
                    ax.plot(np.deg2rad(az), y, style, color=colour, lw=1.2,
                            label=f"beta {beta:g} deg" if (lit and above and label == rows[0][2]) else None)
            if above and label == rows[0][2]:
                ax.legend(loc="lower left", bbox_to_anchor=(-0.35, -0.15), fontsize=7,
                          title="sun over an orbit (V-bar; dotted: eclipse)", title_fontsize=7)
            ax.set_ylim(0, 90)
            ax.set_yticks([0, 30, 60, 90])
            ax.set_yticklabels(["+z" if above else "-z", "60", "30", "0"], fontsize=7)
            ax.set_title(f"{label}, sun {'above' if above else 'below'} the pattern plane\n"
                         "(centre: along the face normal; angle: azimuth)", fontsize=9)
    fig.suptitle(f"SVGS availability on orbit: {config.camera}, {config.trials} trials a cell (red ring: wrong lock)",
                 fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _row_groups(config: SunStudyConfig) -> list:
    """``(range_m, albedo or None, label)`` of the figure's and the README's rows: one per range, or
    per range and Earth albedo when the study sweeps several."""
    if config.earth is not None and len(config.earth_albedos) > 1:
        return [(r, b, f"{r:g} m, albedo {b:g}") for r in config.ranges_m for b in config.earth_albedos]
    return [(r, None, f"{r:g} m") for r in config.ranges_m]


def _in_row(table, r, albedo) -> list:
    return [c for c in table if c["range_m"] == r and (albedo is None or c.get("earth_albedo") == albedo)]


def _frac(cs, key="solved") -> str:
    n = sum(c["trials"] for c in cs)
    return f"{sum(c[key] for c in cs)}/{n} ({100.0 * sum(c[key] for c in cs) / n:.0f} %)" if n else "-"


def write_readme(config: SunStudyConfig, table: list, path, command: str = "") -> Path:
    """``README.md`` of a study folder: the command, the grid, and the solved fraction and wrong locks by
    range and by the sun's elevation (summed over azimuth), each number from ``table``."""
    els = config.elevations_deg
    lines = [f"# SVGS on orbit: {config.camera}", "",
             "Made by (rerun it to rebuild this folder; a killed run resumes):", "", f"    {command}", "",
             f"Grid: ranges {', '.join(f'{r:g}' for r in config.ranges_m)} m; sun azimuths "
             f"{', '.join(f'{a:g}' for a in config.azimuths_deg)} deg; elevations {', '.join(f'{e:g}' for e in els)} deg; "
             f"{config.trials} trials a cell ({config.n_trials} in all). Poses: roll, pitch uniform in +/-25 deg, yaw in "
             "+/-45 deg, the target on the boresight. The sun's elevation is from the pattern plane toward the face "
             "normal (+z, toward a head-on camera): above 0 the sun lights the face, below 0 it is behind the target. "
             f"Body: {BODY[config.body]}. " + (
                 f"Earth: toward azimuth {config.earth[0]:g}, elevation {config.earth[1]:g} deg, {config.earth[2]:g} km "
                 f"below, albedo {', '.join(f'{b:g}' for b in config.earth_albedos)}. " if config.earth else "No Earth. ") + "See docs/orbit.md for the definitions.", "",
             "| cells | solved | wrong locks | " + " | ".join(f"solved, el {e:g}" for e in els) + " |",
             "|---|---|---|" + "---|" * len(els)]
    for r, albedo, label in _row_groups(config):
        cs = _in_row(table, r, albedo)
        lines.append(f"| {label} | {_frac(cs)} | {sum(c['wrong_lock'] for c in cs)} | "
                     + " | ".join(_frac([c for c in cs if c["sun_elevation_deg"] == e]) for e in els) + " |")
    reasons, mech = {}, {m: 0 for m in MECHANISMS}
    for c in table:
        for k, v in c["reasons"].items():
            reasons[k] = reasons.get(k, 0) + v
        for k, v in c["mechanisms"].items():
            mech[k] += v
    flagged = sum(c["wrong_lock_flagged"] for c in table)
    before = sum(c.get("wrong_lock_paper_gates", 0) for c in table)
    lines += ["", f"All cells: solved {_frac(table)}; wrong locks {sum(c['wrong_lock'] for c in table)} "
              f"({flagged} of them flagged by the consistency test; {before} with the paper's test-envelope gates "
              "instead of the physical envelope's, on the same images); failures by reason: "
              + (", ".join(f"{k} {v}" for k, v in sorted(reasons.items(), key=lambda kv: -kv[1])) or "none") + ".",
              "", "Mechanisms (trials showing each): " + ", ".join(f"{k} {v}" for k, v in mech.items()) + ".",
              "", "![availability](sun_study.png)", ""]
    path = Path(path)
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def run_sun_study(config: SunStudyConfig, out_dir, spec, *, chunk_size=None, progress: bool = True,
                  command: str = "") -> dict:
    """Run (or resume) the study into ``out_dir``; write ``cells.json``, ``sun_study.png`` and
    ``summary.json``; return the summary (``cells``, ``outputs``, ``run``)."""
    out = Path(out_dir)
    trials = sun_study_trials(config)
    store, stats = run_stored_study(RENDER, trials, out, config.manifest(), spec, chunk_size=chunk_size,
                                    progress=progress, description=f"sun study {config.camera}")
    rows = store.read_rows()
    table = cells(config, rows)
    fig = figure(config, table, out / "sun_study.png")
    readme = write_readme(config, table, out / "README.md", command)
    summary = {"camera": config.camera, "pattern": config.pattern, "trials_per_cell": config.trials,
               "pose": "roll, pitch uniform in +/-25 deg, yaw in +/-45 deg (the paper's test envelope), on the boresight",
               "wrong_lock_px": f"max({WRONG_LOCK_PX:g} px, the spot's image radius)", "body": config.body,
               "body_description": BODY[config.body],
               "earth": None if config.earth is None else {
                   **dict(zip(("azimuth_deg", "elevation_deg", "altitude_km"), config.earth)),
                   "albedos": list(config.earth_albedos)},
               "cells": table, "command": command, "versions": library_versions(),
               "outputs": {"results_csv": str(out / "results.csv"), "figure": str(fig), "readme": str(readme),
                           "summary_json": str(out / "summary.json")},
               "run": {"trials_run": stats.n_run if stats else 0, "trials": config.n_trials}}
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary
