"""The statistical sensor (svgs_sim.sim.statistical_sensor) and its validation (svgs_sim.studies.sensor_model):
draws against the table they come from (the table is the input here, written by hand), the interpolation
against its closed form, the envelope, and the validation's power to reject a wrong model."""

from __future__ import annotations

import json

import numpy as np
import pytest

from svgs_sim.base.errors import InputError
from svgs_sim.sim.statistical_sensor import (
    GROSS_ERROR, MIN_SOLVED_FOR_STATISTICS, WRONG_LOCK, OutsideEnvelope, SensorTable, StatisticalSensor,
)
from svgs_sim.studies.sensor_model import (
    FRAME_COLUMNS, SensorModelConfig, dropout_check, error_check, gross_mask, outcome_of, table_from_rows, _model_at,
)
from svgs_sim.svgs.frames import STATE_KEYS, pose_from_scenario

STD_NEAR = np.array([1e-3, 2e-3, 5e-4, 0.05, 0.08, 0.02])  # m and deg at the near node


def _table(n=100, solved=(80, 40), merged=(20, 60)) -> SensorTable:
    """Two range nodes (2 m, 8 m), one off-axis node: the far node's scatter 4x the near one's (so its
    covariance 16x), correlated x and pitch, a bias, dropouts by one reason."""
    cov_near = np.diag(STD_NEAR**2)
    cov_near[0, 4] = cov_near[4, 0] = 0.9 * STD_NEAR[0] * STD_NEAR[4]
    cov = np.stack([cov_near, 16 * cov_near])[:, None]
    bias = np.array([[1e-3, 0, 0, 0, 0.02, 0], [4e-3, 0, 1e-3, 0, 0.08, 0]])[:, None]
    return SensorTable(camera="galaxy-nexus", pattern="svgs-3u", ranges_m=np.array([2.0, 8.0]),
                       off_axis_deg=np.array([0.0]), attitude_max_deg=8.0, frame_rate_hz=2.0,
                       n=np.full((2, 1), n), n_solved=np.array(solved)[:, None], n_gross=np.zeros((2, 1), int),
                       n_wrong_lock=np.zeros((2, 1), int),
                       dropouts={"too_few_blobs": np.array(merged)[:, None]}, bias=bias, covariance=cov,
                       crlb_std=np.stack([STD_NEAR, 4 * STD_NEAR])[:, None] / 2,
                       wrong_lock_errors=[[[]], [[]]], gross_errors=[[[]], [[]]])


def _draw(sensor, range_m, n, attitude=(1.0, -2.0, 3.0)):
    R, t = pose_from_scenario(range_m, 0.0, 0.0, *attitude)
    return [sensor.measure(0.5 * k, R, t) for k in range(n)]


def test_draws_at_a_node_have_the_tables_bias_covariance_and_dropout_rate():
    sensor = StatisticalSensor(_table(), seed=3)
    ms = _draw(sensor, 2.0, 6000)
    ok = [m for m in ms if m.ok]
    # dropouts: 20 % at the near node, binomial 4-sigma
    p, n = 0.2, len(ms)
    assert abs((n - len(ok)) / n - p) < 4 * np.sqrt(p * (1 - p) / n)
    assert {m.reason for m in ms if not m.ok} == {"too_few_blobs"}
    e = np.array([[m.error[k] for k in STATE_KEYS] for m in ok])
    t = _table()
    se = np.sqrt(np.diag(t.covariance[0, 0]) / len(e))
    assert np.all(np.abs(e.mean(0) - t.bias[0, 0]) < 4 * se)
    assert np.allclose(e.std(0, ddof=1), STD_NEAR, rtol=0.06)
    assert abs(np.corrcoef(e[:, 0], e[:, 4])[0, 1] - 0.9) < 0.02
    # the estimate is the truth plus the error, and the bound is the table's
    m = ok[0]
    assert all(abs(m.estimate[k] - m.truth[k] - m.error[k]) < 1e-12 for k in STATE_KEYS)
    assert m.crlb_std["x_m"] == pytest.approx(STD_NEAR[0] / 2)


def test_between_nodes_the_model_is_interpolated_in_log_range():
    t = _table()
    mid = float(np.sqrt(2.0 * 8.0))  # halfway in log-range: weights 1/2, 1/2
    p = t.probabilities(mid, 0.0)
    assert p["solved"] == pytest.approx(0.5 * (0.8 + 0.4)) and p["too_few_blobs"] == pytest.approx(0.4)
    assert sum(p.values()) == pytest.approx(1.0)
    bias, cov, _ = t.error_statistics(mid, 0.0)
    assert np.allclose(bias, 0.5 * (t.bias[0, 0] + t.bias[1, 0]))
    assert np.allclose(cov, 0.5 * (1 + 16) * t.covariance[0, 0])
    q = t.probabilities(2.0 * (8.0 / 2.0) ** 0.25, 0.0)  # a quarter of the way
    assert q["solved"] == pytest.approx(0.75 * 0.8 + 0.25 * 0.4)


