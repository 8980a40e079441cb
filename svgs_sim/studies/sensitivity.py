"""Global sensitivity of pose error and success rate to scenario parameters.

Methods
    ``sobol``: variance-based first-order and total indices (Saltelli 2010 estimators) with
    :func:`scipy.stats.sobol_indices` on a Saltelli design: matrices A and B (``n`` rows,
    scrambled Sobol' points, seeded) and the d matrices AB^(i) (A with column i from B),
    ``n (d + 2)`` trials. 95 % confidence intervals by a seeded bootstrap over the ``n``
    rows (:func:`scipy.stats.bootstrap`, percentile).
    ``morris``: elementary effects on ``n`` one-at-a-time trajectories over a 4-level grid
    (Morris 1991, with Campolongo's mu*), ``n (d + 1)`` trials; mu*, sigma and a bootstrap
    interval of mu* over trajectories.

Noise as common random numbers
    Trials are stochastic (centroid noise). Row ``j`` of A and row ``j`` of every AB^(i)
    use the same noise seed, so ``f(A_j) - f(AB^(i)_j)`` measures parameter ``i``, not a new
    noise draw (and, for a parameter that acts after the render, the trials of row ``j`` share
    one render: *render once, expose many*). B uses its own seeds. Morris trajectories do the
    same per trajectory.

Outputs analysed
    ``pos_err_norm_m`` (norm of the position error), ``rot_err_deg`` (attitude error angle;
    names from :mod:`svgs_sim.sim.metrics`) and
    ``success`` (1 solved, 0 failed). A failed trial has no error: it is given the largest
    error seen for that output (a penalty) and the failure fraction is reported.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera as _camera
from svgs_sim.base.profiles import load_pattern as _pattern
from svgs_sim.sim.metrics import POS_ERR_NORM_M, ROT_ERR_DEG, SCALAR_ERROR_KEYS
from svgs_sim.sim.trials import TrialKind, build_scenario, get_trial_kind
from svgs_sim.svgs.envelope import check_range_m

from .execution import Trial, library_versions, run_stored_study
from .report import Report, write_csv
from .seeding import check_seed, trial_seed

OUTPUTS = (POS_ERR_NORM_M, ROT_ERR_DEG, "success")
#: Outputs analysed when the trial kind has them: the rendered kind's ``merge_margin_dn`` (the
#: detector's threshold minus the darkest level between the closest spots: negative, merged).
OPTIONAL_OUTPUTS = ("merge_margin_dn",)


def analysed_outputs(config) -> tuple:
    """:data:`OUTPUTS` plus the :data:`OPTIONAL_OUTPUTS` the study's trial kind records."""
    kind = get_trial_kind(config.trial_kind)
    return OUTPUTS + tuple(k for k in OPTIONAL_OUTPUTS if k in kind.outputs)
MORRIS_LEVELS = 4
CONFIDENCE = 0.95
N_BOOTSTRAP = 499

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_VARY = re.compile(rf"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*({_NUM})\s*:\s*({_NUM})\s*$")
_FIXED = re.compile(rf"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*({_NUM}|[A-Za-z_]+)\s*$")


@dataclass(frozen=True)
class Varied:
    """A varied parameter: name, bounds (uniform), and its registry entry."""

    name: str
    low: float
    high: float
    unit: str
    meaning: str
    needs_render: bool


def _known(kind: TrialKind) -> str:
    return "; ".join(f"{p.name} ({p.unit}): {p.meaning}" for p in kind.parameters.values())


