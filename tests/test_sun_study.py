"""``svgs sun-study``: the trials' design, each trial's outcome and the cells' bookkeeping."""

from __future__ import annotations

import json

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.base.profiles import load_camera, load_pattern
from svgs_sim.cli.main import main
from svgs_sim.studies.sun_study import (
    MECHANISMS,
    WRONG_LOCK_PX,
    cells,
    classify,
    make_config,
    phase_angle_deg,
    sun_in_fov,
    sun_study_trials,
    wrong_lock_px,
)


def _row(**kw):
    row = {"cell": 0, "range_m": 5.0, "roll_deg": 0.0, "pitch_deg": 0.0, "yaw_deg": 0.0, "sun_azimuth_deg": 90.0,
           "sun_elevation_deg": 60.0, "ok": True, "reason": None, "n_blobs": 4, "match_err_max_px": 0.5,
           "stray_px": 0, "stray_saturated_px": 0}
    row.update(kw)
    return row


def test_each_trial_is_solved_a_wrong_lock_or_a_failure_by_its_reason():
    cam, pat = load_camera("galaxy-nexus"), load_pattern("svgs-3u")
    lim = wrong_lock_px(cam, pat, 5.0)
    assert lim == pytest.approx(max(WRONG_LOCK_PX, np.sqrt(cam.fx * cam.fy) * 0.5 * 0.0254 / 5.0), rel=0.3)
    rows = [_row(), _row(match_err_max_px=lim + 1.0),  # solved; reported with a blob off its spot: a wrong lock
            _row(ok=False, reason="inconsistent", match_err_max_px=lim + 5.0),  # the app reports it; the test flags it
            _row(ok=False, reason="inconsistent", match_err_max_px=0.3),  # right blobs, refused: a failure
            _row(ok=False, reason="merged_spots", match_err_max_px=None, stray_px=900, n_blobs=1),
            _row(ok=False, reason="no_blobs", match_err_max_px=None, stray_px=10 ** 6, stray_saturated_px=10 ** 5,
                 sun_azimuth_deg=0.0, sun_elevation_deg=-89.0),
            # right with the physical envelope's gates; the paper's gates locked onto a glint
            _row(paper_gates_reported=True, paper_gates_match_err_max_px=lim + 2.0)]
    out = classify(rows, cam, pat)[:6]
    assert [c["wrong_lock_paper_gates"] for c in classify(rows, cam, pat)] == [False] * 6 + [True]
    assert [c["outcome"] for c in out] == ["solved", "wrong_lock", "wrong_lock", "inconsistent", "merged_spots", "no_blobs"]
    assert [c["flagged"] for c in out] == [False, False, True, False, False, False]
    assert [c["lit_body"] for c in out] == [False, False, False, False, True, True]
    assert out[5]["sun_in_fov"] and out[5]["saturation"] and not out[0]["sun_in_fov"]


def test_the_cells_add_up_and_name_every_key():
    cfg = make_config("galaxy-nexus", [5.0], [90.0], [60.0], 6)
    rows = [_row(), _row(match_err_max_px=50.0), _row(ok=False, reason="merged_spots", match_err_max_px=None),
            _row(ok=False, reason="merged_spots", match_err_max_px=None), _row(ok=False, reason="no_blobs"),
            _row(n_blobs=6)]
    (c,) = cells(cfg, rows)
    assert set(c) == {"range_m", "sun_azimuth_deg", "sun_elevation_deg", "phase_angle_deg", "trials", "solved",
                      "wrong_lock", "wrong_lock_flagged", "wrong_lock_paper_gates", "reasons", "mechanisms"}
    assert c["solved"] + c["wrong_lock"] + sum(c["reasons"].values()) == c["trials"] == 6
    assert (c["solved"], c["wrong_lock"], c["reasons"]) == (2, 1, {"merged_spots": 2, "no_blobs": 1})
    assert set(c["mechanisms"]) == set(MECHANISMS) and c["mechanisms"]["glint"] == 1
    assert c["phase_angle_deg"] == pytest.approx(30.0)  # the sun 60 deg above the plane: 30 deg off the normal


