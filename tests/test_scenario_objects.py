"""Scenarios as typed objects: profiles read once per process, trial scenarios that read and
write the results store's rows (old rows with their -1/0 sentinels included)."""

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import Camera


@pytest.fixture
def camera_reads(monkeypatch):
    """Counts :meth:`Camera.load` calls that read a profile file (a name or a path; a Camera
    passed in is returned as is and reads nothing), per profile."""
    import svgs_sim.base.profiles as profiles

    reads: dict = {}
    orig = Camera.load.__func__

    def counting(cls, name_or_path, **kw):
        if not isinstance(name_or_path, Camera):
            key = str(name_or_path)  # the cached loader reads by the resolved path
            reads[key] = reads.get(key, 0) + 1
        return orig(cls, name_or_path, **kw)

    monkeypatch.setattr(Camera, "load", classmethod(counting))
    profiles.clear_cache()
    yield reads
    profiles.clear_cache()


def test_the_closed_loop_reads_each_profile_once(camera_reads):
    """Scenario, its true lens, the frame's camera, the solver's pipeline: one read."""
    from svgs_sim.sim.closed_loop import Scenario
    from svgs_sim.svgs.pipeline import solve_image
    from synth_svgs import synth_frame

    sc = Scenario(camera="galaxy-nexus", range_m=10.0, roll_deg=3.0, lens_pp_offset_px=(1.0, 0.0))
    assert isinstance(sc.camera, Camera) and sc.pattern.name == "svgs-3u"
    assert sc.camera_profile() is sc.camera_profile()  # made once, not on every access
    assert sc.camera_profile().cx == sc.camera.cx + 1.0
    R, t = sc.pose()
    img = synth_frame(sc.camera, sc.pattern, R, t, seed=1).image
    sol = solve_image(img, "galaxy-nexus", "svgs-3u")
    assert sol and Scenario(camera="galaxy-nexus") == Scenario(camera="galaxy-nexus")
    assert sum(camera_reads.values()) == 1, camera_reads


@pytest.mark.render
def test_render_and_solve_reads_the_camera_profile_once(camera_reads, tmp_path, capsys):
    from svgs_sim.cli.main import main

    rc = main(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--spp", "2", "--roi-spp", "8",
               "--seed", "1", "--json", "--out", str(tmp_path / "out")])
    assert rc in (0, 1)
    assert list(camera_reads.values()) == [1] and next(iter(camera_reads)).endswith("galaxy-nexus.toml"), camera_reads


def test_stand_scenario_has_a_rail_position_not_a_range():
    from svgs_sim.sim.closed_loop import Scenario

    s = Scenario(camera="galaxy-nexus", mount="stand", rail_m=5.0)
    assert s.range_m is None and s.rail_m == 5.0 and s.distance_m == 5.0
    with pytest.raises(InputError, match="rail_m"):  # range_m is the boresight distance, never the rail
        Scenario(camera="galaxy-nexus", mount="stand", range_m=5.0)
    with pytest.raises(InputError, match="rail_m"):
        Scenario(camera="galaxy-nexus", rail_m=5.0)
    with pytest.raises(InputError, match="range_m"):
        Scenario(camera="galaxy-nexus", mount="stand", rail_m=5.0, range_m=5.0)
    # the pivot on the rail at 5 m, no angles: the camera 5 m from the target along the boresight
    assert np.allclose(s.pose()[1], Scenario(camera="galaxy-nexus", range_m=5.0).pose()[1])