def parse_vary(texts, kind: TrialKind, envelope=None) -> list[Varied]:
    """Parse ``PARAM=LOW:HIGH`` specifications against the kind's parameter registry.

    ``envelope(name, value, what)``, if given, checks a bound first (the camera's range envelope,
    :func:`range_envelope_check`: its message is more specific than the parameter's domain).

    Raises
    ------
    InputError
        Malformed text, unknown name (the message lists the known ones with units), a name
        given twice, ``LOW > HIGH``, an empty range ``LOW == HIGH``, or bounds outside the
        parameter's physical domain. All before any work.
    """
    if not texts:
        raise InputError("--vary: give at least two parameters to vary, e.g. --vary range_m=5:30 --vary sigma_px=0.05:0.5")
    out, seen = [], set()
    for t in texts:
        m = _VARY.match(str(t))
        if not m:
            raise InputError(f"--vary: expected PARAM=LOW:HIGH with numbers, got {t!r}")
        name, lo, hi = m.group(1), float(m.group(2)), float(m.group(3))
        if name not in kind.parameters:
            raise InputError(f"--vary: unknown parameter {name!r} for trial kind {kind.name!r}. Known: {_known(kind)}")
        if name in seen:
            raise InputError(f"--vary: parameter {name!r} given twice")
        seen.add(name)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise InputError(f"--vary {name}: bounds must be finite, got {t!r}")
        if lo > hi:
            raise InputError(f"--vary {name}: LOW {lo:g} is greater than HIGH {hi:g}; write {name}={hi:g}:{lo:g}")
        if lo == hi:
            raise InputError(f"--vary {name}: empty range {lo:g}:{hi:g}; to hold it fixed use --fixed {name}={lo:g}")
        p = kind.parameters[name]
        for what, x in (("LOW", lo), ("HIGH", hi)):
            if envelope is not None:
                envelope(name, x, f"--vary {name} {what}")
            p.check(x, f"--vary {name} {what}", codes=False)  # a range of quantities: no choice words
        out.append(Varied(name, lo, hi, p.unit, p.meaning, p.needs_render))
    if len(out) < 2:
        raise InputError("--vary: a sensitivity analysis needs at least two varied parameters")
    return out


def parse_fixed(texts, kind: TrialKind, varied, envelope=None) -> dict:
    """Parse ``PARAM=VALUE`` for parameters held fixed (InputError like :func:`parse_vary`, the
    same ``envelope`` check)."""
    out = {}
    names = {v.name for v in varied}
    for t in texts or ():
        m = _FIXED.match(str(t))
        if not m:
            raise InputError(f"--fixed: expected PARAM=VALUE with a number or a word such as 'profile', got {t!r}")
        name, v = m.group(1), m.group(2)
        if name not in kind.parameters:
            raise InputError(f"--fixed: unknown parameter {name!r} for trial kind {kind.name!r}. Known: {_known(kind)}")
        if name in names:
            raise InputError(f"--fixed {name}: it is also varied")
        if name in out:
            raise InputError(f"--fixed: parameter {name!r} given twice")
        if envelope is not None and re.fullmatch(_NUM, v):
            envelope(name, float(v), f"--fixed {name}")
        out[name] = kind.parameters[name].check(v, f"--fixed {name}")
    return out


def _check_n(n, method: str) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise InputError(f"--n: expected an integer >= 2, got {n!r}")
    n = int(n)
    if method == "sobol" and n & (n - 1):
        raise InputError(f"--n: Sobol' designs need a power of two (balance of the Sobol' points), got {n}; "
                         f"try {1 << (n - 1).bit_length()} or {1 << ((n - 1).bit_length() - 1)}")
    return n


@dataclass(frozen=True)
class SensitivityConfig:
    """What a sensitivity study computes (its manifest)."""

    camera: str
    varied: tuple
    fixed: dict
    method: str = "sobol"
    n: int = 256
    seed: int = 0
    trial_kind: str = "geometric"
    pattern: str = "svgs-3u"

    @property
    def n_trials(self) -> int:
        d = len(self.varied)
        return self.n * (d + 2) if self.method == "sobol" else self.n * (d + 1)

    def manifest(self) -> dict:
        return {"study": "sensitivity", "camera": self.camera, "pattern": self.pattern, "method": self.method,
                "n": self.n, "seed": self.seed, "trial_kind": self.trial_kind,
                "vary": {v.name: [v.low, v.high] for v in self.varied},
                "vary_order": [v.name for v in self.varied],
                "fixed": {k: float(v) for k, v in sorted(self.fixed.items())}}


