"""The scene part (svgs_sim.sim.scene): declared once, it reaches the row, the CLI and the render
key by itself, and random scenarios round-trip exactly through the results store's flat row."""

import dataclasses
import math

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.cli.main import build_parser, main
from svgs_sim.sim.closed_loop import Scenario
from svgs_sim.sim.lab import load_lab
from svgs_sim.sim.render_trial import RENDER_PARAMETERS, RenderScenario, render_key, render_trial_scenario
from svgs_sim.sim.scene import Scene, scene_from_args
from svgs_sim.studies.range_sweep import make_config

RENDERING_COMMANDS = (("render",), ("render-and-solve",), ("range-sweep",), ("approach",))


def _random_scene(rng) -> Scene:
    kw = {}
    orbit = rng.random() < 0.3
    given = {flag: orbit and rng.random() < 0.7 for flag in ("--sun-deg", "--earth-deg")}
    for name, q in Scene.quantities().items():
        if q.component is not None:  # the sun, the Earth: both components, on orbit only
            kw[name] = float(rng.uniform(q.lower, q.upper)) if given[q.flag] else None
            continue
        if name == "environment":
            kw[name] = "orbit" if orbit else "lab"
            continue
        if q.choices:
            kw[name] = str(rng.choice(q.choices))
            continue
        if orbit and name in ("backdrop_distance_m", "ambient_radiance_w_m2_sr"):
            continue  # none in orbit
        if name in ("altitude_km", "earth_albedo"):  # the Earth's: with it only
            if given["--earth-deg"]:
                kw[name] = float(rng.uniform(q.lower, min(q.upper, 2000.0)))
            continue
        hi = min(q.upper, 50.0)
        v = float(rng.uniform(q.lower, hi))
        if q.lower_open and v == q.lower:
            v = hi
        kw[name] = None if (q.none_means and rng.random() < 0.3) else v
    for name, q in Scene.quantities().items():
        if not q.trial:  # not a row column: the lab's
            kw[name] = getattr(Scene(), name)
    return Scene(**kw)


def _random_render_scenario(rng) -> RenderScenario:
    return RenderScenario(
        camera="galaxy-nexus", range_m=float(rng.uniform(1.0, 30.0)), roll_deg=float(rng.uniform(-10, 10)),
        scene=_random_scene(rng), spp=None if rng.random() < 0.5 else int(rng.integers(1, 64)),
        roi_spp=None if rng.random() < 0.5 else int(rng.integers(1, 256)),
        exposure_s=None if rng.random() < 0.5 else float(rng.uniform(1e-4, 0.05)),
        render_seed=int(rng.integers(2**31)))


def test_the_defaults_are_the_labs():
    lab = load_lab()
    s = Scene()
    assert (s.backdrop_distance_m, s.backdrop_reflectance, s.ambient_radiance_w_m2_sr) == \
        (lab.backdrop_distance_m, lab.backdrop_reflectance, lab.ambient_radiance_w_m2_sr)
    assert Scenario().scene == s and RenderScenario(camera="galaxy-nexus").scene == s


def test_random_scenes_round_trip_exactly_through_the_row():
    rng = np.random.default_rng(20261205)
    for _ in range(300):
        s = _random_scene(rng)
        assert Scene.from_row(s.row_values()) == s
        r = _random_render_scenario(rng)
        row = r.to_row()
        # floats; the one distance that does not apply (rail_m on a target mount) is empty
        optional = ("rail_m", "sun_azimuth_deg", "sun_elevation_deg", "earth_azimuth_deg",
                    "earth_elevation_deg")  # empty where they do not apply
        assert all(isinstance(v, float) for k, v in row.items() if k not in ("camera", "pattern", *optional)), row
        assert row["rail_m"] is None and all(row[k] is None or isinstance(row[k], float) for k in optional)
        back = RenderScenario.from_row(row)
        assert back == r, (r, back)
        assert render_key(back) == render_key(r)
        assert render_trial_scenario(**row) == r