def test_geometric_scenario_is_typed_and_reads_its_rows():
    from svgs_sim.sim.trials import GeometricScenario, geometric_scenario

    s = geometric_scenario(camera="galaxy-nexus", rail_m=6.0, stand=1.0, truth_rail=1.0, sigma_px=0.3,
                           labels={"pose_index": 4})
    assert s.mount == "stand" and s.rail_m == 6.0 and s.range_m is None and s.truth == (False, False, True)
    assert s["rail_m"] == 6.0 and s["range_m"] is None and s["stand"] == 1.0 and s["pose_index"] == 4
    assert s.get("nope") is None
    with pytest.raises(InputError, match="rail_m"):  # the rail position is never written as range_m
        geometric_scenario(camera="galaxy-nexus", range_m=6.0, stand=1.0)
    with pytest.raises(InputError, match="rail_m"):
        geometric_scenario(camera="galaxy-nexus", stand=1.0)
    with pytest.raises(InputError, match="rail"):
        geometric_scenario(camera="galaxy-nexus", range_m=6.0, rail_m=6.0, stand=0.0)
    row = {"trial_id": 3, "seed": 9, **s, "ok": True, "est_x_m": 0.1, "wall_s": 1.0}
    assert GeometricScenario.from_row(row) == s and hash(GeometricScenario.from_row(row)) == hash(s)
    assert GeometricScenario(camera="galaxy-nexus").to_row() == dict(geometric_scenario(camera="galaxy-nexus"))
    with pytest.raises(InputError, match="stand"):
        geometric_scenario(camera="galaxy-nexus", stand=0.5)
    with pytest.raises(InputError, match="label"):
        geometric_scenario(camera="galaxy-nexus", labels={"sigma_px": 1})


def test_render_scenario_reads_old_rows_with_sentinels():
    from svgs_sim.sim.render_trial import RenderKey, RenderScenario, render_key, render_trial_scenario

    defaults = RenderScenario(camera="galaxy-nexus")
    assert defaults.to_row() == dict(render_trial_scenario(camera="galaxy-nexus"))
    assert (defaults.spp, defaults.exposure_s, defaults.threshold, defaults.f_number, defaults.demosaic) == \
        (None, None, None, None, None)
    # a row as the old code wrote it: every parameter a number, -1 / 0 meaning "the default"
    old = dict(defaults.to_row(), spp=-1.0, roi_spp=64.0, f_number=-1.0, jpeg_quality=-1.0, glare_veiling_fraction=-1.0,
               threshold=-1.0, exposure_s=0.0, iso=0.0, demosaic=2.0, backdrop_distance_m=0.0, variant="no_jpeg",
               trial_id=1, seed=2, ok=False)
    s = RenderScenario.from_row(old)
    assert (s.spp, s.roi_spp, s.f_number, s.jpeg_quality, s.glare_veiling_fraction) == (None, 64, None, None, None)
    assert (s.threshold, s.exposure_s, s.iso, s.demosaic, s.scene.backdrop_distance_m) == ("otsu", None, None,
                                                                                      "edge_aware", None)
    assert s.label_dict == {"variant": "no_jpeg"}
    assert {k: s[k] for k in defaults.to_row()} == {k: old[k] for k in defaults.to_row()}  # the row unchanged
    assert isinstance(render_key(s), RenderKey) and render_key(s) == render_key(dict(s, threshold=-2.0))
    assert render_key(s) != render_key(dict(s, pattern_scale=1.5))
    assert RenderScenario(camera="galaxy-nexus", threshold="auto")["threshold"] == -2.0
    assert RenderScenario(camera="galaxy-nexus", threshold=37.0)["threshold"] == 37.0