def make_config(camera: str, vary, *, fixed=None, method: str = "sobol", n: int = 256, seed: int = 0,
                trial_kind: str = "geometric", pattern: str = "svgs-3u") -> SensitivityConfig:
    """A validated :class:`SensitivityConfig` (all checks before any work)."""

    kind = get_trial_kind(trial_kind)
    if method not in ("sobol", "morris"):
        raise InputError(f"--method: expected 'sobol' or 'morris', got {method!r}")
    cam = _camera(camera)
    if kind.name == "tof":
        if not cam.is_tof:
            raise InputError(f"--camera: {cam.name!r} is a phone (SVGS) profile; --trial-kind tof needs a "
                             "time-of-flight camera profile such as 'tof-epc660'")
        if pattern == "svgs-3u":  # the default target is the phone's: the ToF sensor's is tof-8
            pattern = "tof-8"
    _pattern(pattern)
    envelope = range_envelope_check(kind, camera, pattern)
    varied = parse_vary(vary, kind, envelope)
    fx = parse_fixed(fixed, kind, varied, envelope)
    return SensitivityConfig(camera, tuple(varied), fx, method, _check_n(n, method), check_seed(seed), kind.name, pattern)


def range_envelope_check(kind: TrialKind, camera: str, pattern: str):
    """``check(name, value, what)``: a ``range_m`` bound (or fixed range) inside the envelope
    ``--range`` takes - the phone's :func:`svgs_sim.svgs.envelope.range_envelope_m` for the phone's kinds,
    the paper's design range for the ToF kind - else :class:`InputError` naming ``what``; other
    parameters pass (their own domain is checked after it)."""

    def check(name: str, x: float, what: str) -> None:
        if name != "range_m":
            return
        if kind.name == "tof":
            from svgs_sim.tof.camera import DESIGN_RANGE_M  # not at module level: heavy (the ToF pipeline loads OpenCV)

            lo, hi = DESIGN_RANGE_M
            if not lo <= x <= hi:
                raise InputError(f"{what}: expected {lo:g}-{hi:g} m (the ToF paper's design range), got {x:g}")
        elif kind.name in ("geometric", "render"):
            check_range_m(x, camera, pattern, what)

    return check


# --------------------------------------------------------------------------- designs
def sobol_design(config: SensitivityConfig):
    """Saltelli design in unit coordinates.

    Returns
    -------
    A, B : ndarray, shape (n, d)
        Columns 0..d-1 and d..2d-1 of one scrambled Sobol' sequence of dimension 2d
        (as :func:`scipy.stats.sobol_indices` samples them), seeded by the study seed.
    """
    from scipy.stats import qmc

    d = len(config.varied)
    AB = qmc.Sobol(d=2 * d, scramble=True, rng=np.random.default_rng(np.random.SeedSequence(config.seed)),
                   bits=64).random(config.n)
    return AB[:, :d], AB[:, d:]


def morris_design(config: SensitivityConfig):
    """Morris trajectories in unit coordinates on a ``MORRIS_LEVELS`` grid.

    Returns
    -------
    X : ndarray, shape (n, d + 1, d)
        Trajectory points.
    order : ndarray, shape (n, d)
        Which factor changes at each step.
    delta : ndarray, shape (n, d)
        Signed step of that factor (+-``p / (2 (p - 1))``).
    """
    p = MORRIS_LEVELS
    jump = p // 2  # grid steps per move: delta = (p / 2) / (p - 1)
    d = len(config.varied)
    rng = np.random.default_rng(np.random.SeedSequence(config.seed))
    X = np.empty((config.n, d + 1, d))
    order = np.empty((config.n, d), int)
    delta = np.empty((config.n, d))
    for t in range(config.n):
        k = rng.integers(0, p, size=d)  # grid levels
        perm = rng.permutation(d)
        X[t, 0] = k / (p - 1)
        for s, i in enumerate(perm):
            dk = jump if k[i] + jump <= p - 1 else -jump
            k = k.copy()
            k[i] += dk
            X[t, s + 1] = k / (p - 1)
            order[t, s] = i
            delta[t, s] = dk / (p - 1)
    return X, order, delta


