"""Sensitivity analysis: estimators against analytic indices, input validation, a real run."""

import numpy as np
import pytest

from svgs_sim.studies.sensitivity import (SensitivityConfig, Varied, analyze_morris, analyze_sobol, make_config,
                                 morris_design, ranking, sobol_design)
from svgs_sim.studies.store import read_rows
from svgs_sim.cli.main import main
from svgs_sim.base.errors import InputError


def _config(method, n, d=3, lo=-np.pi, hi=np.pi):
    varied = tuple(Varied(f"x{i}", lo, hi, "1", "", False) for i in range(d))
    return SensitivityConfig("galaxy-nexus", varied, {}, method=method, n=n, seed=3)


def _ishigami(x):
    return np.sin(x[:, 0]) + 7.0 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])


def test_sobol_indices_of_the_ishigami_function():
    """Analytic indices (Ishigami & Homma 1990, a = 7, b = 0.1): S1 = (0.3139, 0.4424, 0),
    ST = (0.5576, 0.4424, 0.2437)."""
    cfg = _config("sobol", 4096)
    A, B = sobol_design(cfg)
    scale = lambda u: -np.pi + 2 * np.pi * u  # noqa: E731
    y = [_ishigami(scale(A)), _ishigami(scale(B))]
    for i in range(3):
        ABi = A.copy()
        ABi[:, i] = B[:, i]
        y.append(_ishigami(scale(ABi)))
    res = analyze_sobol(np.concatenate(y), cfg)
    s1_true, st_true = np.array([0.3139, 0.4424, 0.0]), np.array([0.5576, 0.4424, 0.2437])
    np.testing.assert_allclose(res["S1"], s1_true, atol=0.03)
    np.testing.assert_allclose(res["ST"], st_true, atol=0.03)
    assert np.all(res["ST_ci"][:, 0] <= st_true + 0.01) and np.all(res["ST_ci"][:, 1] >= st_true - 0.01)
    assert np.all(res["S1_ci"][:, 1] - res["S1_ci"][:, 0] < 0.2)


def test_morris_mu_star_of_a_linear_function():
    """y = 3 u0 + 1 u1 + 0 u2 in unit coordinates: every elementary effect is the coefficient."""
    cfg = _config("morris", 20, lo=0.0, hi=1.0)
    X, order, delta = morris_design(cfg)
    assert np.all(np.isin(X, np.arange(4) / 3))  # on the 4-level grid
    y = (X @ np.array([3.0, 1.0, 0.0])).ravel()
    res = analyze_morris(y, cfg, {"order": order, "delta": delta})
    np.testing.assert_allclose(res["mu_star"], [3.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(res["sigma"], 0.0, atol=1e-12)


@pytest.mark.parametrize("vary, message", [
    (["range_m=5:30", "exposure_s=0.001:0.01"], "unknown parameter 'exposure_s'.*Known: range_m \\(m\\)"),
    (["range_m=30:5", "sigma_px=0.1:0.2"], "LOW 30 is greater than HIGH 5"),
    (["range_m=5:5", "sigma_px=0.1:0.2"], "empty range 5:5"),
    (["range_m=5:30", "range_m=1:2"], "given twice"),
    (["range_m=0:30", "sigma_px=0.1:0.2"], "range_m LOW: expected a range of 0.09-168 m"),
    (["range_m=5..30", "sigma_px=0.1:0.2"], "expected PARAM=LOW:HIGH"),
    (["range_m=5:30"], "at least two"),
])
def test_bad_vary_is_exit_2_before_any_work(tmp_path, capsys, vary, message):
    import re

    out = tmp_path / "never"
    argv = ["sensitivity", "--camera", "galaxy-nexus", "--n", "8", "--out", str(out)]
    for v in vary:
        argv += ["--vary", v]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert re.search(message, err), err
    assert "Traceback" not in err and not out.exists()


def test_bad_n_and_fixed_are_input_errors():
    with pytest.raises(InputError, match="power of two"):
        make_config("galaxy-nexus", ["range_m=5:30", "sigma_px=0.1:0.2"], n=100)
    with pytest.raises(InputError, match="also varied"):
        make_config("galaxy-nexus", ["range_m=5:30", "sigma_px=0.1:0.2"], fixed=["range_m=10"])
    with pytest.raises(InputError, match="unknown parameter 'foo'"):
        make_config("galaxy-nexus", ["range_m=5:30", "sigma_px=0.1:0.2"], fixed=["foo=1"])
    with pytest.raises(InputError, match="--method"):
        make_config("galaxy-nexus", ["range_m=5:30", "sigma_px=0.1:0.2"], method="fast")


@pytest.mark.slow
def test_sobol_over_seven_parameters_ranks_them(tmp_path, capsys):
    out = tmp_path / "sobol"
    vary = ["range_m=5:30", "roll_deg=-25:25", "yaw_deg=-45:45", "sigma_px=0.05:0.3", "focal_error_frac=-0.02:0.02",
            "pp_error_u_px=-10:10", "merge_px=0:0.5"]
    argv = ["sensitivity", "--camera", "galaxy-nexus", "--n", "32", "--out", str(out), "--processes", "0",
            "--no-progress", "--fixed", "pitch_deg=10"]
    for v in vary:
        argv += ["--vary", v]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "pos_err_norm_m ranked by ST: range_m" in text  # errors grow as range squared: range dominates
    rows = read_rows(out / "results.csv")
    assert len(rows) == 32 * 9 and len({r["trial_id"] for r in rows}) == 32 * 9
    # render once, expose many: AB rows of sigma, focal, pp and merge_px (not part of the projection) reuse
    # the projection of their A row; range, roll and yaw need new ones
    assert f"renders needed: {32 * (3 + 2)} of {32 * 9}" in text
    import csv

    with open(out / "indices.csv", newline="") as fh:
        idx = {(r["output"], r["parameter"]): r for r in csv.DictReader(fh)}
    # merge_px never triggers (the spots are > 30 px apart): no effect, exactly
    assert float(idx[("pos_err_norm_m", "merge_px")]["ST"]) == 0.0
    assert float(idx[("pos_err_norm_m", "range_m")]["ST"]) > 0.3
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 4 and "<table>" in html and "svgs sensitivity" in html

    cfg = make_config("galaxy-nexus", vary, fixed=["pitch_deg=10"], n=32)
    from svgs_sim.studies.sensitivity import analyze, sensitivity_trials
    from svgs_sim.studies.store import read_table

    _, layout = sensitivity_trials(cfg)
    res = analyze(read_table(out / "results.csv"), cfg, layout)
    assert ranking(res, cfg)[0][0] == "range_m" and ranking(res, cfg)[-1][0] == "merge_px"
