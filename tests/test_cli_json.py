"""``--json`` of the study commands: exactly one JSON object on stdout (the text on stderr), the
keys of its schema (:data:`svgs_sim.cli.json_out.SCHEMAS`, shown in docs/cli.md), values that agree with
the CSV outputs, and the same object in DIR/summary.json. Small runs: geometric trials, scaled
cameras, one render per rendered study."""

import csv
import json

import pytest

from svgs_sim.cli.json_out import SCHEMAS, clean, failures_from_text
from svgs_sim.cli.main import main

STATE = {"x_m", "y_m", "z_m", "roll_deg", "pitch_deg", "yaw_deg"}
RUN = {"trials_run", "already_done", "elapsed_s", "executor"}


def _run(argv, capsys):
    """Run the command; its stdout parsed as one JSON object (json.loads refuses anything else)."""
    rc = main(argv)
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    obj = json.loads(cap.out)
    assert isinstance(obj, dict) and cap.out.count("\n") == 1
    return obj, cap.err


def _csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _same_as_summary_json(obj, out):
    assert json.loads((out / "summary.json").read_text()) == obj


def test_clean_makes_strict_json():
    import numpy as np

    assert clean({"a": np.float64("nan"), "b": (np.int64(2), np.inf), "c": np.array([1.5, np.nan])}) == \
        {"a": None, "b": [2, None], "c": [1.5, None]}
    assert failures_from_text("merged_spots:2;too_few_blobs:1") == {"merged_spots": 2, "too_few_blobs": 1}
    assert failures_from_text("") == {}


def test_every_command_takes_json_and_has_a_schema():
    import argparse

    from svgs_sim.cli.main import build_parser

    def leaves(parser, name):
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            yield name, parser
        for a in subs:
            for n, p in a.choices.items():
                yield from leaves(p, f"{name} {n}")

    commands = dict(leaves(build_parser(), "svgs"))
    assert len(commands) >= 14 and set(commands) == set(SCHEMAS)
    for name, p in commands.items():
        assert any("--json" in a.option_strings for a in p._actions), name


def test_every_schema_is_in_the_cli_doc():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "cli.md").read_text()
    for name, schema in SCHEMAS.items():
        assert schema.rstrip() in text, name


@pytest.mark.slow
def test_campaign_json(tmp_path, capsys):
    out = tmp_path / "campaign"
    obj, err = _run(["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "6", "--ranges",
                     "5,7", "--out", str(out), "--processes", "0", "--no-progress", "--json"], capsys)
    assert "X std  /paper" in err  # the table went to stderr
    assert {"trial_kind", "camera", "ranges", "outputs", "run"} <= set(obj)
    assert obj["trial_kind"] == "geometric" and obj["camera"] == "galaxy-nexus"
    assert set(obj["run"]) == RUN and obj["run"]["trials_run"] == 12
    at5, at7 = obj["ranges"]
    assert (at5["range_m"], at5["trials"]) == (5.0, 6) and at5["solved"] + sum(at5["failures"].values()) == 6
    for key in ("mean_abs_error", "std", "crlb_std"):
        assert set(at5[key]) == STATE
    assert set(at5["paper"]["mean_error"]) == STATE and at5["paper"]["std"]["x_m"] > 0
    assert at7["paper"] == {"mean_error": None, "std": None}  # the paper has no row at 7 m
    rows = {(float(r["range_m"]), r["component"], r["statistic"]): r for r in _csv(out / "summary.csv")}
    assert at5["std"]["z_m"] == pytest.approx(float(rows[(5.0, "z_m", "std")]["simulated"]))
    assert at5["paper"]["mean_error"]["y_m"] == float(rows[(5.0, "y_m", "mean_abs_error")]["paper"])
    assert at7["crlb_std"]["x_m"] == pytest.approx(float(rows[(7.0, "x_m", "crlb_std")]["simulated"]))
    _same_as_summary_json(obj, out)
    # a rerun runs nothing and says so
    again, _ = _run(["campaign", "--camera", "galaxy-nexus", "--trial-kind", "geometric", "--trials", "6", "--ranges",
                     "5,7", "--out", str(out), "--processes", "0", "--no-progress", "--json"], capsys)
    assert again["run"] == {"trials_run": 0, "already_done": 12, "elapsed_s": None, "executor": None}
    assert again["ranges"] == obj["ranges"]