def _scale(u, varied) -> np.ndarray:
    lo = np.array([v.low for v in varied])
    hi = np.array([v.high for v in varied])
    return lo + np.asarray(u) * (hi - lo)


def sensitivity_trials(config: SensitivityConfig) -> tuple[list, dict]:
    """Every trial of the design, with ids laid out by design block.

    Sobol: ids ``j`` (A), ``n + j`` (B), ``(2 + i) n + j`` (AB^(i)). Morris: ``t (d + 1) + s``.

    Returns
    -------
    trials : list of Trial
    layout : dict
        Design matrices (unit and physical) for the analysis.
    """

    kind = get_trial_kind(config.trial_kind)
    names = [v.name for v in config.varied]
    base = {"camera": config.camera, "pattern": config.pattern, **config.fixed}
    n, d = config.n, len(names)
    trials = []

    def add(tid, x_unit, seed_index, block):
        vals = _scale(x_unit, config.varied)
        values = {**base, **{k: float(v) for k, v in zip(names, vals)}}
        seed = trial_seed(config.seed, seed_index)
        if kind.name == "tof":  # a ToF trial's seed is its run's render seed (Mitsuba's: 32 bits)
            seed = int(seed) % 2**32
            values["render_seed"] = seed
        scen = build_scenario(kind, values, labels={"block": block})
        trials.append(Trial(tid, scen, seed))

    if config.method == "sobol":
        A, B = sobol_design(config)
        for j in range(n):
            add(j, A[j], j, "A")
        for j in range(n):
            add(n + j, B[j], n + j, "B")
        for i in range(d):
            ABi = A.copy()
            ABi[:, i] = B[:, i]
            for j in range(n):
                add((2 + i) * n + j, ABi[j], j, f"AB{i}")  # common random numbers with A_j
        layout = {"A": A, "B": B}
    else:
        X, order, delta = morris_design(config)
        for t in range(n):
            for s in range(d + 1):
                add(t * (d + 1) + s, X[t, s], t * (d + 1), f"T{t}")  # one noise stream per trajectory
        layout = {"X": X, "order": order, "delta": delta}
    return trials, layout


# --------------------------------------------------------------------------- analysis
def output_values(table: dict) -> dict:
    """Per-trial outputs by trial id order: failures penalised with the largest error seen.

    Returns
    -------
    dict of output -> ndarray (n_trials,), and ``failure_fraction``.
    """
    ok = table["ok"] == 1
    out = {"success": ok.astype(float)}
    for k in SCALAR_ERROR_KEYS:
        v = np.array(table[k], float)
        worst = np.nanmax(v[ok]) if np.any(ok) else 1.0
        v[~ok | ~np.isfinite(v)] = worst
        out[k] = v
    for k in OPTIONAL_OUTPUTS:  # recorded for failed trials too (a merged frame has a margin)
        if k in table:
            v = np.array(table[k], float)
            fin = np.isfinite(v)
            v[~fin] = np.nanmin(v[fin]) if fin.any() else 0.0
            out[k] = v
    out["failure_fraction"] = float(1.0 - ok.mean()) if ok.size else float("nan")
    return out


def _saltelli(fA, fB, fAB):
    """Saltelli 2010 first-order and total indices (same estimators as scipy's), shape (d,) each."""
    mean = np.mean([fA, fB])
    fA, fB, fAB = fA - mean, fB - mean, fAB - mean
    var = np.var(np.concatenate([fA, fB]))
    if not var > 0:
        return np.zeros(fAB.shape[0]), np.zeros(fAB.shape[0])
    s1 = np.mean(fB * (fAB - fA), axis=-1) / var
    st = 0.5 * np.mean((fA - fAB) ** 2, axis=-1) / var
    return s1, st


