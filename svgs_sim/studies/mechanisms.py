"""Each error mechanism's share of a campaign's cells of the paper's Tables 3 and 5, with a sampling
interval, and the verdict on each cell outside 2x (issue 39).

A campaign run with ``--budget`` holds, beside its baseline, the same stand settings and noise
seeds with one mechanism switched off at a time (:data:`svgs_sim.studies.error_budget.VARIANTS`), and
the app's threshold moved each way (sensitivities). For a cell (range, component) and a removal
``v`` the share is ``sqrt(max(s_base^2 - s_v^2, 0))`` (the part of the baseline's standard
deviation that goes when the mechanism goes, in quadrature) over the paper's value; "without it"
is ``s_v`` over the paper's value. For a sensitivity, "with it" is ``s_v`` over the paper's value.
Intervals are 90 % paired bootstraps over the stand settings (a setting's exposures stay together;
the baseline and the variant are resampled alike: common random numbers), seeded.

A cell outside 2x is ``measured:<mechanism>`` when switching that mechanism off brings it within
2x (the one with the largest share, of several); a cell below the paper's is ``unexplained``
(switching a modelled mechanism off only removes error), with its size. No parameter is moved.
"""

from __future__ import annotations

import numpy as np

from svgs_sim.assets.papers import svgs_2014_results
from svgs_sim.svgs.frames import STATE_KEYS

from .campaign.design import SHORT
from .error_budget import REMOVAL_NAMES, SENSITIVITY_NAMES, SOURCE_IDS, SOURCE_LABELS, reported_mask

#: Resamples of the bootstrap and its seed (the same seed gives the same intervals).
RESAMPLES = 200
SEED = 0


def _reported_errors(table: dict) -> dict:
    """``(variant, range_m) -> {(pose_index, exposure_index): errors (6,)}`` of the reported trials
    (:func:`svgs_sim.studies.error_budget.reported_mask`), in one pass over the table."""
    keep = np.flatnonzero(reported_mask(table))
    E = np.stack([np.asarray(table[f"err_{c}"], float) for c in STATE_KEYS], 1)
    var, rng = np.asarray(table["variant"]), np.asarray(table["nominal_range_m"], float)
    pose, expo = np.asarray(table["pose_index"]), np.asarray(table["exposure_index"])
    out: dict = {}
    for i in keep:
        out.setdefault((str(var[i]), float(rng[i])), {})[(int(pose[i]), int(expo[i]))] = E[i]
    return out


def _std(e: np.ndarray) -> np.ndarray:
    return e.std(axis=0, ddof=1) if len(e) > 1 else np.full(e.shape[1:], np.nan)


def cell_mechanisms(table: dict, camera_key: str, *, cells=None, resamples: int = RESAMPLES, seed: int = SEED,
                    paper: dict | None = None) -> list[dict]:
    """The mechanisms of a campaign's std cells (Tables 3 and 5).

    Parameters
    ----------
    table : dict of column -> ndarray
        The campaign's rows (``variant``, ``pose_index``, ``exposure_index``, ``nominal_range_m``,
        ``err_<c>``, ``ok``, ``reason``).
    camera_key : str
        The phone (its rows of the paper's tables).
    cells : iterable of (range_m, component), optional
        The cells; default every std cell of the paper's table outside 2x in this campaign.
    resamples, seed : int
        The bootstrap.
    paper : dict, optional
        :func:`svgs_sim.assets.papers.svgs_2014_results`.

    Returns
    -------
    list of dict, one per cell
        ``range_m``, ``component``, ``paper`` (the paper's std), ``simulated`` (std), ``ratio``,
        ``ratio_ci`` (5-95 %), ``verdict`` (``within_2x`` | ``below`` | ``above``),
        ``explanation`` (``measured:<id>`` | ``unexplained`` | ``""``), ``mechanisms``: list of
        ``{"name", "label", "kind", "share", "share_ci", "without", "without_ci"}`` (fractions of
        the paper's value; for a sensitivity ``without`` is the cell with it).
    """
    paper = svgs_2014_results() if paper is None else paper
    by = _reported_errors(table)
    present = {str(v) for v in table["variant"]}
    names = [n for n in (*REMOVAL_NAMES, "all_removed", *SENSITIVITY_NAMES) if n in present]
    ranges = sorted({float(r) for r in np.asarray(table["nominal_range_m"], float)})
    if cells is None:
        cells = []
        for r in ranges:
            p = paper.get((camera_key, "std", r))
            if p is None:
                continue
            b = by.get(("baseline", r), {})
            s = _std(np.array(list(b.values()))) if b else np.full(len(STATE_KEYS), np.nan)
            cells += [(r, c) for i, c in enumerate(STATE_KEYS) if not 0.5 <= s[i] / p[c] <= 2.0]
    rng = np.random.default_rng(seed)
    out = []
    for r, c in cells:
        ci = STATE_KEYS.index(c)
        p = paper[(camera_key, "std", float(r))][c]
        base = by.get(("baseline", float(r)), {})
        B_all = np.array(list(base.values()))
        P_all = np.array([k[0] for k in base])
        poses = np.unique(P_all)
        boots = [np.concatenate([np.flatnonzero(P_all == q) for q in rng.choice(poses, len(poses))])
                 for _ in range(resamples)]
        sb = _std(B_all)[ci]
        bs = np.array([_std(B_all[i])[ci] for i in boots])
        row = {"range_m": float(r), "component": c, "paper": p, "simulated": float(sb), "ratio": float(sb / p),
               "ratio_ci": [float(np.percentile(bs, 5) / p), float(np.percentile(bs, 95) / p)], "mechanisms": []}
        for n in names:
            var = by.get((n, float(r)), {})
            keys = [k for k in base if k in var]
            if len(keys) < 3:
                continue
            B = np.array([base[k] for k in keys])[:, ci]
            V = np.array([var[k] for k in keys])[:, ci]
            P = np.array([k[0] for k in keys])
            qs = np.unique(P)

            def both(idx):
                b, w = np.std(B[idx], ddof=1), np.std(V[idx], ddof=1)
                return np.sqrt(max(b ** 2 - w ** 2, 0.0)), w

            share, without = both(np.arange(len(keys)))
            bb = np.array([both(np.concatenate([np.flatnonzero(P == q) for q in rng.choice(qs, len(qs))]))
                           for _ in range(resamples)])
            kind = "sensitivity" if n in SENSITIVITY_NAMES else ("floor" if n == "all_removed" else "removal")
            row["mechanisms"].append({
                "name": n, "label": SOURCE_LABELS.get(n, "floor (all removed)" if n == "all_removed" else n), "kind": kind,
                "share": float(share / p), "share_ci": [float(np.percentile(bb[:, 0], 5) / p),
                                                         float(np.percentile(bb[:, 0], 95) / p)],
                "without": float(without / p), "without_ci": [float(np.percentile(bb[:, 1], 5) / p),
                                                               float(np.percentile(bb[:, 1], 95) / p)]})
        row.update(_verdict(row))
        out.append(row)
    return out