@pytest.mark.slow
def test_sensitivity_json(tmp_path, capsys):
    out = tmp_path / "sobol"
    obj, err = _run(["sensitivity", "--camera", "galaxy-nexus", "--n", "8", "--vary", "range_m=5:30", "--vary",
                     "sigma_px=0.05:0.3", "--out", str(out), "--processes", "0", "--no-progress", "--json"], capsys)
    assert "ranked by ST" in err
    assert obj["method"] == "sobol" and obj["n_trials"] == 8 * 4 and obj["run"]["trials_run"] == 32
    assert [p["name"] for p in obj["parameters"]] == ["range_m", "sigma_px"]
    assert set(obj["indices"]) == {"pos_err_norm_m", "rot_err_deg", "success"}
    rows = {(r["output"], r["parameter"]): r for r in _csv(out / "indices.csv")}
    for k, entries in obj["indices"].items():
        for e in entries:
            assert {"parameter", "S1", "S1_low", "S1_high", "ST", "ST_low", "ST_high"} <= set(e)
            ref = rows[(k, e["parameter"])]["ST"]
            assert (e["ST"] is None and ref in ("", "nan")) or e["ST"] == pytest.approx(float(ref))
    assert obj["ranking"]["pos_err_norm_m"][0][0] == "range_m"
    _same_as_summary_json(obj, out)


@pytest.mark.slow
def test_calibrate_study_json(tmp_path, capsys):
    from test_calibration_study_cli import QUICK

    out = tmp_path / "study"
    obj, err = _run(["calibrate", "study", *QUICK, "--out", str(out), "--json"], capsys)
    assert "1) full calibration" in err
    assert {"config", "key_numbers", "board_set", "timings_s", "outputs", "run"} <= set(obj)
    assert obj["key_numbers"]["n_views_max"] == 8 and obj["config"]["geometric"] is True
    assert set(obj["run"]) and all(set(r) == RUN for r in obj["run"].values())
    assert obj["outputs"]["pose_errors"].endswith("pose_errors.csv")
    assert {r["n_views"] for r in _csv(obj["outputs"]["calibration_convergence"])} == {"4", "8"}
    _same_as_summary_json(obj, out)


@pytest.mark.render
def test_range_sweep_json(small_camera, tmp_path, capsys):
    out = tmp_path / "sweep"
    obj, err = _run(["range-sweep", "--camera", small_camera, "--ranges", "5", "--trials", "2", "--out", str(out),
                     "--processes", "0", "--no-progress", "--json"], capsys)
    assert "range_m" in err and "wrote" in err
    assert {"camera", "ranges", "outputs", "run"} <= set(obj) and set(obj["run"]) == RUN
    (r,) = obj["ranges"]
    assert {"range_m", "trials", "solved", "failures", "bias", "std"} <= set(r)
    assert set(r["bias"]) == STATE and r["trials"] == 2 and obj["run"]["trials_run"] == 2
    (row,) = _csv(out / "summary.csv")
    assert r["success_rate"] == float(row["success_rate"]) and r["failures"] == failures_from_text(row["failures"])
    assert r["solved"] == round(2 * float(row["success_rate"]))
    if r["solved"]:
        assert r["bias"]["z_m"] == pytest.approx(float(row["err_mean_z_m"]))
    _same_as_summary_json(obj, out)


@pytest.mark.render
def test_exposure_study_json(small_camera, tmp_path, capsys):
    out = tmp_path / "exposure"
    obj, err = _run(["exposure-study", "--camera", small_camera, "--ranges", "5", "--remedy", "baseline",
                     "--remedy", "nd=1", "--trials", "2", "--out", str(out), "--processes", "0", "--no-progress",
                     "--json"], capsys)
    assert "| remedy |" in err
    assert [d["remedy"] for d in obj["remedies"]] == ["baseline", "nd=1"] and obj["run"]["trials_run"] == 4
    rows = {r["remedy"]: r for r in _csv(out / "summary.csv")}
    trials = _csv(out / "trials.csv")
    for d in obj["remedies"]:
        (r,) = d["ranges"]
        assert r["success_rate"] == float(rows[d["remedy"]]["5 m"])
        assert r["solved"] == sum(t["ok"] == "True" for t in trials if t["remedy"] == d["remedy"])
        assert r["trials"] == 2 and r["solved"] + sum(r["failures"].values()) == 2
    _same_as_summary_json(obj, out)
