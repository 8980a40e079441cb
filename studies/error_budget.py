"""The campaign's error budget: which source makes each component's error, at each range.

The rendered campaign is rerun with one error source removed at a time, on the same stand
settings and with the same noise seeds (common random numbers: a variant differs from the
baseline in that one source only), and each variant's statistics are compared with the
baseline's:

=====================  ==========================================================================
variant                what is removed
=====================  ==========================================================================
perfect_calibration    the solver's calibration errors (it knows the true lens: focal length,
                       principal point, distortion)
no_sensor_noise        shot, dark, fixed-pattern and read noise (one exposure per setting: it is
                       deterministic)
no_glare               the lens' veiling glare and ghosts (the diffraction and aberration core kept)
no_quantisation        the delivered image's 8 bits and JPEG (a float image through the same tone
                       curve)
no_misalignment        the phone's rotation in its holder (the errors taken against the actual
                       pose instead of the commanded one)
all_removed            all of the above at once: the floor, what the optics, the retro spots'
                       formation and the pattern give by themselves
geometric              *only* random centroid noise: the geometric trial on the same settings at
                       the centroid scatter measured on the rendered exposures
=====================  ==========================================================================

Attribution. For a statistic ``s`` (mean |error|, standard deviation, RMS) of one component at
one range, the contribution of source ``v`` is ``sqrt(max(s_base^2 - s_v^2, 0))``: the part of
the baseline that goes when ``v`` goes, in quadrature (independent sources add so). The floor is
``s_all_removed``; what the floor and the contributions do not add up to is the sources'
interaction. The geometric variant's ``s`` is itself the contribution of random centroid noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from svgs.frames import STATE_KEYS


@dataclass(frozen=True)
class Variant:
    """One error source removed: its name, what it means, the scenario values that remove it,
    and whether every exposure of a setting is run (``False``: the first only)."""

    name: str
    meaning: str
    values: dict
    all_exposures: bool = True


_PERFECT = {"focal_error_frac": 0.0, "pp_error_u_px": 0.0, "pp_error_v_px": 0.0, "k1_error": 0.0}

VARIANTS = (
    Variant("perfect_calibration", "perfect calibration (the solver knows the true lens)", _PERFECT),
    Variant("no_sensor_noise", "no sensor noise (shot, dark, fixed pattern, read)", {"sensor_noise": 0.0}, False),
    Variant("no_glare", "no glare (veiling wings, ghosts; the diffraction core kept)", {"glare": 0.0}),
    Variant("no_quantisation", "no 8-bit output and no JPEG", {"quantise": 0.0}),
    Variant("no_misalignment", "no installation misalignment of the phone in its holder", {"truth_actual": 1.0}),
    Variant("all_removed", "all of these removed (the floor)",
            {**_PERFECT, "sensor_noise": 0.0, "glare": 0.0, "quantise": 0.0, "truth_actual": 1.0}, False),
)
VARIANT_NAMES = tuple(v.name for v in VARIANTS)
#: The geometric trial at the measured centroid scatter (a separate store, ``DIR/budget-geometric``).
GEOMETRIC_VARIANT = "geometric"
#: What each source is called in tables and figures.
SOURCE_LABELS = {"perfect_calibration": "calibration", "no_sensor_noise": "sensor noise", "no_glare": "glare",
                 "no_quantisation": "8-bit/JPEG", "no_misalignment": "misalignment",
                 GEOMETRIC_VARIANT: "random centroid noise (geometric)", "floor": "floor (all removed)"}
STATISTICS = ("mean_abs", "std", "rms")


def variant_trials(baseline: list, config) -> list:
    """The variant trials of a campaign's baseline trials (same scenario but for the variant's
    values, same seed; ``variant`` label set; ids from ``len(baseline) * (v + 1)``)."""
    from sim.trials import build_scenario, get_trial_kind

    from .execution import Trial

    kind = get_trial_kind(config.trial_kind)
    N = len(baseline)
    label_keys = ("nominal_range_m", "pose_index", "exposure_index")
    out = []
    for v, var in enumerate(VARIANTS):
        for tr in baseline:
            if not var.all_exposures and tr.scenario["exposure_index"] != 0:
                continue
            sc = {k: x for k, x in tr.scenario.items() if k in kind.parameters or k in ("camera", "pattern")}
            sc.update(var.values)
            labels = {k: tr.scenario[k] for k in label_keys}
            labels["variant"] = var.name
            out.append(Trial(N * (v + 1) + tr.trial_id, build_scenario(kind, sc, labels), tr.seed))
    return out


# --------------------------------------------------------------------------- measured centroids
def centroid_statistics(table: dict, ranges_m) -> list[dict]:
    """Per range, from the baseline exposures: the centroids' scatter over the exposures of one
    setting (noise), their mean offset common to all targets (the flash-to-lens parallax moves
    every spot alike) and the rest of the mean offset (differential: what changes the pattern's
    shape), px, medians over the settings; and the median sensor bound (``crlb_centroid_px``).
    """
    base = _select(table, "baseline") & (table["ok"] == 1)
    du = np.stack([table[f"cen_du_px_{k}"] for k in range(4)], 1)
    dv = np.stack([table[f"cen_dv_px_{k}"] for k in range(4)], 1)
    out = []
    for r in ranges_m:
        sel = base & (table["nominal_range_m"] == r)
        scatter, common, diff = [], [], []
        for j in np.unique(table["pose_index"][sel]):
            m = sel & (table["pose_index"] == j)
            d = np.concatenate([du[m], dv[m]], 1)  # (exposures, 8)
            if not np.all(np.isfinite(d)):
                continue
            if m.sum() >= 2:
                scatter.append(float(np.sqrt(np.mean(np.var(d, axis=0, ddof=1)))))
            mean = d.mean(0)
            cu, cv = mean[:4].mean(), mean[4:].mean()
            common.append(float(np.hypot(cu, cv)))
            rest = np.concatenate([mean[:4] - cu, mean[4:] - cv])
            diff.append(float(np.sqrt(np.mean(rest**2))))
        crlb = table.get("crlb_centroid_px")
        cr = crlb[sel] if crlb is not None else np.array([])
        cr = cr[np.isfinite(cr)] if cr.size else cr
        out.append({"range_m": float(r), "scatter_px": float(np.median(scatter)) if scatter else float("nan"),
                    "common_offset_px": float(np.median(common)) if common else float("nan"),
                    "differential_offset_px": float(np.median(diff)) if diff else float("nan"),
                    "crlb_px": float(np.median(cr)) if cr.size else float("nan"), "settings": len(common)})
    return out


def geometric_trials(baseline: list, config, centroids: list[dict]) -> list:
    """Geometric trials on the baseline's settings and seeds, exact calibration, no
    misalignment, with each range's measured centroid scatter as ``sigma_px``."""
    from sim.trials import GEOMETRIC, build_scenario

    from .execution import Trial

    sigma = {c["range_m"]: c["scatter_px"] if np.isfinite(c["scatter_px"]) else 0.0 for c in centroids}
    out = []
    for tr in baseline:
        sc = {k: tr.scenario[k] for k in ("camera", "pattern", "range_m", "stand", "stage_m", "roll_deg", "pitch_deg",
                                          "yaw_deg")}
        sc["sigma_px"] = sigma[tr.scenario["nominal_range_m"]]
        labels = {k: tr.scenario[k] for k in ("nominal_range_m", "pose_index", "exposure_index")}
        labels["variant"] = GEOMETRIC_VARIANT
        out.append(Trial(tr.trial_id, build_scenario(GEOMETRIC, sc, labels), tr.seed))
    return out