def analyze_sobol(y: np.ndarray, config: SensitivityConfig) -> dict:
    """First-order and total Sobol' indices with bootstrap confidence intervals.

    Parameters
    ----------
    y : ndarray, shape (n (d + 2),)
        The output, by trial id.

    Returns
    -------
    dict
        ``S1``, ``ST`` (d,), ``S1_ci``, ``ST_ci`` (d, 2), ``variance``.
    """
    from scipy.stats import bootstrap, sobol_indices

    n, d = config.n, len(config.varied)
    fA, fB = y[:n], y[n:2 * n]
    fAB = y[2 * n:].reshape(d, n)
    var = float(np.var(np.concatenate([fA, fB])))
    if not var > 0:
        z = np.zeros(d)
        return {"S1": z, "ST": z, "S1_ci": np.zeros((d, 2)), "ST_ci": np.zeros((d, 2)), "variance": var}
    res = sobol_indices(func={"f_A": fA[None], "f_B": fB[None], "f_AB": fAB[:, None, :]}, n=n)
    s1, st = np.atleast_1d(res.first_order).astype(float), np.atleast_1d(res.total_order).astype(float)

    def stat(idx, axis=-1):
        idx = np.asarray(idx, int)
        a, b = _saltelli(fA[idx], fB[idx], fAB[:, idx])
        return np.concatenate([a, b])

    boot = bootstrap((np.arange(n),), stat, n_resamples=N_BOOTSTRAP, confidence_level=CONFIDENCE,
                     method="percentile", vectorized=False, rng=np.random.default_rng(config.seed))
    lo, hi = boot.confidence_interval.low, boot.confidence_interval.high
    return {"S1": s1, "ST": st, "S1_ci": np.stack([lo[:d], hi[:d]], -1), "ST_ci": np.stack([lo[d:], hi[d:]], -1),
            "variance": var}


def analyze_morris(y: np.ndarray, config: SensitivityConfig, layout: dict) -> dict:
    """Morris mu* (mean |elementary effect|), mu, sigma and a bootstrap interval of mu*.

    Elementary effects are per unit of the *normalised* range (so mu* of parameters with
    different units compare), i.e. output change for the full LOW..HIGH swing scaled by the
    grid step.
    """
    from scipy.stats import bootstrap

    n, d = config.n, len(config.varied)
    Y = y.reshape(n, d + 1)
    EE = np.empty((n, d))
    for t in range(n):
        for s in range(d):
            i = layout["order"][t, s]
            EE[t, i] = (Y[t, s + 1] - Y[t, s]) / layout["delta"][t, s]
    mu_star = np.mean(np.abs(EE), 0)
    if n >= 3 and np.any(EE != 0):
        boot = bootstrap((np.abs(EE),), lambda a, axis: np.mean(a, axis=axis), n_resamples=N_BOOTSTRAP,
                         confidence_level=CONFIDENCE, method="percentile", axis=0,
                         rng=np.random.default_rng(config.seed))
        ci = np.stack([boot.confidence_interval.low, boot.confidence_interval.high], -1)
    else:
        ci = np.full((d, 2), np.nan)
    return {"mu_star": mu_star, "mu": EE.mean(0), "sigma": EE.std(0, ddof=1) if n > 1 else np.zeros(d),
            "mu_star_ci": ci}


def analyze(table: dict, config: SensitivityConfig, layout: dict) -> dict:
    """Indices for every output of :func:`analysed_outputs`, plus the ranking by total effect."""
    vals = output_values(table)
    res = {"failure_fraction": vals["failure_fraction"], "outputs": {}}
    for k in analysed_outputs(config):
        y = vals[k]
        res["outputs"][k] = analyze_sobol(y, config) if config.method == "sobol" else analyze_morris(y, config, layout)
    return res


def ranking(result: dict, config: SensitivityConfig, output: str = POS_ERR_NORM_M) -> list[tuple[str, float]]:
    """Parameters ranked by total index (Sobol) or mu* (Morris) for ``output``, largest first."""
    r = result["outputs"][output]
    score = r["ST"] if config.method == "sobol" else r["mu_star"]
    names = [v.name for v in config.varied]
    order = np.argsort(-np.asarray(score), kind="stable")
    return [(names[i], float(score[i])) for i in order]


