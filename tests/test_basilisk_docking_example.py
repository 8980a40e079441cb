"""examples/basilisk_docking.py: its Hill-equation filter model against the closed-form
Clohessy-Wiltshire solution, and the example itself in its bounded form (``--quick``: from 5 m,
the preview stream, 40 s at most), skipped with its reason where the basilisk extra is missing."""

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "basilisk_docking.py"


def _example():
    spec = importlib.util.spec_from_file_location("basilisk_docking", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_cw_transition_matches_the_closed_form():
    ex = _example()
    n, t = 1.13e-3, 400.0
    Phi, Gam = ex.cw_matrices(n, t)
    x0, y0, z0, u0, v0, w0 = 1.0, -30.0, 0.5, 0.01, -0.02, 0.003
    s, c = np.sin(n * t), np.cos(n * t)
    # Clohessy & Wiltshire (1960); x radial, y along-track, z normal (e.g. Vallado, 4th ed., eq. 6-66)
    x = (4 - 3 * c) * x0 + s / n * u0 + 2 / n * (1 - c) * v0
    y = 6 * (s - n * t) * x0 + y0 - 2 / n * (1 - c) * u0 + (4 * s - 3 * n * t) / n * v0
    z = z0 * c + w0 / n * s
    u = 3 * n * s * x0 + c * u0 + 2 * s * v0
    v = 6 * n * (c - 1) * x0 - 2 * s * u0 + (4 * c - 3) * v0
    w = -z0 * n * s + w0 * c
    np.testing.assert_allclose(Phi @ [x0, y0, z0, u0, v0, w0], [x, y, z, u, v, w], rtol=1e-9, atol=1e-12)
    # a constant along-track push a over t with no initial state: y = a (4 (1 - c) / n^2 - 3 t^2 / 2)
    a = 1e-4
    np.testing.assert_allclose((Gam @ [0, a, 0])[1], a * (4 * (1 - c) / n**2 - 1.5 * t * t), rtol=1e-9)


@pytest.mark.render
def test_quick_form_runs_and_writes_its_figures(tmp_path):
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    ex = _example()
    summary = ex.main(["--quick", "--phones", "galaxy-nexus", "--max-time-s", "16", "--sensor-rate-hz", "0.5",
                       "--out", str(tmp_path)])
    assert (tmp_path / "basilisk_docking_quick_galaxy-nexus.png").is_file()
    assert json.loads((tmp_path / "basilisk_docking_quick.json").read_text()) == json.loads(json.dumps(summary))
    ideal, nexus = summary["ideal"], summary["galaxy-nexus"]
    # the ideal sensor measures the truth: its navigation error is nil
    assert np.max(np.abs(ideal["final_navigation_error_m"])) < 1e-3
    # 16 s at 0.5 frames/s: frames at 0, 2, ..., 16 s, the last released after 16 s
    assert nexus["frames"] == 8 and nexus["frames_solved"] >= 6
    assert nexus["delta_v_m_s"] > 0 and "cost_vs_ideal" in nexus


@pytest.mark.render
def test_the_orbit_form_crosses_the_eclipse_entry_where_basilisk_puts_it(tmp_path):
    """``--environment orbit``: the approach starts 7 s before the eclipse's entry (our cylindrical
    shadow with the Earth's mean radius, by the example's own scan), and the frames' light comes
    from Basilisk's eclipse module: sunlit before 7 s, in shadow from the first frame after it; the
    sun's elevation over the pattern plane (R-bar from above: the face points up, radially) is the
    Earth's horizon dip at the shadow's edge, asin(R / (R + h)) - 90 = -19.8 deg from 407 km."""
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    ex = _example()
    summary = ex.main(["--quick", "--phones", "galaxy-nexus", "--max-time-s", "10", "--sensor-rate-hz", "0.5",
                       "--environment", "orbit",
                       "--case", "rbar-above", "--eclipse-in-s", "7", "--out", str(tmp_path)])
    assert (tmp_path / "basilisk_docking_orbit_rbar_above_quick_phase_galaxy-nexus.png").is_file()
    nexus = summary["galaxy-nexus"]
    light = nexus["light"]
    assert [x["sunlit"] for x in light] == [x["t_s"] < 7.0 for x in light]
    orbit = nexus["orbit"]
    assert [tr["transition"] for tr in orbit["transitions"]] == ["entry"]
    assert orbit["sunlit"]["frames"] + orbit["eclipse"]["frames"] == nexus["frames"]
    assert orbit["sunlit"]["wrong_locks"] == orbit["eclipse"]["wrong_locks"] == 0
    R, h = 6371.0088e3, 6378.1363e3 + 400e3 - 6371.0088e3
    dip = np.degrees(np.arcsin(R / (R + h))) - 90.0
    at_entry = min(light, key=lambda x: abs(x["t_s"] - 7.0))
    assert at_entry["sun_elevation_deg"] == pytest.approx(dip, abs=0.3)


def test_the_eclipse_exit_follows_the_entry_by_the_shadows_arc():
    """The example's ``--transition exit`` starts before the shadow's exit: with the sun in the orbit
    plane (beta 0) a circular orbit of radius r is in the cylindrical shadow for an arc of
    2 asin(R / r) (R the Earth's mean radius, IUGG 6371.0088 km), 140.4 deg from 400 km."""
    pytest.importorskip("astropy", reason="the orbit extra")
    ex = _example()
    R, r = 6371.0088e3, 6378.1363e3 + 400e3
    sun_N = np.array([1.0, 0.0, 0.0])  # along the ascending node of RAAN 0: beta 0
    entry = ex.eclipse_entry_phase_deg(sun_N, 0.0, 51.6, r, "entry")
    exit_ = ex.eclipse_entry_phase_deg(sun_N, 0.0, 51.6, r, "exit")
    assert (exit_ - entry) % 360.0 == pytest.approx(2 * np.degrees(np.arcsin(R / r)), abs=0.02)


def test_the_order_statistic_interval_covers_the_quantile_at_its_level():
    """The percentiles' intervals of --monte-carlo: over 3000 normal samples of 50, the interval of the
    0.9 quantile holds the true one (scipy's normal quantile, not the code's) at least 90 % of the time,
    within the binomial noise of the check; a sample too small for a bound gives None."""
    from scipy.stats import norm

    ex = _example()
    rng = np.random.default_rng(0)
    hits, n = 0, 3000
    for _ in range(n):
        lo, hi = ex.order_statistic_interval(rng.normal(size=50), 0.9)
        hits += lo is not None and hi is not None and lo <= norm.ppf(0.9) <= hi
    assert hits / n >= 0.90 - 3 * np.sqrt(0.09 / n)
    assert ex.order_statistic_interval([1.0, 2.0, 3.0], 0.5) == [None, None]
    assert ex.order_statistic_interval(np.arange(1, 101), 0.99)[1] is None


def test_monte_carlo_dispersions_are_seeded_and_distinct():
    ex = _example()
    seeds = ex.mc_seeds(0, 3)
    assert len(set(seeds)) == 3 and seeds == ex.mc_seeds(0, 3)
    a, ka = ex.mc_dispersions(seeds[0], ex.START_STATE)
    b, _ = ex.mc_dispersions(seeds[0], ex.START_STATE)
    c, _ = ex.mc_dispersions(seeds[1], ex.START_STATE)
    assert a == b and a != c
    R = ka["thrust"].R_error
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)  # a rotation
    ang = np.degrees(np.arccos((np.trace(R) - 1) / 2))
    assert ang == pytest.approx(abs(next(r for r in a if r["variable"] == "thrust_misalignment_deg")["value"]), abs=1e-9)
    thr = ex.ThrustErrors(1.0, np.eye(3), 5e-4)
    weak = np.array([1e-5, 0.0, 0.0])  # 1e-4 N s over the 1 s period: below the bit
    assert np.all(thr.apply(weak) == 0) and np.allclose(thr.apply(100 * weak), 100 * weak)


