"""The honest count: every fitted value (and chosen app setting) that applies to a campaign, the
cells of Tables 2-5 it consumes (:data:`FIT_USES`), the verdicts of the cells and their counts
under each reading of the paper's mean error."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from svgs_sim.assets import ASSETS_DIR, package_relative
from svgs_sim.assets.papers import svgs_2014_results
from svgs_sim.base.profiles import fitted_overlay_path, load_camera, read_toml
from svgs_sim.sim.lab import DEFAULT_LAB, load_lab

from ..error_budget import HEADLINE_READING, HEADLINE_REASON, MEAN_READINGS, READING_MEANINGS, cell_verdicts
from .design import SHORT, CampaignConfig


@dataclass(frozen=True)
class FitUse:
    """How one fitted or chosen value enters a campaign, and which cells of Tables 2-5 it consumes.

    Attributes
    ----------
    cameras : tuple of str or None
        The camera profiles it applies to; None: every campaign its file serves (a camera's own
        overlay, the lab's light).
    consumes : tuple of (str, str)
        ``(statistic, component)`` pairs (statistic ``mean_error`` | ``std``) it was fitted to, at
        every range of the campaign the paper has a row for; ``()``: it was fitted to something
        that is not a table cell.
    condition : str
        ``"always"``, or ``"misalignment_yaw"``: only when the campaign's holder yaw
        (:attr:`CampaignConfig.misalignment_deg`) is the fitted value (a campaign run with
        ``--misalignment-deg 0,0,0`` does not use it and consumes nothing).
    effect : dict
        Camera profile name -> what the value does to that campaign's statistics (``"*"``: others).
    """

    cameras: tuple | None
    consumes: tuple
    condition: str
    effect: dict


_REACH = ("fitted to the Galaxy Nexus's reach (solutions from 5 to 30 m in Tables 4-5, 'approaching 40 meters' "
          "in the text): a claim about which ranges solve, not a table cell, so it consumes none. It sets every "
          "Galaxy Nexus statistic through the spots' brightness and size: read the Nexus's cells as conditional on it")


#: The consumption rules: fitted key (``[[fit]] key`` of ``assets/cameras/fitted/<camera>.toml`` or
#: ``assets/labs/fitted/msfc-frl.toml``; ``threshold.by_camera`` for the app's threshold) -> :class:`FitUse`.
#: Why these and no others: a value consumes a cell when the cell's number was the target of its fit -
#: then matching it is the fit working, not a prediction. The holder's 2 deg yaw was fitted to the yaw
#: mean error of Table 4 at all five ranges, so those five cells are its data (under every reading of
#: "mean error"); the yaw std cells (Table 5) only told the fit that the offset is constant, and a
#: constant rotation moves no scatter, so they stay predictions. The Galaxy Nexus's manual exposure and
#: the lab's ambient light were fitted to claims of the paper's text (the reach, the merging range),
#: which are not cells; they are listed because every statistic of their phone depends on them.
FIT_USES = {
    "stand.galaxy_nexus_misalignment_yaw_deg": FitUse(
        ("galaxy-nexus",), (("mean_error", "yaw_deg"),), "misalignment_yaw",
        {"*": "fitted to Table 4's yaw mean error at every range: those cells are its data, shown as fitted and "
              "not counted as reproduced; the yaw std cells (Table 5) stay predictions (a constant rotation "
              "moves no scatter)"}),
    "exposure.mode": FitUse(None, (), "always", {"*": _REACH}),
    "exposure.exposure_s": FitUse(None, (), "always", {"*": _REACH}),
    "exposure.iso": FitUse(None, (), "always", {"*": _REACH}),
    "lab.ambient_radiance_w_m2_sr": FitUse(
        None, (), "always",
        {"htc-amaze-4g": "fitted to the Amaze 4G's merging range (four spots 'up to about 6.5 meter', text): it "
                         "consumes no table cell directly, but it sets the Amaze's auto-exposure and so every "
                         "Amaze statistic",
         "galaxy-nexus": "fitted to the Amaze 4G's merging range (text): consumes no cell; the Galaxy Nexus's fixed "
                         "manual exposure hardly sees it (about 5 e- per pixel at 0.5 ms)",
         "*": "fitted to the Amaze 4G's merging range (text): consumes no cell; it sets the exposure of a phone on "
              "auto-exposure"}),
    "threshold.by_camera": FitUse(
        None, (), "always",
        {"*": "a setting of the app chosen once per phone, not fitted to any cell (the file says which cells, if "
              "any, under 'consumes')"}),
}


#: The rule of a fitted key :data:`FIT_USES` does not list.
UNKNOWN_FIT_USE = FitUse(None, (), "always", {"*": "no consumption rule recorded (svgs_sim.studies.campaign.FIT_USES): "
                                                   "what it was fitted to must be checked by hand"})


#: The SVGS app's settings (``[threshold]``, ``[threshold.by_camera]``), when the file exists.
APP_SETTINGS_FILE = ASSETS_DIR / "app" / "svgs-app.toml"


def _fit_use(key: str, phone: str) -> FitUse | None:
    """The rule of a fitted key for a phone; None when it does not apply to that phone (another
    phone's holder misalignment)."""
    use = FIT_USES.get(key)
    if use is None and key.startswith("stand.") and key.endswith("_misalignment_yaw_deg"):
        # any phone's holder yaw is fitted like the Galaxy Nexus's: to its own yaw mean error
        use = FitUse((key[len("stand."):-len("_misalignment_yaw_deg")].replace("_", "-"),),
                     FIT_USES["stand.galaxy_nexus_misalignment_yaw_deg"].consumes, "misalignment_yaw",
                     {"*": "fitted to the phone's yaw mean error at every range: those cells are shown as fitted"})
    use = use or UNKNOWN_FIT_USE
    return use if use.cameras is None or phone in use.cameras else None


def _paper_ranges(config: CampaignConfig) -> list[float]:

    phone = load_camera(config.camera).key
    paper = svgs_2014_results()
    return [float(r) for r in config.ranges_m if (phone, "mean_error", float(r)) in paper]


def _consumed(pairs, config: CampaignConfig) -> list[tuple]:
    """``(statistic, range_m, component)`` of ``pairs`` (``(statistic, component)`` at every paper range,
    or explicit ``(statistic, range_m, component)``)."""
    out = []
    for p in pairs:
        if len(p) == 3:
            out.append((str(p[0]), float(p[1]), str(p[2])))
        else:
            out += [(str(p[0]), r, str(p[1])) for r in _paper_ranges(config)]
    return out


def _fit_row(key, entry: dict, source: str, use: FitUse, config: CampaignConfig, phone: str, status: str,
             in_campaign=None) -> dict:
    used = True
    if use.condition == "misalignment_yaw":
        used = float(config.misalignment_deg[2]) == float(entry["value"]) != 0.0
        in_campaign = f"yaw {config.misalignment_deg[2]:g} deg"
    effect = use.effect.get(phone, use.effect.get("*", ""))
    if not used:
        status = f"{status}, not used"
        effect = (f"not used by this campaign (its holder misalignment is "
                  f"{', '.join(f'{x:g}' for x in config.misalignment_deg)} deg): consumes nothing")
    return {"key": key, "value": entry["value"], "prior": entry.get("prior"), "status": status, "source": source,
            "fitted_to": entry.get("fitted_to", ""), "range": entry.get("range"),
            "range_source": entry.get("range_source", ""), "effect": effect, "in_campaign": in_campaign,
            "consumes": _consumed(use.consumes, config) if used else []}


def fitted_values_table(config: CampaignConfig, table: dict | None = None) -> list[dict]:
    """Every fitted value (and chosen app setting) that applies to a campaign, and the cells it consumes.

    Reads the camera's fitted overlay (``assets/cameras/fitted/<camera>.toml``, through
    :meth:`svgs_sim.base.profiles.Camera.load`), the lab's (``assets/labs/fitted/msfc-frl.toml``, through
    :func:`svgs_sim.base.profiles.read_fitted_overlay`) and, when it exists, the app's threshold for the
    camera (``assets/app/svgs-app.toml``: a *chosen* setting, consuming the cells its
    ``[threshold] consumes`` lists, none otherwise). What each consumes is :data:`FIT_USES`.

    Parameters
    ----------
    config : CampaignConfig
    table : dict, optional
        The campaign's rows; when given, ``in_campaign`` holds the values the trials used where
        they record them (the lab's light).

    Returns
    -------
    list of dict
        ``key``, ``value``, ``prior`` (the unfitted value, or None), ``status`` (``fitted``,
        ``fitted, not used``, ``chosen``), ``source`` (file), ``fitted_to``, ``range``,
        ``range_source``, ``effect`` (text), ``in_campaign``, ``consumes``: list of
        ``(statistic, range_m, component)``.
    """


    cam = load_camera(config.camera)
    phone = cam.key
    rows = []
    for fit in cam.fitted:
        key, entry = fit.key, fit.entry()
        use = _fit_use(key, phone)
        if use is not None:
            rows.append(_fit_row(key, entry, f"assets/cameras/{entry.get('overlay', 'fitted/' + phone + '.toml')}", use,
                                 config, phone, "fitted"))
    lab = load_lab(DEFAULT_LAB)
    overlay = fitted_overlay_path(lab.source)
    if overlay is not None:
        for fit in lab.fitted:
            key, entry = fit.key, fit.entry()
            use = _fit_use(key, phone)
            if use is None:
                continue
            inc = None
            col = key.split(".", 1)[1]
            if table is not None and key.startswith("lab.") and col in table:
                vals = np.unique(np.asarray(table[col], float)[np.isfinite(np.asarray(table[col], float))])
                inc = ", ".join(f"{v:g}" for v in vals) if vals.size else None
            rows.append(_fit_row(key, entry, package_relative(overlay), use, config, phone, "fitted", inc))
    if APP_SETTINGS_FILE.is_file():
        th = read_toml(APP_SETTINGS_FILE, "app settings").get("threshold") or {}
        by = th.get("by_camera") or {}
        if phone in by or "default_dn" in th:
            use = FIT_USES["threshold.by_camera"]
            if th.get("consumes"):
                use = FitUse(None, tuple(tuple(x) for x in th["consumes"]), "always",
                             {"*": "a chosen app setting; the file lists the cells it consumes"})
            key = "threshold.by_camera" if phone in by else "threshold.default_dn"
            value = by.get(phone, th.get("default_dn"))
            entry = {"value": value, "range": th.get("range_dn"), "range_source": th.get("source", ""),
                     "fitted_to": f"not fitted: chosen for this phone's set-up (status {th.get('status', 'not given')}; "
                                  f"the default's source: {th.get('source', 'not given')})"}
            inc = None
            if table is not None and "threshold" in table:
                vals = np.unique(np.asarray(table["threshold"], float))
                inc = ("threshold scenario value " + ", ".join(f"{v:g}" for v in vals)
                       + (" (0: the app's setting; in results made before assets/app/svgs-app.toml existed, 0 was "
                          "the automatic threshold)" if 0.0 in vals else ""))
            rows.append(_fit_row(f"{key}[{phone}]" if phone in by else key, entry, package_relative(APP_SETTINGS_FILE), use,
                                 config, phone, "chosen", inc))
    return rows


def fitted_cells(rows: list[dict]) -> dict:
    """``(statistic, range_m, component) -> key`` of every cell the values of
    :func:`fitted_values_table` consume (several keys joined by ``+``)."""
    out = {}
    for r in rows:
        for cell in r["consumes"]:
            out[cell] = f"{out[cell]}+{r['key']}" if cell in out else r["key"]
    return out


def misalignment_text(config: CampaignConfig, rows: list[dict] | None = None) -> str:
    """The holder misalignment as printed in reports: ``0, 0, 2 (yaw fitted: <key> to <what>)``."""
    txt = ", ".join(f"{x:g}" for x in config.misalignment_deg)
    rows = fitted_values_table(config) if rows is None else rows
    fit = [r for r in rows if r["key"].endswith("_misalignment_yaw_deg") and r["status"] == "fitted"]
    if fit:
        return f"{txt} (yaw FITTED: {fit[0]['key']} = {fit[0]['value']:g} deg, {fit[0]['source']}, to Table 4's yaw mean error)"
    return txt


def paper_table(camera_name: str, statistic: str) -> str:
    """The paper's table of a phone's cells: Tables 2-3 for the Amaze 4G, 4-5 for the Galaxy Nexus."""
    first = {"htc-amaze-4g": 2, "galaxy-nexus": 4}.get(camera_name)
    return f"Table {first + (statistic == 'std')}" if first else ""


def consumes_text(cells: list) -> str:
    if not cells:
        return "no table cell"
    by = {}
    for stat, r, c in cells:
        by.setdefault((stat, c), []).append(r)
    return "; ".join(f"{'mean error' if s == 'mean_error' else s} {SHORT.get(c, c)} at "
                     f"{', '.join(f'{r:g}' for r in sorted(rs))} m" for (s, c), rs in by.items())


def honest_counts(verdicts: list[dict]) -> dict:
    """Counts of the paper's cells under each reading of the mean error.

    Every cell of Tables 2-5 (verdicts other than ``no_paper_value``); ``fitted`` and
    ``not_predictable`` cells (the mean errors of Tables 2 and 4,
    :data:`svgs_sim.studies.error_budget.NOT_PREDICTABLE_REASON`) are left out of ``predicted``; ``within_2x``, ``below``, ``above``, ``no_solution`` count the
    predicted cells, ``measured`` and ``unexplained`` the explanations of those outside 2x. The
    std cells have one reading and count alike under all three.

    Returns
    -------
    dict
        reading (:data:`svgs_sim.studies.error_budget.MEAN_READINGS`) -> ``{"cells", "fitted",
        "not_predictable", "predicted", "within_2x", "below", "above", "no_solution", "measured", "unexplained",
        "by_statistic": {"mean_error" | "std": {same keys}}}``.
    """
    def count(vs, reading):
        out = {"cells": len(vs), "fitted": 0, "not_predictable": 0, "predicted": 0, "within_2x": 0, "below": 0,
               "above": 0, "no_solution": 0, "measured": 0, "unexplained": 0}
        for v in vs:
            verdict, expl = v[f"verdict_{reading}"], v[f"explanation_{reading}"]
            out[verdict] = out.get(verdict, 0) + 1
            if verdict not in ("fitted", "not_predictable"):
                out["predicted"] += 1
            if expl:
                out["measured" if expl.startswith("measured") else "unexplained"] += 1
        return out

    cells = [v for v in verdicts if v["verdict"] != "no_paper_value"]
    res = {}
    for x in MEAN_READINGS:
        res[x] = count(cells, x)
        res[x]["by_statistic"] = {st: count([v for v in cells if v["statistic"] == st], x) for st in ("mean_error", "std")}
    return res


def honest_count_object(config: CampaignConfig, rows: list[dict], verdicts: list[dict]) -> dict:
    """What ``DIR/honest_count.json`` holds (and ``summary.json``'s ``honest_count``): the fitted
    values, the reading the verdicts use and why, and the counts under each reading."""

    return {"headline_reading": HEADLINE_READING, "headline_reason": HEADLINE_REASON,
            "readings": {x: READING_MEANINGS[x] for x in (*MEAN_READINGS, "std")},
            "fitted_values": [{**r, "consumes": [{"statistic": s, "range_m": rr, "component": c}
                                                 for s, rr, c in r["consumes"]]} for r in rows],
            "counts": honest_counts(verdicts)}


def campaign_verdicts(config: CampaignConfig, summary: list[dict], budget: dict | None = None,
                      rows: list[dict] | None = None) -> list[dict]:
    """Every cell of Tables 2-5 judged (:func:`svgs_sim.studies.error_budget.cell_verdicts`), the cells the
    fitted values consume (:func:`fitted_values_table`) as ``fitted``, each with its ``table``
    (``Table 2`` ... ``Table 5``)."""


    rows = fitted_values_table(config) if rows is None else rows
    b = budget or {}
    verdicts = cell_verdicts(summary, b.get("attribution"), b.get("variant_stats"), b.get("centroids"),
                             fitted_cells=fitted_cells(rows))
    phone = load_camera(config.camera).key
    return [{**v, "table": paper_table(phone, v["statistic"])} for v in verdicts]