def test_no_private_names_of_sim_used_outside_sim():
    """Studies and the CLI use sim's public names (no svgs_sim.sim.trials._camera, svgs_sim.sim.render_trial._frame)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    bad = []
    for pkg in ("studies", "cli", "svgs", "render", "camera"):
        for path in (root / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sim"):
                    bad += [f"{path.name}: {node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
    assert not bad, bad


def test_the_pose_fields_are_declared_once():
    """The target's pose besides its range (svgs_sim.sim.target_pose.TargetPose) is declared in one
    class; every scenario inherits it (an AST scan of the package for annotated class fields)."""
    import ast
    from pathlib import Path

    import svgs_sim
    from svgs_sim.sim.closed_loop import Scenario
    from svgs_sim.sim.render_trial import RenderScenario
    from svgs_sim.sim.target_pose import POSE_FIELDS, TargetPose
    from svgs_sim.sim.tof_closed_loop import TofScenario
    from svgs_sim.sim.trials import GeometricScenario
    from svgs_sim.studies.range_sweep import RangeSweepConfig

    root = Path(svgs_sim.__file__).parent
    where = {}
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name) \
                            and item.target.id in POSE_FIELDS:
                        where.setdefault(item.target.id, []).append(f"{path.relative_to(root)}:{node.name}")
    # classes whose angle fields are not a pose: the envelope's limits, a calibration frame's measured roll
    other_meanings = {"svgs/envelope.py:Envelope", "calibration/focal.py:ImageFocal"}
    where = {k: [c for c in v if c not in other_meanings] for k, v in where.items()}
    assert where == {name: ["sim/target_pose.py:TargetPose"] for name in POSE_FIELDS}, where
    for cls in (Scenario, RenderScenario, GeometricScenario, TofScenario, RangeSweepConfig):
        assert issubclass(cls, TargetPose), cls


def test_the_tof_kind_has_a_typed_scenario_that_is_its_row():
    """The `tof` kind registers its typed scenario: the engine gets a TofTrialScenario (its row
    view for the store), and a stored row reads back as the same object."""
    from dataclasses import replace

    from svgs_sim.sim.tof_closed_loop import TofScenario
    from svgs_sim.sim.tof_trial import TofTrialScenario
    from svgs_sim.sim.trials import build_scenario, get_trial_kind

    kind = get_trial_kind("tof")
    assert kind.scenario_type is TofTrialScenario
    ts = TofTrialScenario(TofScenario(range_m=0.697, yaw_deg=3.0, spp=64, ambient_lux=500.0), 0.697, 10, 4,
                          (("max_active_pixels", 300),), "plate", "run-a")
    row = dict(ts)
    assert row == ts.to_row() and row["frame"] == 4 and row["yaw_deg"] == 3.0 and row["render_seed"] == 0
    assert build_scenario(kind, row) == ts and TofTrialScenario.from_row(row) == ts
    assert ts.run_key() == replace(ts, frame=9, run="other").run_key()  # the frames of one run share a render
    with pytest.raises(InputError, match="frame"):
        replace(ts, frame=10)


# ---------------------------------------------------------------- the row codec: a property test
#: Pose fields drawn inside a box where every combination is a valid scenario (the stand's
#: fields only on the stand, the lateral offsets only on a target mount).
_STAND_ONLY = ("stage_m", "misalign_roll_deg", "misalign_pitch_deg", "misalign_yaw_deg", "stand_err_roll_deg",
               "stand_err_pitch_deg", "stand_err_yaw_deg", "stand_err_stage_m", "rail_err_m")
_TARGET_ONLY = ("target_x_m", "target_y_m")


def _random_value(p, rng, integers=()):
    """A value of parameter ``p``: one of its codes (as its word) or a quantity in its domain, drawn
    from the registry's own bounds (capped where they are astronomically wide)."""
    if p.codes and (p.choice_only or rng.random() < 0.3):
        return p.codes[int(rng.integers(len(p.codes)))].word
    lo, hi = p.lower, min(p.upper, max(50.0, 10.0 * p.lower) if p.lower >= 0 else p.upper)
    if p.name.endswith("_deg") and p.name in ("roll_deg", "pitch_deg", "yaw_deg"):
        lo, hi = max(lo, -20.0), min(hi, 20.0)
    v = float(rng.uniform(lo, hi))
    if p.lower_open and v == lo:
        v = hi
    if p.name in integers:  # a switch or a count: the scenario type's own list
        v = float(round(v))
    return v


def _random_trial_scenario(kind, rng):
    from svgs_sim.sim.trials import build_scenario

    stand = bool(rng.random() < 0.5)
    values = {"camera": "galaxy-nexus"}
    for name, p in kind.parameters.items():
        if name in ("stand", "range_m", "rail_m") or rng.random() < 0.3:  # absent: the default
            continue
        if (stand and name in _TARGET_ONLY) or (not stand and name in _STAND_ONLY):
            continue
        values[name] = _random_value(p, rng, (*kind.scenario_type._BOOLS, *kind.scenario_type._INTS))
    if values.get("environment") == "orbit":  # black space: no backdrop, no room light
        values.pop("backdrop_distance_m", None)
        values.pop("ambient_radiance_w_m2_sr", None)
    for body in ("sun", "earth"):  # both angles or neither (eclipse; no Earth); none in the lab
        az, el = f"{body}_azimuth_deg", f"{body}_elevation_deg"
        if values.get("environment") != "orbit" or (az in values) != (el in values):
            values.pop(az, None)
            values.pop(el, None)
    if "earth_azimuth_deg" not in values:  # the Earth's altitude and albedo: with it only
        values.pop("altitude_km", None)
        values.pop("earth_albedo", None)
    distance = float(rng.uniform(1.0, 30.0))
    values.update({"mount": "stand", "rail_m": distance} if stand else {"range_m": distance})
    if stand:  # inside the stand's small geometry
        for k in ("stand_err_stage_m", "rail_err_m"):
            if k in values:
                values[k] = float(rng.uniform(-0.05, 0.05))
    return build_scenario(kind, values, {"pose_index": int(rng.integers(100))})