def test_a_node_with_too_few_solved_frames_lends_no_statistics():
    t = _table(solved=(80, MIN_SOLVED_FOR_STATISTICS - 1), merged=(20, 100 - MIN_SOLVED_FOR_STATISTICS + 1))
    t.bias[1, 0] = np.nan
    t.covariance[1, 0] = np.nan
    bias, cov, _ = t.error_statistics(6.0, 0.0)
    assert np.allclose(bias, t.bias[0, 0]) and np.allclose(cov, t.covariance[0, 0])


def test_outside_the_envelope_the_sensor_refuses():
    sensor = StatisticalSensor(_table(), seed=0)
    with pytest.raises(OutsideEnvelope, match="range 9.000 m"):
        _draw(sensor, 9.0, 1)
    with pytest.raises(OutsideEnvelope, match="range 1.500 m"):
        _draw(sensor, 1.5, 1)
    with pytest.raises(OutsideEnvelope, match="attitude"):
        _draw(sensor, 4.0, 1, attitude=(0.0, 9.0, 0.0))
    R, t = pose_from_scenario(4.0, 0.5, 0.0)  # 7 deg off axis, the table has 0 only
    with pytest.raises(OutsideEnvelope, match="off-axis"):
        sensor.measure(0.0, R, t)
    assert isinstance(OutsideEnvelope("x"), InputError)


def test_the_same_seed_gives_the_same_frames():
    a = [m.error for m in _draw(StatisticalSensor(_table(), seed=5), 3.0, 50)]
    b = [m.error for m in _draw(StatisticalSensor(_table(), seed=5), 3.0, 50)]
    c = [m.error for m in _draw(StatisticalSensor(_table(), seed=6), 3.0, 50)]
    assert a == b and a != c


def test_a_wrong_lock_reports_a_stored_wrong_error():
    t = _table()
    t.n_wrong_lock[:] = 10
    t.n_solved[:] -= 10
    t.wrong_lock_errors = [[[np.array([0.5, 0, 0, 0, 0, 0])]], [[np.array([0.7, 0, 0, 0, 0, 0])]]]
    ms = _draw(StatisticalSensor(t, seed=1), 2.0, 2000)
    wl = [m for m in ms if m.wrong_lock]
    assert abs(len(wl) / len(ms) - 0.1) < 4 * np.sqrt(0.09 / len(ms))
    assert all(m.ok and m.error["x_m"] == 0.5 for m in wl)


def test_the_table_survives_its_file_and_a_bad_file_is_refused(tmp_path):
    t = _table()
    t.bias[1, 0] = np.nan  # a node without statistics: NaN in the file (JSON's NaN)
    path = t.save(tmp_path / "sensor_model.json")
    u = SensorTable.load(tmp_path)
    assert np.array_equal(u.n, t.n) and np.allclose(u.covariance, t.covariance) and np.isnan(u.bias[1, 0, 0])
    (tmp_path / "bad.json").write_text(json.dumps({"kind": "something else"}))
    with pytest.raises(InputError, match="not a sensor model"):
        SensorTable.load(tmp_path / "bad.json")
    d = json.loads(path.read_text())
    d["n"] = [[1]]
    (tmp_path / "short.json").write_text(json.dumps(d))
    with pytest.raises(InputError, match="malformed"):
        SensorTable.load(tmp_path / "short.json")
    with pytest.raises(InputError, match="no such file"):
        SensorTable.load(tmp_path / "missing.json")


def _rows_from(table: SensorTable, ranges, seed, scale=1.0) -> list[dict]:
    """Frames drawn by numpy from the table's own laws (not through the sensor), scatter x ``scale``."""
    rng = np.random.default_rng(seed)
    rows = []
    for k, r in enumerate(ranges):
        p = table.probabilities(r, 0.0)
        bias, cov, crlb = table.error_statistics(r, 0.0)
        outcome = rng.choice(list(p), p=np.array(list(p.values())) / sum(p.values()))
        row = {c: None for c in FRAME_COLUMNS}
        row.update({"node": "v", "frame": k, "range_m": r, "off_axis_deg": 0.0, "ok": int(outcome == "solved"),
                    "reason": "" if outcome == "solved" else outcome, "wrong_lock": int(outcome == WRONG_LOCK)})
        if outcome == "solved":
            e = bias + scale * (rng.multivariate_normal(np.zeros(6), cov))
            row.update({f"err_{key}": float(v) for key, v in zip(STATE_KEYS, e)})
            row.update({f"crlb_{key}": float(v) for key, v in zip(STATE_KEYS, crlb)})
        rows.append(row)
    return rows


