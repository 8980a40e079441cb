"""What the ToF study computes: its configuration, the paper's ranges and the mechanisms it varies,
and its runs (typed trial scenarios for the study engine).

Part of :mod:`svgs_sim.studies.tof_study`.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, replace

from svgs_sim.sim.tof_closed_loop import TofScene, noise_free_frame
from svgs_sim.sim.tof_stability import COLUMNS, RUN_INFO_KEYS, assemble_run, stability_scenario

from ..execution import Trial

#: Short names of the columns in the report's sentences.
SHORT_NAMES = dict(zip(COLUMNS, ("x", "y", "z", "roll", "pitch", "yaw")))


#: The paper's two ranges (m).
PAPER_RANGES_M = (0.697, 5.712)


#: Ranges of the Fig. 14 sweep (m).
SWEEP_RANGES_M = tuple(float(r) for r in range(1, 11))


#: Pose schemes of the sweep: the paper's literal line-of-sight iteration (the default), its converged
#: optimum (Gauss-Newton, the former default) and the maximum-likelihood depth blend.
GN = {"refine_method": "gauss-newton"}


SWEEP_SCHEMES = (("paper (fixed point, default)", {}), ("converged optimum (Gauss-Newton)", GN),
                 ("ML depth blend", {**GN, "depth_weight": None}))


#: The stopping rule's sensitivity: (label, pipeline overrides); the default is 1e-6 m / rad, 500 iterations.
#: The default's row ({}) is the baseline's runs and sweep, not run again.
STOPPING_RULES = tuple((f"tol {tol:g}, cap 500", {"refine_tol_m": tol} if tol != 1e-6 else {})
                       for tol in (1e-3, 1e-4, 1e-5, 1e-6, 1e-7)) + \
    (("tol 1e-06, cap 100", {"refine_max_iter": 100}), ("tol 1e-06, cap 2000", {"refine_max_iter": 2000}))


#: Frame counts at which the long run's fluctuation is reported.
LONG_CHECKPOINTS = (200, 1000, 3000, 10000)


#: The paper's headline accuracy (abstract): 0.13 deg and 2 mm.
PAPER_ACCURACY = {"deg": 0.13, "mm": 2.0}


#: The paper's Fig. 14 text (section 6.5): the range (z) error beyond 5 m, mm.
PAPER_FIG14_Z_MM = 2.5


#: The active-set caps N_max the study tries at the near range, as fractions of the pixels the
#: noise-free baseline frame has above the threshold there: 7600, 7300, 7000 and 6500 of the ~8000
#: the faces filled when the caps were first chosen (the target then 125 mm nearer). The paper's
#: N_max is not legible, so these bracket where a cap starts to bite; none is fitted.
CAP_FRACTIONS = (0.95, 0.9125, 0.875, 0.8125)


def _variants(frames_auto_T_far: float, frames_auto_T_near: float, active_near_px: int):
    """(label, ranges, renderer kwargs, sensor kwargs, pipeline kwargs, reference, what it tests)."""
    both = PAPER_RANGES_M
    near = (PAPER_RANGES_M[0],)
    far = (PAPER_RANGES_M[1],)
    v = [
        ("converged optimum (Gauss-Newton)", both, {}, {}, GN, "markers",
         "the literal iteration's fixed point (the former default): range from the pattern's apparent size"),
        ("reference point: plate centre", both, {}, {}, {}, "plate",
         "the position columns at the plate's front-face centre, 125 mm behind the marker faces' centroid"),
        ("ML depth blending (depth_weight None)", both, {}, {}, {**GN, "depth_weight": None}, "markers",
         "the pipeline's maximum-likelihood blend of the depths with an assumed 0.05 px centroid sigma"),
        ("no recursive median of depth", both, {}, {}, {"temporal_median": False}, "markers",
         "the paper's recursive time-domain median of the depth image (section 3.1.2) switched off"),
        ("centroid weighting: intensity", both, {}, {}, {"centroid_weighting": "intensity"}, "markers",
         "the paper's intensity-weighted centroid over all of a marker's pixels (~1000 per marker at 0.7 m)"),
        ("integration time 1/4 of automatic", near, {}, {"integration_time_s": frames_auto_T_near / 4}, {}, "markers",
         "a quarter of the automatic setting: 4x fewer photo-electrons (shot noise x2)"),
        ("integration time 1/4 of automatic", far, {}, {"integration_time_s": frames_auto_T_far / 4}, {}, "markers",
         "a quarter of the automatic setting: 4x fewer photo-electrons (shot noise x2)"),
        ("persistence window 10 frames", both, {}, {}, {"persistence_window": 10, "persistence_min_count": 5}, "markers",
         "the paper's temporal filter (section 3.4), 0.26 s at 39 fps"),
        ("persistence window 39 frames", both, {}, {}, {"persistence_window": 39, "persistence_min_count": 20}, "markers",
         "1 s at the datasheet's 39 fps"),
        ("Lambertian white markers (albedo 0.85)", both, {"scene_options": {"marker_material": "lambertian"}}, {}, {},
         "markers", "the previous model: white paint instead of sheeting"),
        ("sheeting EN 12899-1 RA1", both, {"scene_options": {"sheeting": "en12899-ra1-white"}}, {}, {}, "markers",
         "engineering-grade glass beads"),
        ("sheeting 3M 983 (microprismatic)", both, {"scene_options": {"sheeting": "3m-983-diamond-grade-white"}}, {}, {},
         "markers", "full-cube prisms (typical values; extrapolated beyond 0.5 deg)"),
        ("fixed integration time (5.7 m setting)", both, {}, {"integration_time_s": frames_auto_T_far}, {}, "markers",
         "one integration time for both ranges: the near markers saturate"),
        ("ambient 10 klux", both, {}, {"ambient_lux": 10000.0}, {}, "markers", "the paper's high light environment"),
        ("multipath (2 bounces)", both, {"max_bounces": 2}, {}, {}, "markers", "diffuse inter-reflections plate <-> markers"),
    ]
    for frac in CAP_FRACTIONS:
        cap = int(round(frac * active_near_px))
        v.append((f"active-set cap N_max = {cap} px", near, {}, {}, {"max_active_pixels": cap}, "markers",
                  f"the paper's cap on the active pixel set (section 3.1), dimmest discarded first: {frac:.1%} of "
                  f"the {active_near_px} px above the threshold"))
    return v


@dataclass(frozen=True)
class TofStudyConfig:
    """What the ToF study computes (its manifest); how it runs is not part of it.

    Attributes
    ----------
    camera, pattern : str
        ToF camera profile and marker target (names or paths).
    frames, variant_frames, sweep_frames, long_frames : int
        Frames of the stability runs, of each mechanism and stopping-rule run, per range of the
        Fig. 14 sweep, and of the long run (0: none).
    seed : int
        Every run's render seed and noise stream (:mod:`svgs_sim.sim.tof_trial`).
    spp, rim_spp_factor : int or None
        The renders' samples per pixel and the factor at the marker rims (None: the renderer's).
    ambient_lux : float or None
        The sensor's ambient light (None: the profile's).
    scene : tuple of (str, value)
        Scene options of every render (``marker_material``, ``sheeting``).
    """

    camera: str = "tof-epc660"
    pattern: str = "tof-8"
    frames: int = 500
    variant_frames: int = 200
    sweep_frames: int = 40
    long_frames: int = 3000
    seed: int = 0
    spp: int | None = None
    rim_spp_factor: int | None = None
    ambient_lux: float | None = None
    scene: tuple = ()

    def manifest(self) -> dict:
        d = asdict(self)
        d["scene"] = dict(self.scene)
        return {"study": "tof-study", "trial_kind": "tof", **d}

    def scenario(self, range_m: float, *, scene: dict | None = None, max_bounces: int = 1, **sensor):
        """The stability scenario at ``range_m`` with this study's render and sensor settings."""

        so = {**dict(self.scene), **(scene or {})}
        kw = {"ambient_lux": self.ambient_lux, **sensor}
        return stability_scenario(range_m, camera=self.camera, pattern=self.pattern, seed=self.seed, spp=self.spp,
                                  rim_spp_factor=self.rim_spp_factor, max_bounces=max_bounces,
                                  scene=TofScene.from_dict(so), **kw)


