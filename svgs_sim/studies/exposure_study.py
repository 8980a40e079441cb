"""The exposure study: what would have extended a phone's range (the paper's remedies).

The paper: "Possible remedies for this issue could include replacing the corner cubes with
reflectors with a lower return brightness or increasing the spacing between the
reflectors." At each range (nominal pose) and for each remedy, ``trials`` noise draws are
exposed and solved:

- ``baseline``: the profile as it is;
- ``exposure=T``: a fixed exposure of T seconds at base ISO (if the phone had allowed it);
- ``nd=OD``: a neutral-density filter of optical density OD over every reflector (the
  return passes it twice: the spots' flux scales by 10^(-2 OD)); render once, expose many;
- ``spacing=K``: the pattern scaled by K about its origin (a wider target; re-rendered).

Scenarios and seeds
    Trial ``i = (i_range * n_remedies + i_remedy) * trials + k`` of the ``render`` trial
    kind (:mod:`svgs_sim.sim.render_trial`) exposes with :func:`svgs_sim.studies.seeding.trial_seed` ``(seed,
    i)``. The render's Monte Carlo seed of a range is drawn from the design stream of the
    range's first trial, so the remedies that do not change the scene (``baseline``,
    ``exposure``, ``nd``) share one render per range and each ``spacing`` gets its own.

Outputs in the study directory
    ``manifest.json`` and ``results.csv`` (the resumable store), ``trials.csv`` (remedy,
    range, trial, outcome, exposure, errors), ``summary.csv`` and ``summary.md`` (success rate
    per range and remedy, the largest range at which >= 95 % of trials solve) and
    ``remedies.png``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera
from svgs_sim.sim.metrics import POS_ERR_NORM_M, ROT_ERR_DEG
from svgs_sim.sim.render_trial import render_trial_scenario

from .execution import Trial
from .seeding import check_seed, design_rng, trial_seed
from .tail import run_rendered_study, write_dict_csv

#: The remedies run when none is given.
DEFAULT_REMEDIES = ("baseline", "exposure=0.001", "exposure=0.0002", "nd=1", "nd=2", "spacing=1.5", "spacing=2")
#: Success rate that counts as "works at this range".
SUCCESS_LEVEL = 0.95


def parse_remedy(text: str) -> tuple[str, float | None]:
    """'baseline', 'exposure=0.001', 'nd=1', 'spacing=1.5' -> (kind, value)."""
    if text == "baseline":
        return ("baseline", None)
    kind, _, val = str(text).partition("=")
    if kind not in ("exposure", "nd", "spacing") or not val:
        raise InputError(f"--remedy: expected baseline, exposure=SECONDS, nd=OD or spacing=FACTOR, got {text!r}")
    try:
        v = float(val)
    except ValueError:
        raise InputError(f"--remedy {text!r}: {val!r} is not a number") from None
    hi, unit = {"exposure": (60.0, " s"), "nd": (10.0, ""), "spacing": (10.0, "x")}[kind]
    if not np.isfinite(v) or v <= 0 or v > hi:
        raise InputError(f"--remedy {text!r}: expected {kind}=VALUE with VALUE > 0 and <= {hi:g}{unit}, got {val}")
    return (kind, v)


def remedy_values(text: str, base_iso: float) -> dict:
    """The ``render`` scenario values of a remedy (``exposure_s``, ``iso``, ``target_scale``,
    ``pattern_scale``; the rest at their defaults)."""
    kind, val = parse_remedy(text)
    if kind == "exposure":
        return {"exposure_s": val, "iso": base_iso}
    if kind == "nd":
        return {"target_scale": 10.0 ** (-2.0 * val)}
    if kind == "spacing":
        return {"pattern_scale": val}
    return {}


@dataclass(frozen=True)
class ExposureStudyConfig:
    """What an exposure study computes (its manifest)."""

    camera: str
    ranges_m: tuple
    remedies: tuple = DEFAULT_REMEDIES
    trials: int = 5
    seed: int = 0
    pattern: str = "svgs-3u"

    def manifest(self) -> dict:
        return {"study": "exposure-study", "trial_kind": "render", "camera": self.camera,
                "pattern": self.pattern, "ranges_m": [float(r) for r in self.ranges_m],
                "remedies": list(self.remedies), "trials": int(self.trials), "seed": int(self.seed)}

    @property
    def n_trials(self) -> int:
        return len(self.ranges_m) * len(self.remedies) * self.trials


def make_config(camera: str, ranges_m, remedies=None, *, trials: int = 5, seed: int = 0,
                pattern: str = "svgs-3u") -> ExposureStudyConfig:
    """A validated :class:`ExposureStudyConfig` (:class:`InputError` naming the option)."""
    rs = [float(r) for r in ranges_m]
    if not rs:
        raise InputError("--ranges: no range given")
    if len(set(rs)) != len(rs):
        raise InputError(f"--ranges: repeated range in {rs}")
    rem = tuple(str(r) for r in (remedies or DEFAULT_REMEDIES))
    for r in rem:
        parse_remedy(r)
    if len(set(rem)) != len(rem):
        raise InputError(f"--remedy: repeated remedy in {list(rem)}")
    if isinstance(trials, bool) or not isinstance(trials, (int, np.integer)) or trials < 1:
        raise InputError(f"--trials: expected a positive integer, got {trials!r}")
    return ExposureStudyConfig(camera=str(camera), ranges_m=tuple(rs), remedies=rem, trials=int(trials),
                               seed=check_seed(seed), pattern=str(pattern))


def _base_iso(camera: str) -> float:

    cam = load_camera(camera)
    return float(cam.sensor.given("base_iso", 100.0))


def exposure_study_trials(cfg: ExposureStudyConfig) -> list:
    """Every trial of the study (see the module docstring).

    Returns
    -------
    list of :class:`svgs_sim.studies.execution.Trial`
    """


    base_iso = _base_iso(cfg.camera)
    n_rem = len(cfg.remedies)
    trials = []
    for ri, r in enumerate(cfg.ranges_m):
        first = ri * n_rem * cfg.trials
        render_seed = int(design_rng(cfg.seed, first).integers(2**31))
        for mi, name in enumerate(cfg.remedies):
            values = remedy_values(name, base_iso)
            for k in range(cfg.trials):
                i = first + mi * cfg.trials + k
                scen = render_trial_scenario(camera=cfg.camera, pattern=cfg.pattern, range_m=r,
                                             render_seed=render_seed, **values, labels={"remedy": name, "trial": k})
                trials.append(Trial(i, scen, trial_seed(cfg.seed, i)))
    return trials


def trial_table(rows: list[dict]) -> list[dict]:
    """The rows of ``trials.csv``: remedy, range_m, trial, ok, reason, n_blobs, exposure_s, iso,
    ``pos_err_norm_m`` and ``rot_err_deg`` (:mod:`svgs_sim.sim.metrics`; empty when unsolved)."""

    return [{"remedy": r["remedy"], "range_m": r["range_m"], "trial": r["trial"], "ok": bool(r["ok"]),
             "reason": r["reason"], "n_blobs": r["n_blobs"], "exposure_s": r["exposure_s_used"], "iso": r["iso_used"],
             POS_ERR_NORM_M: r[POS_ERR_NORM_M], ROT_ERR_DEG: r[ROT_ERR_DEG]} for r in rows]


def summarise(rows, remedies, ranges) -> list[dict]:
    """Per remedy: the success rate at each range (key ``"<r> m"``) and ``max_range_95_m``."""
    table = []
    for name in remedies:
        d = {"remedy": name}
        best = None
        for r in ranges:
            rr = [x for x in rows if x["remedy"] == name and x["range_m"] == r]
            rate = float(np.mean([x["ok"] for x in rr])) if rr else float("nan")
            d[f"{r:g} m"] = rate
            if rate >= SUCCESS_LEVEL and (best is None or r > best):
                best = r
        d["max_range_95_m"] = best
        table.append(d)
    return table


def markdown_table(table, ranges) -> list[str]:
    """``summary.md``: success rate per remedy and range, and the largest range >= 95 %."""
    lines = ["| remedy | " + " | ".join(f"{r:g} m" for r in ranges) + " | max range (>= 95 %) |",
             "|---|" + "---|" * len(ranges) + "---|"]
    for d in table:
        lines.append(f"| {d['remedy']} | " + " | ".join(f"{d[f'{r:g} m']:.2f}" for r in ranges)
                     + f" | {d['max_range_95_m'] if d['max_range_95_m'] is not None else '-'} |")
    return lines


def write_outputs(out_dir, cfg: ExposureStudyConfig, rows: list[dict]) -> tuple[list[dict], list[str]]:
    """``trials.csv``, ``summary.csv``, ``summary.md`` and ``remedies.png`` from the stored rows.

    Returns
    -------
    (table, markdown lines)
    """
    from matplotlib.figure import Figure

    out_dir = Path(out_dir)
    tt = trial_table(rows)
    ranges = list(cfg.ranges_m)
    table = summarise(tt, cfg.remedies, ranges)
    write_dict_csv(out_dir / "trials.csv", tt)
    write_dict_csv(out_dir / "summary.csv", table)
    # one panel per remedy beside the baseline: overlapping lines on one axis hid most of them
    n = len(table)
    ncols = min(4, n)
    nrows = -(-n // ncols)
    fig = Figure(figsize=(3.2 * ncols, 2.6 * nrows))
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, sharey=True)).ravel()
    base = next((d for d in table if d["remedy"] == "baseline"), None)
    for ax, d in zip(axes, table):
        if base is not None and d is not base:
            ax.plot(ranges, [base[f"{r:g} m"] for r in ranges], "--", color="grey", lw=1, label="baseline")
        ax.plot(ranges, [d[f"{r:g} m"] for r in ranges], "o-", color="C0" if d is not base else "k", label=d["remedy"])
        ax.axhline(SUCCESS_LEVEL, color="grey", lw=0.5)
        ax.set_title(d["remedy"], fontsize=9)
        ax.set_ylim(-0.05, 1.05)
    for ax in axes[n:]:
        ax.set_visible(False)
    for ax in axes[(nrows - 1) * ncols:]:
        ax.set_xlabel("range (m)")
    for ax in axes[::ncols]:
        ax.set_ylabel("fraction solved")
    fig.suptitle(f"{cfg.camera}: remedies (grey dashed: the baseline)")
    fig.tight_layout()
    fig.savefig(out_dir / "remedies.png", dpi=110)
    lines = markdown_table(table, ranges)
    (out_dir / "summary.md").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return table, lines


def run_exposure_study(cfg: ExposureStudyConfig, out_dir, spec, *, chunk_size=None, progress: bool = True):
    """Run (or resume) an exposure study into ``out_dir`` and write its outputs.

    Returns
    -------
    (markdown lines, stats)
        ``stats`` is the :class:`~svgs_sim.studies.execution.RunStats`, None if every trial was done.
    """
    (_, lines), stats = run_rendered_study(exposure_study_trials(cfg), out_dir, cfg.manifest(), spec,
                                           lambda rows: write_outputs(out_dir, cfg, rows),
                                           description=f"exposure study {cfg.camera}", chunk_size=chunk_size,
                                           progress=progress)
    return lines, stats
