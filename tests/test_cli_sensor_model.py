"""``svgs sensor-model build`` / ``validate`` on the command line: checks before any work, the plan, and
a tiny build and validation end to end (rendered)."""

from __future__ import annotations

import json

import pytest

from svgs_sim.cli.main import main


def _run(capsys, argv):
    rc = main(argv)
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_plan_only_prints_the_frames_and_writes_nothing(capsys, tmp_path):
    rc, out, err = _run(capsys, ["sensor-model", "build", "--camera", "galaxy-nexus", "--ranges", "2,5",
                                 "--off-axis-deg", "0,5", "--frames-per-node", "4", "--out", str(tmp_path / "m"), "--plan-only", "--json"])
    assert rc == 0 and json.loads(out)["plan"]["frames"] == 2 * 2 * 4 and not (tmp_path / "m").exists()
    assert "16 rendered frames" in err


@pytest.mark.parametrize("argv, message", [
    (["--ranges", "5,2"], "--ranges"),
    (["--off-axis-deg", "2,4"], "--off-axis-deg"),
    (["--frames-per-node", "1"], "--frames-per-node"),
    (["--attitude-deg", "-1"], "--attitude-deg"),
    (["--chunk-size", "4"], "--chunk-size"),
    (["--camera", "no-such-phone"], "no-such-phone"),
])
def test_bad_build_input_exits_2_before_any_work(capsys, tmp_path, argv, message):
    base = ["sensor-model", "build", "--camera", "galaxy-nexus", "--out", str(tmp_path / "m"), "--processes", "0"]
    rc, _, err = _run(capsys, base + argv)
    assert rc == 2 and message in err and not (tmp_path / "m" / "nodes").exists()


def test_validate_refuses_a_missing_or_foreign_model(capsys, tmp_path):
    rc, _, err = _run(capsys, ["sensor-model", "validate", "--model", str(tmp_path / "none.json"), "--out", str(tmp_path / "v")])
    assert rc == 2 and "no such file" in err
    (tmp_path / "x.json").write_text("{}")
    rc, _, err = _run(capsys, ["sensor-model", "validate", "--model", str(tmp_path / "x.json"), "--out", str(tmp_path / "v")])
    assert rc == 2 and "not a sensor model" in err


@pytest.mark.render
def test_a_tiny_build_and_validation_end_to_end_and_resumed(capsys, tmp_path):
    out = tmp_path / "m"
    argv = ["sensor-model", "build", "--camera", "galaxy-nexus", "--ranges", "3,6", "--off-axis-deg", "0",
            "--frames-per-node", "2", "--out", str(out), "--processes", "0", "--no-progress", "--json"]
    rc, stdout, _ = _run(capsys, argv)
    s = json.loads(stdout)
    assert rc == 0 and s["frames"] == 4 and s["solved"] == 4
    table = json.loads((out / "sensor_model.json").read_text())
    assert table["n"] == [[2], [2]] and "svgs sensor-model build" in table["provenance"]["command"]
    assert (out / "sensor_model.png").is_file() and len((out / "frames.csv").read_text().splitlines()) == 5
    # a rerun renders nothing; other parameters in the same folder are refused
    rc, _, err = _run(capsys, argv[:-1])
    assert rc == 0 and "2 of 2 nodes already" in err
    rc, _, err = _run(capsys, [a if a != "2" else "3" for a in argv])
    assert rc == 2 and "other parameters" in err
    rc, stdout, _ = _run(capsys, ["sensor-model", "validate", "--model", str(out), "--frames", "10", "--out",
                                  str(tmp_path / "v"), "--processes", "0", "--no-progress", "--json"])
    v = json.loads(stdout)
    assert rc in (0, 1) and v["frames"] == 10 and (tmp_path / "v" / "validation.png").is_file()
    assert set(v["errors"]) == {"x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"}
    # two frames a node lend no statistics (fewer than MIN_SOLVED_FOR_STATISTICS): only the outcomes are tested
    assert v["errors"]["x_m"]["n_rendered"] == 0 and v["ks_min_p"] is None and v["outcomes"]["solved"]["observed"] >= 8


def test_validate_plan_only_refuses_a_folder_holding_another_validation(capsys, tmp_path):
    import numpy as np

    from svgs_sim.sim.statistical_sensor import SensorTable

    t = SensorTable(camera="galaxy-nexus", pattern="svgs-3u", ranges_m=np.array([2.0, 8.0]), off_axis_deg=np.array([0.0]),
                    attitude_max_deg=5.0, frame_rate_hz=2.0, n=np.full((2, 1), 10), n_solved=np.full((2, 1), 10),
                    n_gross=np.zeros((2, 1), int), n_wrong_lock=np.zeros((2, 1), int), dropouts={},
                    bias=np.zeros((2, 1, 6)), covariance=np.broadcast_to(np.eye(6) * 1e-6, (2, 1, 6, 6)).copy(),
                    crlb_std=np.full((2, 1, 6), 1e-4), wrong_lock_errors=[[[]], [[]]], gross_errors=[[[]], [[]]])
    t.save(tmp_path / "sensor_model.json")
    (tmp_path / "v").mkdir()
    (tmp_path / "v" / "validation_manifest.json").write_text('{"kind": "sensor-model validate", "seed": 9}')
    rc, _, err = _run(capsys, ["sensor-model", "validate", "--model", str(tmp_path), "--out", str(tmp_path / "v"),
                               "--plan-only"])
    assert rc == 2 and "other parameters" in err
    rc, out, err = _run(capsys, ["sensor-model", "validate", "--model", str(tmp_path), "--out", str(tmp_path / "w"),
                                 "--frames", "20", "--plan-only", "--json"])
    assert rc == 0 and json.loads(out)["plan"]["frames"] == 20 and not (tmp_path / "w").exists()