def _verdict(row: dict) -> dict:
    """``verdict`` and ``explanation`` of a cell: a removal that brings it within 2x explains it
    (``measured:<id>``); otherwise ``unexplained``, with ``; within 2x with <sensitivity>`` where a
    chosen setting moved (the app's threshold, which the paper does not give) brings it there."""
    ratio = row["ratio"]
    if 0.5 <= ratio <= 2.0:
        return {"verdict": "within_2x", "explanation": ""}
    verdict = "below" if ratio < 0.5 else "above"
    if verdict == "above":
        removals = sorted((m for m in row["mechanisms"] if m["kind"] == "removal"), key=lambda m: -m["share"])
        for m in removals:
            if m["without"] <= 2.0:
                return {"verdict": verdict, "explanation": f"measured:{SOURCE_IDS.get(m['name'], m['name'])}"}
        floor = [m for m in row["mechanisms"] if m["kind"] == "floor"]
        if floor and floor[0]["without"] <= 2.0:
            return {"verdict": verdict, "explanation": "measured:all_sources"}
    sens = [m["label"] for m in row["mechanisms"] if m["kind"] == "sensitivity" and 0.5 <= m["without"] <= 2.0]
    return {"verdict": verdict, "explanation": "unexplained" + (f"; within 2x with {', '.join(sens)}" if sens else "")}


def mechanisms_markdown(rows: list[dict], camera_key: str, *, min_share: float = 0.1) -> str:
    """The cells of :func:`cell_mechanisms` as Markdown: per cell a line with its ratio and verdict,
    then the mechanisms whose share is at least ``min_share`` of the paper's value (or whose
    upper bound reaches it), the floor and the sensitivities."""
    if not rows:
        return f"Every std cell of the {camera_key}'s table is within 2x of the paper's: no mechanism to report.\n"
    lines = []
    for r in rows:
        head = (f"- **{r['range_m']:g} m {SHORT[r['component']]}**: simulated/paper {r['ratio']:.2f} "
                f"({r['ratio_ci'][0]:.2f}-{r['ratio_ci'][1]:.2f}), {r['verdict'].replace('_', ' ')}")
        head += f", {r['explanation']}" if r["explanation"] else ""
        lines.append(head + ".")
        parts = []
        for m in r["mechanisms"]:
            if m["kind"] == "removal" and m["share_ci"][1] < min_share:
                continue
            if m["kind"] == "removal":
                parts.append(f"{m['label']}: share {m['share']:.2f} ({m['share_ci'][0]:.2f}-{m['share_ci'][1]:.2f}), "
                             f"without it {m['without']:.2f}")
            elif m["kind"] == "floor":
                parts.append(f"all removed: {m['without']:.2f} ({m['without_ci'][0]:.2f}-{m['without_ci'][1]:.2f})")
            else:
                parts.append(f"{m['label']}: {m['without']:.2f} ({m['without_ci'][0]:.2f}-{m['without_ci'][1]:.2f})")
        if parts:
            lines.append("  " + "; ".join(parts) + ".")
    return "\n".join(lines) + "\n"


__all__ = ["RESAMPLES", "SEED", "cell_mechanisms", "mechanisms_markdown"]