@pytest.mark.render
@pytest.mark.slow
def test_the_monte_carlo_writes_its_runs_and_percentiles(tmp_path):
    """The issue's acceptance form, shortened to 6 s of flight: distinct seeds, the phone's 2 frames/s,
    the ideal sensor on the same seeds, percentiles of every quantity."""
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    ex = _example()
    ex.main(["--quick", "--monte-carlo", "2", "--phones", "galaxy-nexus", "--max-time-s", "6", "--processes", "2",
             "--out", str(tmp_path)])
    mc = json.loads((tmp_path / "montecarlo.json").read_text())
    assert (tmp_path / "montecarlo.png").is_file() and mc["sensor_rate_hz"] == 2.0
    assert len({r["seed"] for r in mc["runs"]}) == 2 and [r["seed"] for r in mc["ideal_runs"]] == [r["seed"] for r in mc["runs"]]
    for r in mc["runs"]:
        assert r["frames"] >= 10 and r["delta_v_m_s"] > 0 and set(r) >= {"arrival_error_m", "arrival_time_s",
                                                                        "dropouts", "dropouts_by_reason", "wrong_locks"}
    assert set(mc["percentiles"]) == {"arrival_error_m", "arrival_time_s", "delta_v_m_s", "dropouts", "wrong_locks"}
    assert set(mc["percentiles"]["delta_v_m_s"]) >= {"p50", "p90", "p99", "ci90"}