def test_table_from_rows_recovers_the_laws_the_frames_were_drawn_from():
    truth = _table()
    cfg = SensorModelConfig("galaxy-nexus", ranges_m=(2.0, 8.0), off_axis_deg=(0.0,), frames_per_node=3000)
    rows = []
    for i, r in enumerate((2.0, 8.0)):
        for row in _rows_from(truth, [r] * 3000, seed=10 + i):
            rows.append({**row, "node": f"{i:02d}-00"})
    t = table_from_rows(cfg, rows, {})
    assert t.n.tolist() == [[3000], [3000]]
    for i, p in enumerate((0.8, 0.4)):
        assert abs(t.n_solved[i, 0] / 3000 - p) < 4 * np.sqrt(p * (1 - p) / 3000)
        assert np.allclose(np.sqrt(np.diag(t.covariance[i, 0])), np.sqrt(np.diag(truth.covariance[i, 0])), rtol=0.08)
    assert t.dropouts["too_few_blobs"].sum() == 6000 - t.n_solved.sum()


def _check(table, rows, seed=2):
    bias, std = _model_at(table, rows)
    kinds = [outcome_of(r, b, s) for r, b, s in zip(rows, bias, std)]
    return dropout_check(table, rows, kinds, seed), error_check(table, rows, kinds, bias, std, seed)


def test_the_validation_passes_the_right_model_and_rejects_a_wrong_one():
    table = _table()
    ranges = list(np.exp(np.random.default_rng(0).uniform(np.log(2.0), np.log(8.0), 400)))
    right = _rows_from(table, ranges, seed=1)
    outcomes, ok = _check(table, right)
    assert all(v["within"] for v in outcomes.values()) and outcomes[GROSS_ERROR]["observed"] == 0
    assert min(v["ks_p"] for v in ok.values()) > 0.001
    assert all(v["scatter_ratio_interval90"][0] < 1 < v["scatter_ratio_interval90"][1] * 1.05 for v in ok.values())
    # frames with twice the scatter: every component's ratio near 2 and its KS test rejects
    _, bad = _check(table, _rows_from(table, ranges, seed=1, scale=2.0))
    assert all(1.7 < v["scatter_ratio"] < 2.3 and v["ks_p"] < 1e-4 for v in bad.values())
    # frames that never drop out: the dropout count falls outside the model's interval
    solid = [dict(r, ok=1, reason="") if not r["ok"] else r for r in right]
    for r in solid:
        if r["err_x_m"] is None:
            r.update({f"err_{k}": 0.0 for k in STATE_KEYS})
    assert not _check(table, solid)[0]["too_few_blobs"]["within"]
    # frames with a gross error the table never saw: counted apart, outside the interval when there are many
    gross = [dict(r, err_z_m=1.0) if r["ok"] and k % 10 == 0 else r for k, r in enumerate(right)]
    o, _ = _check(table, gross)
    assert o[GROSS_ERROR]["observed"] >= 20 and not o[GROSS_ERROR]["within"]


def test_an_outcome_the_table_never_saw_keeps_a_small_probability_in_the_interval():
    """The table's 200 frames saw no gross error; one in 400 held-out frames is within the predictive
    interval (the table's counts plus its Jeffreys prior, 1/2 over its frames), 20 are not (the test
    above)."""
    table = _table()
    ranges = list(np.exp(np.random.default_rng(0).uniform(np.log(2.0), np.log(8.0), 400)))
    rows = _rows_from(table, ranges, seed=1)
    one = [dict(r, err_z_m=1.0) if k == min(i for i, x in enumerate(rows) if x["ok"]) else r for k, r in enumerate(rows)]
    o, _ = _check(table, one)
    assert o[GROSS_ERROR]["observed"] == 1 and o[GROSS_ERROR]["within"] and o[GROSS_ERROR]["model_interval90"][0] == 0


def test_gross_errors_are_the_frames_far_from_the_robust_core():
    rng = np.random.default_rng(4)
    e = rng.normal(size=(200, 6)) * [1e-3, 1e-3, 1e-3, 0.1, 0.1, 0.1]
    e[7, 2] += 0.02  # 20 sigma in z
    e[50, 4] += 0.5  # 5 sigma in pitch: not gross
    m = gross_mask(e)
    assert m.tolist() == [i == 7 for i in range(200)]


def test_the_sensor_draws_gross_errors_from_the_nearest_node_that_holds_them():
    t = _table()
    t.n_gross[:] = [[20], [0]]
    t.n_solved[:] = [[60], [40]]
    t.gross_errors = [[[np.array([0, 0, 0.05, 0, 0, 0])]], [[]]]
    ms = _draw(StatisticalSensor(t, seed=2), 8.0, 400) + _draw(StatisticalSensor(t, seed=3), 2.0, 1000)
    far = [m for m in ms[:400] if m.ok and m.error["z_m"] == 0.05]
    near = [m for m in ms[400:] if m.ok and m.error["z_m"] == 0.05]
    assert not far and abs(len(near) / 1000 - 0.2) < 4 * np.sqrt(0.16 / 1000)