def test_the_design_draws_the_pose_over_the_papers_envelope_the_same_on_every_run():
    cfg = make_config("galaxy-nexus", [2.0, 5.0], [0.0, 180.0], [-60.0, 30.0], 3, seed=4)
    a, b = sun_study_trials(cfg), sun_study_trials(cfg)
    assert len(a) == cfg.n_trials == 24 and [t.trial_id for t in a] == list(range(24))
    assert [dict(t.scenario) for t in a] == [dict(t.scenario) for t in b] and [t.seed for t in a] == [t.seed for t in b]
    s = np.array([[t.scenario["roll_deg"], t.scenario["pitch_deg"], t.scenario["yaw_deg"]] for t in a])
    assert np.all(np.abs(s[:, :2]) <= 25.0) and np.all(np.abs(s[:, 2]) <= 45.0) and s.std(0).min() > 3.0
    first = a[0].scenario
    assert (first.scene.environment, first.scene.sun_azimuth_deg, first.scene.sun_elevation_deg) == ("orbit", 0.0, -60.0)
    assert a[-1].scenario["range_m"] == 5.0 and a[-1].scenario["cell"] == 7


def test_the_sun_behind_the_target_is_in_the_field_of_view():
    cam = load_camera("galaxy-nexus")
    assert sun_in_fov(cam, _row(sun_azimuth_deg=0.0, sun_elevation_deg=-89.0))
    assert not sun_in_fov(cam, _row(sun_azimuth_deg=0.0, sun_elevation_deg=60.0))  # behind the camera's back
    assert phase_angle_deg(0.0, -90.0) == pytest.approx(180.0)


def test_bad_grids_are_refused_before_any_work(tmp_path, capsys):
    base = ["sun-study", "--camera", "galaxy-nexus", "--ranges", "5", "--trials", "1"]
    for extra, words in ((["--sun-azimuths-deg", "0", "--sun-elevations-deg", "95"], "--sun-elevations-deg"),
                         (["--sun-azimuths-deg", "0,0", "--sun-elevations-deg", "10"], "distinct"),
                         (["--sun-azimuths-deg", "x", "--sun-elevations-deg", "10"], "--sun-azimuths-deg")):
        out = tmp_path / "out"
        rc = main([*base, *extra, "--out", str(out)])
        err = capsys.readouterr().err
        assert rc == 2 and words in err and "Traceback" not in err and not out.exists(), (extra, err)
    with pytest.raises(InputError, match="--trials"):
        make_config("galaxy-nexus", [5.0], [0.0], [10.0], 0)


def test_negative_lists_are_values_not_options(tmp_path, capsys):
    rc = main(["sun-study", "--camera", "galaxy-nexus", "--ranges", "5", "--sun-azimuths-deg", "-90,90",
               "--sun-elevations-deg", "-60,0,60", "--trials", "1", "--out", str(tmp_path / "o"), "--plan-only"])
    assert rc == 0, capsys.readouterr().err


@pytest.mark.render
def test_a_small_study_runs_resumes_and_prints_its_cells(tmp_path, capsys):
    argv = ["sun-study", "--camera", "galaxy-nexus", "--ranges", "5", "--sun-azimuths-deg", "90",
            "--sun-elevations-deg", "-60,60", "--trials", "1", "--out", str(tmp_path / "s"), "--processes", "0",
            "--no-progress", "--json"]
    assert main(argv) == 0
    obj = json.loads(capsys.readouterr().out)
    assert len(obj["cells"]) == 2
    for c in obj["cells"]:
        assert c["solved"] + c["wrong_lock"] + sum(c["reasons"].values()) == c["trials"] == 1
    assert (tmp_path / "s" / "sun_study.png").stat().st_size > 1000
    assert main(argv) == 0  # a rerun: every trial stored
    again = json.loads(capsys.readouterr().out)
    assert again["cells"] == obj["cells"] and again["run"]["trials_run"] == 0