def _write_table(path, camera="galaxy-nexus", rate=2.0):
    """A hand-written sensor model over 0.8-8 m (errors of a few mm, 10 % dropouts)."""
    from svgs_sim.sim.statistical_sensor import SensorTable

    cov = np.diag([2e-3, 2e-3, 1e-3, 0.05, 0.05, 0.02]) ** 2
    t = SensorTable(camera=camera, pattern="svgs-3u", ranges_m=np.array([0.8, 8.0]), off_axis_deg=np.array([0.0, 10.0]),
                    attitude_max_deg=8.0, frame_rate_hz=rate, n=np.full((2, 2), 50), n_solved=np.full((2, 2), 45),
                    n_gross=np.zeros((2, 2), int),
                    n_wrong_lock=np.zeros((2, 2), int), dropouts={"too_few_blobs": np.full((2, 2), 5)},
                    bias=np.zeros((2, 2, 6)), covariance=np.broadcast_to(cov, (2, 2, 6, 6)).copy(),
                    crlb_std=np.full((2, 2, 6), 1e-4), wrong_lock_errors=[[[], []], [[], []]],
                    gross_errors=[[[], []], [[], []]])
    path.mkdir(parents=True, exist_ok=True)
    t.save(path / "sensor_model.json")
    return path


@pytest.mark.slow
def test_the_statistical_monte_carlo_runs_resumes_and_checks_its_tables(tmp_path, capsys):
    """--statistical-runs without rendering: its runs on the rendered runs' seeds, a resumed rerun that
    flies nothing again, another table's runs flown again, and tables refused before any run (another
    phone's, another rate)."""
    pytest.importorskip("Basilisk", reason="the basilisk extra is not installed (pip install -e \".[basilisk]\")")
    from svgs_sim.base.errors import InputError

    ex = _example()
    models = str(tmp_path / "model-{phone}")
    _write_table(tmp_path / "model-galaxy-nexus")
    argv = ["--monte-carlo", "0", "--statistical-runs", "3", "--phones", "galaxy-nexus", "--start-z-m", "3",
            "--max-time-s", "15", "--processes", "0", "--sensor-models", models, "--out", str(tmp_path / "mc")]
    mc = ex.main(argv)
    runs = mc["sensors"]["galaxy-nexus (statistical)"]["runs"]
    assert [r["seed"] for r in runs] == ex.mc_seeds(0, 3) == [r["seed"] for r in mc["ideal_runs"]]
    assert all(r["frames"] >= 25 for r in runs) and sum(r["dropouts"] for r in runs) > 0
    assert mc["statistical_runs"] == 3 and mc["sensor_rate_hz"] == 2.0
    assert mc["complete"] and mc["sensors"]["galaxy-nexus (statistical)"]["runs_done"] == 3
    # --report-only with more runs asked: nothing flown, the report of the 3 stored, said incomplete
    more = list(argv)
    more[argv.index("--statistical-runs") + 1] = "5"
    part = ex.main(more + ["--report-only"])
    assert not part["complete"] and part["sensors"]["galaxy-nexus (statistical)"]["runs_done"] == 3
    assert part["sensors"]["galaxy-nexus (statistical)"]["runs_requested"] == 5 and len(part["ideal_runs"]) == 3
    capsys.readouterr()
    again = ex.main(argv)
    assert "6 of 6 runs already" in capsys.readouterr().err
    assert json.loads(json.dumps(again)) == json.loads((tmp_path / "mc" / "montecarlo.json").read_text())
    (tmp_path / "mc" / "montecarlo_runs.jsonl").unlink()  # the committed form: montecarlo.json alone resumes
    assert ex.main(argv) == again and "6 of 6 runs already" in capsys.readouterr().err
    # another table in the same place: the stored statistical runs are flown again, the ideal ones kept
    t = json.loads((tmp_path / "model-galaxy-nexus" / "sensor_model.json").read_text())
    t["n_solved"], t["dropouts"]["too_few_blobs"] = [[50, 50], [50, 50]], [[0, 0], [0, 0]]
    (tmp_path / "model-galaxy-nexus" / "sensor_model.json").write_text(json.dumps(t))
    third = ex.main(argv)
    assert "3 stored statistical runs were drawn from other sensor models" in capsys.readouterr().err
    assert sum(r["dropouts"] for r in third["sensors"]["galaxy-nexus (statistical)"]["runs"]) == 0
    assert third["ideal_runs"] == again["ideal_runs"]
    _write_table(tmp_path / "model-galaxy-nexus", camera="htc-amaze-4g")
    with pytest.raises(InputError, match="not of galaxy-nexus"):
        ex.main(argv[:-1] + [str(tmp_path / "other")])
    _write_table(tmp_path / "model-galaxy-nexus", rate=1.0)
    with pytest.raises(InputError, match="built at 1 frames/s"):
        ex.main(argv[:-1] + [str(tmp_path / "other")])
    assert not (tmp_path / "other" / "montecarlo_runs.jsonl").exists()
