"""tools/test_durations.py reads a pytest JUnit report into seconds per file, and the committed
tests/durations.json names files that exist (issue 40: the order make test hands them out)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_seconds_per_file_from_a_junit_report(tmp_path):
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        from test_durations import file_seconds
    finally:
        sys.path.remove(str(ROOT / "tools"))
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "test_a.py").write_text(
        "import time\n\nclass TestK:\n    def test_x(self):\n        time.sleep(0.2)\n\n"
        "def test_y():\n    time.sleep(0.1)\n")
    (tmp_path / "tests" / "test_b.py").write_text("def test_z():\n    pass\n")
    junit = tmp_path / "j.xml"
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
                        f"--junitxml={junit}", "tests"], cwd=tmp_path, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-2000:]
    s = file_seconds(junit)
    assert set(s) == {"tests/test_a.py", "tests/test_b.py"}
    assert s["tests/test_a.py"] == pytest.approx(0.3, abs=0.1) and s["tests/test_b.py"] < 0.1


def test_the_committed_durations_name_test_files_that_exist():
    files = json.loads((ROOT / "tests" / "durations.json").read_text())["files"]
    assert len(files) > 50 and all(v >= 0 for v in files.values())
    missing = [f for f in files if not (ROOT / f).is_file()]
    assert len(missing) <= len(files) // 10, missing  # a renamed file costs order, never a result