# --------------------------------------------------------------------------- statistics
def _select(table: dict, variant: str) -> np.ndarray:
    v = table.get("variant")
    if v is None:
        return np.full(len(table["ok"]), variant == "baseline")
    return np.array([str(x) == variant for x in v])


def _stats(e: np.ndarray) -> dict:
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {"mean_abs": float("nan"), "std": float("nan"), "rms": float("nan"), "n": 0}
    return {"mean_abs": float(np.mean(np.abs(e))), "std": float(np.std(e, ddof=1)) if e.size > 1 else float("nan"),
            "rms": float(np.sqrt(np.mean(e**2))), "n": int(e.size)}


def variant_statistics(table: dict, ranges_m, geometric_table: dict | None = None) -> dict:
    """``stats[variant][range_index][component] = {mean_abs, std, rms, n}`` of the solved trials
    (variants ``baseline``, :data:`VARIANT_NAMES` and, when given, ``geometric``), and
    ``solved[variant][range_index]`` (solved, trials)."""
    stats, solved = {}, {}
    names = ["baseline", *VARIANT_NAMES]
    sources = [(n, table) for n in names] + ([(GEOMETRIC_VARIANT, geometric_table)] if geometric_table else [])
    for name, tab in sources:
        sel_v = _select(tab, name)
        if not sel_v.any():
            continue
        stats[name], solved[name] = [], []
        for r in ranges_m:
            sel = sel_v & (tab["nominal_range_m"] == r)
            ok = sel & (tab["ok"] == 1)
            solved[name].append((int(ok.sum()), int(sel.sum())))
            stats[name].append({c: _stats(tab[f"err_{c}"][ok]) for c in STATE_KEYS})
    return {"stats": stats, "solved": solved}