def auto_integration_times(cfg: TofStudyConfig) -> dict:
    """The automatic integration time at the paper's two ranges (s; the baseline renders'
    noise-free frames): the mechanism runs at a quarter of it and at the far range's."""
    from svgs_sim.sim.tof_trial import cached_render

    return {r: float(noise_free_frame(cached_render(cfg.scenario(r))).integration_time_s) for r in PAPER_RANGES_M}


def active_pixels_near(cfg: TofStudyConfig) -> int:
    """Pixels above the active-set threshold in the near baseline's noise-free frame (the
    pipeline's defaults, no cap binding): what the active-set caps are fractions of."""
    from svgs_sim.sim.tof_trial import cached_render
    from svgs_sim.tof import PipelineParams
    from svgs_sim.tof.active import active_pixel_set

    P = PipelineParams()
    frame = noise_free_frame(cached_render(cfg.scenario(PAPER_RANGES_M[0])))
    return int(active_pixel_set(frame.gray, P.threshold_rel, P.max_active_pixels, noise_k=P.noise_k).n_above)


def study_runs(cfg: TofStudyConfig, auto_T: dict, active_near_px: int) -> list:
    """Every run of the study, in trial order: ``(section, label, TofTrialScenario of frame 0, extra)``.

    ``section``: ``baseline``, ``mechanism``, ``sweep``, ``stopping`` or ``long``; ``extra``:
    the mechanism's explanation, the sweep's scheme or the stopping rule's overrides.
    """
    from svgs_sim.sim.tof_trial import TofTrialScenario

    def run(r, frames, label, pipeline=None, reference="markers", scenario=None):
        sc = scenario if scenario is not None else cfg.scenario(r)
        return TofTrialScenario(sc, float(r), int(frames), 0, tuple((pipeline or {}).items()), reference, label)

    out = [("baseline", f"baseline @ {r}", run(r, cfg.frames, f"baseline @ {r}"), None) for r in PAPER_RANGES_M]
    for label, ranges, rkw, skw, pkw, ref, why in _variants(auto_T[PAPER_RANGES_M[1]], auto_T[PAPER_RANGES_M[0]],
                                                               active_near_px):
        for r in ranges:
            sc = cfg.scenario(r, scene=rkw.get("scene_options"), max_bounces=rkw.get("max_bounces", 1), **skw)
            name = f"mechanism {label} @ {r}"
            out.append(("mechanism", label, run(r, cfg.variant_frames, name, pkw, ref, sc), why))
    for scheme, pkw in SWEEP_SCHEMES:
        for r in SWEEP_RANGES_M:
            out.append(("sweep", scheme, run(r, cfg.sweep_frames, f"sweep {scheme} @ {r}", pkw), None))
    for label, pkw in STOPPING_RULES:
        if not pkw:  # the default: the baseline runs and the sweep above
            continue
        for r in (*PAPER_RANGES_M, *SWEEP_RANGES_M):
            n = cfg.variant_frames if r in PAPER_RANGES_M else cfg.sweep_frames
            out.append(("stopping", label, run(r, n, f"stopping {label} @ {r}", pkw), pkw))
    if cfg.long_frames:
        r = PAPER_RANGES_M[0]
        out.append(("long", "long run", run(r, cfg.long_frames, f"long run @ {r}"), None))
    return out