@pytest.mark.parametrize("kind_name", ["geometric", "render"])
def test_random_scenarios_round_trip_exactly_through_the_results_store(kind_name, tmp_path):
    """Random scenarios of a kind -> the store's row -> ``results.csv`` -> read back -> the same
    scenario, bit for bit (every field, both mounts, codes and quantities)."""
    import svgs_sim.sim.render_trial  # noqa: F401  (registers the render kind)
    from svgs_sim.sim.trials import get_trial_kind
    from svgs_sim.studies.store import ResultStore, read_rows

    kind = get_trial_kind(kind_name)
    rng = np.random.default_rng(20261205)
    scenarios = [_random_trial_scenario(kind, rng) for _ in range(150)]
    mounts = {s.mount for s in scenarios}
    assert mounts == {"stand", "target"}
    columns = ["trial_id", "seed", *scenarios[0].to_row()]
    with ResultStore(tmp_path / "s", {"kind": kind_name}, columns) as store:
        store.append([{"trial_id": i, "seed": i, **s.to_row()} for i, s in enumerate(scenarios)])
    rows = read_rows(tmp_path / "s" / "results.csv", columns)
    for s, row in zip(scenarios, rows):
        back = type(s).from_row(row)
        assert back == s and hash(back) == hash(s), (s, back)
        assert all(getattr(back, f) == getattr(s, f) for f in ("range_m", "rail_m", "mount")), (s, back)
        assert (back.range_m is None) == (s.mount == "stand") and (back.rail_m is None) == (s.mount == "target")


def test_a_format_1_store_reads_and_resumes_with_the_rail_position_in_its_own_column(tmp_path):
    """A store written before ``rail_m`` had its column (format 1: the rail position in ``range_m``
    on stand rows) reads in the current layout and is upgraded on disk when its study runs again,
    every value's text unchanged."""
    import json

    from svgs_sim.studies.store import FORMAT_VERSION, ResultStore, read_rows

    old_cols = ["trial_id", "seed", "camera", "range_m", "stand", "err_x_m"]
    d = tmp_path / "old"
    d.mkdir()
    (d / "manifest.json").write_text(json.dumps({"format_version": 1, "parameters": {"n": 2}, "columns": old_cols}))
    (d / "results.csv").write_text("trial_id,seed,camera,range_m,stand,err_x_m\n"
                                   "0,7,galaxy-nexus,6.021448721844407,1,0.1\n"
                                   "1,8,galaxy-nexus,10.0,0,-0.25\n")
    new_cols = ["trial_id", "seed", "camera", "range_m", "rail_m", "stand", "err_x_m"]
    rows = read_rows(d / "results.csv", new_cols)
    assert rows[0]["rail_m"] == 6.021448721844407 and rows[0]["range_m"] is None
    assert rows[1]["range_m"] == 10.0 and rows[1]["rail_m"] is None
    before = (d / "results.csv").read_bytes()
    with ResultStore(d, {"n": 2}, new_cols) as store:
        assert store.done_ids == {0, 1}
    assert json.loads((d / "manifest.json").read_text())["format_version"] == FORMAT_VERSION == 2
    text = (d / "results.csv").read_text()
    assert text.splitlines() == ["trial_id,seed,camera,range_m,rail_m,stand,err_x_m",
                                 "0,7,galaxy-nexus,,6.021448721844407,1,0.1",
                                 "1,8,galaxy-nexus,10.0,,0,-0.25"], text
    assert before != text.encode() and read_rows(d / "results.csv", new_cols) == rows
    # a store of a newer format is refused, naming the format
    (d / "manifest.json").write_text(json.dumps({"format_version": 99, "parameters": {"n": 2}, "columns": new_cols}))
    with pytest.raises(InputError, match="format 99"):
        ResultStore(d, {"n": 2}, new_cols)