def attribute(vs: dict, ranges_m) -> list[dict]:
    """The budget: per range, component and statistic, the baseline, the floor and each source's
    contribution in quadrature (see the module docstring).

    Returns
    -------
    list of dict
        ``range_m``, ``component``, ``statistic``, ``baseline``, ``floor``, one key per source
        (:data:`VARIANT_NAMES` less ``all_removed``, and ``geometric``), ``interaction``.
    """
    st = vs["stats"]
    rows = []
    for ri, r in enumerate(ranges_m):
        for c in STATE_KEYS:
            for stat in STATISTICS:
                b = st["baseline"][ri][c][stat]
                row = {"range_m": float(r), "component": c, "statistic": stat, "baseline": b}
                floor = st["all_removed"][ri][c][stat] if "all_removed" in st else float("nan")
                row["floor"] = floor
                total = floor**2 if np.isfinite(floor) else 0.0
                for name in VARIANT_NAMES:
                    if name == "all_removed" or name not in st:
                        continue
                    s = st[name][ri][c][stat]
                    row[name] = float(np.sqrt(max(b**2 - s**2, 0.0))) if np.isfinite(s) and np.isfinite(b) else float("nan")
                    if np.isfinite(row[name]):
                        total += row[name] ** 2
                if GEOMETRIC_VARIANT in st:
                    row[GEOMETRIC_VARIANT] = st[GEOMETRIC_VARIANT][ri][c][stat]
                row["interaction"] = float(np.sign(b**2 - total) * np.sqrt(abs(b**2 - total))) if np.isfinite(b) else float("nan")
                rows.append(row)
    return rows


def _sources(row: dict) -> list[str]:
    return [n for n in VARIANT_NAMES if n != "all_removed" and n in row]


def cell_verdicts(summary: list[dict], budget: list[dict], vs: dict, centroids: list[dict] | None = None) -> list[dict]:
    """Every cell of the paper's Tables 2-5 (mean error and standard deviation per range and
    component): the simulated value, the paper's, the ratio, and either ``within 2x`` or the
    source that makes the difference with its measured size.

    A cell below the paper's has an error source the simulation lacks, of the size that adds in
    quadrature to the simulated value to give the paper's; with ``centroids``
    (:func:`centroid_statistics`) and the geometric variant it is also given as the random
    centroid noise that would produce it (``sigma_equivalent_px``: the geometric trial's errors
    scale with its centroid noise).

    Returns
    -------
    list of dict
        ``range_m``, ``component``, ``statistic`` (``mean_error`` | ``std``), ``simulated``,
        ``paper``, ``ratio``, ``verdict`` (``within_2x``, ``above`` or ``below``), ``text``,
        ``sigma_equivalent_px`` (below only, else NaN).
    """
    index = {(b["range_m"], b["component"], b["statistic"]): b for b in budget}
    out = []
    for ri, s in enumerate(summary):
        for c in STATE_KEYS:
            for stat, key_sim, key_paper in (("mean_error", "mean_abs", "paper_mean"), ("std", "std", "paper_std")):
                sim, paper = s[f"{key_sim}_{c}"], s[f"{key_paper}_{c}"]
                row = {"range_m": s["range_m"], "component": c, "statistic": stat, "simulated": sim, "paper": paper,
                       "ratio": sim / paper if np.isfinite(paper) and paper > 0 else float("nan"),
                       "sigma_equivalent_px": float("nan")}
                b = index.get((s["range_m"], c, key_sim))
                if not np.isfinite(row["ratio"]):
                    row.update(verdict="no_paper_value", text="the paper has no value")
                elif 0.5 <= row["ratio"] <= 2.0:
                    row.update(verdict="within_2x", text="within 2x")
                elif b is None:
                    row.update(verdict="above" if row["ratio"] > 2 else "below", text="no error budget run")
                elif row["ratio"] > 2.0:
                    srcs = {n: b[n] for n in _sources(b) if np.isfinite(b[n])}
                    if np.isfinite(b["floor"]):
                        srcs["floor"] = b["floor"]
                    name = max(srcs, key=srcs.get) if srcs else None
                    text = f"the simulation is {row['ratio']:.2g}x the paper's"
                    if name == "floor":
                        text += (f"; the floor dominates (all removable sources off: {b['floor']:.3g}, "
                                 f"{b['floor'] / paper:.2g}x the paper's): the spots' formation and the optics themselves")
                    elif name is not None:
                        without = vs["stats"][name][ri][c][key_sim]
                        text += (f"; the largest simulated source is {SOURCE_LABELS[name]} ({srcs[name]:.3g}): without "
                                 f"it {without:.3g}, {without / paper:.2g}x the paper's")
                    row.update(verdict="above", text=text)
                else:
                    missing = float(np.sqrt(max(paper**2 - sim**2, 0.0)))
                    text = (f"the simulation is {row['ratio']:.2g}x the paper's: the test had an error source of about "
                            f"{missing:.3g} (in quadrature) that no modelled source produces")
                    g = vs["stats"].get(GEOMETRIC_VARIANT)
                    if centroids is not None and g is not None:
                        scatter = centroids[ri]["scatter_px"]
                        gv = g[ri][c][key_sim]
                        if np.isfinite(scatter) and np.isfinite(gv) and gv > 0:
                            row["sigma_equivalent_px"] = float(scatter * missing / gv)
                            text += (f"; as random centroid noise: {row['sigma_equivalent_px']:.2g} px per axis "
                                     f"(the sensor's own scatter: {scatter:.2g} px)")
                    row.update(verdict="below", text=text)
                out.append(row)
    return out