# --------------------------------------------------------------------------- report
def write_sensitivity_report(out_dir, config: SensitivityConfig, table: dict, result: dict, *, command: str,
                             versions: dict, stats=None, n_render_groups: int | None = None) -> Path:
    """``DIR/report.html`` and ``DIR/indices.csv``."""

    out_dir = Path(out_dir)
    names = [v.name for v in config.varied]
    d = len(names)
    rows = index_rows(result, config, names)
    cols = list(rows[0])
    write_csv(out_dir / "indices.csv", cols, rows)

    title = f"Sensitivity of SVGS pose error ({config.method}): {config.camera}, {config.trial_kind} trials"
    rep = Report(title, command, versions)
    n_tr = config.n_trials
    render_note = ""
    if n_render_groups is not None:
        render_note = (f" Trials needing a new render: {n_render_groups} of {n_tr} (the others share a render with "
                       "a trial that differs only in parameters acting after the render).")
    rep.paragraph(f"{config.method} design with n = {config.n} over {d} parameters: {n_tr} trials; "
                  f"{100 * result['failure_fraction']:.1f} % of them failed to solve.{render_note}")
    rep.heading("Parameters")
    rep.table(["parameter", "low", "high", "unit", "acts", "meaning"],
              [[v.name, v.low, v.high, v.unit, "before the render" if v.needs_render else "after the render", v.meaning]
               for v in config.varied], text_columns=["unit", "acts", "meaning"], digits=4)
    if config.fixed:
        params = get_trial_kind(config.trial_kind).parameters  # a code shown as its word ('profile')
        rep.table(["fixed parameter", "value"],
                  [[k, params[k].word(v) if params[k].codes else v] for k, v in sorted(config.fixed.items())],
                  text_columns=["value"] if any(params[k].codes for k in config.fixed) else (), digits=4)
    _report_ranking(rep, result, config)
    rep.heading("Indices")
    for k in analysed_outputs(config):
        sub = [r for r in rows if r["output"] == k]
        rep.table(cols[1:], [[r[c] for c in cols[1:]] for r in sub],
                  caption=f"{k}: indices with {int(100 * CONFIDENCE)} % bootstrap intervals")
        rep.figure(_index_figure(result["outputs"][k], k, config, names),
                   f"{k}: sensitivity indices with {int(100 * CONFIDENCE)} % confidence intervals.")
    rep.figure(_scatter_figure(table, config, names),
               "Position error against each varied parameter (independent design rows).")
    return rep.write(out_dir / "report.html")


def index_rows(result: dict, config: SensitivityConfig, names: list) -> list[dict]:
    """One row per (output, parameter): the indices and their bootstrap interval (``indices.csv``)."""
    rows = []
    for k in analysed_outputs(config):
        r = result["outputs"][k]
        for i, nm in enumerate(names):
            if config.method == "sobol":
                rows.append({"output": k, "parameter": nm, "S1": r["S1"][i], "S1_low": r["S1_ci"][i, 0],
                             "S1_high": r["S1_ci"][i, 1], "ST": r["ST"][i], "ST_low": r["ST_ci"][i, 0],
                             "ST_high": r["ST_ci"][i, 1]})
            else:
                rows.append({"output": k, "parameter": nm, "mu_star": r["mu_star"][i], "mu_star_low": r["mu_star_ci"][i, 0],
                             "mu_star_high": r["mu_star_ci"][i, 1], "mu": r["mu"][i], "sigma": r["sigma"][i]})
    return rows


