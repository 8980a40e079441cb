"""The layered package graph (docs/architecture.md) and what ``svgs solve`` loads.

The contracts live in ``pyproject.toml`` (``[tool.importlinter]``); import-linter counts
function-level (lazy) imports too. The second test proves the contract can fail: the same
configuration on a copy of the tree with one lazy import that closes a cycle is broken.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("svgs", "tof", "calibration", "camera", "render", "sim", "studies", "cli", "assets")
LINT = shutil.which("lint-imports", path=str(Path(sys.executable).parent)) or shutil.which("lint-imports")


def _lint(cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(cwd)}
    return subprocess.run([LINT, "--config", "pyproject.toml", "--no-cache"], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def lint_available():
    if LINT is None:
        pytest.fail("lint-imports not found: install the test extra (pip install -e '.[test]')")
    return LINT


def test_import_contracts_are_kept(lint_available):
    r = _lint(ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "0 broken" in r.stdout


def test_import_contract_fails_on_a_cycle(lint_available, tmp_path):
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    for p in PACKAGES:
        shutil.copytree(ROOT / p, tmp_path / p, ignore=shutil.ignore_patterns("__pycache__"))
    # a lazy import from the sensor layer up to the closed loop: svgs -> sim -> svgs
    with open(tmp_path / "svgs" / "frames.py", "a") as fh:
        fh.write("\n\ndef _cycle():\n    from sim.closed_loop import Scenario\n\n    return Scenario\n")
    r = _lint(tmp_path)
    assert r.returncode != 0
    assert "svgs.frames -> sim.closed_loop" in r.stdout


def test_svgs_solve_loads_no_renderer_study_or_calibration_code(tmp_path):
    import cv2
    import numpy as np

    img = tmp_path / "dark.png"
    cv2.imwrite(str(img), np.zeros((1944, 2592), np.uint8))
    code = (
        "import json, sys\n"
        "from cli.main import main\n"
        f"rc = main(['solve', {str(img)!r}, '--camera', 'galaxy-nexus', '--json'])\n"
        "mods = sorted({m.split('.')[0] for m in sys.modules})\n"
        "print(json.dumps({'rc': rc, 'mods': mods}))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["rc"] == 1  # a dark frame: no solution, a clean exit
    loaded = set(out["mods"])
    for forbidden in ("render", "sim", "studies", "calibration", "camera", "tof", "mitsuba", "drjit"):
        assert forbidden not in loaded, f"svgs solve loaded {forbidden}"


def test_every_registered_command_is_in_the_parser():
    """The registry (cli.main.COMMANDS) is the parser: each command and group exists once."""
    from cli.main import COMMANDS, build_parser

    parser = build_parser()
    top = next(a for a in parser._actions if a.dest == "command")
    for group, _module, names in COMMANDS:
        choices = top.choices
        if group is not None:
            sub = next(a for a in top.choices[group]._actions if hasattr(a, "choices") and a.choices)
            choices = sub.choices
        for name in names:
            assert name in choices, (group, name)


def test_building_one_command_registers_only_its_modules():
    from cli.main import _selected

    assert _selected(["solve", "x.png", "--camera", "galaxy-nexus"]) == {"cli.solve"}
    assert _selected(["calibrate", "focal"]) == {"cli.calibrate", "cli.calibrate_study"}
    assert _selected(["tof", "solve"]) == {"cli.tof", "cli.tof_render", "cli.tof_stability"}
    assert _selected(["--help"]) is None and _selected(["no-such-command"]) is None
