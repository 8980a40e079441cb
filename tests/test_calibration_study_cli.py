"""``svgs calibrate study`` end to end in its geometric mode (no Mitsuba: seconds), and bad input."""

import csv
import json

import pytest

from svgs_sim.cli.main import main

QUICK = ["--camera", "galaxy-nexus", "--width", "640", "--height", "480", "--geometric", "--views-list", "4,8",
         "--subsets", "2", "--focal-ranges", "1,3,5,10", "--focal-exposures", "2", "--pose-ranges", "2,5,10,20,30",
         "--poses-per-range", "4", "--processes", "0", "--no-progress"]


def _csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_study_writes_report_csv_and_summary(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "study"
    rc = main(["calibrate", "study", *QUICK, "--out", "study"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    text = cap.out
    assert "1) full calibration" in text and "2) paper's focal method" in text and "Table 4:" in text
    assert "N =   8" in text
    files = {p.name for p in out.iterdir()}
    assert {"report.html", "summary.json", "calibration_convergence.csv", "focal_method.csv", "pose_errors.csv",
            "table4_comparison.csv", "cameras.csv", "focal_frames.csv"} <= files
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64") == 5 and "Table 4" in html and "--geometric" in html
    assert str(tmp_path) not in html  # no absolute paths of this machine
    rows = _csv(out / "pose_errors.csv")
    by = {(r["case"], r["range_m"], r["noise_px"]): r for r in rows}
    # focal +1 %: Z bias 1 % of the range, at 30 m 0.3 m
    assert float(by[("focal +1 %", "30.0", "0.0")]["mean_z_m"]) == pytest.approx(0.3, rel=0.05)
    s = json.loads((out / "summary.json").read_text())
    assert s["config"]["geometric"] is True and s["key_numbers"]["n_views_max"] == 8
    assert abs(s["key_numbers"]["focal_only_error_pct"]) < 1.0
    conv = _csv(out / "calibration_convergence.csv")
    assert {r["n_views"] for r in conv} == {"4", "8"}


@pytest.mark.parametrize("args, what", [
    (["--views-list", "2,5"], "minimum 3"),
    (["--views-list", "five"], "not a number"),
    (["--true-dist", "0.1,0"], "5 numbers"),
    (["--true-pp-offset-px", "9000", "0"], "expected -1000 to 1000 px"),
    (["--focal-ranges", "0.01"], "closer than"),  # the validation layer: the phone's range envelope
    (["--cols", "2"], "at least 3"),
    (["--subsets", "0"], "--subsets"),
    (["--width", "100"], "--width and --height"),
    (["--camera", "nope"], "unknown camera"),
    (["--processes", "-1"], "--processes"),
    (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler"),  # unreachable (or Dask missing): before any work
])
def test_study_bad_input(tmp_path, capsys, args, what):
    argv = ["calibrate", "study", "--camera", "galaxy-nexus", "--geometric", "--out", str(tmp_path / "o"), *args]
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and what in err and "Traceback" not in err


def test_study_out_is_a_file(tmp_path, capsys):
    f = tmp_path / "x"
    f.write_text("")
    rc = main(["calibrate", "study", *QUICK, "--out", str(f)])
    assert rc == 2 and "not a folder" in capsys.readouterr().err