# --------------------------------------------------------------------------- figure
def budget_figure(budget: list[dict], ranges_m, camera: str, statistic: str = "rms"):
    """Stacked shares of each component's mean square error per range: the floor and each
    source's contribution (in quadrature), with what they do not explain (interaction). Where
    the parts add up to more than the baseline (the sources are not independent), the shares
    are of their sum."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 6.8))
    axes = fig.subplots(2, 3).ravel()
    x = np.arange(len(ranges_m))
    names = ["floor", *[n for n in VARIANT_NAMES if n != "all_removed"]]
    colors = dict(zip(names + ["interaction"], ["0.55", "C0", "C1", "C2", "C3", "C4", "0.85"]))
    for ax, c in zip(axes, STATE_KEYS):
        rows = [next(b for b in budget if b["range_m"] == r and b["component"] == c and b["statistic"] == statistic)
                for r in ranges_m]
        bottom = np.zeros(len(rows))
        # shares of the larger of the baseline's mean square and the sum of the parts (so they add up to 1 at most)
        norm = []
        for b in rows:
            parts = sum(b.get(n, np.nan) ** 2 for n in names if np.isfinite(b.get(n, np.nan)))
            base = b["baseline"] ** 2 if np.isfinite(b["baseline"]) else np.nan
            norm.append(max(base, parts) if np.isfinite(base) and max(base, parts) > 0 else np.nan)
        for n in names + ["interaction"]:
            v = []
            for b, d in zip(rows, norm):
                val = b.get(n, np.nan)
                val = max(val, 0.0) if n == "interaction" else val
                v.append(val**2 / d if np.isfinite(val) and np.isfinite(d) else 0.0)
            v = np.array(v)
            ax.bar(x, v, bottom=bottom, color=colors[n], label=SOURCE_LABELS.get(n, n), width=0.7)
            bottom += v
        for xi, b in zip(x, rows):
            ax.text(xi, min(bottom[xi], 1.0) + 0.02, f"{b['baseline']:.2g}", ha="center", fontsize=7)
        ax.set_xticks(x, [f"{r:g}" for r in ranges_m])
        ax.set_xlabel("range (m)")
        ax.set_ylabel(f"share of {c} mean square error")
        ax.set_ylim(0, 1.15)
        ax.grid(alpha=0.3, axis="y")
    axes[0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{camera}: error budget - each source's share of the error (RMS over the trials written above "
                 "the bars)")
    fig.tight_layout()
    return fig


def budget_rows_for_csv(budget: list[dict]) -> tuple[list[str], list[dict]]:
    """Columns and rows of ``budget.csv``."""
    cols = ["range_m", "component", "statistic", "baseline", "floor",
            *[n for n in VARIANT_NAMES if n != "all_removed"], GEOMETRIC_VARIANT, "interaction"]
    return cols, [{k: b.get(k) for k in cols} for b in budget]