def test_every_trial_quantity_is_a_row_column_an_option_and_a_key_field():
    params = Scene.quantities()
    trial = [n for n, q in params.items() if q.trial]
    assert trial and set(trial) <= set(RENDER_PARAMETERS)
    for name in trial:
        p, q = RENDER_PARAMETERS[name], params[name]
        assert (p.unit, p.lower, p.upper) == (q.unit, q.lower, q.upper)
        assert [c.word for c in p.codes] == list(q.choices)  # a choice's words are its codes
        assert p.optional == (q.none_means is not None and q.row_none is None)  # none as an empty cell
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for (cmd,) in RENDERING_COMMANDS:
        flags = {s: a for a in sub[cmd]._actions for s in a.option_strings}
        for name in trial:
            q = params[name]
            flag = q.flag or "--" + name.replace("_", "-")
            if not q.option:  # the commands' own option, where they take it (--body, which takes a mesh file too)
                continue
            assert flag in flags, (cmd, flag)
            if q.choices:  # a choice: its words, checked by argparse
                assert tuple(flags[flag].choices) == q.choices
                continue
            if q.component is not None:  # a component of a shared option (--sun-deg AZ,EL): checked by the scene
                continue
            lo, hi, _ = flags[flag].bounds
            assert (lo, hi) == (q.lower, q.upper)
    # a different scene is a different render (the key holds the part)
    a = RenderScenario(camera="galaxy-nexus")
    assert render_key(a) != render_key(dataclasses.replace(a, scene=a.scene.replace(ambient_radiance_w_m2_sr=0.0)))