def design_digest(runs) -> str:
    """A digest of the study's runs (section, label, range, frames, pipeline overrides, reference),
    kept in the store's manifest: a store made by another design (the code's runs changed, the
    configuration not) is refused instead of read back under the wrong runs."""
    spec = [[sec, lab, float(f.nominal_range_m), int(f.frames), [list(kv) for kv in f.pipeline], f.reference]
            for sec, lab, f, _ in runs]
    return hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()[:16]


def study_trials(runs) -> list:
    """The study engine's trials: every frame of every run, ids in run order, each with its run's seed."""


    trials = []
    for _, _, first, _ in runs:
        for k in range(first.frames):
            trials.append(Trial(len(trials), replace(first, frame=k), int(first.scenario.seed)))
    return trials


def runs_from_rows(runs, rows) -> list:
    """The stored rows back as the stability runs of :func:`svgs_sim.sim.tof_stability.assemble_run`, one per run."""

    by_label: dict = {}
    for r in rows:
        by_label.setdefault(r["run"], []).append(r)
    out = []
    for _, _, first, _ in runs:
        rr = sorted(by_label[first.run], key=lambda x: x["frame"])
        frame_rows = [{"frame": int(x["frame"]), "ok": bool(x["ok"]), "reason": x["reason"], "n_blobs": x["n_blobs"],
                       "iterations": x["iterations"], **{c: x[f"col_{c}"] for c in COLUMNS}, "rot_err_deg": x["rot_err_deg"],
                       "saturated_pixels": x["saturated_pixels"]} for x in rr]
        info = {k: rr[0][k] for k in RUN_INFO_KEYS}
        info["nf_ok"] = bool(info["nf_ok"])
        out.append(assemble_run(first.nominal_range_m, frame_rows, info, frames=first.frames, reference=first.reference,
                                frames_s=float(sum(x["wall_s"] for x in rr))))
    return out