def test_posit_of_collinear_or_coincident_points_is_no_pose_not_a_crash():
    """Sunlit clutter gave the identification a candidate set of collinear blobs: POSIT divided by
    zero inside the compiled kernel and the whole study stopped (found by the first sun study)."""
    from svgs_sim.svgs.solver import posit, solve_centroids

    P = load_pattern("svgs-3u").points_m
    line = np.array([[[0.01 * k, 0.02 * k] for k in range(4)]], float)  # collinear image points
    same = np.zeros((1, 4, 2))  # coincident
    for xy in (line, same):
        R, t = posit(xy, P)
        assert np.isnan(R).all() and np.isnan(t).all()
    cam = load_camera("galaxy-nexus")
    uv = np.array([[1000.0 + 10 * k, 900.0 + 20 * k] for k in range(4)])
    with pytest.raises(InputError, match="degenerate"):  # the solver's own entry refuses such a set, naming it
        solve_centroids(uv, cam, "svgs-3u")
    R, t = posit(np.concatenate([line, cam.pixels_to_normalized(np.array(
        [[1200.0, 900.0], [1200.0, 1000.0], [1200.0, 950.0], [1240.0, 950.0]]))[None]]), P)
    assert np.isnan(R[0]).all() and np.isfinite(R[1]).all()  # one degenerate frame spoils no other


@pytest.mark.parametrize("beta_deg", [0.0, 30.0, 60.0, 75.0])
def test_the_sun_path_spends_the_eclipse_fraction_in_shadow(beta_deg):
    """The fraction of an orbit in the Earth's (cylindrical) shadow, (1 / pi) acos(sqrt(h^2 + 2 R h) /
    ((R + h) cos beta)) (0 beyond beta* = asin(R / (R + h)), 70.2 deg at 400 km: the orbit never enters it);
    and noon at beta 0: the sun radial out, on the target's +x; a quarter orbit later, on its face normal."""
    from svgs_sim.studies.sun_study import sun_path_vbar

    R, h = 6371.0088, 400.0
    az, el, ecl = sun_path_vbar(beta_deg, altitude_km=h, n=20001)
    x = np.sqrt(h * h + 2 * R * h) / ((R + h) * np.cos(np.radians(beta_deg)))
    expected = np.arccos(x) / np.pi if x < 1 else 0.0
    assert ecl[:-1].mean() == pytest.approx(expected, abs=2e-4)
    if beta_deg == 0.0:
        assert (az[0], el[0]) == pytest.approx((0.0, 0.0), abs=1e-9)
        assert el[len(el) // 4] == pytest.approx(90.0, abs=0.05)


def test_the_earths_albedo_is_an_axis_and_the_body_reaches_every_trial():
    cfg = make_config("galaxy-nexus", [5.0], [0.0], [-45.0, 45.0], 2, earth=(0.0, -90.0, 400.0),
                      earth_albedos=[0.05, 0.8], body="3u")
    assert cfg.n_trials == 2 * 2 * 2
    trials = sun_study_trials(cfg)
    albedos = [t.scenario.scene.earth_albedo for t in trials]
    assert albedos == [0.05] * 4 + [0.8] * 4  # the albedo outside the sun's directions
    assert {t.scenario.scene.body for t in trials} == {"3u"}
    # the row holds the body (a results store column), and a trial rebuilt from its row keeps it
    from svgs_sim.sim.render_trial.scenario import RenderScenario

    row = trials[0].scenario.to_row()
    assert RenderScenario.from_row(row).scene.body == "3u"
    m = cfg.manifest()
    assert m["earth_albedos"] == [0.05, 0.8] and m["body"] == "3u"
    # without the Earth no albedos; a mesh body is the single-scene commands'
    with pytest.raises(InputError, match="--earth-albedos"):
        make_config("galaxy-nexus", [5.0], [0.0], [45.0], 1, earth_albedos=[0.3])
    with pytest.raises(InputError, match="--body"):
        make_config("galaxy-nexus", [5.0], [0.0], [45.0], 1, body="plate.ply")
    with pytest.raises(InputError, match="--earth-albedos"):
        make_config("galaxy-nexus", [5.0], [0.0], [45.0], 1, earth=(0.0, -90.0, 400.0), earth_albedos=[0.3, 1.5])


def test_the_cli_refuses_albedos_without_the_earth_before_any_work(tmp_path, capsys):
    rc = main(["sun-study", "--camera", "galaxy-nexus", "--ranges", "5", "--sun-azimuths-deg", "0",
               "--sun-elevations-deg", "45", "--trials", "1", "--earth-albedos", "0.05,0.8", "--out", str(tmp_path / "o")])
    assert rc == 2 and "--earth-albedos" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
