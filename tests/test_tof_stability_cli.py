"""``svgs tof stability``: the paper's stability run as a command (JSON schema, paper tables,
outputs, bad input refused before any work)."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from svgs_sim.cli.main import main

if importlib.util.find_spec("mitsuba") is None:
    pytest.skip("Mitsuba is not installed (the 'render' extra)", allow_module_level=True)

pytestmark = pytest.mark.render

#: Our columns, written out: the target's reference point in the camera frame and the state's angles
#: (the paper's x, y, z, pitch, yaw, roll in its order).
COLUMNS = ("target_x_cam_mm", "target_y_cam_mm", "target_z_cam_mm", "roll_deg", "pitch_deg", "yaw_deg")
FAST = ["--frames", "12", "--spp", "16"]


def run_json(capsys, *args):
    rc = main(["tof", "stability", *args, "--json"])
    out = capsys.readouterr().out
    return rc, json.loads(out)


def test_json_schema_and_the_paper_table_at_5712_mm(capsys, tmp_path):
    rc, d = run_json(capsys, "--range", "5.712", *FAST, "--out", str(tmp_path / "run"))
    assert rc == 0
    assert d["range_m"] == 5.712 and d["frames"] == 12 and 0 < d["solved"] <= 12
    assert d["spp"] == 16 and d["rim_spp"] == 16 * 64  # the marker rims get 64x (svgs_sim.render.tof.camera)
    for k in ("average", "maximum", "minimum", "fluctuation", "std", "truth"):
        assert set(d[k]) == set(COLUMNS)
    # Table 2 of the paper, as published (assets/data/tof_2022_stability.csv)
    assert d["paper"]["2"]["fluctuation"]["target_z_cam_mm"] == pytest.approx(2.116)
    assert d["paper"]["2"]["average"]["target_x_cam_mm"] == pytest.approx(5.097)
    assert d["paper"]["2"]["fluctuation"]["roll_deg"] == pytest.approx(0.52, abs=0.005)  # the paper's "pitch"
    r = d["ratio_to_paper"]["2"]
    assert r["target_z_cam_mm"] == pytest.approx(d["fluctuation"]["target_z_cam_mm"] / 2.116)
    for c in COLUMNS:
        assert d["fluctuation"][c] == pytest.approx(d["maximum"][c] - d["minimum"][c])
        assert d["within_2x"]["2"][c] == (0.5 <= r[c] <= 2.0)
    files = {p.name for p in (tmp_path / "run").iterdir()}
    assert {"frames.csv", "summary.json", "stability.png"} <= files
    rows = (tmp_path / "run" / "frames.csv").read_text().splitlines()
    assert rows[0].split(",")[:3] == ["frame", "ok", "reason"] and len(rows) == 13


def test_the_near_range_carries_tables_1_and_3_and_other_ranges_none(capsys):
    rc, d = run_json(capsys, "--range", "0.697", "--frames", "3", "--spp", "8")
    assert rc == 0 and set(d["paper"]) == {"1", "3"}
    assert d["paper"]["3"]["fluctuation"]["target_x_cam_mm"] == pytest.approx(0.378)
    rc, d = run_json(capsys, "--range", "3.0", "--frames", "3", "--spp", "8")
    assert rc == 0 and d["paper"] == {} and d["ratio_to_paper"] == {}


@pytest.mark.parametrize("args, needle", [
    (["--range", "5.712", "--frames", "0"], "--frames"),
    (["--range", "5.712", "--frames", "20001"], "--frames"),
    (["--range", "0.1"], "--range"),
    (["--range", "40"], "--range"),
    (["--range", "nan"], "--range"),
    (["--range", "5.712", "--seed", "-1"], "--seed"),
    (["--range", "5.712", "--camera", "galaxy-nexus"], "phone"),
    (["--range", "5.712", "--sheeting", "tinfoil"], "sheeting"),
    (["--range", "5.712", "--persistence", "0"], "--persistence"),
    (["--range", "5.712", "--rim-spp-factor", "0"], "--rim-spp-factor"),
])
def test_bad_input_is_refused_before_any_work(capsys, args, needle):
    rc = main(["tof", "stability", *args])
    err = capsys.readouterr().err
    assert rc == 2 and needle in err and "Traceback" not in err
    assert "rendering" not in err


def test_an_output_path_that_is_a_file_is_refused_and_nothing_written(capsys, tmp_path):
    f = tmp_path / "taken"
    f.write_text("x")
    rc = main(["tof", "stability", "--range", "5.712", *FAST, "--out", str(f)])
    err = capsys.readouterr().err
    assert rc == 2 and "--out" in err and f.read_text() == "x"


def test_python_m_cli_tof_stability_is_the_command():
    repo = Path(__file__).resolve().parents[1]
    p = subprocess.run([sys.executable, "-m", "svgs_sim.cli.tof_stability", "--range", "5.712", "--frames", "2", "--spp", "8",
                        "--json"], cwd=repo, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    assert d["frames"] == 2 and "2" in d["paper"]


def test_phone_profiles_are_refused_by_every_tof_command(capsys, tmp_path):
    for argv in (["tof", "render-and-solve", "--range", "2", "--camera", "galaxy-nexus"],
                 ["tof", "solve", "--gray", str(tmp_path / "g.npy"), "--depth", str(tmp_path / "d.npy"),
                  "--camera", "htc-amaze-4g"],
                 ["tof", "study", "--camera", "galaxy-nexus", "--out", str(tmp_path / "s")]):
        rc = main(argv)
        err = capsys.readouterr().err
        assert rc == 2 and "phone" in err, argv
    assert not (tmp_path / "s").exists()


def test_the_text_table_keeps_its_columns_apart(capsys):
    """The text table's header has every column's name as its own word, and each row as many
    numbers as there are columns (the names ran together at 11 characters a column)."""
    from svgs_sim.sim.tof_stability import COLUMNS

    assert main(["tof", "stability", "--range", "3.0", "--frames", "3", "--spp", "8"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split() == list(COLUMNS)
    assert all(len(ln[24:].split()) == len(COLUMNS) for ln in lines[2:8])