def test_the_cli_builds_the_scene_none_from_its_code():
    parser = build_parser()
    args = parser.parse_args(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--backdrop-m", "0",
                              "--ambient", "0.5"])
    assert scene_from_args(args) == Scene(backdrop_distance_m=None, ambient_radiance_w_m2_sr=0.5)
    args = parser.parse_args(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10"])
    assert scene_from_args(args) == Scene()


@pytest.mark.parametrize("kw, words", [
    (dict(backdrop_distance_m=-1.0), ("backdrop_distance_m", "> 0 and <= 1000 m", "None for none")),
    (dict(backdrop_distance_m=0.0), ("backdrop_distance_m", "> 0")),
    (dict(backdrop_reflectance=1.5), ("backdrop_reflectance", "0 to 1")),
    (dict(ambient_radiance_w_m2_sr=math.nan), ("ambient_radiance_w_m2_sr", "W m^-2 sr^-1")),
    (dict(ambient_radiance_w_m2_sr="dark"), ("ambient_radiance_w_m2_sr", "'dark'")),
])
def test_a_bad_scene_is_refused_naming_the_field_and_its_domain(kw, words):
    with pytest.raises(InputError) as e:
        Scene(**kw)
    for w in words:
        assert w in str(e.value), (w, str(e.value))
    assert "(-1" not in str(e.value) and " -1:" not in str(e.value)  # no sentinel in the message


def test_the_cli_refuses_a_scene_out_of_its_domain_before_any_work(capsys, tmp_path):
    rc = main(["render-and-solve", "--camera", "galaxy-nexus", "--range", "10", "--ambient", "-1",
               "--out", str(tmp_path / "o")])
    assert rc == 2
    err = capsys.readouterr().err
    assert "--ambient" in err and "W m^-2 sr^-1" in err
    assert not (tmp_path / "o").exists()


def test_the_range_sweep_config_holds_a_scene_and_writes_the_old_manifest():
    cfg = make_config("galaxy-nexus", [5.0, 10.0], scene=Scene(backdrop_distance_m=None))
    m = cfg.manifest()
    # the manifest of 0.1 (flat row values) so an old folder resumes
    assert (m["backdrop_distance_m"], m["ambient_radiance_w_m2_sr"], m["spp"], m["exposure_s"]) == \
        (0.0, load_lab().ambient_radiance_w_m2_sr, -1, 0.0)
    assert cfg.spp is None and cfg.exposure_s is None
    with pytest.raises(InputError, match="scene"):
        make_config("galaxy-nexus", [5.0], scene={"backdrop_distance_m": 1.0})


# ---------------------------------------------------------------- the environment: lab or orbit
def test_orbit_has_no_backdrop_and_no_room_light_and_refuses_the_labs_options(capsys):
    s = Scene(environment="orbit")
    assert (s.backdrop_distance_m, s.ambient_radiance_w_m2_sr) == (None, 0.0)
    assert Scene.from_row(s.row_values()) == s and s.row_values()["environment"] == 1.0
    assert Scene().environment == "lab" and Scene().row_values()["environment"] == 0.0
    with pytest.raises(InputError, match="orbit"):
        Scene(environment="orbit", ambient_radiance_w_m2_sr=0.5)
    with pytest.raises(InputError, match="environment"):
        Scene(environment="mars")
    for cmd in ("render", "render-and-solve", "approach"):
        rng = ["--range", "5"] if cmd != "approach" else ["--from", "6", "--to", "5", "--duration", "1", "--fps", "1"]
        rc = main([cmd, "--camera", "galaxy-nexus", *rng, "--environment", "orbit", "--ambient", "0.1",
                   "--out", "never-made"])
        err = capsys.readouterr().err
        assert rc == 2 and "--ambient" in err and "orbit" in err and "Traceback" not in err, (cmd, err)


def test_the_approach_records_a_scene_only_when_it_is_not_the_lab():
    from svgs_sim.sim.approach import Trajectory
    from svgs_sim.studies.approach import make_config, scene_of

    traj = Trajectory.straight(6.0, 5.0, 1.0)
    lab = make_config("galaxy-nexus", traj, 1.0)
    assert "scene" not in lab and scene_of(lab) == Scene()  # a folder made before the option resumes
    orbit = make_config("galaxy-nexus", traj, 1.0, scene=Scene(environment="orbit"))
    assert scene_of(orbit) == Scene(environment="orbit")


@pytest.mark.render
def test_in_orbit_space_is_black_and_the_flash_lit_target_still_solves(tmp_path):
    """Black space: every pixel that sees no part of the target gets no photon at all (no source
    behind it), where the lab's backdrop and room light reach every pixel; the spots are the same
    flash-lit spots, and the pose solves."""
    import json

    for env in ("lab", "orbit"):
        rc = main(["render", "--camera", "galaxy-nexus", "--range", "5", "--environment", env, "--seed", "1",
                   "--out", str(tmp_path / env)])
        assert rc == 0
    orbit, lab = np.load(tmp_path / "orbit" / "flux.npy"), np.load(tmp_path / "lab" / "flux.npy")
    assert (orbit == 0).mean() > 0.99 and (lab > 0).all()
    truth = json.loads((tmp_path / "orbit" / "truth.json").read_text())
    assert truth["scenario"]["environment"] == "orbit" and truth["scenario"]["backdrop_distance_m"] is None
    # the corner of the frame: the lab's closed-form radiance, nothing in orbit
    assert orbit[:50, :50].max() == 0.0 and lab[:50, :50].min() > 0
    rc = main(["render-and-solve", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit", "--seed", "1",
               "--json"])
    assert rc == 0


def test_the_sun_is_given_as_az_el_on_orbit_only(capsys):
    parser = build_parser()
    args = parser.parse_args(["render", "--camera", "galaxy-nexus", "--range", "5", "--environment", "orbit",
                              "--sun-deg=-30,10", "--out", "never-made"])
    s = scene_from_args(args)
    assert (s.sun_azimuth_deg, s.sun_elevation_deg) == (-30.0, 10.0)
    d = np.array(s.sun_direction_target)
    assert d == pytest.approx([np.cos(np.deg2rad(10)) * np.cos(np.deg2rad(-30)),
                               np.cos(np.deg2rad(10)) * np.sin(np.deg2rad(-30)), np.sin(np.deg2rad(10))])
    assert Scene(environment="orbit").sun_direction_target is None  # eclipse
    assert Scene.from_row(s.row_values()) == s and Scene.from_row(Scene(environment="orbit").row_values()).sun_azimuth_deg is None
    for argv, words in ((["--sun-deg=30,10"], "orbit only"), (["--environment", "orbit", "--sun-deg", "30"], "2 numbers"),
                        (["--environment", "orbit", "--sun-deg=30,100"], "sun_elevation_deg")):
        rc = main(["render", "--camera", "galaxy-nexus", "--range", "5", *argv, "--out", "never-made"])
        err = capsys.readouterr().err
        assert rc == 2 and words in err and "Traceback" not in err, (argv, err)
