"""A campaign folder's own files: the runs it has seen (``runs.json``), its honest count
(``honest_count.json``), the configuration its ``manifest.json`` records, and strict JSON."""

from __future__ import annotations

import json
from pathlib import Path


from svgs_sim.base.errors import InputError
from svgs_sim.base.jsonable import to_jsonable

from .design import CampaignConfig


def run_log(out_dir) -> list[dict]:
    """The runs a campaign folder has seen (``DIR/runs.json``): trials run, wall time, executor."""

    p = Path(out_dir) / "runs.json"
    try:
        return list(json.loads(p.read_text()))
    except (OSError, ValueError, TypeError):
        return []


def log_run(out_dir, part: str, stats) -> None:

    if stats is None:
        return
    log = run_log(out_dir)
    log.append({"part": part, "trials_run": stats.n_run, "elapsed_s": round(stats.elapsed_s, 2),
                "executor": stats.executor})
    (Path(out_dir) / "runs.json").write_text(json.dumps(log, indent=1), encoding="utf-8")


def read_honest_count(out_dir) -> dict | None:
    """``DIR/honest_count.json`` of a campaign report (None when absent): for ``summary.json``."""

    p = Path(out_dir) / "honest_count.json"
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def config_from_manifest(out_dir) -> CampaignConfig:
    """The :class:`CampaignConfig` a campaign folder's ``manifest.json`` records (with
    ``calibration_info`` from ``calibration.json`` when there is one); nothing is recomputed."""

    out_dir = Path(out_dir)
    try:
        m = json.loads((out_dir / "manifest.json").read_text())["parameters"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{out_dir}: no campaign manifest.json ({exc})") from None
    if m.get("study") != "campaign":
        raise InputError(f"{out_dir}: manifest.json is a {m.get('study')!r} study, not a campaign")
    info = {}
    try:
        info = json.loads((out_dir / "calibration.json").read_text())["result"]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    return CampaignConfig(camera=m["camera"], ranges_m=tuple(float(r) for r in m["ranges_m"]),
                          trials_per_range=int(m["trials_per_range"]), seed=int(m["seed"]),
                          sigma_px=float(m["sigma_px"]), trial_kind=m["trial_kind"], pattern=m["pattern"],
                          calibration=m["calibration"], calibration_error=dict(m["calibration_error"]),
                          merge_px=float(m["merge_px"]), exposures_per_render=int(m["exposures_per_render"]),
                          misalignment_deg=tuple(float(x) for x in m["misalignment_deg"]), lens=dict(m["lens"]),
                          budget=bool(m["budget"]), lab_errors=dict(m.get("lab_errors") or {}), calibration_info=info)


def finite_json(obj):
    """``obj`` in plain JSON types (:func:`svgs_sim.base.jsonable.to_jsonable`) with NaN and infinite floats
    as None (strict JSON)."""

    return to_jsonable(obj, nonfinite="null", other=None)