def _report_ranking(rep, result: dict, config: SensitivityConfig) -> None:
    """The report's "Ranking" section: parameters by total index or mu*, and how to read them."""
    rep.heading("Ranking")
    for k in analysed_outputs(config):
        rk = ranking(result, config, k)
        label = "total index ST" if config.method == "sobol" else "mu*"
        rep.paragraph(f"{k} by {label}: " + ", ".join(f"{nm} ({s:.3g})" for nm, s in rk))
    if config.method == "sobol":
        rep.paragraph(
            "How to read this. S1 is the share of the output's variance explained by the parameter alone; ST adds "
            "every interaction it takes part in. ST well above S1 means the parameter matters through others (e.g. an "
            "attitude whose effect grows with range). A parameter whose ST interval stays near zero can be held at any "
            "value in its range without changing the output's spread: it is not worth controlling in a design. "
            "Indices are relative to the ranges given: widen a range and its parameter's share grows. Small negative "
            "S1 values are estimator noise around zero.", "note")
        for k in analysed_outputs(config):
            if not result["outputs"][k]["variance"] > 0:
                rep.paragraph(f"{k} did not vary over the design (e.g. every trial solved): its indices are zero.",
                              "note")
    else:
        rep.paragraph(
            "How to read this. mu* is the mean absolute change of the output when the parameter moves across "
            "two-thirds of its range (the 4-level grid step), sigma the spread of that change: sigma comparable to mu* "
            "means the effect depends on the other parameters (interactions or non-linearity).", "note")


def _index_figure(res: dict, k: str, config: SensitivityConfig, names: list):
    """Bar chart of one output's indices (S1 and ST, or mu*) with their confidence intervals."""
    from matplotlib.figure import Figure

    d = len(names)
    fig = Figure(figsize=(max(6, 0.9 * d + 2), 3.4))
    ax = fig.subplots()
    x = np.arange(d)
    if config.method == "sobol":
        for off, key, lab in ((-0.18, "S1", "first order S1"), (0.18, "ST", "total ST")):
            v, ci = res[key], res[f"{key}_ci"]
            ax.bar(x + off, v, 0.36, label=lab,
                   yerr=np.abs(np.stack([v - ci[:, 0], ci[:, 1] - v])), capsize=3)
        ax.set_ylabel("Sobol' index")
    else:
        v, ci = res["mu_star"], res["mu_star_ci"]
        ax.bar(x, v, 0.5, label="mu*", yerr=np.abs(np.stack([v - ci[:, 0], ci[:, 1] - v])), capsize=3)
        ax.set_ylabel("mu* (output per unit normalised range)")
    ax.set_xticks(x, names, rotation=30, ha="right")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    ax.set_title(k)
    fig.tight_layout()
    return fig


def _scatter_figure(table: dict, config: SensitivityConfig, names: list):
    """The position error against each varied parameter (A and B rows, or all trajectory points)."""
    from matplotlib.figure import Figure

    d = len(names)
    vals = output_values(table)
    X = np.array([[table[nm][j] for nm in names] for j in range(len(table["trial_id"]))])
    sel = slice(0, 2 * config.n) if config.method == "sobol" else slice(None)
    fig = Figure(figsize=(min(3.0 * d, 18), 3.0))
    axes = np.atleast_1d(fig.subplots(1, d))
    for i, ax in enumerate(axes):
        ax.plot(X[sel, i], vals[POS_ERR_NORM_M][sel], ".", ms=2, alpha=0.5)
        ax.set_yscale("log")
        ax.set_xlabel(f"{names[i]} ({config.varied[i].unit})")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(POS_ERR_NORM_M)
    fig.tight_layout()
    return fig


def run_sensitivity(config: SensitivityConfig, out_dir, spec, *, chunk_size=None, progress: bool = True,
                    command: str = ""):
    """Run (or resume) a sensitivity study into ``out_dir``; analyse and report.

    Returns
    -------
    (result, stats, report_path, n_render_groups)
    """

    kind = get_trial_kind(config.trial_kind)
    trials, layout = sensitivity_trials(config)
    n_groups = len({kind.render_key(t.scenario) for t in trials}) if kind.render_key else len(trials)
    store, stats = run_stored_study(kind, trials, out_dir, config.manifest(), spec, chunk_size=chunk_size,
                                    progress=progress, description=f"{config.method} {config.camera}")
    table = store.read_table()
    result = analyze(table, config, layout)
    path = write_sensitivity_report(out_dir, config, table, result, command=command, versions=library_versions(),
                                    stats=stats, n_render_groups=n_groups)
    return result, stats, path, n_groups
